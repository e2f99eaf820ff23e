"""The contact statistic (``knitrun.sim.contact``) of every named pattern, simulated at rest and under the issue-14
deformations: the 5th percentile and the median of d / 2r (1 = touching, below 1 the yarns interpenetrate), with
the fraction of samples below 0.8. Target (issue 14): 5th percentile ≥ 0.80 and median in [0.95, 1.10] in every
cell.

    .venv/bin/python benchmarks/bench_contact.py [--rows 12 --cols 12]

Each cell simulates the pattern's chart (``knitrun pattern P --rows R --cols C``) with one frame of the full
deformation (the default 3 Gauss-Newton iterations) and measures that frame with the simulator's radius.
"""

import argparse
import time

from knitrun.sim.contact import DEEP, contact_statistic
from knitrun.sim.deformations import deformation_frames
from knitrun.sim.knit_chart import PATTERNS, chart_to_mesh, pattern_chart
from knitrun.sim.simulate import simulate

DEFORMATIONS = {"at rest": [], "stretch-x 1.5": ["stretch-x=1.5"], "stretch-y 1.5": ["stretch-y=1.5"],
                "shear 0.3": ["shear=0.3"]}


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--rows", type=int, default=12)
    parser.add_argument("--cols", type=int, default=12)
    args = parser.parse_args()
    t0 = time.perf_counter()
    header = " | ".join(f"{name}: p5 / median / < {DEEP}" for name in DEFORMATIONS)
    print(f"| pattern | {header} |")
    print("|---" * (len(DEFORMATIONS) + 1) + "|")
    radius = None
    for pattern in PATTERNS:
        mesh = chart_to_mesh(pattern_chart(pattern, args.rows, args.cols))
        cells = []
        for specs in DEFORMATIONS.values():
            curves, report = simulate(mesh, deformation_frames(mesh.vertices, specs, 1))
            radius = report["yarn_radius"]
            s = contact_statistic(curves, radius, 0)
            cells.append(f"{s['p5']:.3f} / {s['p50']:.3f} / {s[f'fraction_below_{DEEP}']:.2f}")
        print(f"| {pattern} | " + " | ".join(cells) + " |")
    print(f"\n{args.rows}×{args.cols} stitches, r = {radius} (the simulator's), {time.perf_counter() - t0:.1f} s")


if __name__ == "__main__":
    main()
