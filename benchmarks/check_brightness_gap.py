"""Where the strip renderer's brightness gap on a scene lies (issue 13, item 2): probes, not models.

1. The tangent spread a pack's texture holds, per mip level: the Toksvig variance (1 − r)/r from r = |T|/coverage
   (``knitrun.render.strip_shading.tangent_spread``, without its cap), as an angle in degrees: median and
   coverage-weighted RMS over texels with coverage > 0.05.
2. The mean radiance ratio and yarn-scale rel L1 (ratio to the fiber-instance floor) of the regular fibers' model
   (the full model without its flyaway layer: ξ, Ψ^Fiber, inter-reflection), as rendered, with inter-reflection
   switched off, and with every yarn-level visibility forced to 1 (no shadow maps: the probe that bounds what
   yarn-level shadowing takes away).
3. Coverage: the fraction of pixels brighter than 0.02 (luminance) in the reference and in the strip image, and the
   share of the reference's energy in pixels the strips leave at the background.
4. The flyaway layer against the reference's hairs: pixels the full model's regular strips cover (luminance > 0.02)
   are the body, the rest is beside it; the summed radiance beside the body with the layer (the full model) over the
   reference's,
   and the body's radiance with the layer over without it.
5. The flyaways' share of the reference (``--flyaway-spp`` > 0): the scene path traced without flyaways at that spp,
   its mean over the reference's, and the full model's mean ratio against it (the part of the gap that the regular
   fibers' model owns).

    .venv/bin/python benchmarks/check_brightness_gap.py --pack out/bench/cotton1_standard.h5 \\
        [--scene knit_patch_sky] [--reference-dir out/bench/refs] [--flyaway-spp 16] [--papers-xi]

The reference and its instance floor are ``DIR/<scene>.exr`` and ``DIR/<scene>_instance.exr``
(``benchmarks/bench_floors.py``).
"""

import argparse
import dataclasses
from pathlib import Path

import h5py
import numpy as np

from data_formats.conventions import LUMINANCE
from data_formats.images import read_exr
from data_formats.scene import load_scene
from knitbake.compare.image_metrics import yarn_scale_metrics
from knitbake.compare.report import yarn_diameter_px
from knitrun.render import pipeline
from knitrun.render.ablations import ABLATIONS

LIT = 0.02  # luminance above which a pixel counts as covered


def tangent_spread_by_level(pack_path):
    with h5py.File(pack_path, "r") as f:
        levels = sorted(int(k[3:]) for k in f["textures/tangent"])
        for k in levels:
            tangent, coverage = f[f"textures/tangent/mip{k}"][()], f[f"textures/coverage/mip{k}"][()]
            covered = coverage > 0.05
            r = np.minimum(np.linalg.norm(tangent, axis=-1)[covered] / coverage[covered], 1.0)
            spread2 = (1.0 - r) / np.maximum(r, 1e-3)
            rms = np.sqrt(np.average(spread2, weights=coverage[covered]))
            median = np.degrees(np.sqrt(np.median(spread2)))
            print(f"mip {k} {tangent.shape[0]}×{tangent.shape[1]}: spread median {median:.2f}°, "
                  f"RMS {np.degrees(rms):.2f}°")


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--pack", required=True, help="cotton1 asset pack")
    parser.add_argument("--scene", default="knit_patch_sky")
    parser.add_argument("--reference-dir", default="out/bench/refs")
    parser.add_argument("--flyaway-spp", type=int, default=16, help="spp of the flyaway-free reference; 0: skip")
    parser.add_argument("--papers-xi", action="store_true",
                        help="every model with the paper's ξ instead of the pack's closed one")
    args = parser.parse_args()
    tangent_spread_by_level(args.pack)
    scene = load_scene(Path(__file__).resolve().parent.parent / "examples" / "scenes" / f"{args.scene}.toml")
    reference = read_exr(Path(args.reference_dir) / f"{args.scene}.exr")
    floor = yarn_scale_metrics(read_exr(Path(args.reference_dir) / f"{args.scene}_instance.exr"), reference,
                               yarn_diameter_px(scene))["rel_l1"]
    closed = {"closed_xi": not args.papers_xi}
    base = dataclasses.replace(ABLATIONS["full"], flyaways=False, **closed)
    shadowed = pipeline._visibility
    probes = [("full", base, shadowed),
              ("  without inter-reflection", dataclasses.replace(ABLATIONS["xi_shadowing"], **closed), shadowed),
              ("  without yarn-level shadows (probe)", base,
         lambda lines, radius, direction, size, angular, receivers, depth_maps:
         [np.ones(len(p)) for p, _ in receivers])]
    reference_lum = reference @ LUMINANCE
    for label, features, visibility in probes:
        pipeline._visibility = visibility
        try:
            image = pipeline.render(scene, {"cotton1": args.pack}, features).image
        finally:
            pipeline._visibility = shadowed
        m = yarn_scale_metrics(image, reference, yarn_diameter_px(scene))
        lum = image @ LUMINANCE
        empty = lum < 0.005
        print(f"{label}: mean ratio {m['mean_ratio']:.3f}, yarn-scale rel L1 {m['rel_l1']:.3f} "
              f"({m['rel_l1'] / floor:.2f}× the instance floor); covered {np.mean(lum > LIT):.3f} "
              f"(reference {np.mean(reference_lum > LIT):.3f}); reference energy where the strips draw nothing "
              f"{reference_lum[empty].sum() / reference_lum.sum():.3f}", flush=True)
        if label == "full":
            full_mean, full_lum = float(lum.mean()), lum
    fly = pipeline.render(scene, {"cotton1": args.pack}, dataclasses.replace(ABLATIONS["full"], **closed)).image \
        @ LUMINANCE
    body = full_lum > LIT
    print(f"flyaway layer: radiance beside the body {fly[~body].sum() / reference_lum[~body].sum():.2f}× the "
          f"reference's; the body's radiance with the layer {fly[body].sum() / full_lum[body].sum():.3f}× without it "
          f"(the reference's over the full model's there: {reference_lum[body].sum() / full_lum[body].sum():.3f})",
          flush=True)
    if args.flyaway_spp > 0:
        bare = _trace_without_flyaways(scene, args.flyaway_spp) @ LUMINANCE
        print(f"reference without flyaways ({args.flyaway_spp} spp): mean {bare.mean() / reference_lum.mean():.3f} of "
              f"the reference's; full model / flyaway-free reference {full_mean / bare.mean():.3f}")


def _trace_without_flyaways(scene, spp):
    """The scene's reference image, traced with the fiber sweep's flyaways switched off."""
    from knitbake.fibers.fiber_sweep import sweep_fibers
    from knitbake.trace import reference

    def bare(*args, **kw):
        return sweep_fibers(*args, **{**kw, "flyaways": False})

    reference.sweep_fibers = bare
    try:
        return reference.trace_reference(scene, spp, seed=scene.render.seed, max_depth=scene.render.max_depth)[0]
    finally:
        reference.sweep_fibers = sweep_fibers


if __name__ == "__main__":
    main()
