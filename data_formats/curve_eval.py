"""Yarn curves (PL, C0, BS, BZ control points) as dense polylines carrying a rest arc-length coordinate.

Conventions (curve types as in ``data_formats/YARN_CURVES.md``)
-----------------------------------------------------------------
* A curve of n control points has S segments, segment j spanning the curve parameter u ∈ [j, j + 1]:
  PL, C0, BS: S = n − 1 open, n closed (the last segment runs from point n − 1 back to point 0);
  BZ: S = (n − 1)/3 open, n/3 closed.
* PL, C0, BS evaluate segment j from the window P_{j−1}, P_j, P_{j+1}, P_{j+2} (indices wrap on a closed curve). An open
  curve gets phantom end points P_{−1} = 2P_0 − P_1 and P_n = 2P_{n−1} − P_{n−2}: Catmull-Rom then starts with the
  end chord's direction and the B-spline interpolates both end points. BZ segment j uses P_{3j} … P_{3j+3}.
* Rest arc length σ (length units): control point k sits at ``rest[k]`` (BZ: only the on-curve points 3j count).
  A closed curve's rest length L adds the closing segment (``rest_length``). Inside a segment σ runs linearly with
  the *current* arc length of the dense samples, so a segment stretched between frames stretches the rest
  coordinate uniformly and the control points keep their rest coordinates.
* A dense polyline of a closed curve repeats its first point at the end (σ = L there).
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

from data_formats.errors import FormatError
from data_formats.yarn_curves import YarnCurves


def _basis(curve_type: str, u: np.ndarray) -> np.ndarray:
    """(len(u), 4) weights of the four window points for parameters u ∈ [0, 1)."""
    u = u[:, None] ** np.arange(4)  # 1, u, u², u³
    mats = {  # rows: weight of window point i as coefficients of 1, u, u², u³
        "PL": [[0, 0, 0, 0], [1, -1, 0, 0], [0, 1, 0, 0], [0, 0, 0, 0]],
        "C0": [[0, -0.5, 1, -0.5], [1, 0, -2.5, 1.5], [0, 0.5, 2, -1.5], [0, 0, -0.5, 0.5]],
        "BS": [[1 / 6, -0.5, 0.5, -1 / 6], [2 / 3, 0, -1, 0.5], [1 / 6, 0.5, 0.5, -0.5], [0, 0, 0, 1 / 6]],
        "BZ": [[1, -3, 3, -1], [0, 3, -6, 3], [0, 0, 3, -3], [0, 0, 0, 1]],
    }
    return u @ np.asarray(mats[curve_type], dtype=float).T


def _windows(n: int, closed: bool, curve_type: str) -> np.ndarray:
    """(S, 4) indices of each segment's window into the control points padded by one phantom point per end
    (padded index i is control point i − 1)."""
    if curve_type == "BZ":
        starts = 3 * np.arange(n // 3 if closed else (n - 1) // 3)
        idx = starts[:, None] + np.arange(4)
        return (idx % n if closed else idx) + 1
    segs = np.arange(n if closed else n - 1)
    idx = segs[:, None] + np.arange(-1, 3)
    return (idx % n) + 1 if closed else idx + 1


def evaluate(points: np.ndarray, closed: bool, curve_type: str, samples_per_segment: int) -> np.ndarray:
    """Dense points (S·samples_per_segment + 1, 3) of one curve: each segment sampled at u = i/samples_per_segment,
    i = 0 … samples_per_segment − 1, then the curve's end (for a closed curve: its start again)."""
    points = np.asarray(points, dtype=float)
    n = len(points)
    if n < 2 or (curve_type == "BZ" and (n % 3 if closed else (n - 1) % 3)):
        raise FormatError(f"{n} control points do not make a {'closed' if closed else 'open'} {curve_type} curve")
    padded = np.concatenate([2 * points[:1] - points[1:2], points, 2 * points[-1:] - points[-2:-1]])
    win = padded[_windows(n, closed, curve_type)]  # (S, 4, 3)
    u = np.arange(samples_per_segment + 1) / samples_per_segment
    dense = np.einsum("mk,skd->smd", _basis(curve_type, u), win)  # (S, M + 1, 3); u = 1 is the next segment's start
    out = np.concatenate([dense[:, :-1].reshape(-1, 3), dense[-1:, -1]])
    if closed:
        out[-1] = out[0]  # exactly, not to rounding
    return out


