"""Fibers as triangle tubes, for the Embree ray tracer of the offline baker.

Conventions
-----------
* Lengths are those of the FiberSet (centimetres for every preset); vertices are float32, triangle indices int32.
* Each fiber polyline gets one ring of ``sides`` vertices per point. The ring frame is rotation-minimising: the
  frame of segment ``k`` is that of segment ``k - 1`` carried over by the rotation that takes one segment direction
  to the next (discrete parallel transport), so there is no twist along straight or curved parts and no flip.
* Ring at an end point: perpendicular to its segment. Ring at an interior point: in the mitre plane (normal along
  the averaged tangent) and stretched in the bend direction by ``1 / cos(bend / 2)``, i.e. it is the section of both
  adjacent cylinders by that plane, so the tube keeps its radius across the joint. The stretch is limited to
  ``MITRE_LIMIT`` (bends sharper than 120 degrees are pinched rather than spiked). Walls of consecutive segments share
  their ring, so the tube is watertight; with ``caps`` each end is closed by a fan over its ring (``sides - 2``
  triangles, no extra vertex) and each tube is a closed 2-manifold.
* Polygon fit (``fit``), with ``c = cos(pi / sides)``. The true fiber is the cylinder of radius ``r``:
    - ``"inscribed"``: ring vertices on the circle (radius ``r``). The wall lies between ``r c`` and ``r`` from the
      axis: always inside the cylinder, max distance error ``r (1 - c)``.
    - ``"perimeter"`` (default): ring radius ``r' = r (pi / sides) / sin(pi / sides)``, so the polygon has the
      circle's perimeter and, by Cauchy's formula, the same mean projected width: fiber coverage seen by rays is
      unbiased. The wall lies between ``r' c`` and ``r'``, max distance error ``r max(r'/r - 1, 1 - c r'/r)``
      (6 sides: -9.3 % / +4.7 %; inscribed: -13.4 %).
  ``radial_band(sides, fit)`` gives these bounds as multiples of ``r``.
* Consecutive points closer than ``MERGE_TOL * r`` are merged before tessellation (zero-length segments would give
  degenerate triangles and undefined tangents); the fiber's last point is kept exactly.
* Triangle order: fiber by fiber; within a fiber the walls segment by segment (``2 * sides`` each, side by side),
  then the caps, alternating start and end cap triangles. ``tri_segment`` names each triangle's axis segment
  (caps: the first and last segment). Triangles wind counter-clockwise seen from outside (outward normals).
"""

from dataclasses import dataclass

import numpy as np
from numba import njit, prange

from knitbake.fibers.fiber_set import FiberSet

MERGE_TOL = 1e-3  # relative to the fiber radius
MITRE_LIMIT = 2.0  # max ring stretch at a joint, 1 / cos(60 degrees)
FITS = ("inscribed", "perimeter")


@dataclass
class TubeMesh:
    """Triangle tubes of a FiberSet (see module docstring)."""

    vertices: np.ndarray  # (V, 3) float32
    triangles: np.ndarray  # (T, 3) int32
    tri_fiber: np.ndarray  # (T,) int32, fiber index of each triangle
    axis_points: np.ndarray  # (P', 3) float64, the fiber polylines after merging close points
    tri_segment: np.ndarray  # (T,) int32, axis_points[s], axis_points[s + 1] is the segment a triangle belongs to
    tube_radius: np.ndarray  # (F,) float64, ring vertex radius: no wall point is farther from its axis


def ring_radius_factor(sides: int, fit: str) -> float:
    """Ring vertex radius as a multiple of the fiber radius."""
    if fit not in FITS:
        raise ValueError(f"fit must be one of {FITS}, got {fit!r}")
    return 1.0 if fit == "inscribed" else (np.pi / sides) / np.sin(np.pi / sides)


def radial_band(sides: int, fit: str = "perimeter") -> tuple[float, float]:
    """(min, max) distance of a straight tube's wall from the fiber axis, as multiples of the fiber radius."""
    k = ring_radius_factor(sides, fit)
    return k * np.cos(np.pi / sides), k


def tube_counts(n_points: int, sides: int, caps: bool) -> tuple[int, int]:
    """(vertices, triangles) of one tube over ``n_points`` polyline points (after merging)."""
    return n_points * sides, 2 * sides * (n_points - 1) + (2 * (sides - 2) if caps else 0)


