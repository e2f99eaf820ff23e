"""The hair canopy: the fraction of a distant light's beam that other yarns' flyaways let through to a point.

The shadow maps (``shadow_map``) block a light by the yarns' bodies, tubes of the yarn radius r; the flyaways
around each body, a layer out to the flyaway strip's half-width h (about 2.3 r for cotton1), block nothing there.
In the path-traced reference they do: a beam toward the light that runs through another yarn's hair layer meets
hairs. Traced on the reference's fibers (``benchmarks/probe_hair_canopy.py``; BENCHMARKS.md, stop 60), other yarns'
flyaways keep 8.5 % of the directional light off the camera-visible lit regular fibers of the grazing patch's
interior and 2.9 % off the directional patch's; this model, built from the pack's flyaway coverage alone, keeps
10.6 % and 3.1 % at those fibers, and 8.0 % and 2.4 % as the renderer evaluates it (at the polyline points,
``pipeline._canopy``).

Model. Each yarn's hair layer is a cylindrical medium about its centre line: K shells between 1 and h/r yarn radii,
shell k of constant density σ_k (per yarn radius of path). The densities come from the pack's flyaway coverage
(``hair_shells``): the texture's mean coverage α(v) per row (over its three variants and along the yarn) is what an
orthographic ray at offset v from the axis meets, 1 − exp(−τ(v)) with τ(v) the density integrated along the chord;
peeling the shells from the outside in (the discrete Abel inversion) makes each shell's chord at its band's mid
offset give the band's mean coverage. Inside the body (below one radius) the medium is empty: the body is the
shadow map's.

Per receiver p and light direction d the optical depth is the sum, over the polyline segments of other yarns (and
of the receiver's own yarn further than ``yarn_bounce.REACH_RADII`` yarn radii of rest arc length away, as the
yarn-level bounce and the tracer's ``own_yarn`` diagnostic count neighbours), of each shell's density times the
length of the ray p + t d (t ≥ 0) inside that shell of the segment's infinite cylinder, clipped to the t where the
ray's axial coordinate lies along the segment; the transmittance is exp(−τ). A receiver's own hair layer is left
out: it shadows the lone yarn as much as a yarn in a knit (traced, 11–12 % of the direct light on the camera-visible
regular fibers of the straight yarn and of both patches), and the strips' lone yarn already matches its reference
without it.

Candidates: segments are binned (count, prefix sum, fill) into a square grid in the light's view (orthographic along
d; cells of half the largest hair reach h), each into every cell its projected hair cylinder (grown by h) comes
near; a receiver reads the one cell it projects into, whose segments are sorted nearest the light first, up to the
first that lies wholly behind it. Units: scene units; σ per yarn radius. Every receiver writes its own entry, so
results do not depend on the thread count; a non-finite receiver reads 1.
"""

from __future__ import annotations

import math
from typing import NamedTuple

import numpy as np
from numba import njit, prange

from knitrun.render.yarn_bounce import REACH_RADII

HAIR_SHELLS = 8  # shells of the hair layer between the body and the flyaway strip's half-width
MAX_CELLS = 512  # cap on the light-view grid's cells per axis (cells grow beyond it)


