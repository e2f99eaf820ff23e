"""How far yarns stay apart: the contact statistic of a set of yarn curves (issue 14; for comparison, a relaxed
yarn-level knit model measures about 0.83 at the 5th percentile and 1.03 at the median).

Definition
----------
Every curve is resampled at arc-length steps of r/4 (r the yarn radius, lengths in the curves' units). For each
sample, the distance d to the nearest point of *another part* of the yarns: another curve, or the same curve more
than ``EXCLUDE_RADII`` · r away along it (along the loop, either way round, for a closed curve). The statistic is
d / 2r: 1.0 where two yarns of radius r touch, below 1 where they interpenetrate (0.5: sunk into each other by half
a diameter), above 1 where they leave a gap. d is measured to the resampled polyline of the other part (the nearest
sample, then its two adjacent segments), so its error is second order in the step. Samples with no other part
within ``CAP`` · 2r count as ``CAP`` (a free yarn end, the patch's outer edge): the high percentiles saturate there,
the low ones (the interpenetration) do not.

``contact_over_frames`` summarises an animation (the worst of up to 9 evenly spaced frames, and the last);
``contact_statistic`` returns percentiles of d / 2r over all samples (equal weight per unit length), the minimum and
the fraction of samples below ``DEEP`` (sunk by more than a fifth of the diameter). Smooth curve types are evaluated
to dense polylines first (``data_formats.curve_eval.dense_curve``). The nearest-neighbour search is scipy's cKDTree
(queried in blocks, so memory stays bounded on large models; first for ``K_FIRST`` neighbours, then, for the samples
whose ``K_FIRST`` nearest all lie on their own curve's excluded stretch, for the whole exclusion window's: the same
answer as one query of the window's size, at a quarter of its cost on a knitted rib).
"""

from __future__ import annotations

import math

import numpy as np
from scipy.spatial import cKDTree

from data_formats.curve_eval import dense_curve
from data_formats.errors import FormatError

STEP_RADII = 0.25  # resampling step, in yarn radii
EXCLUDE_RADII = 8.0  # the same curve within this arc length (in radii) is not "another part"
CAP = 2.0  # d / 2r reported for samples with no other part within CAP · 2r
DEEP = 0.8  # d / 2r below this counts as deep interpenetration
PERCENTILES = (5, 25, 50, 75, 95)
BLOCK = 65536  # samples per nearest-neighbour query block
K_FIRST = 24  # neighbours asked first: the sample, its curve's ±8 samples within 2r, room for a touching yarn's


def resample(xyz: np.ndarray, step: float, closed: bool):
    """Points every ``step`` of arc length along the polyline ``xyz`` (a closed one repeats its first point at its
    end) and their arc length; the last point of an open curve is kept too. Returns (points (m, 3), s (m,), length)."""
    seg = np.linalg.norm(np.diff(xyz, axis=0), axis=1)
    cum = np.concatenate([[0.0], np.cumsum(seg)])
    length = float(cum[-1])
    if length <= 0.0:
        return xyz[:1].copy(), np.zeros(1), 0.0
    count = max(int(math.floor(length / step)), 1)
    s = np.arange(count + (0 if closed else 1)) * (length / count)
    points = np.column_stack([np.interp(s, cum, xyz[:, k]) for k in range(3)])
    return points, s, length


def _segment_distance(p, a, b):
    """Distance from points p (n, 3) to segments a–b (n, 3)."""
    ab = b - a
    denom = np.einsum("ij,ij->i", ab, ab)
    t = np.clip(np.einsum("ij,ij->i", p - a, ab) / np.where(denom > 0, denom, 1.0), 0.0, 1.0)
    return np.linalg.norm(p - (a + t[:, None] * ab), axis=1)


