"""Where in the image a model's light is off: each model's light in boxes of pixels over the reference's (issue 13).

Reads a ``bench_compare.py --out`` folder (one sub-folder per scene holding ``reference.exr``, ``floor_instance.exr``
and ``strip_<model>.exr``) and, for each scene and each box, prints the box's share of the reference's light and the
light of the instance floor and of every model drawn there over the reference's (the mean of RGB, as
``probe_flyaway_light.py``). Boxes are named pixel ranges ``name=y0:y1:x0:x1`` (rows, then columns, ends excluded);
on the 512² knit-patch scenes the defaults split off the first course (the loop heads at the top of the image), the
last course's open loops (bottom) and the courses between (interior). A box where the floor itself is far from 1
is one where fiber instances differ, not a model's error.

    .venv/bin/python benchmarks/probe_regions.py --compare-dir out/compare57all \\
        --scenes knit_patch_grazing,knit_patch_directional [--box top=60:130:30:480 ...]
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np

from data_formats.images import read_exr

PATCH_BOXES = ("top=60:130:30:480", "interior=130:380:30:440", "bottom=380:460:30:480")


def parse_box(text: str):
    """``name=y0:y1:x0:x1`` -> (name, (y0, y1, x0, x1)); a one-line error names a malformed box."""
    name, _, ranges = text.partition("=")
    parts = ranges.split(":")
    if not name or len(parts) != 4 or not all(p.strip().isdigit() for p in parts):
        raise SystemExit(f"--box {text!r}: expected name=y0:y1:x0:x1 (non-negative pixel indices)")
    y0, y1, x0, x1 = (int(p) for p in parts)
    if y1 <= y0 or x1 <= x0:
        raise SystemExit(f"--box {text!r}: empty (y1 must exceed y0, x1 x0)")
    return name, (y0, y1, x0, x1)


def region_table(folder: Path, boxes) -> list[str]:
    """Lines of one scene's table: per box, its share of the reference's light and each image's light over it."""
    images = {"floor_instance": folder / "floor_instance.exr"}
    images.update({p.stem[len("strip_"):]: p for p in sorted(folder.glob("strip_*.exr"))})
    reference = read_exr(folder / "reference.exr")[..., :3].mean(axis=-1)
    light = {name: read_exr(path)[..., :3].mean(axis=-1) for name, path in images.items() if path.exists()}
    total = float(reference.sum())
    lines = ["| box | share of the reference's light | " + " | ".join(light) + " |",
             "|---|---|" + "---|" * len(light)]
    for name, (y0, y1, x0, x1) in [("all", (0, reference.shape[0], 0, reference.shape[1])), *boxes]:
        ref = float(reference[y0:y1, x0:x1].sum())
        if ref <= 0.0:
            lines.append(f"| {name} | 0 (no light: box outside the image or on the background) |" + " |" * len(light))
            continue
        ratios = [float(img[y0:y1, x0:x1].sum()) / ref for img in light.values()]
        lines.append(f"| {name} | {ref / total:.3f} | " + " | ".join(f"{r:.3f}" for r in ratios) + " |")
    return lines


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--compare-dir", type=Path, required=True, help="a bench_compare.py --out folder")
    parser.add_argument("--scenes", default="knit_patch_directional,knit_patch_sky,knit_patch_grazing",
                        help="comma-separated scene folders in --compare-dir")
    parser.add_argument("--box", action="append", default=None,
                        help="name=y0:y1:x0:x1, repeatable (default: the knit patches' top, interior, bottom)")
    args = parser.parse_args(argv)
    boxes = [parse_box(b) for b in (args.box or PATCH_BOXES)]
    for scene in args.scenes.split(","):
        folder = args.compare_dir / scene
        if not (folder / "reference.exr").is_file():
            print(f"{folder}: no reference.exr (run bench_compare.py --out {args.compare_dir} first)", file=sys.stderr)
            return 1
        print(f"\n{scene}\n")
        print("\n".join(region_table(folder, boxes)))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
