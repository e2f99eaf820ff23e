"""Sequences: many frames of one scene's yarn curves drawn by one ``pipeline.Renderer`` (packs read, kernels compiled
and the environment fitted once), each written as a PNG (and optionally an EXR) named from a pattern, and optionally
gathered into an animated GIF (imageio).

File patterns: the first run of ``#`` in a file name is replaced by the frame number, zero-padded to the run's length
(``out/frame_####.png`` → ``out/frame_0007.png``); a pattern without ``#`` is refused for more than one frame (every
frame would overwrite the last).
"""

from __future__ import annotations

import re
import time
from pathlib import Path

import numpy as np

from data_formats.atomic import atomic_path
from data_formats.errors import FormatError
from data_formats.images import tonemap, write_exr, write_png

_RUN = re.compile(r"#+")


def frame_path(pattern, frame: int) -> Path:
    """``pattern`` with its first run of ``#`` in the file name replaced by ``frame``, zero-padded to its length."""
    pattern = Path(pattern)
    match = _RUN.search(pattern.name)
    if match is None:
        return pattern
    name = pattern.name[:match.start()] + f"{frame:0{len(match.group())}d}" + pattern.name[match.end():]
    return pattern.with_name(name)


def parse_frames(text: str, count: int) -> range:
    """Frames ``A:B`` (B exclusive, as a Python slice; ``A:`` to the end, ``N`` one frame) of a scene whose curves
    have ``count`` frames; FormatError (one line) for anything else or a range outside [0, count)."""
    match = re.fullmatch(r"\s*(\d*)\s*(?::\s*(\d*)\s*)?", text)
    if match is None or (match.group(2) is None and not match.group(1)):
        raise FormatError(f"--frames {text!r}: expected A:B (B exclusive), A: or N")
    start = int(match.group(1) or 0)
    stop = start + 1 if match.group(2) is None and ":" not in text else int(match.group(2) or count)
    if not 0 <= start < stop <= count:
        raise FormatError(f"--frames {text!r}: the scene's curves have {count} frame(s), frames 0 to {count - 1}")
    return range(start, stop)


def render_sequence(renderer, frames: range, png_pattern, *, exposure: float = 0.0, exr_pattern=None, gif=None,
                    gif_fps: float = 12.0, on_frame=None) -> list:
    """Draw ``frames`` with ``renderer`` and write each to ``frame_path(png_pattern, frame)`` (and to
    ``exr_pattern``); with ``gif`` also an animated GIF of the tone-mapped frames at ``gif_fps``. Returns one record
    per frame: frame, png, ms (the whole frame: draw and write) and ms per pass; ``on_frame(record)`` is called as
    each one ends."""
    if len(frames) > 1:
        for name, pattern in (("PNG", png_pattern), ("EXR", exr_pattern)):
            if pattern is not None and _RUN.search(Path(pattern).name) is None:
                raise FormatError(f"{pattern}: a {name} pattern for {len(frames)} frames needs a run of '#' for the "
                                  f"frame number, e.g. out/frame_####.png")
    records, stills = [], []
    for frame in frames:
        start = time.perf_counter()
        result = renderer.render(frame)
        png = frame_path(png_pattern, frame)
        write_png(png, result.image, exposure)
        if exr_pattern is not None:
            write_exr(frame_path(exr_pattern, frame), result.image)
        if gif is not None:
            stills.append(tonemap(result.image, exposure))
        record = {"frame": frame, "png": str(png), "ms": (time.perf_counter() - start) * 1e3,
                  "ms_per_pass": {k: v * 1e3 for k, v in result.timings.items()}, "warnings": result.facts["warnings"]}
        records.append(record)
        if on_frame is not None:
            on_frame(record)
    if gif is not None:
        write_gif(gif, stills, gif_fps)
    return records


def write_gif(path, stills, fps: float) -> None:
    """An animated, looping GIF of 8-bit RGB frames (imageio's pillow plugin), written atomically."""
    import imageio.v3 as iio

    if not stills:
        raise FormatError(f"{path}: no frames to write")
    with atomic_path(path) as tmp:
        iio.imwrite(tmp, np.stack(stills), extension=".gif", duration=1000.0 / fps, loop=0)