def tessellate_fibers(fibers: FiberSet, sides: int = 6, caps: bool = True, fit: str = "perimeter") -> TubeMesh:
    """Triangle tubes around every fiber of ``fibers``; raises ValueError on bad input, naming the fiber."""
    if isinstance(sides, bool) or not isinstance(sides, (int, np.integer)) or sides < 3:
        raise ValueError(f"sides must be an integer >= 3, got {sides!r}")
    ring_factor = ring_radius_factor(int(sides), fit)
    points, offsets, radius = _validated(fibers)
    keep = _merge_mask(points, offsets, radius * MERGE_TOL)
    counts = np.add.reduceat(keep.astype(np.int64), offsets[:-1]) if keep.size else np.zeros(0, np.int64)
    short = np.flatnonzero(counts < 2)
    if short.size:
        i = int(short[0])
        raise ValueError(f"fiber {i} has zero length (all its points lie within {MERGE_TOL} * radius of each other)")
    new_offsets = np.zeros(offsets.size, np.int64)
    np.cumsum(counts, out=new_offsets[1:])
    n_vert, n_tri = tube_counts(counts, int(sides), caps)
    vert_start = np.concatenate([[0], np.cumsum(n_vert)]).astype(np.int64)
    tri_start = np.concatenate([[0], np.cumsum(n_tri)]).astype(np.int64)
    if vert_start[-1] > np.iinfo(np.int32).max:
        raise ValueError(f"{vert_start[-1]} vertices do not fit int32 triangle indices")
    vertices = np.empty((vert_start[-1], 3), np.float32)
    triangles = np.empty((tri_start[-1], 3), np.int32)
    tri_fiber = np.empty(tri_start[-1], np.int32)
    tri_segment = np.empty(tri_start[-1], np.int32)
    axis_points = np.ascontiguousarray(points[keep])
    _tessellate(axis_points, new_offsets, radius * ring_factor, int(sides), bool(caps),
                vert_start, tri_start, vertices, triangles, tri_fiber, tri_segment)
    return TubeMesh(vertices, triangles, tri_fiber, axis_points, tri_segment, radius * ring_factor)


def _validated(fibers: FiberSet) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    points = np.ascontiguousarray(fibers.points, dtype=np.float64)
    offsets = np.ascontiguousarray(fibers.offsets, dtype=np.int64)
    radius = np.ascontiguousarray(fibers.radius, dtype=np.float64)
    n = offsets.size - 1
    if points.ndim != 2 or points.shape[1] != 3:
        raise ValueError(f"points must have shape (P, 3), got {points.shape}")
    if offsets.ndim != 1 or n < 0 or offsets[0] != 0 or offsets[-1] != points.shape[0]:
        raise ValueError(f"offsets must be (F + 1,) from 0 to {points.shape[0]} points")
    if radius.shape != (n,):
        raise ValueError(f"radius must have shape ({n},), got {radius.shape}")
    lengths = np.diff(offsets)
    if np.any(lengths < 2):
        i = int(np.argmax(lengths < 2))
        raise ValueError(f"fiber {i} has {int(lengths[i])} points, needs at least 2")
    bad = ~(np.isfinite(radius) & (radius > 0))
    if np.any(bad):
        i = int(np.argmax(bad))
        raise ValueError(f"fiber {i} has radius {radius[i]}, must be finite and > 0")
    bad_points = ~np.all(np.isfinite(points), axis=1)
    if np.any(bad_points):
        p = int(np.argmax(bad_points))
        i = int(np.searchsorted(offsets, p, side="right") - 1)
        raise ValueError(f"fiber {i} has a non-finite point (point {p - offsets[i]}: {points[p].tolist()})")
    return points, offsets, radius


@njit(cache=True, parallel=True)
def _merge_mask(points, offsets, tol):
    """True for the points kept: the first of each fiber, then each farther than tol from the last kept one.
    A dropped last point is kept instead of the last kept one, so the fiber end is exact."""
    keep = np.zeros(points.shape[0], np.bool_)
    for f in prange(offsets.size - 1):
        a, b = offsets[f], offsets[f + 1]
        last = a
        keep[a] = True
        for p in range(a + 1, b):
            d = points[p] - points[last]
            if np.sqrt(d[0] * d[0] + d[1] * d[1] + d[2] * d[2]) > tol[f]:
                keep[p] = True
                last = p
        if last != b - 1 and last != a:
            keep[last] = False
            keep[b - 1] = True
    return keep


