"""How sharply the example scenes' yarn polylines turn, against the yarn radius (issue 13, the look).

Both renderers draw a PL curve as it is: the strips interpolate the vertex tangents along each segment, the reference
sweeps its fibers along the straight segments with the frame interpolated between the vertices
(``knitbake.fibers.fiber_sweep``). Where a polyline turns gently the two agree (the fiber bend, SHADING.md §2); where
it turns by tens of degrees at a vertex they need not, and where it bends tighter than the radius (κ·r > 1) the
swept tube folds on its inside (BENCHMARKS.md, stop 76). Per scene, of the polylines the
strip renderer draws (``pipeline._polylines``): the vertex spacing over the radius r, the turn at each inner vertex
(the angle between its two segments), the discrete curvature there, κ·r = turn / (mean of the two segments' lengths)
· r, and the share of vertices with κ·r > 1. Geometry only, no rendering: about a second a scene.

    .venv/bin/python benchmarks/probe_curve_turns.py [--scenes simulated_patch_directional,knit_patch_directional]
"""

from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np

from data_formats.scene import load_scene, read_curves
from knitrun.render import pipeline

EXAMPLES = Path(__file__).resolve().parent.parent / "examples" / "scenes"
SCENES = "straight_yarn_directional,knit_patch_directional,simulated_patch_directional"
SAMPLES_PER_SEGMENT = 4  # smooth curve types: the strip renderer's default sampling (``pipeline.Renderer``); PL as is


def vertex_turns(points: np.ndarray, offsets: np.ndarray, radius: np.ndarray):
    """(spacing / r of every segment, turn in degrees and κ·r of every inner vertex) of the polylines
    ``points[offsets[c]:offsets[c + 1]]``, r the radius of each polyline (``radius[c]``); zero-length segments are
    left out."""
    spacing, turn, bend = [], [], []
    for c, (a, b) in enumerate(zip(offsets[:-1], offsets[1:])):
        d = np.diff(points[a:b], axis=0)
        length = np.linalg.norm(d, axis=1)
        keep = length > 0
        d, length = d[keep], length[keep]
        spacing.append(length / radius[c])
        if len(d) < 2:
            continue
        u = d / length[:, None]
        angle = np.arccos(np.clip(np.sum(u[:-1] * u[1:], axis=1), -1.0, 1.0))
        turn.append(np.degrees(angle))
        bend.append(angle / (0.5 * (length[:-1] + length[1:])) * radius[c])
    joined = [np.concatenate(x) if x else np.zeros(0) for x in (spacing, turn, bend)]
    return tuple(joined)


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--scenes", default=SCENES, help="comma-separated example scene names")
    args = parser.parse_args(argv)
    print("| scene | vertices | spacing / r, median | turn at a vertex: median, p90, max | κ·r: median, p90, max | "
          "κ·r > 1 |")
    print("|---|---|---|---|---|---|")
    for name in args.scenes.split(","):
        scene = load_scene(EXAMPLES / f"{name}.toml")
        curves = [read_curves(entry.curves, scene.units) for entry in scene.yarns]
        lines = pipeline._polylines(scene, curves, scene.render.frame, SAMPLES_PER_SEGMENT)
        radius = np.array([scene.yarns[k].radius for k in lines.entry])
        spacing, turn, bend = vertex_turns(lines.points, np.asarray(lines.offsets), radius)
        if len(turn) == 0:
            print(f"| {name} | {len(lines.points)} | {np.median(spacing):.2f} | — (no inner vertex) | — | — |")
            continue
        turns = f"{np.median(turn):.1f}°, {np.percentile(turn, 90):.1f}°, {turn.max():.1f}°"
        bends = f"{np.median(bend):.2f}, {np.percentile(bend, 90):.2f}, {bend.max():.2f}"
        folded = np.mean(bend > 1.0)
        print(f"| {name} | {len(lines.points)} | {np.median(spacing):.2f} | {turns} | {bends} | {folded:.3f} |")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
