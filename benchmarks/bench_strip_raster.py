"""Strip rasterizer: ms per frame at 1280×960 for a ~60K-control-point stockinette patch (60 rows × 21 stitches,
48 points per stitch, yarn radius 0.03 cm, patch about 5 × 10 cm), MSAA k = 1 and 4, 1 and 2 Numba threads.

Views: "front" (pinhole, fov 40°, the whole patch in view, strips ~5 px wide) and "grazing" (pinhole, fov 40°, 20°
above the patch plane, 12 cm from its centre on the side of its first row: near rows large, far rows thin and
overlapping).
Every timing is the median over ``--frames`` calls after one warm-up call (which pays Numba compile or cache load);
"best" is the fastest call. Two buffers: "visibility" (``rasterize_visibility``: triangle, curve and depth per sample,
what the renderer draws) and "g-buffer" (``rasterize_strips``: every attribute at every covered sample).

    .venv/bin/python benchmarks/bench_strip_raster.py [--frames 9]
"""

import argparse
import time

import numba
import numpy as np

from knitrun.render.camera import Camera
from knitrun.render.strip_raster import rasterize_strips, rasterize_visibility
from knitrun.sim.crane_stockinette import stockinette_curves

WIDTH, HEIGHT = 1280, 960


def views():
    """(name, Camera) pairs for the patch spanning x ∈ [0, 5], y ∈ [0, 10] cm."""
    centre = np.array([2.4, 5.0, 0.0])
    grazing = centre + 12.0 * np.array([0.0, -np.cos(np.radians(20)), np.sin(np.radians(20))])
    return [("front", Camera(centre + [0, 0, 15.0], centre, np.array([0.0, 1.0, 0.0]), WIDTH, HEIGHT, 40.0)),
            ("grazing", Camera(grazing, centre, np.array([0.0, 0.0, 1.0]), WIDTH, HEIGHT, 40.0))]


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--frames", type=int, default=9)
    args = parser.parse_args()
    yc = stockinette_curves(60, 21)
    points, n_curves = yc.points[0], len(yc.offsets) - 1
    radius = np.full(n_curves, 0.03)
    print(f"## Strip rasterizer, {WIDTH}×{HEIGHT}, {points.shape[0]} control points, {n_curves} curves")
    print(f"{'view':>8}{'buffer':>11}{'k':>3}{'threads':>8}{'ms/frame':>10}{'best ms':>9}{'coverage':>10}")
    default_threads = numba.get_num_threads()
    for name, cam in views():
        for buffer, draw in (("visibility", rasterize_visibility), ("g-buffer", rasterize_strips)):
            for k in (1, 4):
                for threads in sorted({1, min(2, default_threads)}):
                    numba.set_num_threads(threads)
                    times = []
                    for _ in range(args.frames + 1):
                        t0 = time.perf_counter()
                        out = draw(points, yc.offsets, yc.closed, yc.rest_arclength, radius, yc.yarn_type, cam,
                                   msaa=k)
                        times.append(time.perf_counter() - t0)
                    times = times[1:]
                    print(f"{name:>8}{buffer:>11}{k:>3}{threads:>8}{1e3 * np.median(times):>10.1f}"
                          f"{1e3 * min(times):>9.1f}{out.coverage.mean():>10.3f}")
    numba.set_num_threads(default_threads)


if __name__ == "__main__":
    main()
