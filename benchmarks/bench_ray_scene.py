"""Tessellation, Embree build and ray throughput on one period of a procedural yarn.

Prints: fibers and segments, tessellation time (after a warm-up call, so without Numba compile or cache load),
triangle count, RayScene construction time (mesh copy + BVH commit), and rays/s for 1 and 2 threads. Rays are
primary rays at the yarn: random unit directions, aimed at random points of the yarn's bounding cylinder, starting
outside it. Lengths in the yarn spec's unit (cm).

    .venv/bin/python benchmarks/bench_ray_scene.py                     # cotton1
    .venv/bin/python benchmarks/bench_ray_scene.py --preset rayon1
    .venv/bin/python benchmarks/bench_ray_scene.py --synthetic         # helix bundle, no generator needed
"""

import argparse
import time

import numpy as np

from knitbake.fiber_set import FiberSet
from knitbake.ray_scene import RayScene
from knitbake.tessellate import tessellate_fibers


def synthetic_fibers(n_fibers=225, n_segments=64, yarn_radius=0.03, period=0.45, fiber_radius=8e-4, seed=0):
    """Helical fibers of one twist period, uniformly spread over the yarn cross-section (cotton1-like sizes)."""
    rng = np.random.default_rng(seed)
    rho = yarn_radius * np.sqrt(rng.random(n_fibers))
    phase = 2 * np.pi * rng.random(n_fibers)
    s = np.linspace(0.0, 1.0, n_segments + 1)
    angle = phase[:, None] + 2 * np.pi * s
    points = np.stack([rho[:, None] * np.cos(angle), rho[:, None] * np.sin(angle),
                       np.broadcast_to(period * s, angle.shape)], axis=-1).reshape(-1, 3)
    offsets = np.arange(n_fibers + 1) * (n_segments + 1)
    return FiberSet(points, offsets, np.full(n_fibers, fiber_radius), np.zeros(n_fibers, np.int8),
                    np.zeros(n_fibers, np.int16), 0.0, period)


def preset_fibers(name, seed):
    from data_formats.yarn_spec import load_preset
    from knitbake.procedural_yarn import generate_fibers

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
    parser.add_argument("--synthetic", action="store_true", help="225 helical fibers x 64 segments instead")
    parser.add_argument("--sides", type=int, default=6)
    parser.add_argument("--rays", type=int, default=1_000_000)
    parser.add_argument("--seed", type=int, default=0)
    args = parser.parse_args()

    fibers, t_gen = timed(synthetic_fibers if args.synthetic else preset_fibers,
                          **({} if args.synthetic else {"name": args.preset, "seed": args.seed}))
    print(f"yarn             {'synthetic helix bundle' if args.synthetic else args.preset}  "
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
