"""Check the renderer's n_occluded = n_cross/2 (``knitrun.shading.dual_scattering.fiber_counts``): on the bake's
straight yarn, the bin-averaged DS estimate the renderer uses (exact lit fraction, one fiber count f·n_cross for every
shadowed hit) against the per-hit DS with each hit's own count of fibers toward the light, over 48 light/view
directions. Prints the mean |error| relative to the per-hit DS for several f. (ξ divides by the renderer's estimate,
so this error matters where ξ is not applied: the no-tables ablation and the environment's multiple scattering.)

    .venv/bin/python benchmarks/check_n_occluded.py [cotton1 rayon1 ...]
"""

import argparse
import math

import numpy as np

from data_formats.yarn_spec import load_preset
from knitbake.stages.correction import (fiber_frames, fibers_toward, primary_hits, strip_camera, yarn_direction,
                                        yarn_tracer)
from knitbake.stages.ds_precompute import precompute_dual_scattering
from knitrun.shading.dual_scattering import evaluate_ds, fiber_counts
from knitrun.shading.fiber_bcsdf import params_from_optics
from knitrun.shading.fiber_frame import fiber_angles

FRACTIONS = (0.15, 0.25, 1 / 3, 0.4, 0.5, 0.6)


def check(name):
    spec = load_preset(name)
    params = params_from_optics(spec.optics)
    n_cross = fiber_counts(spec.geometry, spec.radius)[0]
    ds = {k: v[0] for k, v in precompute_dual_scattering(params, n_theta=32).items()}
    geom = yarn_tracer(spec, 0)
    err, total = np.zeros(len(FRACTIONS)), 0.0
    for theta_o in (0.0, 0.5):
        cam = strip_camera(spec, theta_o, 16)
        _, points, prims, _ = primary_hits(geom, cam, 0, 0)
        t = fiber_frames(geom, prims)
        wo = np.tile(-cam.basis()[0], (len(t), 1))
        for theta_i in (-0.6, 0.0, 0.6):
            for phi in np.linspace(-math.pi, math.pi, 8, endpoint=False) + math.pi / 8:
                light = yarn_direction(theta_i, -phi)
                th_i, th_o, az = fiber_angles(t, wo, np.tile(light, (len(t), 1)))
                n = fibers_toward(geom, prims, points, light)
                exact = evaluate_ds(ds, th_i, th_o, az, n, params=params)[:, 1].mean()
                lit = float((n == 0).mean())
                for k, f in enumerate(FRACTIONS):
                    run = evaluate_ds(ds, th_i, th_o, az, f * n_cross, params=params, direct_fraction=lit)
                    err[k] += abs(run[:, 1].mean() - exact)
                total += exact
    cells = ", ".join(f"f = {f:.2f}: {e:.3f}" for f, e in zip(FRACTIONS, err / total))
    print(f"{name} (n_cross {n_cross:.2f}) mean |error| / exact DS — {cells}")


def main():
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("presets", nargs="*", default=["cotton1", "rayon1"],
                        help="yarn presets (data_formats.yarn_spec.load_preset; default: cotton1 rayon1)")
    args = parser.parse_args()
    for name in args.presets:
        try:
            load_preset(name)
        except (KeyError, ValueError, FileNotFoundError) as e:
            parser.error(f"preset {name!r}: {e}")
        check(name)


if __name__ == "__main__":
    main()
