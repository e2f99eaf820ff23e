"""How much of each pixel the hairs cover, on the reference's fibers and on the strips at K hair layers (issue 13).

Geometry only, no shading. The reference's hair coverage of a pixel is the share of its camera rays (``--rays``
jittered rays a pixel, the path tracer's own ``camera_rays``) whose first hit is a loop or hair fiber of the
reference's draw (the scene's fiber seed); the strips' is ``Renderer.hair_cover``: the flyaway layers' coverage
composited as the resolve composites them, every hair opaque. The strips draw the K = ``render.hair_layers`` nearest
hair strips at each sample (``strip_raster.rasterize_before``); in a knit the hair strips of three to five yarns
overlap in the gaps between stitches (BENCHMARKS.md, stop 53), so too few layers leave out hairs the camera sees.
This probe says at which K the strips' hairs cover what the reference's do: per scene and box
(``probe_regions.PATCH_BOXES`` on the knit patches, the whole image everywhere) the reference's coverage and the
strips' at each K.

    .venv/bin/python benchmarks/probe_hair_coverage.py --pack out/bench/cotton1_standard_56.h5 \\
        [--scenes knit_patch_directional,straight_yarn_directional] [--hair-layers 1,2,3,4,6] [--rays 16]
"""

from __future__ import annotations

import argparse
import dataclasses
import sys
import time
from pathlib import Path

import numpy as np

from data_formats.scene import load_scene
from knitbake.fibers.fiber_set import KIND_REGULAR
from knitbake.trace.embree_curves import closest_hits
from knitbake.trace.path_tracer import camera_rays
from knitrun.render.camera import scene_camera, tan_half_fov
from knitrun.render.pipeline import Renderer

sys.path.insert(0, str(Path(__file__).resolve().parent))
from probe_hair_canopy import reference_fibers  # noqa: E402
from probe_regions import PATCH_BOXES, boxes_and_all, parse_box  # noqa: E402

ROOT = Path(__file__).resolve().parent.parent
SCENES = ("straight_yarn_directional", "knit_patch_directional", "knit_patch_grazing", "knit_patch_sky",
          "simulated_patch_directional")


def reference_hair_cover(scene, rays: int) -> np.ndarray:
    """(H, W) the share of each pixel's ``rays`` jittered camera rays whose first hit is a loop or hair fiber of the
    scene's reference draw (its fiber seed; one yarn entry)."""
    fibers, curve_scene = reference_fibers(scene)
    camera = scene_camera(scene)
    fwd, right, up = camera.basis()
    n_pix = camera.width * camera.height
    hairs = np.zeros(n_pix)
    origins, directions = np.empty((n_pix, 3)), np.empty((n_pix, 3))
    for sample in range(rays):
        camera_rays(np.asarray(camera.position, float), fwd, right, up, camera.width, camera.height,
                    tan_half_fov(camera), float(camera.ortho_height), scene.render.seed, sample, 1, origins, directions)
        _, segment, _, _ = closest_hits(curve_scene, origins, directions)
        hit = segment >= 0
        hairs[hit] += fibers.kind[curve_scene.segment_fiber[segment[hit]]] != KIND_REGULAR
    return (hairs / rays).reshape(camera.height, camera.width)


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--pack", required=True, help="the asset pack of cotton1")
    parser.add_argument("--scenes", default=",".join(SCENES), help="comma-separated example scene names")
    parser.add_argument("--hair-layers", default="1,2,3,4,6", help="comma-separated render.hair_layers of the strips")
    parser.add_argument("--rays", type=int, default=16, help="jittered camera rays a pixel on the reference")
    args = parser.parse_args(argv)
    try:
        layers = [int(k) for k in args.hair_layers.split(",")]
    except ValueError:
        parser.error(f"--hair-layers: integers, got {args.hair_layers!r}")
    if args.rays < 1:
        parser.error("--rays: at least 1")
    for name in [s for s in args.scenes.split(",") if s]:
        path = ROOT / "examples" / "scenes" / f"{name}.toml"
        if not path.exists():
            parser.error(f"no example scene {name!r}")
        scene = load_scene(path)
        t0 = time.perf_counter()
        reference = reference_hair_cover(scene, args.rays)
        cast_s = time.perf_counter() - t0
        packs = {str(k): args.pack for k in range(len(scene.yarns))}
        strips = {k: Renderer(dataclasses.replace(scene, render=dataclasses.replace(scene.render, hair_layers=k)),
                              packs).hair_cover() for k in layers}
        boxes = [parse_box(b) for b in PATCH_BOXES] if reference.shape == (512, 512) else []
        print(f"\n{name} (reference: {args.rays} rays a pixel, cast in {cast_s:.0f} s)\n")
        print("| box | reference | " + " | ".join(f"strips, K = {k}" for k in layers) + " |")
        print("|---|---|" + "---|" * len(layers))
        for box, (y0, y1, x0, x1) in boxes_and_all(reference.shape, boxes):
            at = (slice(y0, y1), slice(x0, x1))
            ref = float(reference[at].mean())
            print(f"| {box} | {ref:.4f} | " + " | ".join(
                f"{float(strips[k][at].mean()):.4f} ({float(strips[k][at].mean()) / max(ref, 1e-300):.3f})"
                for k in layers) + " |")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