def hair_shells(alpha_rows, half_width_radii: float, shells: int = HAIR_SHELLS):
    """(edges (K + 1,), σ (K,)) of a hair layer, radii in yarn radii, σ per yarn radius (module docstring), from the
    flyaway coverage ``alpha_rows`` (R,) per texture row across the strip, v from −1 to 1 in flyaway half-widths, and
    the half-width in yarn radii. Bands with no coverage give σ 0; coverage is clamped below 0.999. A half-width of
    at most one radius (ASSET_PACK.md allows the yarn radius) leaves no room outside the body: σ 0."""
    alpha_rows = np.asarray(alpha_rows, np.float64).reshape(-1)
    if not half_width_radii > 1.0:
        return np.ones(shells + 1), np.zeros(shells)
    n = len(alpha_rows)
    v = np.abs((np.arange(n) + 0.5) / n * 2.0 - 1.0) * half_width_radii
    edges = np.linspace(1.0, half_width_radii, shells + 1)
    alpha = np.array([alpha_rows[(v >= lo) & (v < hi)].mean() if np.any((v >= lo) & (v < hi)) else 0.0
                      for lo, hi in zip(edges[:-1], edges[1:])])
    tau = -np.log1p(-np.clip(np.nan_to_num(alpha), 0.0, 0.999))
    mid = 0.5 * (edges[:-1] + edges[1:])
    sigma = np.zeros(shells)
    for j in range(shells - 1, -1, -1):  # outside in: the outer shells' share of band j's chord is known
        outer = sum(sigma[k] * (_chord(edges[k + 1], mid[j]) - _chord(edges[k], mid[j])) for k in range(j + 1, shells))
        own = _chord(edges[j + 1], mid[j]) - _chord(edges[j], mid[j])
        sigma[j] = max((tau[j] - outer) / own, 0.0) if own > 0.0 else 0.0
    return edges, sigma


def _chord(rho, v):
    """Length of the chord at offset v through a disc of radius rho (0 where it misses)."""
    return 2.0 * math.sqrt(max(rho * rho - v * v, 0.0))


class CanopyGrid(NamedTuple):
    """The hair layers of a frame's polylines binned in one light's view (``canopy_grid``; module docstring)."""

    points: np.ndarray  # (P, 3) polyline points, scene units
    toward: np.ndarray  # (P,) each point's coordinate along the light direction
    rest: np.ndarray  # (P,) rest arc length
    first: np.ndarray  # (S,) the first point of each binned segment
    axis: np.ndarray  # (S, 3) its unit direction (0 for a zero-length segment)
    length: np.ndarray  # (S,) its length, scene units
    seg_curve: np.ndarray  # (S,) its curve
    radius: np.ndarray  # (C,) yarn radius of each curve
    reach: np.ndarray  # (C,) the hair layer's outer radius (0: no layer)
    edges: np.ndarray  # (C, K + 1) shell edges, yarn radii
    sigma: np.ndarray  # (C, K) shell densities per yarn radius
    start: np.ndarray  # (cells + 1,) each cell's first entry in members
    members: np.ndarray  # segment indices, cell by cell
    basis: np.ndarray  # (3, 3) rows right, up, direction
    lo: np.ndarray  # (2,) the grid's corner in the light's view
    cell: float  # cell size, scene units
    size: np.ndarray  # (2,) cells per axis


