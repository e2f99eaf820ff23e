"""Where in the image a model's light is off: each model's light in boxes of pixels over the reference's (issue 13).

Reads a ``bench_compare.py --out`` folder (one sub-folder per scene holding ``reference.exr``, ``floor_instance.exr``
and ``strip_<model>.exr``) and, for each scene and each box, prints the box's share of the reference's light and the
light of the instance floor and of every model drawn there over the reference's (the mean of RGB, as
``probe_flyaway_light.py``). Boxes are named pixel ranges ``name=y0:y1:x0:x1`` (rows, then columns, ends excluded);
on the 512² knit-patch scenes the defaults split off the first course (the loop heads at the top of the image), the
last course's open loops (bottom) and the courses between (interior). A box where the floor itself is far from 1
is one where fiber instances differ, not a model's error.

With ``--regular-dir`` (the reference traced with its regular fibers alone, ``<scene>_regular.exr``, as
``probe_flyaway_light.py`` keeps them) a second table splits each box between the regular fibers and the hairs: the
regular-only reference over the full one, the strips without their flyaway layer (``closed``) over the regular-only
reference, and the light the hairs add (over the full reference's light in the box) in the reference and in the
strips (``full`` less ``closed``).

With ``--worst F`` a third table asks where each image's error lies rather than its light: both images filtered to
the scene's projected yarn diameter d (``knitbake.compare.report.yarn_diameter_px`` of the example scene of that
name), over the reference's lit pixels (above ``LIT`` of its largest), the fraction F of them where the image's
error is largest: their share of its summed error, its light over the reference's there and how many of them it
draws darker, and its share of error in the second instance's worst F (the instance's places). An image whose worst
pixels hold no more of its error than the instance's do, at the instance's ratio, has its error spread like a fiber
draw's; a model that is darker in most of them misses something the fibers put there.

    .venv/bin/python benchmarks/probe_regions.py --compare-dir out/compare57all \\
        --scenes knit_patch_grazing,knit_patch_directional [--box top=60:130:30:480 ...] \\
        [--regular-dir out/bench/regular_refs] [--worst 0.05]
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np

from data_formats.images import read_exr
from data_formats.scene import load_scene
from knitbake.compare.image_metrics import yarn_filter
from knitbake.compare.report import yarn_diameter_px

EXAMPLES = Path(__file__).resolve().parent.parent / "examples" / "scenes"
LIT = 0.02  # --worst: a pixel is lit where the filtered reference is above this fraction of its largest

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


def _light(path: Path) -> np.ndarray:
    """An image's light per pixel: the mean of its RGB."""
    return read_exr(path)[..., :3].mean(axis=-1)


def boxes_and_all(shape, boxes):
    """The whole image as box "all", then ``boxes`` (name, (y0, y1, x0, x1))."""
    return [("all", (0, shape[0], 0, shape[1])), *boxes]


def region_table(reference: np.ndarray, light: dict, boxes) -> list[str]:
    """Lines of one scene's table: per box, its share of the reference's light and each image's light over it."""
    total = float(reference.sum())
    lines = ["| box | share of the reference's light | " + " | ".join(light) + " |",
             "|---|---|" + "---|" * len(light)]
    for name, (y0, y1, x0, x1) in boxes_and_all(reference.shape, boxes):
        ref = float(reference[y0:y1, x0:x1].sum())
        if ref <= 0.0:
            lines.append(f"| {name} | 0 (no light: box outside the image or on the background) |" + " |" * len(light))
            continue
        ratios = [float(img[y0:y1, x0:x1].sum()) / ref for img in light.values()]
        lines.append(f"| {name} | {ref / total:.3f} | " + " | ".join(f"{r:.3f}" for r in ratios) + " |")
    return lines


def hair_split_table(reference, regular, closed, full, boxes) -> list[str]:
    """Lines of one scene's regular/hair split per box (module docstring): the light of the reference, the
    regular-only reference and the strips without and with their flyaway layer."""
    lines = ["| box | regular-only reference / reference | closed / regular-only reference | hairs add: reference | "
             "hairs add: strips |", "|---|---|---|---|---|"]
    for name, (y0, y1, x0, x1) in boxes_and_all(reference.shape, boxes):
        box = (slice(y0, y1), slice(x0, x1))
        ref, reg = float(reference[box].sum()), float(regular[box].sum())
        if ref <= 0.0 or reg <= 0.0:
            lines.append(f"| {name} | no light in the box | | | |")
            continue
        lines.append(f"| {name} | {reg / ref:.3f} | {float(closed[box].sum()) / reg:.3f} | {(ref - reg) / ref:+.3f} | "
                     f"{float(full[box].sum() - closed[box].sum()) / ref:+.3f} |")
    return lines


