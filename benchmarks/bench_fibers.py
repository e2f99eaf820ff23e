"""Fiber generation rate: fiber segments per second for the cotton1 and rayon1 presets, 1 and 2 Numba threads.

For each preset, a warm-up call (Numba compile or cache load) and then the best of ``--repeats`` timed calls of
``generate_fibers`` over ``--periods`` ply-twist periods, with flyaways (full generator) and without (regular
fibers only). Segments are polyline segments of all fibers.

    .venv/bin/python benchmarks/bench_fibers.py [--periods 50] [--presets cotton1,rayon1]
"""

import argparse
import time

import numba

from data_formats.yarn_spec import load_preset
from knitbake.fibers.procedural_yarn import generate_fibers


def best_time(fn, repeats):
    best, out = float("inf"), None
    for _ in range(repeats):
        t0 = time.perf_counter()
        out = fn()
        best = min(best, time.perf_counter() - t0)
    return out, best


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--presets", default="cotton1,rayon1")
    parser.add_argument("--periods", type=float, default=50.0)
    parser.add_argument("--repeats", type=int, default=3)
    args = parser.parse_args()
    print(f"{'preset':<10}{'flyaways':>9}{'threads':>8}{'fibers':>8}{'segments':>11}{'time ms':>10}{'Mseg/s':>9}")
    default_threads = numba.get_num_threads()
    for name in args.presets.split(","):
        spec = load_preset(name)
        length = args.periods * spec.geometry.ply_pitch
        generate_fibers(spec, length=spec.geometry.ply_pitch)  # warm-up
        for flyaways in (False, True):
            for threads in sorted({1, default_threads}):
                numba.set_num_threads(threads)
                fib, t = best_time(lambda: generate_fibers(spec, length=length, seed=1, flyaways=flyaways),
                                   args.repeats)
                print(f"{name:<10}{'yes' if flyaways else 'no':>9}{threads:>8}{fib.n_fibers:>8}{fib.n_segments:>11}"
                      f"{t * 1e3:>10.1f}{fib.n_segments / t / 1e6:>9.2f}")
        numba.set_num_threads(default_threads)


if __name__ == "__main__":
    main()
