"""Closure of the bake: does the strip renderer reproduce the path tracer where the correction ξ was measured?

The correction stage (``knitbake/stages/correction.py``) measures ξ(v, θ_d, φ) on a straight yarn along +z seen by an
orthographic camera from θ_o = θ_d (azimuth 0), lit from θ_i = −θ_d, φ_i = −φ. This probe builds that yarn as a scene
(the same spec, drawn along a straight curve), frames two ply periods with an orthographic camera from the same
direction, lights it with the same directional light, and compares the strip renderer's image with the path-traced
one (flyaways off in both: the fibers the bake sees; ``ablations.regular_fibers``) at the table's bin centres.
Printed per configuration: the luminance of each model over the reference's over the whole frame.

Where ξ is a ratio of bin sums Σ Ψ_* / Σ Ψ_DS, the renderer's image at a bin centre should come back to the
reference within the bake's noise, if the renderer evaluates the DS term that the bake divided by. A ratio far from
1 says that it does not (BENCHMARKS.md, "Issue 13: the environment's sun as one lobe, and where the regular fibers'
error lies").

``--views`` probes other views and lights instead, each "θ_i:θ_o:φ" in degrees (the same yarn, camera from θ_o,
light from (θ_i, −φ)): off the diagonal, where the closure stage closes ξ at every view (``correction/xi_view``), and
between its bin centres, where the renderer interpolates it (BENCHMARKS.md, "Issue 13: where in a knit's shape the
error starts").

    .venv/bin/python benchmarks/probe_closure.py --pack out/bench/cotton1_standard.h5 [--ablations full,factored] \
        [--views 0:56.25:22.5,11.25:56.25:22.5]
"""

from __future__ import annotations

import argparse
import math
import sys
import tempfile
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).parent))
from check_brightness_gap import _trace_without_flyaways  # noqa: E402

from data_formats.conventions import LUMINANCE  # noqa: E402
from data_formats.scene import load_scene  # noqa: E402
from data_formats.yarn_curves import make_yarn_curves, write_yarn_curves  # noqa: E402
from data_formats.yarn_spec import load_preset  # noqa: E402
from knitbake.stages.correction import yarn_direction  # noqa: E402
from knitrun.render.ablations import regular_fibers  # noqa: E402
from knitrun.render.pipeline import render  # noqa: E402

THETA_D = (0.19635, 0.58905, -0.58905)  # bin centres of the standard pack's 8 θ_d cells (rad)
PHI = (0.39270, 1.96350, -1.17810, 2.74889)  # bin centres of its 8 φ cells (rad)


def _scene(folder: Path, period: float, theta_i: float, theta_o: float, phi: float, spp: int):
    wo, light = yarn_direction(theta_o, 0.0), yarn_direction(theta_i, -phi)
    centre = np.array([0.0, 0.0, 0.5 * period])
    (folder / "closure.toml").write_text(f"""format = "knit-scene"
version = "1.0"
units = "cm"
background = [0.0, 0.0, 0.0]
[[yarns]]
curves = "yarn.h5"
yarn = "cotton1"
[camera]
position = {(centre + 2.0 * wo).tolist()}
look_at = {centre.tolist()}
up = [0.0, 0.0, 1.0]
ortho_height = {2.0 * period * math.cos(theta_o)}
width = 80
height = 640
[[lights]]
type = "directional"
direction = {light.tolist()}
irradiance = [3.0, 3.0, 3.0]
[render]
spp = {spp}
""")
    return load_scene(folder / "closure.toml")


def main():
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--pack", required=True, help="cotton1 asset pack")
    parser.add_argument("--ablations", default="full,factored")
    parser.add_argument("--spp", type=int, default=32)
    parser.add_argument("--views", default=None, help="θ_i:θ_o:φ in degrees, comma-separated (default: the diagonal "
                        "bin centres θ_i = −θ_o = −θ_d)")
    args = parser.parse_args()
    if args.views:
        try:
            views = [tuple(math.radians(float(x)) for x in view.split(":")) for view in args.views.split(",")]
        except ValueError:
            parser.error(f"--views {args.views!r}: expected θ_i:θ_o:φ in degrees, comma-separated")
        if any(len(view) != 3 for view in views):
            parser.error(f"--views {args.views!r}: expected θ_i:θ_o:φ in degrees, comma-separated")
    else:
        views = [(-theta_d, theta_d, phi) for theta_d in THETA_D for phi in PHI]
    period = load_preset("cotton1").geometry.ply_pitch
    ablations = args.ablations.split(",")
    print("| θ_i | θ_o | φ | " + " | ".join(ablations) + " |")
    print("|---|---|---|" + "---|" * len(ablations))
    with tempfile.TemporaryDirectory() as tmp:
        folder = Path(tmp)
        points = np.stack([np.zeros(31), np.zeros(31), np.linspace(-1.5 * period, 2.5 * period, 31)], axis=1)
        write_yarn_curves(folder / "yarn.h5", make_yarn_curves(points[None], np.array([0, 31], np.int64),
                                                                yarn_types=["cotton1"], units="cm"))
        for theta_i, theta_o, phi in views:
            scene = _scene(folder, period, theta_i, theta_o, phi, args.spp)
            reference = (_trace_without_flyaways(scene, args.spp) @ LUMINANCE).sum()
            ratios = [(render(scene, {"cotton1": args.pack}, regular_fibers(a)).image @ LUMINANCE).sum() / reference
                      for a in ablations]
            print(f"| {math.degrees(theta_i):+.2f}° | {math.degrees(theta_o):+.2f}° | {math.degrees(phi):+.1f}° | "
                  + " | ".join(f"{r:.3f}" for r in ratios) + " |", flush=True)


if __name__ == "__main__":
    main()
