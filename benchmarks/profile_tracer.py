"""Where the reference path tracer's time goes: build an example scene's fibers, warm the kernels up, then render
``--spp`` samples (run it under a sampling profiler; Numba's kernels show as JIT code, Embree as its library).

    perf record -F 499 -g -o tracer.perf .venv/bin/python benchmarks/profile_tracer.py [--scene knit_patch_directional]
    perf report -i tracer.perf --sort dso --stdio --no-children -g none
"""

import argparse
import time
from pathlib import Path

from data_formats.scene import load_scene
from knitbake.trace.path_tracer import render
from knitbake.trace.reference import build_reference

EXAMPLES = Path(__file__).resolve().parent.parent / "examples" / "scenes"


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--scene", default="knit_patch_directional")
    parser.add_argument("--spp", type=int, default=8)
    args = parser.parse_args()
    built = build_reference(load_scene(EXAMPLES / f"{args.scene}.toml"))
    render(built.tracer, built.camera, 1, max_depth=2)  # kernels loaded before the profiled part
    t0 = time.perf_counter()
    _, stats = render(built.tracer, built.camera, args.spp)
    seconds = time.perf_counter() - t0
    print(f"{args.scene}: {args.spp} spp in {seconds:.2f} s, {stats.rays_per_second / 1e6:.2f} M rays/s")


if __name__ == "__main__":
    main()
