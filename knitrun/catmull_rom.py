"""Centripetal Catmull-Rom subdivision of yarn polylines (smooth strips from coarse control points).

Curves are as in ``knitrun.strip_raster.rasterize_strips``: curve c is points[offsets[c]:offsets[c+1]] (scene
units), ``closed[c]`` joins its last point back to its first, ``rest_arclength`` is the rest arc length s of every
point (scene units).

* Every span (p1, p2) between consecutive control points (and a closed curve's closing span, last → first) becomes
  ``per_span`` sub-segments of the centripetal (α = ½) Catmull-Rom spline through p0, p1, p2, p3, evaluated in the
  Barry–Goldman pyramid with knots t_{i+1} = t_i + |p_{i+1} − p_i|^½ at t = t1 + (k / per_span)(t2 − t1),
  k = 0 … per_span − 1. Sub-point k = 0 is p1 itself, so the control points are kept exactly (every per_span-th output
  point, starting with the first). p0 and p3 are the neighbours (wrapping on a closed curve); at the ends of an open
  curve the phantoms p_{−1} = 2 p_0 − p_1 and p_{n} = 2 p_{n−1} − p_{n−2}.
* Coincident points: a zero-length span (t2 = t1) is the constant p1 (its linear interpolation); a zero outer knot
  interval (p0 = p1 or p2 = p3) takes the pyramid's limit, whose first-level point is then p1 (resp. p2), so the
  spline is finite and continuous everywhere.
* Rest arc length is linear in the spline parameter: s = s1 + (k / per_span)(s2 − s1), where on a closing span
  s2 = s_last + the curve's closing rest length (``closing_length``, default |p_last − p_first|).
* Output sizes per curve of n points: open, (n − 1)·per_span + 1 (0 if n = 0); closed, n·per_span (a 1-point closed
  curve becomes per_span copies of its point). The new closing segment's rest length is the old one / per_span.
"""

import math

import numpy as np
from numba import njit, prange


def subdivide(points, offsets, closed, rest_arclength, per_span: int, closing_length=None):
    """Subdivide every curve ``per_span`` times (module docstring). ``points`` (P, 3), ``offsets`` (C+1,),
    ``closed`` (C,) bool or a scalar, ``rest_arclength`` (P,), ``closing_length`` (C,), a scalar or None (the
    current closing lengths). Returns (points2 (P2, 3) float64, offsets2 (C+1,) int64, rest2 (P2,) float64,
    closing_length2 (C,) float64, 0 for open curves). ValueError for per_span < 1, bad offsets or shapes, or a
    non-finite input (naming the curve and point)."""
    if int(per_span) != per_span or per_span < 1:
        raise ValueError(f"per_span = {per_span}, expected an integer >= 1")
    per_span = int(per_span)
    points = np.ascontiguousarray(points, dtype=np.float64).reshape(-1, 3)
    offsets = np.asarray(offsets, dtype=np.int64)
    n_curves = len(offsets) - 1
    if n_curves < 0 or offsets.ndim != 1 or offsets[0] != 0 or offsets[-1] != len(points) \
            or np.any(np.diff(offsets) < 0):
        raise ValueError(f"offsets must run non-decreasing from 0 to the point count {len(points)}")
    closed = np.broadcast_to(np.asarray(closed, dtype=np.bool_), (n_curves,))
    rest = np.ascontiguousarray(rest_arclength, dtype=np.float64)
    if rest.shape != (len(points),):
        raise ValueError(f"rest_arclength has shape {rest.shape}, expected ({len(points)},)")
    if not (np.isfinite(points).all() and np.isfinite(rest).all()):
        p = int(np.flatnonzero(~(np.isfinite(points).all(axis=1) & np.isfinite(rest)))[0])
        c = int(np.searchsorted(offsets, p, side="right") - 1)
        raise ValueError(f"curve {c}: point {p - offsets[c]} has non-finite coordinates or rest arc length "
                         f"({points[p].tolist()}, {rest[p]})")

    first, last = offsets[:-1], offsets[1:] - 1
    count = np.diff(offsets)
    nonempty = count > 0
    if closing_length is None:
        closing = np.zeros(n_curves)
        closing[nonempty] = np.linalg.norm(points[last[nonempty]] - points[first[nonempty]], axis=1)
    else:
        closing = np.array(np.broadcast_to(np.asarray(closing_length, np.float64), (n_curves,)))
        bad = np.flatnonzero(closed & ~(np.isfinite(closing) & (closing >= 0)))
        if bad.size:
            raise ValueError(f"curve {bad[0]}: closing_length = {closing[bad[0]]}, expected finite and >= 0")
    closing2 = np.where(closed & nonempty, closing / per_span, 0.0)
    if per_span == 1:
        return points.copy(), offsets.copy(), rest.copy(), closing2

    n_out = np.where(closed, count * per_span, np.maximum(count - 1, 0) * per_span + nonempty)
    offsets2 = np.concatenate([[0], np.cumsum(n_out)]).astype(np.int64)
    curve_of = np.repeat(np.arange(n_curves, dtype=np.int64), count)
    nxt = np.arange(1, len(points) + 1, dtype=np.int64)
    prev = np.arange(-1, len(points) - 1, dtype=np.int64)
    nxt[last[nonempty]] = np.where(closed[nonempty], first[nonempty], -1)
    prev[first[nonempty]] = np.where(closed[nonempty], last[nonempty], -1)
    seg_a = np.flatnonzero(nxt >= 0)
    seg_b = nxt[seg_a]
    seg_curve = curve_of[seg_a]
    s_b = rest[seg_b]
    wrap = seg_b <= seg_a  # closing spans (a 1-point closed curve closes onto itself)
    s_b[wrap] = rest[seg_a[wrap]] + closing[seg_curve[wrap]]
    out_start = offsets2[seg_curve] + (seg_a - offsets[seg_curve]) * per_span

    points2 = np.empty((offsets2[-1], 3))
    rest2 = np.empty(offsets2[-1])
    _spans(points, rest, seg_a, seg_b, prev[seg_a], nxt[seg_b], s_b, out_start, per_span, points2, rest2)
    ends = np.flatnonzero(nonempty & ~closed)  # an open curve's last point ends its last span
    points2[offsets2[ends + 1] - 1] = points[last[ends]]
    rest2[offsets2[ends + 1] - 1] = rest[last[ends]]
    if not np.isfinite(points2).all():
        c = int(np.searchsorted(offsets2, np.flatnonzero(~np.isfinite(points2).all(axis=1))[0], side="right") - 1)
        raise ValueError(f"curve {c}: coordinates too large to subdivide (the spline overflows)")
    return points2, offsets2, rest2, closing2


