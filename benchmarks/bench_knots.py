"""Knot simulator: ms per frame for 1K, 10K and 100K faces with 1 and 2 Numba threads, the 200K-rendering-point
target, compile time (cold and cached), Gauss-Newton versus a converged dense solve, and the Huang et al. 2025 Fig. 9
comparison (naive interpolation of control points / knot interpolation / knot optimisation).

Every timing is the median over ``--frames`` frames of a stretch-and-release animation (stretch-x=1.5 and shear=0.3,
3 Gauss-Newton iterations), after ``prepare`` (which pays Numba compile or cache load); "solve" is the per-face
kernel, "assembly" the join + Catmull-Rom up-sampling into rendering points (4 per control segment); "best" the
fastest frame (solve + assembly).

    .venv/bin/python benchmarks/bench_knots.py [--frames 21] [--sizes 32,100,316] [--skip-compile]
"""

import argparse
import os
import subprocess
import sys
import tempfile
import time

import numba
import numpy as np
from scipy.optimize import least_squares

from knitrun.sim.deformations import deform, deformation_frames
from knitrun.sim.knit_chart import chart_to_mesh, pattern_chart
from knitrun.sim.simulate import (control_segment_lengths, course_knot_spacing, face_problem, prepare, solve_frame,
                                  yarn_points)

COMPILE_SNIPPET = """
import time
t0 = time.perf_counter()
from knitrun.sim.knit_chart import chart_to_mesh, pattern_chart
from knitrun.sim.simulate import prepare, solve_frame, yarn_points
mesh = chart_to_mesh(pattern_chart("eyelet", 4, 4))
model = prepare(mesh)
yarn_points(model, solve_frame(model, mesh.vertices).points)
print(time.perf_counter() - t0)
"""


def frame_times(model, frames):
    """Median solve and assembly times and the best total time of the frames, in ms (buffers reused over frames,
    as in an animation loop)."""
    solve, assembly = [], []
    solved, render = solve_frame(model, frames[0]), yarn_points(model, model.rest_points)
    for v in frames:
        t0 = time.perf_counter()
        solved = solve_frame(model, v, out=solved)
        t1 = time.perf_counter()
        yarn_points(model, solved.points, out=render)
        t2 = time.perf_counter()
        solve.append(t1 - t0)
        assembly.append(t2 - t1)
    return 1e3 * np.median(solve), 1e3 * np.median(assembly), 1e3 * np.min(np.add(solve, assembly))


def speed(sizes, n_frames):
    print("\n## Speed (stockinette, stretch-x=1.5 + shear=0.3 stretch and release, 3 iterations)")
    print(f"{'faces':>8}{'ctrl pts':>10}{'render pts':>12}{'threads':>8}{'solve ms':>10}{'assembly ms':>12}"
          f"{'total ms':>10}{'best ms':>9}{'Mpts/s':>8}{'prepare s':>10}")
    default_threads = numba.get_num_threads()
    for n in sizes:
        mesh = chart_to_mesh(pattern_chart("stockinette", n, n))
        t0 = time.perf_counter()
        model = prepare(mesh)
        prep = time.perf_counter() - t0
        frames = deformation_frames(mesh.vertices, ["stretch-x=1.5", "shear=0.3"], n_frames)
        for threads in sorted({1, default_threads}):
            numba.set_num_threads(threads)
            frame_times(model, frames[:2])  # warm the threads
            solve, assembly, best = frame_times(model, frames)
            total = solve + assembly
            print(f"{len(mesh.stitch_type):>8}{len(model.layout.index):>10}{model.plan.offsets[-1]:>12}{threads:>8}"
                  f"{solve:>10.2f}{assembly:>12.2f}{total:>10.2f}{best:>9.2f}"
                  f"{model.plan.offsets[-1] / total / 1e3:>8.1f}{prep:>10.2f}")
        numba.set_num_threads(default_threads)


def compile_time():
    print("\n## Compile time (prepare + one frame of a 16-face mesh in a fresh process)")
    with tempfile.TemporaryDirectory() as cache:
        env = dict(os.environ, NUMBA_CACHE_DIR=cache)
        for label in ("cold (empty cache: compile)", "warm (cache=True: load)"):
            out = subprocess.run([sys.executable, "-c", COMPILE_SNIPPET], env=env, capture_output=True, text=True,
                                 check=True)
            print(f"  {label}: {float(out.stdout):.1f} s")


