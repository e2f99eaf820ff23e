"""Which part of a knit's shape the strip model's yarn-scale error comes from (issue 13, the look): one cotton1 yarn
in the knit patches' frame, from a straight line to one course of the patch.

The patches are 1.4–1.9× their instance floor while the lone straight yarn is at 0.8–1.1× (BENCHMARKS.md). This
probe keeps everything of ``knit_patch_directional`` / ``knit_patch_sky`` (camera, 288 px/cm, light, colour, yarn
radius r = 0.03 cm) and swaps the yarns for, in turn:

* ``straight``: a straight yarn across the frame in the fabric plane (z = 0);
* ``bend``: the same yarn bent in the fabric plane, y = A sin(2πx/λ), A = r, λ = 10 r (bend radius ≥ 2.5 r, as the
  loops' heads);
* ``wave``: the same sine out of the plane (in z): the yarn tilts up to 32° toward and away from the camera and bends
  toward and away from it, as a course does where it passes over and under its neighbours;
* ``tilted``: the straight yarn turned 30° toward the camera about the image's y axis (ω_o · t = 0.5);
* ``course``: one course (row 2) of the patch's curves, alone: every shape of a knit's yarn, no other course;
* ``two_courses``: rows 2 and 3, interlooped.

Each is path traced ``--instances`` K times at ``--spp``, draw k with seed k for its paths and its fibers, and drawn
by the strip models ``--models``; printed per light and shape, against that ensemble of fiber instances
(``knitbake.compare.image_metrics.ensemble_floor``, ``ensemble_metrics``): the ensemble floor (the leave-one-out
yarn-scale rel L1 at d of a draw against the others' mean) and each model's mean radiance ratio / leave-one-out rel L1
over that floor. One second draw alone is too noisy a ruler for a lone yarn: the straight yarn's single-pair floor
was 0.197 here and 0.243 on a longer yarn, moving its ratio 1.06× ↔ 1.38×. ``--white`` draws every yarn white (the
directional patch's is red). The references are kept in ``--out`` and reused when present. About 6 min on 2 cores
at 64 spp and K = 4, most of it the two courses' references.

    .venv/bin/python benchmarks/probe_shapes.py --pack out/bench/cotton1_standard.h5 [--out out/probe_shapes] \\
        [--spp 64] [--lights directional,sky] [--shapes straight,bend,wave,tilted,course,two_courses] \\
        [--models full,diagonal_xi] [--instances 4] [--white]
"""

from __future__ import annotations

import argparse
import dataclasses
import math
from pathlib import Path

import numpy as np

from data_formats.images import read_exr, write_exr
from data_formats.scene import load_scene
from data_formats.yarn_curves import make_yarn_curves, read_yarn_curves, write_yarn_curves
from knitbake.compare.image_metrics import ensemble_floor, ensemble_metrics, yarn_filter
from knitbake.compare.report import yarn_diameter_px
from knitbake.trace.reference import trace_reference
from knitrun.render import pipeline
from knitrun.render.ablations import combined

EXAMPLES = Path(__file__).parent.parent / "examples" / "scenes"
SHAPES = ("straight", "bend", "wave", "tilted", "course", "two_courses")
COURSES = {"course": (2,), "two_courses": (2, 3)}  # rows of knit_patch_6x6.h5
SPAN = (0.2, 1.1)  # cm along x: inside the frame at every tilt
SAMPLES = 361  # polyline points of a synthetic shape (0.0025 cm apart: r / 12)


def shape_curves(shape: str, radius: float, centre, path: Path) -> None:
    """Write the curve file of ``shape`` (module docstring) for a yarn of ``radius`` centred on ``centre``."""
    if shape in COURSES:
        patch = read_yarn_curves(EXAMPLES / "knit_patch_6x6.h5")
        rows = COURSES[shape]
        points = [patch.points[0, patch.offsets[r]:patch.offsets[r + 1]] for r in rows]
        rest = [patch.rest_arclength[patch.offsets[r]:patch.offsets[r + 1]] for r in rows]
        offsets = np.cumsum([0] + [len(p) for p in points])
        curves = make_yarn_curves(np.concatenate(points), offsets, yarn_types=patch.yarn_types,
                                  rest_arclength=np.concatenate(rest), curve_type=patch.curve_type, units=patch.units)
    else:
        x = np.linspace(*SPAN, SAMPLES)
        wave = radius * np.sin(2.0 * math.pi * (x - centre[0]) / (10.0 * radius))
        y, z = np.full_like(x, centre[1]), np.zeros_like(x)
        if shape == "bend":
            y = y + wave
        elif shape == "wave":
            z = wave
        elif shape == "tilted":
            z = (x - centre[0]) * math.tan(math.radians(30.0))
        elif shape != "straight":
            raise ValueError(f"unknown shape {shape!r} ({', '.join(SHAPES)})")
        curves = make_yarn_curves(np.stack([x, y, z], axis=1), [0, SAMPLES], yarn_types=["cotton1"],
                                  curve_type="PL", units="cm")
    write_yarn_curves(path, curves)


