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

``--split`` compares single and multiple scattering apart instead, as the closure closes them (``correction/xi_view_ss``,
``_ms``): per view, the reference traced with ``--seeds`` fiber instances at full depth and with one scattering event
(``trace_reference(..., max_depth=1)``: single scattering SS, the rest MS), the model with
``Features.multiple_scattering`` off for its SS, and the model's SS without ξ (``xi`` off: what ξ_ss starts from).
Printed per view: the reference's SS and MS (mean of RGB) and, per model, its SS, MS and whole over the reference's.
At a bin centre ξ_ss is what the closure made it; between centres it is interpolated, so there the renderer's
single scattering is right only as far as its response without ξ changes as the reference's does (BENCHMARKS.md,
"Issue 13: single scattering, counted apart and between the closure's cells").

    .venv/bin/python benchmarks/probe_closure.py --pack out/bench/cotton1_standard.h5 [--ablations full,factored] \
        [--views 0:56.25:22.5,11.25:56.25:22.5] [--split [--seeds 4]]
"""

from __future__ import annotations

import argparse
import dataclasses
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
from knitbake.trace.reference import trace_reference  # noqa: E402
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
    parser.add_argument("--split", action="store_true", help="single and multiple scattering apart (module docstring)")
    parser.add_argument("--seeds", type=int, default=4, help="with --split: fiber instances the reference averages")
    args = parser.parse_args()
    if args.seeds < 1:
        parser.error(f"--seeds {args.seeds}: at least 1")
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
    if args.split:
        print("| θ_i | θ_o | φ | reference SS, MS | " + " | ".join(f"{a}: SS, MS, whole" for a in ablations)
              + " | SS without ξ |")
        print("|---|---|---|---|" + "---|" * (len(ablations) + 1))
    else:
        print("| θ_i | θ_o | φ | " + " | ".join(ablations) + " |")
        print("|---|---|---|" + "---|" * len(ablations))
    with tempfile.TemporaryDirectory() as tmp:
        folder = Path(tmp)
        points = np.stack([np.zeros(31), np.zeros(31), np.linspace(-1.5 * period, 2.5 * period, 31)], axis=1)
        write_yarn_curves(folder / "yarn.h5", make_yarn_curves(points[None], np.array([0, 31], np.int64),
                                                                yarn_types=["cotton1"], units="cm"))
        for theta_i, theta_o, phi in views:
            scene = _scene(folder, period, theta_i, theta_o, phi, args.spp)
            angles = f"| {math.degrees(theta_i):+.2f}° | {math.degrees(theta_o):+.2f}° | {math.degrees(phi):+.1f}° | "
            if args.split:
                print(angles + _split_row(scene, args.pack, ablations, args.spp, args.seeds), flush=True)
                continue
            reference = (_trace_without_flyaways(scene, args.spp) @ LUMINANCE).sum()
            ratios = [(render(scene, {"cotton1": args.pack}, regular_fibers(a)).image @ LUMINANCE).sum() / reference
                      for a in ablations]
            print(angles + " | ".join(f"{r:.3f}" for r in ratios) + " |", flush=True)


def _split_row(scene, pack, ablations, spp, seeds) -> str:
    """The cells of one view of ``--split`` after its angles: the reference's SS and MS over ``seeds`` fiber
    instances (regular fibers), then each model's SS, MS and whole over them, then the first model's SS without ξ."""
    def traced(depth):
        return np.mean([trace_reference(scene, spp, seed=scene.render.seed + 2 * s + (depth == 1), max_depth=depth,
                                        fiber_seed=s, flyaways=False)[0][..., :3].mean() for s in range(seeds)])

    def drawn(features):
        return float(np.asarray(render(scene, {"cotton1": pack}, features).image, np.float64)[..., :3].mean())

    whole, single = traced(scene.render.max_depth), traced(1)
    cells = [f"{single * 1e3:.2f}, {(whole - single) * 1e3:.2f} (×10⁻³)"]
    for name in ablations:
        features = regular_fibers(name)
        all_, ss = drawn(features), drawn(dataclasses.replace(features, multiple_scattering=False))
        cells.append(f"{ss / single:.3f}, {(all_ - ss) / (whole - single):.3f}, {all_ / whole:.3f}")
    raw = regular_fibers(ablations[0])
    cells.append(f"{drawn(dataclasses.replace(raw, multiple_scattering=False, xi=False)) / single:.3f}")
    return " | ".join(cells) + " |"


if __name__ == "__main__":
    main()
