"""Images: float32 linear HDR in OpenEXR (renders; read and written), Radiance RGBE ``.hdr`` (environment maps;
read), and tone-mapped 8-bit PNG previews.

Conventions: arrays are (H, W, 3) float32, linear RGB, row 0 at the top. EXR files hold one ``RGB`` layer (ZIP
compression). PNG previews apply exposure 2^stops, then the sRGB transfer curve, then clamp to [0, 1].
Writers refuse NaN/Inf and write atomically.
"""

from __future__ import annotations

import re

import numpy as np

from .atomic import atomic_path
from .errors import FormatError
from .input_files import read_head, regular_file

EXR_MAGIC = b"\x76\x2f\x31\x01"


def _check_image(img, where):
    img = np.asarray(img, dtype=np.float32)
    if img.ndim != 3 or img.shape[2] != 3 or img.shape[0] < 1 or img.shape[1] < 1:
        raise FormatError(f"{where}: image must have shape (H, W, 3), got {img.shape}")
    if not np.all(np.isfinite(img)):
        y, x, _ = np.argwhere(~np.isfinite(img))[0]
        raise FormatError(f"{where}: pixel (row {y}, column {x}) is not finite")
    return img


def write_exr(path, img) -> None:
    import OpenEXR

    img = _check_image(img, path)
    header = {"compression": OpenEXR.ZIP_COMPRESSION, "type": OpenEXR.scanlineimage}
    with atomic_path(path) as tmp, OpenEXR.File(header, {"RGB": np.ascontiguousarray(img)}) as f:
        f.write(str(tmp))


def read_exr(path) -> np.ndarray:
    import OpenEXR

    regular_file(path, "an OpenEXR image")
    try:
        with OpenEXR.File(str(path)) as f:
            channels = f.channels()
            if "RGB" in channels:
                img = np.asarray(channels["RGB"].pixels, dtype=np.float32)
            elif all(c in channels for c in "RGB"):
                img = np.stack([np.asarray(channels[c].pixels, dtype=np.float32) for c in "RGB"], axis=-1)
            else:
                raise FormatError(f"{path}: EXR has no RGB channels (has {', '.join(channels)})")
    except FormatError:
        raise
    except Exception as exc:  # OpenEXR raises plain Exceptions for corrupt files
        raise FormatError(f"{path}: cannot read EXR ({' '.join(str(exc).split())})") from None
    return _check_image(img, path)


def read_hdr(path) -> np.ndarray:
    """Radiance RGBE (flat or new-style run-length encoded scanlines), ``-Y H +X W`` orientation."""
    try:
        data = regular_file(path, "a Radiance HDR image").read_bytes()
    except OSError as exc:
        raise FormatError(f"{path}: cannot read ({exc.strerror})") from None
    if not (data.startswith(b"#?RADIANCE") or data.startswith(b"#?RGBE")):
        raise FormatError(f"{path}: not a Radiance HDR file (no #?RADIANCE header)")
    m = re.search(rb"\n\n-Y (\d+) \+X (\d+)\n", data)
    if not m:
        raise FormatError(f"{path}: missing or unsupported resolution line (only '-Y H +X W')")
    h, w = int(m.group(1)), int(m.group(2))
    pos = m.end()
    rgbe = np.empty((h, w, 4), np.uint8)
    try:
        for y in range(h):
            if 8 <= w < 32768 and data[pos] == 2 and data[pos + 1] == 2 and (data[pos + 2] << 8 | data[pos + 3]) == w:
                pos += 4
                for c in range(4):
                    x = 0
                    while x < w:
                        n = data[pos]
                        pos += 1
                        if n > 128:
                            rgbe[y, x:x + n - 128, c] = data[pos]
                            x, pos = x + n - 128, pos + 1
                        else:
                            rgbe[y, x:x + n, c] = np.frombuffer(data, np.uint8, n, pos)
                            x, pos = x + n, pos + n
            else:
                rgbe[y] = np.frombuffer(data, np.uint8, 4 * w, pos).reshape(w, 4)
                pos += 4 * w
    except (IndexError, ValueError):
        raise FormatError(f"{path}: truncated pixel data (row {y} of {h})") from None
    e = rgbe[..., 3].astype(np.int32)
    scale = np.where(e > 0, np.ldexp(1.0, e - 136), 0.0)
    return _check_image(rgbe[..., :3] * scale[..., None], path)


def read_image(path) -> np.ndarray:
    """An HDR image by content: EXR or Radiance RGBE."""
    magic = read_head(regular_file(path, "an OpenEXR or Radiance HDR image"), 10)
    if not magic:
        raise FormatError(f"{path}: {'empty file' if magic == b'' else 'cannot read'}, expected an OpenEXR or "
                          f"Radiance HDR image")
    if magic[:4] == EXR_MAGIC:
        return read_exr(path)
    if str(path).lower().endswith(".exr"):
        raise FormatError(f"{path}: not an OpenEXR file (first bytes {magic[:4]!r})")
    return read_hdr(path)


def tonemap(img, exposure_stops: float = 0.0) -> np.ndarray:
    """8-bit sRGB of a linear image."""
    x = np.clip(np.asarray(img, np.float64) * 2.0 ** exposure_stops, 0.0, 1.0)
    srgb = np.where(x <= 0.0031308, 12.92 * x, 1.055 * x ** (1 / 2.4) - 0.055)
    return (srgb * 255 + 0.5).astype(np.uint8)


def write_png(path, img, exposure_stops: float = 0.0) -> None:
    from PIL import Image

    img = _check_image(img, path)
    with atomic_path(path) as tmp:
        Image.fromarray(tonemap(img, exposure_stops)).save(tmp, format="PNG")
