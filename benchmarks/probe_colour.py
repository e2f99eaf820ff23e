"""The strip renderer against the reference with the example scenes' yarns in another colour (issue 13, the look): does
a model hold for a white yarn as for the examples' red one? The pack is baked once, for a white fiber; a scene's
colour multiplies the BCSDF lobe colours in both renderers (``knitrun.render.yarn_look``).

Per scene and colour: the reference (the scene's seed) and a second fiber instance (seed + 1, fiber seed + 1) traced
at the ruler's spp with every yarn entry in that colour, then each model of ``--models`` rendered in it. Printed per
model: the mean luminance ratio, the ratio of each RGB channel's mean, and the yarn-scale rel L1 over the instance
floor (``knitbake.compare.image_metrics.yarn_scale_metrics``).

    .venv/bin/python benchmarks/probe_colour.py --pack out/bench/cotton1_standard.h5 \\
        [--scenes a,b] [--colors 1,1,1:0.9,0.25,0.2] [--models no_bounce,full] [--spp N]
"""

from __future__ import annotations

import argparse
import dataclasses
import sys
from pathlib import Path

import numpy as np

from data_formats.scene import load_scene
from knitbake.compare.image_metrics import yarn_scale_metrics
from knitbake.compare.report import yarn_diameter_px
from knitbake.trace.reference import trace_reference
from knitrun.render import pipeline
from knitrun.render.ablations import combined

sys.path.insert(0, str(Path(__file__).resolve().parent))
from probe_split import SCENES, checked_models_and_scenes  # noqa: E402  (SCENES: name → the ruler's spp)

ROOT = Path(__file__).resolve().parent.parent
DEFAULT_SCENES = ("straight_yarn_directional", "knit_patch_directional", "knit_patch_grazing",
                  "simulated_patch_directional")


def parse_colours(parser, text):
    """The colours of ``--colors`` ("R,G,B[:R,G,B...]", each in [0, 1]); a one-line ``parser.error`` otherwise."""
    try:
        colours = [tuple(float(x) for x in c.split(",")) for c in text.split(":")]
    except ValueError:
        parser.error(f"--colors: expected R,G,B[:R,G,B...], got {text!r}")
    if any(len(c) != 3 or not all(0.0 <= x <= 1.0 for x in c) for c in colours):
        parser.error(f"--colors: each colour is three numbers in [0, 1], got {text!r}")
    return colours


def scenes_in_colours(names, colours, spp=None):
    """(name, colour, scene, spp) for each example scene of ``names`` with every yarn entry in each colour of
    ``colours``, at ``spp`` or the ruler's spp of the scene."""
    for name in names:
        base = load_scene(ROOT / "examples" / "scenes" / f"{name}.toml")
        for colour in colours:
            yield (name, colour, dataclasses.replace(base, yarns=[dataclasses.replace(y, color=colour)
                                                                  for y in base.yarns]), spp or SCENES.get(name, 16))


def main():
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--pack", required=True, help="the asset pack of cotton1")
    parser.add_argument("--scenes", default=",".join(DEFAULT_SCENES), help="comma-separated example scene names")
    parser.add_argument("--colors", default="1,1,1:0.9,0.25,0.2", help="colours R,G,B separated by ':'")
    parser.add_argument("--models", default="no_bounce,full",
                        help="names of knitrun.render.ablations, or combinations a+b")
    parser.add_argument("--spp", type=int, default=None, help="samples per pixel (default: the ruler's per scene)")
    args = parser.parse_args()
    models, names = checked_models_and_scenes(parser, args)
    colours = parse_colours(parser, args.colors)
    print("| scene | colour | model | mean ratio | RGB means' ratios | rel L1 (d) / instance floor |")
    print("|---|---|---|---|---|---|")
    for name, colour, scene, spp in scenes_in_colours(names, colours, args.spp):
        d, seed = yarn_diameter_px(scene), scene.render.seed
        ref = np.asarray(trace_reference(scene, spp, seed, scene.render.max_depth)[0], np.float64)[..., :3]
        inst = np.asarray(trace_reference(scene, spp, seed + 1, scene.render.max_depth, fiber_seed=seed + 1)[0],
                          np.float64)[..., :3]
        floor = yarn_scale_metrics(inst, ref, d)["rel_l1"]
        label = ", ".join(f"{x:g}" for x in colour)
        rows = [("*other fiber instance*", inst)] + [
            (m, np.asarray(pipeline.Renderer(scene, {"cotton1": args.pack}, combined(m)).render().image,
                           np.float64)[..., :3]) for m in models]
        for model, image in rows:
            metrics = yarn_scale_metrics(image, ref, d)
            channels = " / ".join(f"{x:.3f}" for x in image.mean(axis=(0, 1)) / ref.mean(axis=(0, 1)))
            print(f"| {name} | {label} | {model} | {metrics['mean_ratio']:.3f} | {channels} | "
                  f"{metrics['rel_l1'] / floor:.2f}× |", flush=True)


if __name__ == "__main__":
    main()
