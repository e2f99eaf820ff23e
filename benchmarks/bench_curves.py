"""Fibers as Embree 4 round linear curves against the tessellated tubes the tracer uses today (issue 16): memory per
fiber segment, build time and closest-hit rays per second, for the fibers of an example scene.

Each variant runs in its own process: the fibers are swept from the scene's yarn curves (``sweep_fibers``, as
``build_reference`` does), then the scene is built and its peak resident memory over the process's after the sweep
is divided by the segment count. Rays: random directions through random points of the fibers' bounding box, started
outside it (the same rays for both), traced after one warm-up batch; 2 threads.

    .venv/bin/python benchmarks/bench_curves.py [--scene knit_patch_directional] [--rays 1000000]
"""

import argparse
import json
import resource
import subprocess
import sys
import time
from pathlib import Path

import numpy as np

EXAMPLES = Path(__file__).resolve().parent.parent / "examples" / "scenes"


def _fibers(scene_name):
    from data_formats.scene import load_scene, read_curves
    from knitbake.fibers.fiber_sweep import sweep_fibers

    scene = load_scene(EXAMPLES / f"{scene_name}.toml")
    entry = scene.yarns[0]
    curves = read_curves(entry.curves, scene.units)
    return sweep_fibers(curves, scene.render.frame, {i: entry.spec for i in entry.yarn_type_indices},
                        {i: entry.radius for i in entry.yarn_type_indices}, seed=0)


def _rays(fibers, n):
    rng = np.random.default_rng(1)
    lo, hi = fibers.points.min(axis=0), fibers.points.max(axis=0)
    d = rng.normal(size=(n, 3))
    d /= np.linalg.norm(d, axis=1, keepdims=True)
    target = lo + (hi - lo) * rng.random((n, 3))
    return target - 2 * np.linalg.norm(hi - lo) * d, d


def _peak_mib():
    return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024


def run_variant(variant, scene_name, n_rays):
    fibers = _fibers(scene_name)
    origins, directions = _rays(fibers, n_rays)
    base = _peak_mib()
    t0 = time.perf_counter()
    if variant == "curves":
        from knitbake.trace.embree_curves import CurveScene, closest_hits

        scene = CurveScene(fibers)
        build = time.perf_counter() - t0
        trace = lambda o, d: closest_hits(scene, o, d)[1]  # noqa: E731
    else:
        from knitbake.fibers.tessellate import tessellate_fibers
        from knitbake.trace.reference import TUBE_SIDES
        from knitbake.trace.ray_scene import RayScene

        scene = RayScene(tessellate_fibers(fibers, sides=TUBE_SIDES))
        build = time.perf_counter() - t0
        trace = lambda o, d: scene.intersect(o, d).prim  # noqa: E731
    peak = _peak_mib()
    trace(origins[:1000], directions[:1000])
    t0 = time.perf_counter()
    hits = trace(origins, directions)
    seconds = time.perf_counter() - t0
    return {"variant": variant, "segments": int(fibers.n_segments), "build_s": build,
            "bytes_per_segment": (peak - base) * 2 ** 20 / fibers.n_segments, "peak_mib": peak,
            "rays_per_s": n_rays / seconds, "hit_fraction": float(np.mean(np.asarray(hits) >= 0))}


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--scene", default="knit_patch_directional")
    parser.add_argument("--rays", type=int, default=1_000_000)
    parser.add_argument("--variant", choices=["curves", "tubes"], help=argparse.SUPPRESS)
    args = parser.parse_args()
    if args.variant:
        print(json.dumps(run_variant(args.variant, args.scene, args.rays)))
        return
    print(f"## {args.scene}: fibers as curves vs tessellated tubes (2 threads, {args.rays} rays)")
    print("| variant | segments | build s | bytes per segment | peak MiB | M rays/s | hit fraction |")
    print("|---|---|---|---|---|---|---|")
    for variant in ("tubes", "curves"):
        out = subprocess.run([sys.executable, __file__, "--variant", variant, "--scene", args.scene, "--rays",
                              str(args.rays)], check=True, capture_output=True, text=True).stdout
        r = json.loads(out.strip().splitlines()[-1])
        print(f"| {variant} | {r['segments']} | {r['build_s']:.2f} | {r['bytes_per_segment']:.0f} | "
              f"{r['peak_mib']:.0f} | {r['rays_per_s'] / 1e6:.2f} | {r['hit_fraction']:.3f} |", flush=True)


if __name__ == "__main__":
    main()
