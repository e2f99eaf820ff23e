"""How much of a scene's light the yarns send each other, in the reference and in the strip renderer's bounce (issue 13,
the look): splits a patch's brightness error into the light between yarns and the light of each yarn alone.

The path tracer's diagnostic ``trace_reference(..., inter_yarn=False)`` ends a path where it would scatter off
another yarn than the one its camera ray hit (``knitbake.trace.path_tracer``); the full reference less it is the
inter-yarn light B_ref. The strip renderer's counterpart is the full model less the ablation ``no_bounce``, B_model
(``knitrun.render.yarn_bounce``). Per scene and colour, printed:

* B_ref's share of the reference's light (RGB means' ratio; luminance-free, so a red yarn's green reads as such);
* B_model / B_ref (means) and the correlation of the two at the yarn scale (``knitbake.compare.image_metrics``);
* the full model (no bounce) over the reference without inter-yarn light: how well the strips draw each yarn's own
  light, the part the baked tables are for.

    .venv/bin/python benchmarks/probe_inter_yarn.py --pack out/bench/cotton1_standard.h5 \\
        [--scenes a,b] [--colors 1,1,1:0.9,0.25,0.2] [--spp N]
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np

from knitbake.compare.image_metrics import yarn_filter
from knitbake.compare.report import yarn_diameter_px
from knitbake.trace.reference import trace_reference
from knitrun.render import pipeline
from knitrun.render.ablations import combined

sys.path.insert(0, str(Path(__file__).resolve().parent))
from probe_colour import parse_colours, scenes_in_colours  # noqa: E402
from probe_split import checked_models_and_scenes  # noqa: E402

DEFAULT_SCENES = ("knit_patch_directional", "knit_patch_grazing", "simulated_patch_directional")


def main():
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--pack", required=True, help="the asset pack of cotton1")
    parser.add_argument("--scenes", default=",".join(DEFAULT_SCENES), help="comma-separated example scene names "
                        "(with a directional light: the bounce is the directional lights')")
    parser.add_argument("--colors", default="1,1,1:0.9,0.25,0.2", help="colours R,G,B separated by ':'")
    parser.add_argument("--spp", type=int, default=None, help="samples per pixel (default: the ruler's per scene)")
    args = parser.parse_args()
    args.models = "no_bounce,full"
    _, names = checked_models_and_scenes(parser, args)
    colours = parse_colours(parser, args.colors)
    print("| scene | colour | inter-yarn share of the reference (RGB) | bounce / inter-yarn | yarn-scale correlation "
          "| full model / reference without inter-yarn light |")
    print("|---|---|---|---|---|---|")
    for name, colour, scene, spp in scenes_in_colours(names, colours, args.spp):
        d, seed = yarn_diameter_px(scene), scene.render.seed

        def traced(inter_yarn, scene=scene, seed=seed, spp=spp):
            return np.asarray(trace_reference(scene, spp, seed, scene.render.max_depth, inter_yarn=inter_yarn)[0],
                              np.float64)[..., :3]

        def drawn(model, scene=scene):
            return np.asarray(pipeline.Renderer(scene, {"cotton1": args.pack}, combined(model)).render().image,
                              np.float64)[..., :3]

        full, own = traced(True), traced(False)
        strips, bounced = drawn("no_bounce"), drawn("full")
        between, bounce = full - own, bounced - strips
        share = " / ".join(f"{x:.3f}" for x in between.mean(axis=(0, 1)) / full.mean(axis=(0, 1)))
        a, b = yarn_filter(between, d).mean(-1).ravel(), yarn_filter(bounce, d).mean(-1).ravel()
        corr = float(np.corrcoef(a, b)[0, 1]) if a.std() > 0 and b.std() > 0 else float("nan")
        print(f"| {name} | {', '.join(f'{x:g}' for x in colour)} | {share} | {bounce.mean() / between.mean():.2f} | "
              f"{corr:.2f} | {strips.mean() / own.mean():.3f} |", flush=True)


if __name__ == "__main__":
    main()