def shape_scene(light: str, shape: str, folder: Path, white: bool):
    """``knit_patch_<light>`` with its yarns swapped for ``shape`` (white with ``white``)."""
    base = load_scene(EXAMPLES / f"knit_patch_{light}.toml")
    entry = base.yarns[0]
    path = folder / f"{shape}.h5"
    shape_curves(shape, entry.radius, base.camera.look_at, path)
    entry = dataclasses.replace(entry, curves=path, **({"color": (1.0, 1.0, 1.0)} if white else {}))
    return dataclasses.replace(base, yarns=(entry,))


def traced(scene, spp: int, path: Path, seed: int):
    """The reference of ``scene`` (seed ``seed`` for paths and fibers), read from ``path`` or traced and written."""
    if path.exists():
        return read_exr(path).astype(np.float64)[..., :3]
    image, _ = trace_reference(scene, spp, seed=seed, fiber_seed=seed, max_depth=scene.render.max_depth)
    write_exr(path, image)
    return np.asarray(image, np.float64)[..., :3]


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--pack", required=True, help="cotton1 asset pack")
    parser.add_argument("--out", default="out/probe_shapes", help="folder for the curves and references")
    parser.add_argument("--spp", type=int, default=64)
    parser.add_argument("--lights", default="directional,sky",
                        help="knit_patch_<light> scenes to take the frame from (directional, sky, grazing)")
    parser.add_argument("--shapes", default=",".join(SHAPES))
    parser.add_argument("--models", default="full", help="ablations or combinations a+b (knitrun.render.ablations)")
    parser.add_argument("--instances", type=int, default=4, help="fiber instances traced per shape (at least 3)")
    parser.add_argument("--white", action="store_true", help="draw every yarn white")
    args = parser.parse_args()
    shapes, models = args.shapes.split(","), args.models.split(",")
    for name in shapes:
        if name not in SHAPES:
            parser.error(f"--shapes: unknown shape {name!r} ({', '.join(SHAPES)})")
    for name in models:
        try:
            combined(name)
        except ValueError as error:
            parser.error(f"--models: {error}")
    for light in args.lights.split(","):
        if not (EXAMPLES / f"knit_patch_{light}.toml").is_file():
            parser.error(f"--lights: no example scene knit_patch_{light}.toml (directional, sky, grazing)")
    if args.instances < 3:
        parser.error("--instances: an ensemble needs at least 3 fiber instances")
    folder = Path(args.out)
    folder.mkdir(parents=True, exist_ok=True)
    tag = "_white" if args.white else ""
    for light in args.lights.split(","):
        print(f"\nknit_patch_{light}{' (white)' if args.white else ''}, {args.spp} spp\n")
        print("| shape | ensemble floor, rel L1 (d) | " + " | ".join(f"{m}: mean ratio / ×floor" for m in models) + " |")
        print("|---|---|" + "---|" * len(models))
        for shape in shapes:
            scene = shape_scene(light, shape, folder, args.white)
            stem = folder / f"{light}{tag}_{shape}_{args.spp}spp"
            draws = [traced(scene, args.spp, stem.with_name(f"{stem.name}_fiber{k}.exr"), k)
                     for k in range(args.instances)]
            d = yarn_diameter_px(scene)
            floor = ensemble_floor(draws, d)
            filtered = [yarn_filter(draw, d) for draw in draws]
            cells = [shape, f"{floor['rel_l1']:.3f}"]
            for model in models:
                image = pipeline.Renderer(scene, {"cotton1": str(args.pack)}, combined(model)).render().image
                m = ensemble_metrics(np.asarray(image, np.float64)[..., :3], draws, d, floor, filtered)
                cells.append(f"{m['mean_ratio']:.3f} / {m['to_floor']:.2f}×")
            print("| " + " | ".join(cells) + " |", flush=True)


if __name__ == "__main__":
    main()
