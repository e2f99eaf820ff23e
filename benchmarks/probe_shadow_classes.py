"""Where the strip renderer's yarn-level shadows fall against where the reference's light lies (issue 13, the look).

Per example scene with directional lights: the front regular strips are rasterised at one sample per pixel
(``strip_raster.rasterize_visibility``) and each covered pixel gets the yarn-level visibility V of its point toward
every directional light (``shadow_map``: the scene's map size, PCF of a delta light, the renderer's bias,
``pipeline.receiver_bias``), looked up where the renderer looks it up: on the tube surface the camera sees (the
default, ``pipeline.strip_receivers``) or on the strip plane through the yarn's axis (``axis_shadows``). Pixels fall
into classes by V (summed over the lights, divided by their count): lit (V > 0.95), partly lit, shadowed (V < 0.05),
and no front strip. Printed per class: its share of the pixels, its share of the reference's light (luminance), and each
model's light over the reference's there.

A shadow placed where the reference is lit shows as a shadowed class that holds much of the reference's light; a
model's ratio per class then says whether the lit parts or the shadowed parts carry its brightness error. Needs the
references of ``bench_floors.py`` (``<scene>.exr``); about 10 s per scene and model on 2 cores.

    .venv/bin/python benchmarks/probe_shadow_classes.py --pack out/bench/cotton1_standard.h5 \\
        --reference-dir out/bench/refs2 [--scenes knit_patch_grazing] [--models axis_shadows,full]
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np

from data_formats.conventions import LUMINANCE
from data_formats.images import read_exr
from data_formats.scene import EnvironmentLight, load_scene
from knitrun.render import pipeline
from knitrun.render.ablations import combined
from knitrun.render.camera import scene_camera
from knitrun.render.shadow_map import build_shadow_map, shadow_visibility
from knitrun.render.strip_raster import rasterize_visibility
from knitrun.render.strip_shading import shading_points

sys.path.insert(0, str(Path(__file__).resolve().parent))
from probe_split import checked_models_and_scenes  # noqa: E402

EXAMPLES = Path(__file__).parent.parent / "examples" / "scenes"
SCENES = "knit_patch_directional,knit_patch_grazing,simulated_patch_directional"
LIT, SHADOWED = 0.95, 0.05
CLASSES = ("lit", "partly lit", "shadowed", "no front strip")


def pixel_visibility(scene, renderer, surface: bool) -> np.ndarray:
    """(H, W) mean yarn-level visibility over the scene's directional lights of each pixel's front regular point
    (module docstring); NaN where no front strip covers the pixel centre."""
    camera = scene_camera(scene)
    lines = pipeline._polylines(scene, renderer.curves, renderer.frame_index(None), renderer.samples_per_segment)
    radius = np.array([renderer.looks[k].radius for k in lines.entry])
    vis = rasterize_visibility(lines.points, lines.offsets, False, lines.rest, radius, lines.entry, camera, 1)
    points = shading_points(vis, camera)
    receivers = pipeline.strip_receivers(points, renderer.looks, surface)
    lights = [light for light in scene.lights if not isinstance(light, EnvironmentLight)]
    v = np.zeros(len(receivers.position))
    for light in lights:
        sm = build_shadow_map(lines.points, lines.offsets, False, lines.rest, radius, light.unit_direction,
                              scene.render.shadow_map_size, lines.points.min(axis=0), lines.points.max(axis=0))
        v += shadow_visibility(sm, receivers.position, pipeline.receiver_bias(receivers, light.unit_direction), 0.0)
    v /= max(len(lights), 1)
    start = points["start"]
    count = np.diff(start)
    per_pixel = np.full(len(count), np.nan)
    covered = count > 0
    per_pixel[covered] = np.add.reduceat(v, start[:-1][covered]) / count[covered]
    return per_pixel.reshape(camera.height, camera.width)


def classes(v):
    """Masks of ``CLASSES`` over the pixels of ``pixel_visibility``'s ``v``."""
    drawn = np.isfinite(v)
    w = np.where(drawn, v, 0.0)
    return [drawn & (w > LIT), drawn & (w >= SHADOWED) & (w <= LIT), drawn & (w < SHADOWED), ~drawn]


def main():
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--pack", required=True)
    parser.add_argument("--reference-dir", required=True)
    parser.add_argument("--scenes", default=SCENES)
    parser.add_argument("--models", default="axis_shadows,full",
                        help="ablations or combinations a+b (ablations.combined); a model with surface_shadows is "
                             "classed by its own lookups")
    args = parser.parse_args()
    models, _ = checked_models_and_scenes(parser, args)
    lum = np.asarray(LUMINANCE, np.float64)
    print("| scene | lookups at | class | pixels | reference's light | " + " | ".join(models) + " |")
    print("|---|---|---|---|---|" + "---|" * len(models))
    scenes = {name: load_scene(EXAMPLES / f"{name}.toml") for name in args.scenes.split(",")}
    for name, scene in scenes.items():
        if all(isinstance(light, EnvironmentLight) for light in scene.lights):
            parser.error(f"--scenes: {name} has no directional light (the classes are by a directional light's V)")
    for name, scene in scenes.items():
        packs = {"cotton1": args.pack}
        reference = read_exr(Path(args.reference_dir) / f"{name}.exr").astype(np.float64)[..., :3] @ lum
        images, renderer = {}, None
        for model in models:
            renderer = pipeline.Renderer(scene, packs, features=combined(model))
            images[model] = np.asarray(renderer.render().image, np.float64)[..., :3] @ lum
        for surface, label in ((False, "strip plane"), (True, "tube surface")):
            for cls, mask in zip(CLASSES, classes(pixel_visibility(scene, renderer, surface))):
                share = reference[mask].sum() / reference.sum()
                ratios = " | ".join(f"{images[m][mask].sum() / reference[mask].sum():.3f}"
                                    if reference[mask].sum() > 0 else "—" for m in models)
                print(f"| {name} | {label} | {cls} | {mask.mean():.3f} | {share:.3f} | {ratios} |", flush=True)


if __name__ == "__main__":
    main()
