"""Reference path tracer at scale: a knit patch of N×N stitches with explicit fibers (closed-form stockinette curves,
cotton1 with flyaways), built and path-traced, as the fibers' Embree curves (default) or the former tessellated tubes.

Prints fibers, segments (and triangles for tubes), build times (sweep, tessellation, Embree), the process's peak
resident memory and that peak less the resident memory before the build, per fiber segment (what the scene costs);
the render time and rays/s of the whole tracer (camera, scattering and shadow rays, kernels included); a short
render with 1 and with 2 threads (time, and whether the images are identical); bare Embree closest-hit rays/s on
the same scene with 1 and 2 threads.

    .venv/bin/python benchmarks/bench_reference.py [--size 512] [--spp 64] [--stitches 10] [--geometry curves]
        [--out ref.exr]
"""

import argparse
import os
import resource
import tempfile
import time
from pathlib import Path

import numba
import numpy as np

from data_formats.images import write_exr, write_png
from data_formats.scene import load_scene
from knitbake.trace.embree_curves import closest_hits
from knitbake.trace.path_tracer import render
from knitbake.trace.reference import GEOMETRIES, build_reference
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


def _peak_mib():
    return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024


def _resident_mib():
    with open(f"/proc/{os.getpid()}/statm") as statm:
        return int(statm.read().split()[1]) * os.sysconf("SC_PAGE_SIZE") / 2**20


def _warm_up(folder, args):
    """Build a 1×1-stitch patch once and trace a few rays, so that compiled kernels and libraries are resident
    before the memory baseline is taken."""
    folder = folder / "warm-up"
    folder.mkdir()
    write_example_patch(folder / "patch.h5", 1, 1, args.radius)
    (folder / "scene.toml").write_text(SCENE.format(radius=args.radius, cx=0, cy=0, height=1, size=8))
    built = build_reference(load_scene(folder / "scene.toml"), geometry=args.geometry)
    if built.tracer.curves is not None:
        closest_hits(built.tracer.curves, np.zeros((4, 3)), np.tile([0.0, 0.0, 1.0], (4, 1)))
    del built


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--size", type=int, default=512)
    parser.add_argument("--spp", type=int, default=64)
    parser.add_argument("--stitches", type=int, default=10)
    parser.add_argument("--radius", type=float, default=0.03)
    parser.add_argument("--geometry", choices=GEOMETRIES, default="curves")
    parser.add_argument("--thread-spp", type=int, default=2, help="spp of the 1- vs 2-thread renders")
    parser.add_argument("--out", default=None, help="also write the image (EXR + PNG)")
    args = parser.parse_args()
    with tempfile.TemporaryDirectory() as tmp:
        curves = write_example_patch(Path(tmp) / "patch.h5", args.stitches, args.stitches, args.radius)
        lo, hi = curves.points[0].min(axis=0), curves.points[0].max(axis=0)
        centre = (lo + hi) / 2
        (Path(tmp) / "scene.toml").write_text(SCENE.format(radius=args.radius, cx=centre[0], cy=centre[1],
                                                           height=1.05 * max(hi[:2] - lo[:2]), size=args.size))
        scene = load_scene(Path(tmp) / "scene.toml")
        _warm_up(Path(tmp), args)  # the sweep's and Embree's kernels loaded: a fixed cost, not the scene's
        before = _resident_mib()
        t0 = time.perf_counter()
        built = build_reference(scene, geometry=args.geometry)
        t_build = time.perf_counter() - t0
    f = built.facts
    peak = _peak_mib()
    triangles = f", {f['triangles']:,} triangles" if f["triangles"] else ""
    print(f"patch            {args.stitches}x{args.stitches} stitches, {f['fibers']:,} fibers, "
          f"{f['segments']:,} segments{triangles} ({args.geometry})")
    print(f"build            {t_build:.1f} s (sweep {f['sweep_s']:.1f}, tessellate {f['tessellate_s']:.1f}, "
          f"Embree {f['embree_build_s']:.1f})")
    print(f"memory           peak {peak:,.0f} MiB; {before:,.0f} MiB resident before the build; "
          f"{(peak - before) * 2**20 / f['segments']:.0f} B per segment over that")
    render(built.tracer, built.camera, 1, max_depth=2)  # warm-up: kernel cache load
    image, stats = render(built.tracer, built.camera, args.spp)
    print(f"render           {args.size}x{args.size}, {args.spp} spp: {stats.seconds:.1f} s, "
          f"{stats.rays / 1e6:.1f} M rays, "
          f"{stats.rays_per_second / 1e6:.2f} M rays/s (whole tracer, {numba.get_num_threads()} threads)")
    images = {}
    for threads in (1, 2):
        numba.set_num_threads(threads)
        images[threads], st = render(built.tracer, built.camera, args.thread_spp)
        print(f"threads {threads}        {args.thread_spp} spp: {st.seconds:.1f} s, "
              f"{st.rays_per_second / 1e6:.2f} M rays/s")
    print(f"thread count     images with 1 and 2 threads identical: {bool(np.array_equal(images[1], images[2]))}")
    rng = np.random.default_rng(0)
    n = 1_000_000
    target = built.camera.look_at + np.c_[rng.uniform(-0.5, 0.5, (n, 2)) * 1.0, np.zeros(n)]
    origins = target + [0.0, 0.0, 4.0]
    dirs = np.tile([0.0, 0.0, -1.0], (n, 1)) + rng.normal(0, 0.05, (n, 3))
    dirs /= np.linalg.norm(dirs, axis=1, keepdims=True)
    for threads in (1, 2):
        numba.set_num_threads(threads)
        if built.tracer.ray_scene is not None:
            built.tracer.ray_scene.threads = threads
        t0 = time.perf_counter()
        if built.tracer.curves is not None:
            closest_hits(built.tracer.curves, origins, dirs)
        else:
            built.tracer.ray_scene.intersect(origins, dirs)
        rate = n / (time.perf_counter() - t0) / 1e6
        print(f"embree {threads} thread{'s' if threads > 1 else ' '} {rate:.2f} M rays/s (primary rays at the patch)")
    print(f"peak memory      {_peak_mib():,.0f} MiB")
    print(f"image mean       {image.reshape(-1, 3).mean(axis=0).round(4).tolist()}")
    if args.out:
        write_exr(args.out, image)
        write_png(str(Path(args.out).with_suffix(".png")), image)


if __name__ == "__main__":
    main()