@njit(cache=True)
def _unit(v):
    return v / np.sqrt(v[0] * v[0] + v[1] * v[1] + v[2] * v[2])


@njit(cache=True)
def _cross(a, b):
    return np.array([a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0]])


@njit(cache=True)
def _initial_normal(d):
    """A unit vector perpendicular to d, built from the coordinate axis least aligned with d."""
    axis = np.zeros(3)
    axis[np.argmin(np.abs(d))] = 1.0
    return _unit(axis - np.dot(axis, d) * d)


@njit(cache=True)
def _write_ring(out, base, centre, u, v, d, t, radius, cos_phi, sin_phi):
    """Ring vertices at ``centre``: circle of radius ``radius`` in frame (u, v) perpendicular to segment direction d,
    projected along d onto the plane through centre with normal t."""
    dt = max(np.dot(d, t), 1.0 / MITRE_LIMIT)
    for j in range(cos_phi.size):
        o = radius * (cos_phi[j] * u + sin_phi[j] * v)
        o = o - (np.dot(o, t) / dt) * d
        out[base + j, 0] = centre[0] + o[0]
        out[base + j, 1] = centre[1] + o[1]
        out[base + j, 2] = centre[2] + o[2]


@njit(cache=True, parallel=True)
def _tessellate(points, offsets, ring_radius, sides, caps, vert_start, tri_start, vertices, triangles, tri_fiber,
                tri_segment):
    phi = 2.0 * np.pi * np.arange(sides) / sides
    cos_phi, sin_phi = np.cos(phi), np.sin(phi)
    for f in prange(offsets.size - 1):
        a, b = offsets[f], offsets[f + 1]
        vb, tb = vert_start[f], tri_start[f]
        d = _unit(points[a + 1] - points[a])
        u = _initial_normal(d)
        _write_ring(vertices, vb, points[a], u, _cross(d, u), d, d, ring_radius[f], cos_phi, sin_phi)
        for k in range(1, b - a):
            if k < b - a - 1:
                d_next = _unit(points[a + k + 1] - points[a + k])
                s = d + d_next
                s_len = np.sqrt(np.dot(s, s))
                t = s / s_len if s_len > 1e-9 else d_next  # hairpin: no mitre plane
            else:
                d_next, t = d, d
            _write_ring(vertices, vb + k * sides, points[a + k], u, _cross(d, u), d, t, ring_radius[f],
                        cos_phi, sin_phi)
            # parallel transport: the rotation taking d to d_next acts on vectors normal to d as the reflection in t
            u = u - 2.0 * np.dot(u, t) * t
            u = _unit(u - np.dot(u, d_next) * d_next)
            d = d_next
        n_tri = _write_walls(triangles, tb, vb, b - a, sides)
        for k in range(b - a - 1):
            tri_segment[tb + 2 * sides * k:tb + 2 * sides * (k + 1)] = a + k
        if caps:
            _write_caps(triangles, tb + n_tri, vb, b - a, sides)
            tri_segment[tb + n_tri:tri_start[f + 1]:2] = a  # caps alternate: start, end, start, ...
            tri_segment[tb + n_tri + 1:tri_start[f + 1]:2] = b - 2
        tri_fiber[tb:tri_start[f + 1]] = f


@njit(cache=True)
def _write_walls(triangles, tb, vb, n_rings, sides):
    i = tb
    for k in range(n_rings - 1):
        r0, r1 = vb + k * sides, vb + (k + 1) * sides
        for j in range(sides):
            jn = (j + 1) % sides
            triangles[i, 0], triangles[i, 1], triangles[i, 2] = r0 + j, r0 + jn, r1 + jn
            triangles[i + 1, 0], triangles[i + 1, 1], triangles[i + 1, 2] = r0 + j, r1 + jn, r1 + j
            i += 2
    return i - tb


@njit(cache=True)
def _write_caps(triangles, tb, vb, n_rings, sides):
    first, last = vb, vb + (n_rings - 1) * sides
    for j in range(1, sides - 1):
        i = tb + 2 * (j - 1)
        triangles[i, 0], triangles[i, 1], triangles[i, 2] = first, first + j + 1, first + j
        triangles[i + 1, 0], triangles[i + 1, 1], triangles[i + 1, 2] = last, last + j, last + j + 1
