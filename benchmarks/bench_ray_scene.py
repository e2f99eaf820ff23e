"""Tessellation, Embree build and ray throughput on one period of a procedural yarn.

Prints: fibers and segments, tessellation time (after a warm-up call, so without Numba compile or cache load),
triangle count, RayScene construction time (mesh copy + BVH commit), and rays/s for 1 and 2 threads. Rays are
primary rays at the yarn: random unit directions, aimed at random points of the yarn's bounding cylinder, starting
outside it. Lengths in the yarn spec's unit (cm).

    .venv/bin/python benchmarks/bench_ray_scene.py                     # cotton1
    .venv/bin/python benchmarks/bench_ray_scene.py --preset rayon1
"""

import argparse
import time

import numpy as np

from knitbake.fibers.tessellate import tessellate_fibers
from knitbake.trace.ray_scene import RayScene


def preset_fibers(name, seed):
    from data_formats.yarn_spec import load_preset
    from knitbake.fibers.procedural_yarn import generate_fibers

    return generate_fibers(load_preset(name), seed=seed)


def primary_rays(fibers, n, seed):
    """Rays from outside the yarn's bounding cylinder towards random points inside it."""
    rng = np.random.default_rng(seed)
    radius = np.hypot(fibers.points[:, 0], fibers.points[:, 1]).max()
    z0, z1 = fibers.points[:, 2].min(), fibers.points[:, 2].max()
    d = rng.normal(size=(n, 3))
    d /= np.linalg.norm(d, axis=1, keepdims=True)
    a = 2 * np.pi * rng.random(n)
    rho = radius * np.sqrt(rng.random(n))
    target = np.c_[rho * np.cos(a), rho * np.sin(a), rng.uniform(z0, z1, n)]
    return target - (2 * radius + (z1 - z0)) * d, d


def timed(f, *args, **kwargs):
    t0 = time.perf_counter()
    out = f(*args, **kwargs)
    return out, time.perf_counter() - t0


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--preset", default="cotton1", help="yarn preset (default cotton1; e.g. rayon1)")
    parser.add_argument("--sides", type=int, default=6)
    parser.add_argument("--rays", type=int, default=1_000_000)
    parser.add_argument("--seed", type=int, default=0)
    args = parser.parse_args()

    fibers, t_gen = timed(preset_fibers, args.preset, args.seed)
    print(f"yarn             {args.preset}  "
          f"({fibers.n_fibers} fibers, {fibers.n_segments} segments, generated in {t_gen:.2f} s)")
    tessellate_fibers(fibers, sides=args.sides)  # warm-up: Numba compile or cache load
    mesh, t_tess = timed(tessellate_fibers, fibers, sides=args.sides)
    print(f"tessellation     {t_tess * 1e3:8.1f} ms   {mesh.triangles.shape[0]} triangles, "
          f"{mesh.vertices.shape[0]} vertices ({args.sides} sides)")
    scene, t_build = timed(RayScene, mesh)
    print(f"embree build     {t_build * 1e3:8.1f} ms   (mesh copy + commit), eps = {scene.eps:.3g}")
    origins, directions = primary_rays(fibers, args.rays, args.seed)
    results = {}
    for threads in (1, 2):
        scene.threads = threads
        best = np.inf
        for _ in range(2):
            hits, dt = timed(scene.intersect, origins, directions)
            best = min(best, dt)
        results[threads] = hits
        print(f"intersect {threads} thr  {args.rays / best / 1e6:8.2f} Mrays/s   ({best:.2f} s, "
              f"{hits.hit.mean() * 100:.1f} % hit)")
    same = all(np.array_equal(getattr(results[1], k), getattr(results[2], k)) for k in ("t", "prim", "normal"))
    print(f"1 vs 2 threads   {'identical' if same else 'DIFFERENT'} hits")


if __name__ == "__main__":
    main()