def canopy_grid(lines, radius_of_curve, shells, direction) -> CanopyGrid | None:
    """The hair layers of ``lines`` (the frame's polylines: ``points``, ``offsets``, ``rest``) binned in the view of
    unit ``direction`` (toward the light); ``radius_of_curve`` (C,) yarn radii (scene units); ``shells`` a list over
    curves of (edges, σ) from ``hair_shells``, or None for a yarn without flyaways. None when no curve has a layer."""
    layered = [k for k, s in enumerate(shells) if s is not None and np.any(s[1] > 0.0)]
    if not layered:
        return None
    n_shells = max(len(shells[k][1]) for k in layered)
    edges = np.zeros((len(shells), n_shells + 1))
    sigma = np.zeros((len(shells), n_shells))
    for k in layered:
        e, s = shells[k]
        edges[k, :len(e)], edges[k, len(e):] = e, e[-1]
        sigma[k, :len(s)] = s
    d = np.asarray(direction, np.float64).reshape(3)
    d = d / np.linalg.norm(d)
    helper = np.array([1.0, 0.0, 0.0]) if abs(d[0]) < 0.9 else np.array([0.0, 1.0, 0.0])
    right = np.cross(helper, d)
    right /= np.linalg.norm(right)
    basis = np.stack([right, np.cross(d, right), d])
    radius = np.ascontiguousarray(radius_of_curve, np.float64)
    reach = radius * edges[:, -1]  # 0 for a curve without a layer (its edges are 0)
    points = np.ascontiguousarray(lines.points, np.float64)
    offsets = np.ascontiguousarray(lines.offsets, np.int64)
    per_curve = np.maximum(np.diff(offsets) - 1, 0)  # segments of each curve (a closed curve's closing one left out)
    seg_curve = np.repeat(np.arange(len(per_curve), dtype=np.int64), per_curve)
    first = (np.arange(len(seg_curve)) + np.repeat(offsets[:-1] - np.concatenate([[0], np.cumsum(per_curve)[:-1]]),
                                                   per_curve)).astype(np.int64)
    keep = reach[seg_curve] > 0.0
    first, seg_curve = first[keep], seg_curve[keep]
    if len(first) == 0:
        return None
    xy = points @ basis[:2].T
    grow = reach.max()
    lo = xy.min(axis=0) - grow
    cell = max(0.5 * grow, float(np.ptp(xy, axis=0).max() + 2.0 * grow) / MAX_CELLS)
    size = np.minimum(np.ceil((xy.max(axis=0) + grow - lo) / cell).astype(np.int64) + 1, MAX_CELLS + 2)
    # each cell's segments nearest the light first (a receiver stops at the first one wholly behind it): the
    # segments are scattered in that order, which the counting sort keeps within each cell (a lexsort of the
    # members by cell and depth afterwards took 130 ms of bench_render's 220 ms canopy, BENCHMARKS.md stop 72)
    toward = points @ d
    top = np.maximum(toward[first], toward[first + 1]) + reach[seg_curve]
    order = np.argsort(-top, kind="stable")
    counts = np.zeros(size[0] * size[1] + 1, np.int64)
    _bin(xy, first, seg_curve, reach, lo, cell, size, order, counts, np.zeros(0, np.int64), False)
    start = np.zeros_like(counts)
    np.cumsum(counts[:-1], out=start[1:])
    members = np.empty(int(start[-1]), np.int64)
    _bin(xy, first, seg_curve, reach, lo, cell, size, order, start.copy(), members, True)
    axis = points[first + 1] - points[first]
    length = np.linalg.norm(axis, axis=1)
    axis = np.divide(axis, length[:, None], out=np.zeros_like(axis), where=length[:, None] > 0.0)
    return CanopyGrid(points, toward, np.ascontiguousarray(lines.rest, np.float64), first, axis, length, seg_curve,
                      radius, reach, edges, sigma, start, members, basis, lo, float(cell), size)


def canopy_transmittance(grid: CanopyGrid | None, position, curve, arclength) -> np.ndarray:
    """(N,) the fraction of the beam toward the light of ``grid`` (``canopy_grid``) that other yarns' hair layers let
    through to each receiver (module docstring): ``position`` (N, 3), ``curve`` (N,) and ``arclength`` (N,) their
    position, curve and rest arc length. All ones where ``grid`` is None."""
    position = np.ascontiguousarray(position, np.float64).reshape(-1, 3)
    out = np.ones(len(position))
    if grid is not None and len(position):
        _transmittance(grid, position, np.ascontiguousarray(curve, np.int64),
                       np.ascontiguousarray(arclength, np.float64), REACH_RADII, out)
    return out


@njit(cache=True)
def _cells_of(xy, a, b, grow, lo, cell, size):
    """The cell range (i0, i1, j0, j1), ends included, of segment a–b's projection grown by ``grow``."""
    x0 = min(xy[a, 0], xy[b, 0]) - grow
    x1 = max(xy[a, 0], xy[b, 0]) + grow
    y0 = min(xy[a, 1], xy[b, 1]) - grow
    y1 = max(xy[a, 1], xy[b, 1]) + grow
    i0 = min(max(int((x0 - lo[0]) / cell), 0), size[0] - 1)
    i1 = min(max(int((x1 - lo[0]) / cell), 0), size[0] - 1)
    j0 = min(max(int((y0 - lo[1]) / cell), 0), size[1] - 1)
    j1 = min(max(int((y1 - lo[1]) / cell), 0), size[1] - 1)
    return i0, i1, j0, j1