def rest_length(curves: YarnCurves, c: int) -> float:
    """Rest length of curve c: its last rest arc length, plus for a closed curve the closing segment — the frame-0
    distance from the last control point back to the first, in the rest scale of the curve's control polygon
    (rest arc length ÷ frame-0 polygon length)."""
    a, b = curves.offsets[c], curves.offsets[c + 1]
    total = float(curves.rest_arclength[b - 1])
    if not curves.closed[c]:
        return total
    p0 = curves.points[0, a:b]
    polygon = float(np.linalg.norm(np.diff(p0, axis=0), axis=1).sum())
    scale = total / polygon if polygon > 0 and total > 0 else 1.0
    return total + scale * float(np.linalg.norm(p0[0] - p0[-1]))


def dense_curve(curves: YarnCurves, c: int, frame: int, samples_per_segment: int | None = None):
    """(xyz (m, 3), sigma (m,)): curve c at ``frame`` as a dense polyline with the rest arc length of every sample.

    ``samples_per_segment`` defaults to 1 for PL (the control polygon itself) and 8 for the smooth types."""
    if samples_per_segment is None:
        samples_per_segment = 1 if curves.curve_type == "PL" else 8
    a, b = curves.offsets[c], curves.offsets[c + 1]
    closed = bool(curves.closed[c])
    xyz = evaluate(curves.points[frame, a:b], closed, curves.curve_type, samples_per_segment)
    rest = np.append(curves.rest_arclength[a:b], rest_length(curves, c))  # rest[n] = L closes the loop
    on_curve = rest[::3] if curves.curve_type == "BZ" else rest
    n_seg = (len(xyz) - 1) // samples_per_segment
    s0, s1 = on_curve[:n_seg], on_curve[1:n_seg + 1]
    chords = np.linalg.norm(np.diff(xyz, axis=0), axis=1).reshape(n_seg, samples_per_segment)
    seg_len = chords.sum(axis=1, keepdims=True)
    uniform = np.broadcast_to(np.arange(samples_per_segment) / samples_per_segment, chords.shape)
    cum = np.concatenate([np.zeros((n_seg, 1)), np.cumsum(chords, axis=1)[:, :-1]], axis=1)
    frac = np.where(seg_len > 0, cum / np.where(seg_len > 0, seg_len, 1.0), uniform)
    sigma = np.append((s0[:, None] + frac * (s1 - s0)[:, None]).ravel(), on_curve[n_seg])
    return xyz, sigma


# --- the yarn frame along a curve (fibers and strip textures attach to it) -----------------------------------------

def initial_normal(t: np.ndarray) -> np.ndarray:
    """Unit normal ⟂ unit tangent t: x̂ made orthogonal to t, or ŷ when |t·x̂| > 0.9."""
    ref = np.array([1.0, 0.0, 0.0]) if abs(t[0]) <= 0.9 else np.array([0.0, 1.0, 0.0])
    n = ref - (ref @ t) * t
    return n / np.linalg.norm(n)


def tangents(xyz: np.ndarray, closed: bool) -> np.ndarray:
    """Unit tangents (m, 3) of a dense polyline by central differences (one-sided at open ends; a closed polyline
    repeats its first point at the end). Samples where the difference vanishes take the nearest valid tangent."""
    if closed:
        ext = np.concatenate([xyz[-2:-1], xyz, xyz[1:2]])
        d = ext[2:] - ext[:-2]
    else:
        d = np.empty_like(xyz)
        d[1:-1] = xyz[2:] - xyz[:-2]
        d[0], d[-1] = xyz[1] - xyz[0], xyz[-1] - xyz[-2]
    norm = np.linalg.norm(d, axis=1)
    valid = norm > 1e-300
    if not valid.any():
        raise FormatError("the curve has zero length (all its points coincide)")
    idx = np.maximum.accumulate(np.where(valid, np.arange(len(d)), -1))
    idx[idx < 0] = np.flatnonzero(valid)[0]
    return d[idx] / norm[idx, None]