@njit(parallel=True, cache=True, error_model="numpy")
def _spans(points, rest, seg_a, seg_b, seg_p, seg_n, s_b, out_start, per_span, out_points, out_rest):
    """Span g (p1 = points[seg_a[g]], p2 = points[seg_b[g]], neighbours seg_p / seg_n, −1 for a phantom) writes its
    sub-points k = 0 … per_span − 1 to out[out_start[g] + k]; spans own disjoint output ranges."""
    for g in prange(seg_a.shape[0]):
        a, b, p, n = seg_a[g], seg_b[g], seg_p[g], seg_n[g]
        dt1 = math.sqrt(_dist(points, a, b))  # knot intervals t1 − t0, t2 − t1, t3 − t2 (t1 = 0 below)
        dt0 = math.sqrt(_dist(points, p, a)) if p >= 0 else dt1  # a phantom mirrors the span
        dt2 = math.sqrt(_dist(points, b, n)) if n >= 0 else dt1
        s_a = rest[a]
        for k in range(per_span):
            o = out_start[g] + k
            u = k / per_span
            out_rest[o] = s_a + u * (s_b[g] - s_a)
            t = u * dt1
            for m in range(3):
                p1, p2 = points[a, m], points[b, m]
                p0 = points[p, m] if p >= 0 else 2.0 * p1 - p2
                p3 = points[n, m] if n >= 0 else 2.0 * p2 - p1
                a2 = p1 + u * (p2 - p1)
                if k == 0 or dt1 == 0.0:  # the control point itself; a zero-length span is linear (constant)
                    out_points[o, m] = p1 if k == 0 else a2
                    continue
                a1 = p1 + t * (p1 - p0) / dt0 if dt0 > 0.0 else p1
                a3 = p2 + (t - dt1) * (p3 - p2) / dt2 if dt2 > 0.0 else p2
                b1 = ((dt1 - t) * a1 + (t + dt0) * a2) / (dt0 + dt1)
                b2 = ((dt1 + dt2 - t) * a2 + t * a3) / (dt1 + dt2)
                out_points[o, m] = (1.0 - u) * b1 + u * b2


@njit(cache=True, error_model="numpy")
def _dist(points, i, j):
    """|points[i] − points[j]| without intermediate overflow or underflow."""
    return math.hypot(math.hypot(points[i, 0] - points[j, 0], points[i, 1] - points[j, 1]),
                      points[i, 2] - points[j, 2])
