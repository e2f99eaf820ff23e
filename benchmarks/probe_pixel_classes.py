"""Where a patch's light is missing, by what the strip renderer draws at each pixel (issue 13, the look): pixels
classed by the front regular strips' MSAA coverage and depth, and by distance from the nearest yarn axis.

Over a patch's interior (the pixels the regular strips' bounding box holds, less a band of ``--band`` pixels), each
pixel falls into one class: no regular strip, partly covered, or covered and in one of the four quarters of the
covered pixels' mean depth (nearest first). Beyond the strips, rings by distance from the nearest yarn axis: the
pixels a strip of 1.1, 1.2, 1.35, 1.5, 1.75 and 2 yarn radii covers and the narrower one does not. Printed per
class: its share of the interior, the mean of RGB of the reference, of another fiber instance
(``<scene>_instance.exr`` beside it) and of the full model at each ``--hair-layers`` K (``render.hair_layers``),
with the model over the reference.

    .venv/bin/python benchmarks/probe_pixel_classes.py --pack out/bench/cotton1_standard_51.h5 \\
        --reference-dir out/bench/refs2 [--reference out/bench/refs512/knit_patch_sky.exr] \\
        [--scenes knit_patch_sky] [--hair-layers 1,2]
"""

from __future__ import annotations

import argparse
import dataclasses
import sys
import warnings
from pathlib import Path

import numpy as np

from data_formats.images import read_exr
from data_formats.scene import load_scene
from knitrun.render import pipeline
from knitrun.render.camera import scene_camera
from knitrun.render.strip_raster import rasterize_visibility

sys.path.insert(0, str(Path(__file__).resolve().parent))
from probe_split import ROOT, checked_models_and_scenes  # noqa: E402

RINGS = (1.0, 1.1, 1.2, 1.35, 1.5, 1.75, 2.0)  # yarn radii


def strips(scene, lines, factor):
    """The regular strips of ``lines`` drawn ``factor`` yarn radii wide: (H, W, k) StripVisibility."""
    radius = factor * np.array([scene.yarns[k].radius for k in lines.entry])
    return rasterize_visibility(lines.points, lines.offsets, False, lines.rest, radius, lines.entry,
                                scene_camera(scene), scene.render.msaa)


def classes(scene, band):
    """(interior slices, {class name: (H, W) bool mask}) of ``scene``'s frame (module docstring)."""
    lines = pipeline._polylines(scene, [pipeline._scene_curves(e, scene.units, []) for e in scene.yarns],
                                scene.render.frame, 4)
    front = strips(scene, lines, 1.0)
    cover = front.coverage.mean(axis=-1)
    rows, cols = np.nonzero(cover > 0)
    inside = (slice(rows.min() + band, rows.max() - band), slice(cols.min() + band, cols.max() - band))
    with warnings.catch_warnings():  # the mean depth of an uncovered pixel is NaN, and never used
        warnings.simplefilter("ignore", RuntimeWarning)
        depth = np.nanmean(np.where(front.coverage, front.depth, np.nan), axis=-1)
    full = cover == 1.0
    quarters = np.quantile(depth[inside][full[inside]], [0.0, 0.25, 0.5, 0.75, 1.0])
    out = {"no regular strip": cover == 0.0, "partly covered": (cover > 0.0) & (cover < 1.0)}
    names = ("nearest", "second", "third", "farthest")
    for q in range(4):
        out[f"covered, {names[q]} quarter of depth"] = full & (depth >= quarters[q]) & (depth <= quarters[q + 1])
    drawn = cover > 0.0
    for lo, hi in zip(RINGS[:-1], RINGS[1:]):
        wider = strips(scene, lines, hi).coverage.mean(axis=-1) > 0.0
        out[f"ring {lo:g}–{hi:g} r from the nearest axis"] = wider & ~drawn
        drawn = drawn | wider
    return inside, out


def main():
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--pack", required=True, help="the asset pack of cotton1")
    parser.add_argument("--reference-dir", required=True, help="<scene>.exr and <scene>_instance.exr")
    parser.add_argument("--reference", help="another reference of the one scene (e.g. more spp) instead of "
                                            "<scene>.exr")
    parser.add_argument("--scenes", default="knit_patch_sky", help="comma-separated example scene names")
    parser.add_argument("--hair-layers", default="1,2", help="comma-separated render.hair_layers of the full model")
    parser.add_argument("--band", type=int, default=40, help="pixels left out round the patch's edge")
    args = parser.parse_args()
    args.models = "full"
    _, names = checked_models_and_scenes(parser, args)
    if args.reference and len(names) != 1:
        parser.error("--reference: give one scene")
    try:
        layers = [int(k) for k in args.hair_layers.split(",")]
    except ValueError:
        parser.error(f"--hair-layers: integers, got {args.hair_layers!r}")
    for name in names:
        scene = load_scene(ROOT / "examples" / "scenes" / f"{name}.toml")
        folder = Path(args.reference_dir)
        reference = read_exr(args.reference or folder / f"{name}.exr").mean(axis=-1)
        instance = read_exr(folder / f"{name}_instance.exr").mean(axis=-1)
        drawn = {}
        for k in layers:
            layered = dataclasses.replace(scene, render=dataclasses.replace(scene.render, hair_layers=k))
            drawn[k] = pipeline.Renderer(layered, {"cotton1": args.pack}).render().image.mean(axis=-1)
        inside, masks = classes(scene, args.band)
        print(f"\n{name} (interior {inside[0].stop - inside[0].start} × {inside[1].stop - inside[1].start} px; "
              f"reference {args.reference or folder / (name + '.exr')})\n")
        print("| class | share of the interior | reference | other instance | " +
              " | ".join(f"full, {k} hair layer{'s' * (k > 1)}" for k in layers) + " |")
        print("|---|---|---|---|" + "---|" * len(layers))
        for label, mask in masks.items():
            m = mask[inside]
            if not m.any():
                continue
            ref = reference[inside][m].mean()
            cells = " | ".join(f"{drawn[k][inside][m].mean():.4f} ({drawn[k][inside][m].mean() / ref:.2f}×)"
                               for k in layers)
            print(f"| {label} | {100 * m.mean():.1f} % | {ref:.4f} | {instance[inside][m].mean():.4f} | {cells} |",
                  flush=True)


if __name__ == "__main__":
    main()