@njit(cache=True)
def _bin(xy, first, seg_curve, reach, lo, cell, size, order, cursor, members, fill):
    """Bin then scatter (serial: cells are shared): without ``fill``, cursor[c] += the segments of cell c; with it,
    each cell's segments into members from cursor[c] on, in the order ``order`` lists the segments."""
    for s in order:
        a, grow = first[s], reach[seg_curve[s]]
        i0, i1, j0, j1 = _cells_of(xy, a, a + 1, grow, lo, cell, size)
        for i in range(i0, i1 + 1):
            for j in range(j0, j1 + 1):
                if _cell_near(xy, a, grow, lo, cell, i, j):
                    if fill:
                        members[cursor[i * size[1] + j]] = s
                    cursor[i * size[1] + j] += 1


@njit(cache=True, inline='always')
def _cell_near(xy, a, grow, lo, cell, i, j):
    """Whether cell (i, j) may hold points within ``grow`` of segment a–(a+1)'s projection: its centre lies within
    grow + half the cell's diagonal of the segment."""
    cx, cy = lo[0] + (i + 0.5) * cell, lo[1] + (j + 0.5) * cell
    ex, ey = xy[a + 1, 0] - xy[a, 0], xy[a + 1, 1] - xy[a, 1]
    wx, wy = cx - xy[a, 0], cy - xy[a, 1]
    e2 = ex * ex + ey * ey
    f = min(max((wx * ex + wy * ey) / e2, 0.0), 1.0) if e2 > 0.0 else 0.0
    dx, dy = wx - f * ex, wy - f * ey
    limit = grow + 0.7072 * cell
    return dx * dx + dy * dy <= limit * limit


@njit(parallel=True, cache=True)
def _transmittance(grid, position, curve, arclength, own_reach, out):
    """exp(−τ) per receiver (module docstring); each receiver writes its own entry."""
    points, toward, rest, first, seg_curve = grid.points, grid.toward, grid.rest, grid.first, grid.seg_curve
    axis, seg_length = grid.axis, grid.length
    radius, reach, edges, sigma, start, members = grid.radius, grid.reach, grid.edges, grid.sigma, grid.start, \
        grid.members
    basis, lo, cell, size = grid.basis, grid.lo, grid.cell, grid.size
    d0, d1, d2 = basis[2, 0], basis[2, 1], basis[2, 2]
    for q in prange(position.shape[0]):
        p0, p1, p2 = position[q, 0], position[q, 1], position[q, 2]
        if not (math.isfinite(p0) and math.isfinite(p1) and math.isfinite(p2)):
            out[q] = 1.0
            continue
        x = p0 * basis[0, 0] + p1 * basis[0, 1] + p2 * basis[0, 2]
        y = p0 * basis[1, 0] + p1 * basis[1, 1] + p2 * basis[1, 2]
        i = int((x - lo[0]) / cell)
        j = int((y - lo[1]) / cell)
        if x < lo[0] or y < lo[1] or i >= size[0] or j >= size[1]:
            out[q] = 1.0
            continue
        c = i * size[1] + j
        z = p0 * d0 + p1 * d1 + p2 * d2
        tau = 0.0
        for m in range(start[c], start[c + 1]):
            s = members[m]
            k = seg_curve[s]
            a = first[s]
            if max(toward[a], toward[a + 1]) + reach[k] < z:  # wholly behind the receiver, and so are the rest
                break
            length = seg_length[s]
            if k != curve[q]:
                tau += _segment_depth(points[a, 0], points[a, 1], points[a, 2], axis[s, 0], axis[s, 1], axis[s, 2],
                                      length, 0.0, length, radius[k], edges, sigma, k, p0, p1, p2,
                                      d0, d1, d2)
                continue
            # the receiver's own hair layer is left out (module docstring): the stretch of the segment within
            # own_reach radii of rest arc length of the receiver is not counted
            per_u = (rest[a + 1] - rest[a]) / length if length > 0.0 else 0.0
            if per_u <= 0.0:
                continue
            u_q = (arclength[q] - rest[a]) / per_u
            window = own_reach * radius[k] / per_u
            tau += _segment_depth(points[a, 0], points[a, 1], points[a, 2], axis[s, 0], axis[s, 1], axis[s, 2],
                                      length, 0.0, min(length, u_q - window), radius[k], edges,
                                  sigma, k, p0, p1, p2, d0, d1, d2)
            tau += _segment_depth(points[a, 0], points[a, 1], points[a, 2], axis[s, 0], axis[s, 1], axis[s, 2],
                                      length, max(0.0, u_q + window), length, radius[k], edges,
                                  sigma, k, p0, p1, p2, d0, d1, d2)
        out[q] = math.exp(-tau)