def worst_table(reference, light: dict, d: float, fraction: float) -> list[str]:
    """Lines of one scene's ``--worst`` table (module docstring): ``reference`` and ``light`` (name → image) per
    pixel, filtered here to ``d`` px; the instance is ``light["floor_instance"]`` where present."""
    ref = yarn_filter(reference[..., None], d)[..., 0]
    lit = ref > LIT * ref.max()
    if not lit.any():
        return ["(no lit pixel: the reference is black)"]
    ref = ref[lit]
    drawn = {name: yarn_filter(img[..., None], d)[..., 0][lit] for name, img in light.items()}
    errors = {name: np.abs(img - ref) for name, img in drawn.items()}
    n = max(1, int(round(fraction * ref.size)))
    worst = {name: np.argsort(error, kind="stable")[::-1][:n] for name, error in errors.items()}
    there = worst.get("floor_instance")
    lines = [f"| image (d = {d:.1f} px, worst {n} of {ref.size} lit pixels) | share of its error in its worst | "
             "its light / the reference's there | of them darker | share of its error in the instance's worst |",
             "|---|---|---|---|---|"]
    for name, img in drawn.items():
        error, at = errors[name], worst[name]
        total = error.sum()
        if not total > 0:
            lines.append(f"| {name} | no error | | | |")
            continue
        in_instance = f"{error[there].sum() / total:.2f}" if there is not None else "—"
        lines.append(f"| {name} | {error[at].sum() / total:.2f} | {img[at].sum() / ref[at].sum():.2f} | "
                     f"{np.mean(img[at] < ref[at]):.2f} | {in_instance} |")
    return lines


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--compare-dir", type=Path, required=True, help="a bench_compare.py --out folder")
    parser.add_argument("--scenes", default="knit_patch_directional,knit_patch_sky,knit_patch_grazing",
                        help="comma-separated scene folders in --compare-dir")
    parser.add_argument("--box", action="append", default=None,
                        help="name=y0:y1:x0:x1, repeatable (default: the knit patches' top, interior, bottom)")
    parser.add_argument("--regular-dir", type=Path, default=None,
                        help="regular-only references (<scene>_regular.exr): split each box between fibers and hairs")
    parser.add_argument("--worst", type=float, default=None,
                        help="fraction F in (0, 1): where each image's yarn-scale error lies (module docstring)")
    args = parser.parse_args(argv)
    if args.worst is not None and not 0.0 < args.worst < 1.0:
        parser.error(f"--worst must lie in (0, 1), not {args.worst}")
    boxes = [parse_box(b) for b in (args.box or PATCH_BOXES)]
    for scene in args.scenes.split(","):
        folder = args.compare_dir / scene
        if not (folder / "reference.exr").is_file():
            print(f"{folder}: no reference.exr (run bench_compare.py --out {args.compare_dir} first)", file=sys.stderr)
            return 1
        reference = _light(folder / "reference.exr")
        paths = {"floor_instance": folder / "floor_instance.exr"}
        paths.update({p.stem[len("strip_"):]: p for p in sorted(folder.glob("strip_*.exr"))})
        light = {name: _light(path) for name, path in paths.items() if path.exists()}
        print(f"\n{scene}\n")
        print("\n".join(region_table(reference, light, boxes)))
        if args.regular_dir is not None:
            regular = args.regular_dir / f"{scene}_regular.exr"
            needed = ((regular.name, regular.is_file()), ("strip_closed.exr", "closed" in light),
                      ("strip_full.exr", "full" in light))
            missing = [name for name, there in needed if not there]
            if missing:
                print(f"\n(no regular/hair split: {', '.join(missing)} missing)")
            else:
                split = hair_split_table(reference, _light(regular), light["closed"], light["full"], boxes)
                print("\n" + "\n".join(split))
        if args.worst is not None:
            toml = EXAMPLES / f"{scene}.toml"
            if not toml.is_file():
                print(f"\n(no --worst table: no example scene {toml.name} to size the yarn from)")
            else:
                print("\n" + "\n".join(worst_table(reference, light, yarn_diameter_px(load_scene(toml)), args.worst)))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
