"""How the strip model's brightness depends on the light's longitudinal angle θ_i against a yarn (issue 13, the look).

``straight_yarn_directional`` (a straight cotton1 yarn along x, seen head-on, θ_o = 0) with its light turned so
that θ_i = asin(ω_i·x) takes each value asked for (default 0°, 20°, 35°, 50°, 65°), the light's part normal to the
yarn along that scene's (0, 0.5, 1). The diagonal ξ of a pack (``correction/xi_closed``) was measured only at
θ_o = −θ_i, so at θ_o = 0 it is looked up at θ_d = −θ_i/2, a configuration it never saw (``--ablations
diagonal_xi,…``); ``correction/xi_view`` (the full model's) was closed at every (θ_i, θ_o). Each scene is path traced
at ``--spp`` (flyaways included, as the example scene) and again with another fiber seed (the instance floor);
printed per θ_i: the floor's mean ratio and yarn-scale rel L1, and each ablation's mean radiance ratio / yarn-scale
rel L1 over the floor.

    .venv/bin/python benchmarks/probe_light_angle.py --pack out/bench/cotton1_standard.h5 \\
        [--angles 0,20,35,50,65] [--ablations diagonal_xi,full] [--spp 16]
"""

from __future__ import annotations

import argparse
import dataclasses
import math
from pathlib import Path

import numpy as np

from data_formats.scene import load_scene
from knitbake.compare.image_metrics import yarn_scale_metrics
from knitbake.compare.report import yarn_diameter_px
from knitbake.trace.reference import trace_reference
from knitrun.render import pipeline
from knitrun.render.ablations import ABLATIONS

SCENE = Path(__file__).resolve().parent.parent / "examples" / "scenes" / "straight_yarn_directional.toml"


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--pack", required=True, help="cotton1 asset pack")
    parser.add_argument("--angles", default="0,20,35,50,65", help="θ_i in degrees, comma-separated")
    parser.add_argument("--ablations", default="diagonal_xi,full")
    parser.add_argument("--spp", type=int, default=16)
    args = parser.parse_args()
    base = load_scene(SCENE)
    diameter = yarn_diameter_px(base)
    normal = np.array([0.0, 0.5, 1.0]) / math.hypot(0.5, 1.0)
    for degrees in (float(a) for a in args.angles.split(",")):
        theta = math.radians(degrees)
        light = dataclasses.replace(base.lights[0], direction=tuple(math.cos(theta) * normal + [math.sin(theta), 0, 0]))
        scene = dataclasses.replace(base, lights=(light,))
        reference, _ = trace_reference(scene, args.spp, seed=0, max_depth=32)
        instance, _ = trace_reference(scene, args.spp, seed=1, max_depth=32, fiber_seed=7)
        floor = yarn_scale_metrics(instance, reference, diameter)
        row = [f"θ_i {degrees:5.1f}°: floor mean {floor['mean_ratio']:.3f}, rel L1 {floor['rel_l1']:.3f}"]
        for name in args.ablations.split(","):
            image = pipeline.render(scene, {"cotton1": args.pack}, ABLATIONS[name]).image
            m = yarn_scale_metrics(image, reference, diameter)
            row.append(f"{name} {m['mean_ratio']:.3f} / {m['rel_l1'] / floor['rel_l1']:.2f}×")
        print(" | ".join(row), flush=True)


if __name__ == "__main__":
    main()