def gn_versus_dense(n_frames=8, seed=1):
    print("\n## Gauss-Newton after k iterations versus a converged dense solve (E_k/E_* - 1, per face)")
    print("eyelet 7 x 8 (knit, yarn-over, k2tog, ssk), random stretch-x 0.6-1.8, stretch-y 0.7-1.4, shear +-0.6,\n"
          "vertex noise 0.01 cm; E_* = scipy least_squares (LM, tolerances 1e-15) on the same face problem and start")
    model = prepare(chart_to_mesh(pattern_chart("eyelet", 7, 8)))
    mesh = model.mesh
    rng = np.random.default_rng(seed)
    c = 0.5 * (mesh.vertices.min(axis=0) + mesh.vertices.max(axis=0))
    iterations = (1, 2, 3, 5)
    ratios = {k: [] for k in iterations}
    for _ in range(n_frames):
        v = deform(mesh.vertices, "stretch-x", rng.uniform(0.6, 1.8), 1.0, c)
        v = deform(v, "stretch-y", rng.uniform(0.7, 1.4), 1.0, c)
        v = deform(v, "shear", rng.uniform(-0.6, 0.6), 1.0, c)
        v = v + rng.normal(0, 0.01, v.shape) * [1, 1, 0]
        history = solve_frame(model, v, iterations=max(iterations)).energy
        for f in range(len(mesh.stitch_type)):
            theta0, fun, jac = face_problem(model, v, f)
            best = 2 * least_squares(fun, theta0, jac=jac, method="lm", xtol=1e-15, ftol=1e-15, gtol=1e-15).cost
            for k in iterations:
                ratios[k].append(history[f, k] / best - 1)
    print(f"{'iterations':>10}{'faces':>7}{'median':>10}{'95th pct':>10}{'max':>10}")
    for k in iterations:
        r = np.array(ratios[k])
        print(f"{k:>10}{len(r):>7}{np.median(r):>10.2e}{np.percentile(r, 95):>10.2e}{r.max():>10.2e}")


def fig9():
    print("\n## Seed 000 Fig. 9: stockinette 8 x 8; naive = every control point by the face's F, knots = knot "
          "interpolation\n(iterations 0), ours = 3 iterations; length error = RMS of L/L0 - 1 over control segments; "
          "knot spacing = consecutive knot distances along courses / rest")
    model = prepare(chart_to_mesh(pattern_chart("stockinette", 8, 8)))
    rest_len = control_segment_lengths(model, model.rest_points)
    rest_gap = course_knot_spacing(model, model.rest_points)
    print(f"{'deformation':>14}{'method':>7}{'energy':>10}{'len err':>9}{'total len':>10}{'spacing':>9}{'cv':>9}")
    for spec in ("stretch-x=1.5", "stretch-x=2.0", "stretch-y=1.5", "shear=0.5"):
        v = deformation_frames(model.mesh.vertices, [spec])[0]
        for name, mode in (("naive", {"naive": True}), ("knots", {"iterations": 0}), ("ours", {})):
            solved = solve_frame(model, v, **mode)
            ratio = control_segment_lengths(model, solved.points) / rest_len
            gap = course_knot_spacing(model, solved.points) / rest_gap
            energy = solved.energy[:, 0 if mode.get("naive") else -1].sum()
            print(f"{spec:>14}{name:>7}{energy:>10.1f}{np.sqrt(np.mean((ratio - 1) ** 2)):>9.4f}"
                  f"{(ratio * rest_len).sum() / rest_len.sum():>10.4f}{gap.mean():>9.4f}{gap.std() / gap.mean():>9.1e}")


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--frames", type=int, default=21)
    parser.add_argument("--sizes", default="32,58,100,316", help="n for n x n stitch meshes (58: ~200K points)")
    parser.add_argument("--skip-compile", action="store_true")
    args = parser.parse_args()
    print(f"numba {numba.__version__}, {numba.get_num_threads()} threads, {os.cpu_count()} CPUs, load average "
          f"{os.getloadavg()[0]:.2f} (other work on the machine slows the 2-thread runs most)")
    if not args.skip_compile:
        compile_time()
    speed([int(s) for s in args.sizes.split(",")], args.frames)
    gn_versus_dense()
    fig9()


if __name__ == "__main__":
    main()