@njit(cache=True)
def rotation_minimizing_normals(xyz, t, n0):
    """Normals (m, 3) of the rotation-minimising frame along points xyz with unit tangents t, starting from the
    unit normal n0 ⟂ t[0]: double reflection (Wang et al. 2008, Algorithm 1). A zero-length step skips its
    first reflection; equal tangents skip the second."""
    m = xyz.shape[0]
    out = np.empty((m, 3))
    out[0, 0], out[0, 1], out[0, 2] = n0[0], n0[1], n0[2]
    for i in range(m - 1):  # scalar arithmetic: no temporaries, no array-shape checks to compile
        v1x, v1y, v1z = xyz[i + 1, 0] - xyz[i, 0], xyz[i + 1, 1] - xyz[i, 1], xyz[i + 1, 2] - xyz[i, 2]
        c1 = v1x * v1x + v1y * v1y + v1z * v1z
        rx, ry, rz = out[i, 0], out[i, 1], out[i, 2]
        tx, ty, tz = t[i, 0], t[i, 1], t[i, 2]
        if c1 > 0.0:
            k = (2.0 / c1) * (v1x * rx + v1y * ry + v1z * rz)
            rx, ry, rz = rx - k * v1x, ry - k * v1y, rz - k * v1z
            k = (2.0 / c1) * (v1x * tx + v1y * ty + v1z * tz)
            tx, ty, tz = tx - k * v1x, ty - k * v1y, tz - k * v1z
        v2x, v2y, v2z = t[i + 1, 0] - tx, t[i + 1, 1] - ty, t[i + 1, 2] - tz
        c2 = v2x * v2x + v2y * v2y + v2z * v2z
        if c2 > 0.0:
            k = (2.0 / c2) * (v2x * rx + v2y * ry + v2z * rz)
            rx, ry, rz = rx - k * v2x, ry - k * v2y, rz - k * v2z
        # remove rounding drift; the exact result is already ⟂ t[i+1]
        k = rx * t[i + 1, 0] + ry * t[i + 1, 1] + rz * t[i + 1, 2]
        rx, ry, rz = rx - k * t[i + 1, 0], ry - k * t[i + 1, 1], rz - k * t[i + 1, 2]
        norm = math.sqrt(rx * rx + ry * ry + rz * rz)
        out[i + 1, 0], out[i + 1, 1], out[i + 1, 2] = rx / norm, ry / norm, rz / norm
    return out


def curve_frames(xyz: np.ndarray, sigma: np.ndarray, closed: bool, n0: np.ndarray | None = None):
    """(T, N, holonomy) along a dense polyline: unit tangents, rotation-minimising normals from n0 (default
    ``initial_normal(T_0)``; otherwise made orthogonal to T_0), and for a closed curve (xyz[-1] == xyz[0],
    sigma[-1] = L) the holonomy Δ (rad), distributed as a turn of −Δ·σ/L about T so that the frame closes;
    holonomy is 0.0 for an open curve."""
    t = tangents(xyz, closed)
    if n0 is None:
        n0 = initial_normal(t[0])
    n0 = n0 - (n0 @ t[0]) * t[0]
    n0 = n0 / np.linalg.norm(n0)
    n = rotation_minimizing_normals(xyz, t, n0)
    if not closed:
        return t, n, 0.0
    t0, n_end = t[0], n[-1]
    holonomy = math.atan2(float(np.cross(n0, n_end) @ t0), float(n0 @ n_end))
    phi = -holonomy * sigma / sigma[-1]
    n = n * np.cos(phi)[:, None] + np.cross(t, n) * np.sin(phi)[:, None]
    n[-1] = n0
    return t, n, holonomy


def start_normal(curves: YarnCurves, c: int, frame: int, t_now: np.ndarray,
                  samples_per_segment: int | None) -> np.ndarray | None:
    """The start normal of curve c at ``frame`` whose start tangent is t_now (module docstring: Start normal);
    None at frame 0 (``curve_frames`` then uses ``initial_normal``)."""
    if frame == 0:
        return None
    xyz0, _ = dense_curve(curves, c, 0, samples_per_segment)
    t0 = tangents(xyz0, bool(curves.closed[c]))[0]
    n0 = initial_normal(t0)
    cos = float(t0 @ t_now)
    if cos > -1.0 + 1e-12:  # smallest rotation taking t0 to t_now, applied to n0 ⟂ t0
        n = n0 - ((t_now @ n0) / (1.0 + cos)) * (t0 + t_now)
    else:  # opposite tangents: half turn about n0 keeps n0
        n = n0
    n = n - (n @ t_now) * t_now
    return n / np.linalg.norm(n)


def yarn_frame(curves: YarnCurves, c: int, frame: int, samples_per_segment: int | None = None):
    """(xyz, sigma, T, N) of curve c at ``frame``: the dense polyline (``dense_curve``) and its yarn frame — unit
    tangents and the rotation-minimising normals from the curve's start normal (``start_normal``), closed curves
    with their holonomy spread so the frame closes (``curve_frames``). Yarn-space (x, y) lies along (N, T × N)."""
    xyz, sigma = dense_curve(curves, c, frame, samples_per_segment)
    closed = bool(curves.closed[c])
    n0 = start_normal(curves, c, frame, tangents(xyz, closed)[0], samples_per_segment)
    t, n, _ = curve_frames(xyz, sigma, closed, n0)
    return xyz, sigma, t, n
