"""Reference path tracer: rays/s on both cores, and a 512×512, 64-spp render of a 10×10-stitch knit patch with
explicit fibers (closed-form stockinette curves until the knot simulator drives the scene).

Prints fibers, triangles, build times (sweep, tessellation, Embree), render time, rays/s of the whole tracer
(camera, scattering and shadow rays, kernels included), rays/s of bare Embree intersection on the same scene with
1 and 2 threads, and the process's peak resident memory.

    .venv/bin/python benchmarks/bench_reference.py [--size 512] [--spp 64] [--stitches 10] [--out ref.exr]
"""

import argparse
import resource
import tempfile
import time
from pathlib import Path

import numpy as np

from data_formats.images import write_exr, write_png
from data_formats.scene import load_scene
from knitbake.trace.path_tracer import render
from knitbake.trace.reference import build_reference
from knitrun.sim.crane_stockinette import write_example_patch

SCENE = """format = "knit-scene"
version = "1.0"
units = "cm"
[[yarns]]
curves = "patch.h5"
yarn = "cotton1"
radius = {radius}
[camera]
position = [{cx}, {cy}, 4.0]
look_at = [{cx}, {cy}, 0.0]
ortho_height = {height}
width = {size}
height = {size}
[[lights]]
type = "directional"
direction = [0.4, 0.6, 1.0]
irradiance = [3.0, 3.0, 3.0]
[[lights]]
type = "environment"
builtin = "sky"
scale = [0.3, 0.3, 0.3]
"""


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--size", type=int, default=512)
    parser.add_argument("--spp", type=int, default=64)
    parser.add_argument("--stitches", type=int, default=10)
    parser.add_argument("--radius", type=float, default=0.03)
    parser.add_argument("--out", default=None, help="also write the image (EXR + PNG)")
    args = parser.parse_args()
    with tempfile.TemporaryDirectory() as tmp:
        curves = write_example_patch(Path(tmp) / "patch.h5", args.stitches, args.stitches, args.radius)
        lo, hi = curves.points[0].min(axis=0), curves.points[0].max(axis=0)
        centre = (lo + hi) / 2
        (Path(tmp) / "scene.toml").write_text(SCENE.format(radius=args.radius, cx=centre[0], cy=centre[1],
                                                           height=1.05 * max(hi[:2] - lo[:2]), size=args.size))
        scene = load_scene(Path(tmp) / "scene.toml")
        t0 = time.perf_counter()
        built = build_reference(scene)
        t_build = time.perf_counter() - t0
    f = built.facts
    print(f"patch            {args.stitches}x{args.stitches} stitches, {f['fibers']} fibers, {f['segments']} segments, "
          f"{f['triangles']} triangles")
    print(f"build            {t_build:.1f} s (sweep {f['sweep_s']:.1f}, tessellate {f['tessellate_s']:.1f}, "
          f"Embree {f['embree_build_s']:.1f})")
    render(built.tracer, built.camera, 1, max_depth=2)  # warm-up: kernel cache load
    image, stats = render(built.tracer, built.camera, args.spp)
    print(f"render           {args.size}x{args.size}, {args.spp} spp: {stats.seconds:.1f} s, {stats.rays / 1e6:.1f} M rays, "
          f"{stats.rays_per_second / 1e6:.2f} M rays/s (whole tracer, 2 cores)")
    rng = np.random.default_rng(0)
    n = 1_000_000
    target = built.camera.look_at + np.c_[rng.uniform(-0.5, 0.5, (n, 2)) * 1.0, np.zeros(n)]
    origins = target + [0.0, 0.0, 4.0]
    dirs = np.tile([0.0, 0.0, -1.0], (n, 1)) + rng.normal(0, 0.05, (n, 3))
    for threads in (1, 2):
        built.tracer.ray_scene.threads = threads
        t0 = time.perf_counter()
        built.tracer.ray_scene.intersect(origins, dirs)
        print(f"embree {threads} thread{'s' if threads > 1 else ' '} {n / (time.perf_counter() - t0) / 1e6:.2f} M rays/s "
              f"(primary rays at the patch)")
    print(f"peak memory      {resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024:.0f} MiB")
    print(f"image mean       {image.reshape(-1, 3).mean(axis=0).round(4).tolist()}")
    if args.out:
        write_exr(args.out, image)
        write_png(str(Path(args.out).with_suffix(".png")), image)


if __name__ == "__main__":
    main()
