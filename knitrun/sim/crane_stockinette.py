"""Closed-form yarn centre curves of a plain-knit (stockinette) patch, and the example knit-patch scene files.

Model (Keenan Crane, "A Simple Parametric Model of Plain-Knit Yarns", github.com/keenancrane/plain-knit-yarn,
note ``YarnCurve.pdf``, eq. 1): every course (row) is a translated copy of

    γ(t) = s · (t + a sin 2t,  h cos t + w·row,  −d cos 2t),   one stitch per 2π of t,

a sinusoid in the wale direction (y, loop height h) made round by the overshoot a sin 2t along the course (x) and
bent out of the fabric plane (z) at twice the frequency, so that each row passes its sinkers behind (−z) the legs of
the row below and its legs in front (+z) of that row's heads: consecutive rows interloop. Crane's constants are
a = 3/2, h = 4, d = 1 and row spacing w = h + 1/2, for which he states that a tube of radius 4/5 fits snugly. We keep
them and scale the curve by s = radius / (4/5), so the patch is in the unit of ``radius``. Crane's z is negated so
that the technical face looks toward +z, the stitch-mesh convention (x along the course, y up the wales, z out of
the front); the curve is mirror-symmetric in x, so this is the same fabric turned about y, not its mirror image.

Assumptions and facts: the model is geometric, not physical (no energy minimum); all rows are identical (no cast-on
or bind-off). At the default constants tubes of the given radius come slightly closer than a diameter, between rows
and between non-neighbouring parts of one row, i.e. they overlap a little (real yarns are compressible and hairy);
``tests/test_fiber_sweep.py::test_stockinette_rows_interloop_without_interpenetration`` holds the closest approach of
the default polyline (48 points per stitch) between rows within (1.85, 2.1) × radius and within a row above
1.85 × radius, and prints both; the measured approaches are in BENCHMARKS.md, section "Stockinette patch: closest
approach". One stitch is 2π·s ≈ 7.85 radii wide and the rows are 5.63 radii apart; one stitch uses ≈ 30.8 radii of
yarn. Each row runs t ∈ [−π/2, 2π·cols − π/2], from the middle of a leg to the middle of a leg; the V-shaped legs lie
at z = +d·s (the technical face), the heads and sinkers at z = −d·s (the back).
"""

from __future__ import annotations

import numpy as np

from data_formats.errors import FormatError
from data_formats.yarn_curves import YarnCurves, make_yarn_curves, write_yarn_curves

CRANE_RADIUS = 0.8  # the tube radius of Crane's constants, in curve parameter units
ROUNDNESS = 1.5  # a
LOOP_HEIGHT = 4.0  # h
LOOP_DEPTH = 1.0  # d
ROW_SPACING = 4.5  # w = h + 1/2


def stockinette_curves(rows: int, cols: int, radius: float = 0.03, samples_per_stitch: int = 48,
                       roundness: float = ROUNDNESS, loop_height: float = LOOP_HEIGHT, loop_depth: float = LOOP_DEPTH,
                       row_spacing: float = ROW_SPACING, yarn_type: str = "cotton1", units: str = "cm") -> YarnCurves:
    """Centre curves of a stockinette patch of ``rows`` courses × ``cols`` stitches for yarn ``radius`` (in
    ``units``): one open PL curve per row (row r at y offset r·w·s), ``samples_per_stitch`` points per stitch
    uniform in t, rest arc length = control-polygon length. Shape constants in Crane's units (module docstring)."""
    if rows < 1 or cols < 1 or samples_per_stitch < 4:
        raise FormatError(f"rows = {rows}, cols = {cols}, samples_per_stitch = {samples_per_stitch}: expected "
                          f"rows, cols >= 1 and samples_per_stitch >= 4")
    if not (np.isfinite(radius) and radius > 0):
        raise FormatError(f"radius = {radius!r}, expected a positive finite number")
    s = radius / CRANE_RADIUS
    t = -np.pi / 2 + 2 * np.pi * np.arange(cols * samples_per_stitch + 1) / samples_per_stitch
    row = np.stack([t + roundness * np.sin(2 * t), loop_height * np.cos(t), -loop_depth * np.cos(2 * t)], axis=1)
    shift = np.zeros((rows, 1, 3))
    shift[:, 0, 1] = row_spacing * np.arange(rows)
    points = s * (row[None] + shift).reshape(-1, 3)
    offsets = len(t) * np.arange(rows + 1)
    return make_yarn_curves(points, offsets, curve_type="PL", yarn_types=[yarn_type], units=units)


def write_example_patch(path, rows: int = 6, cols: int = 6, radius: float = 0.03) -> YarnCurves:
    """Write the stockinette curves of ``rows`` × ``cols`` stitches (cotton1, cm) as a knit-yarn-curves file."""
    yc = stockinette_curves(rows, cols, radius)
    write_yarn_curves(path, yc)
    return yc