@njit(cache=True)
def _segment_depth(a0, a1, a2, e0, e1, e2, length, u_lo, u_hi, r, edges, sigma, c, p0, p1, p2, d0, d1, d2):
    """Optical depth of the hair shells of the segment from (a0, a1, a2) along unit (e0, e1, e2) for ``length``
    (scalars: a view of a shared array costs an atomic reference count per call), the shells edges[c], sigma[c], the
    stretch
    of its axis from u_lo to u_hi (scene units from its start), along the ray p + t d, t ≥ 0 (module docstring)."""
    if length <= 0.0 or u_hi <= u_lo:
        return 0.0
    w0, w1, w2 = p0 - a0, p1 - a1, p2 - a2
    we = w0 * e0 + w1 * e1 + w2 * e2
    wd = w0 * d0 + w1 * d1 + w2 * d2
    b = d0 * e0 + d1 * e1 + d2 * e2
    s = 1.0 - b * b  # sin² of the angle between the ray and the axis
    perp2 = max(w0 * w0 + w1 * w1 + w2 * w2 - we * we, 0.0)
    t_star = -(wd - b * we) / s if s >= 1e-12 else 0.0
    rho_min2 = max(perp2 - s * t_star * t_star, 0.0) if s >= 1e-12 else perp2
    if rho_min2 >= (edges[c, -1] * r) ** 2:  # the ray passes outside the hair layer (most candidates)
        return 0.0
    # the t range where the ray's axial coordinate we + t b lies along the segment, and t ≥ 0
    if abs(b) < 1e-12:
        if we < u_lo or we >= u_hi:
            return 0.0
        t_lo, t_hi = 0.0, math.inf
    else:
        t_a, t_b = (u_lo - we) / b, (u_hi - we) / b
        t_lo, t_hi = max(min(t_a, t_b), 0.0), max(t_a, t_b)
    if t_hi <= t_lo:
        return 0.0
    tau = 0.0
    if s < 1e-12:  # the ray runs along the axis at a constant distance
        rho = math.sqrt(perp2) / r
        for k in range(sigma.shape[1]):
            if edges[c, k] <= rho < edges[c, k + 1]:
                tau += sigma[c, k] / r * (t_hi - t_lo)
        return tau
    for k in range(sigma.shape[1]):
        if sigma[c, k] <= 0.0:
            continue
        outer2 = (edges[c, k + 1] * r) ** 2
        if rho_min2 >= outer2:
            continue
        h_out = math.sqrt((outer2 - rho_min2) / s)
        h_in = math.sqrt(max((edges[c, k] * r) ** 2 - rho_min2, 0.0) / s)
        inside = _overlap(t_star - h_out, t_star - h_in, t_lo, t_hi) + _overlap(t_star + h_in, t_star + h_out, t_lo,
                                                                                 t_hi)
        tau += sigma[c, k] / r * inside
    return tau


@njit(cache=True, inline='always')
def _overlap(a0, a1, b0, b1):
    """Length of [a0, a1] ∩ [b0, b1] (0 where they miss)."""
    return max(min(a1, b1) - max(a0, b0), 0.0)