def contact_ratios(curves, radius: float, frame: int = 0) -> np.ndarray:
    """d / 2r for every r/4 sample of ``frame`` of ``curves`` (``YarnCurves``), per the module docstring."""
    if not (isinstance(radius, (int, float)) and math.isfinite(radius) and radius > 0):
        raise FormatError(f"contact statistic: radius = {radius!r}, expected a finite number > 0")
    if not 0 <= frame < curves.points.shape[0]:
        raise FormatError(f"contact statistic: frame {frame} out of range (the curves have "
                          f"{curves.points.shape[0]} frames)")
    step = STEP_RADII * radius
    parts, curve_id, arc, lengths, closed = [], [], [], [], []
    for c in range(len(curves.offsets) - 1):
        xyz, _ = dense_curve(curves, c, frame)
        pts, s, length = resample(xyz, step, bool(curves.closed[c]))
        parts.append(pts)
        curve_id.append(np.full(len(pts), c))
        arc.append(s)
        lengths.append(length)
        closed.append(bool(curves.closed[c]))
    points, curve_id, arc = np.concatenate(parts), np.concatenate(curve_id), np.concatenate(arc)
    lengths, closed = np.array(lengths), np.array(closed)
    start = np.concatenate([[0], np.cumsum([len(p) for p in parts])])
    tree = cKDTree(points)
    bound = CAP * 2.0 * radius
    exclude = EXCLUDE_RADII * radius
    k_all = min(len(points), int(2 * EXCLUDE_RADII / STEP_RADII) + 64)  # the exclusion window and the nearest beyond

    def nearest_other(rows, k):
        """For the samples ``rows``: whether another part lies within ``bound`` among their k nearest samples, its
        index and distance, and whether the k nearest were all within ``bound`` (then a larger k may find one)."""
        dist, idx = tree.query(points[rows], k=k, distance_upper_bound=bound)
        dist, idx = dist.reshape(len(rows), k), idx.reshape(len(rows), k)
        found = idx < len(points)
        j = np.where(found, idx, 0)
        mine = curve_id[rows, None]
        along = np.abs(arc[j] - arc[rows, None])
        loop = closed[mine] & found
        along = np.where(loop, np.minimum(along, lengths[mine] - along), along)
        other = found & ((curve_id[j] != mine) | (along > exclude))
        first = np.argmax(other, axis=1)  # the nearest candidate (query results are sorted by distance)
        pick = np.arange(len(rows))
        return other.any(axis=1), j[pick, first], dist[pick, first], found[:, -1]

    out = np.full(len(points), CAP)
    for lo in range(0, len(points), BLOCK):
        rows = np.arange(lo, min(lo + BLOCK, len(points)))
        # most samples find another part among their nearest few; the rest are asked again with the window's k
        has, near, best, full = nearest_other(rows, min(k_all, K_FIRST))
        again = np.flatnonzero(~has & full) if K_FIRST < k_all else np.zeros(0, np.int64)
        if again.size:
            has[again], near[again], best[again], _ = nearest_other(rows[again], k_all)
        rows, near, best = rows[has], near[has], best[has]
        if not rows.size:
            continue
        p = points[rows]
        c = curve_id[near]
        for step_to in (-1, 1):  # the nearest sample's two segments on its own polyline
            nb = near + step_to
            first_of, last_of = start[c], start[c + 1] - 1
            wrap = closed[c]
            nb = np.where(nb < first_of, np.where(wrap, last_of, near), nb)
            nb = np.where(nb > last_of, np.where(wrap, first_of, near), nb)
            best = np.minimum(best, _segment_distance(p, points[near], points[nb]))
        out[rows] = np.minimum(best / (2.0 * radius), CAP)
    return out


def contact_statistic(curves, radius: float, frame: int = 0) -> dict:
    """JSON-ready summary of ``contact_ratios``: samples, p5 … p95, min, and the fraction below ``DEEP``."""
    ratios = contact_ratios(curves, radius, frame)
    stats = {f"p{q}": round(float(v), 4) for q, v in zip(PERCENTILES, np.percentile(ratios, PERCENTILES))}
    return {"radius": float(radius), "frame": int(frame), "samples": int(len(ratios)), **stats,
            "min": round(float(ratios.min()), 4), f"fraction_below_{DEEP}": round(float((ratios < DEEP).mean()), 4)}


def contact_over_frames(curves, radius: float, max_frames: int = 9) -> dict:
    """The statistic on up to ``max_frames`` evenly spaced frames (the first and the last included): the frames
    evaluated, and the summary of the worst of them (lowest 5th percentile) and of the last."""
    count = curves.points.shape[0]
    frames = sorted({int(round(x)) for x in np.linspace(0, count - 1, min(count, max_frames))})
    stats = [contact_statistic(curves, radius, t) for t in frames]
    return {"frames_evaluated": frames, "worst": min(stats, key=lambda s: s["p5"]), "last": stats[-1]}
