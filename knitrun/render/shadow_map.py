"""Yarn-level shadow map for a distant light: yarns as tubes, filtered by PCSS (percentage-closer soft shadows).

Units and conventions:

* ``direction`` is the unit vector from the scene TOWARD the light. The light camera (``knitrun.render.camera``) is
  orthographic, square, looks along −direction at the centre of the bounding sphere (radius R_s) of the scene box
  grown by the largest yarn radius, and sits at distance 2·R_s from that centre (outside the sphere, so every yarn
  lies at view depth in [R_s, 3·R_s]); ortho_height = 2·R_s.
* The map is rendered by ``rasterize_depth`` (``rasterize_strips``' depth at msaa 1): strips face the light camera,
  so each yarn covers its tube silhouette of half-width radius, at the depth of the tube's axis plane. ``depth`` is
  that view depth (scene units along fwd from the camera plane) of the nearest strip, +inf where no yarn covers the
  texel centre.
* Texel (row i, column j) covers light-view x ∈ [−h/2 + j·τ, −h/2 + (j + 1)·τ) and y ∈ (h/2 − (i + 1)·τ, h/2 − i·τ]
  (h = ortho_height, τ = h / size the texel size); row 0 is the top (+up). Its centre, where the depth was taken, is
  x = −h/2 + (j + ½)τ, y = h/2 − (i + ½)τ. Continuous texel coordinates of view point (x, y): u = x/τ + size/2
  (columns), w = size/2 − y/τ (rows); texel centres at integer + ½.
* A receiver at view depth z is occluded by a texel of depth d when d < z − bias. The renderer's bias
  (``knitrun.render.pipeline.SHADOW_BIAS_RADII``, ½ radius) keeps a receiver on a yarn's axis from its own yarn's
  strip: yarn-level shadows are between yarns, self-shadowing is fiber-level (``ASSET_PACK.md`` §7). A receiver off
  the axis (on the tube's surface) lies ``own_strip_depth`` behind its own yarn's strip, which faces the light and
  so tilts as the light turns toward the yarn's axis: its bias grows by that much, so its margin from its own strip
  stays the same.
* ``behind`` (with ``layers`` = 2): the depth of the second yarn along each texel's ray, the nearest strip more
  than the first one's radius behind it (``strip_raster.rasterize_depth`` with ``behind_gap``: depth peeling by
  ``rasterize_behind``'s rule), +inf where there is none; the same PCSS on it (``behind_map``) gives the fraction
  of the light that at most one yarn blocks.

PCSS (Fernando 2005) for a light of angular radius θ (``light_angular_radius``, radians; 0 = a delta light):

1. Blocker search: n × n taps (n = min(8, ⌈2r⌉ + 1), nearest texel) evenly spaced over [−r, r]² texels around the
   receiver, r = min(max(pcf_radius, (z − d_min)·tanθ / τ), 32) with d_min the map's nearest depth; d_avg is the
   mean depth of the occluding taps. None → visibility 1. (With r = 32 the stride is ~9 texels: a blocker thinner
   than that between taps can be missed.)
2. Penumbra half-width: (z − d_avg)·tanθ scene units → r' = min(max(pcf_radius, that / τ), 32) texels.
3. PCF: the mean, over n' × n' taps (n' = min(8, ⌈2r'⌉), at the cell centres of [−r', r']²), of the bilinearly
   weighted lit test (d ≥ z − bias, texels outside the map lit) of the 4 texels around each tap.

Receivers off the map or with non-finite positions are lit (1). Every receiver is independent, so results are the
same for any thread count.
"""

import math
from dataclasses import dataclass, replace

import numpy as np
from numba import njit, prange

from data_formats.conventions import HALF_PI
from knitrun.render.camera import Camera, view_matrix
from knitrun.render.strip_raster import rasterize_depth

MAX_FILTER_TEXELS = 32.0  # cap on the blocker-search and PCF half-widths
MAX_TAPS = 8  # taps per axis of each filter grid
OWN_STRIP_MAX = 6.0  # ``own_strip_depth``'s cap, in units of the offset's length


def own_strip_depth(offset, tangent, direction) -> np.ndarray:
    """How far (N,) scene units toward the light a receiver ``offset`` (N, 3) off its yarn's axis (``tangent`` (N, 3)
    there, normalised here) lies behind its own yarn's strip in a map toward unit ``direction`` d (3,); 0 where the
    strip lies beyond it, and where an input is not finite or the tangent zero. The map draws the yarn as the strip
    through its axis that contains the tangent and faces the light: the plane of normal
    n = (d − (d·t) t)/√(1 − (d·t)²), whose distance along d from the receiver is
    s = −(o·n)/(d·n) = −(o·d − (o·t)(d·t))/(1 − (d·t)²). For an offset o ⊥ t of length Δ, s ≤ Δ/cos θ (θ the
    light's angle from the yarn's normal plane): Δ with the light across the yarn, without bound as the light turns
    along it (the strip tilts in depth). Growing a receiver's bias by s hides no other yarn where its own is
    straight: from a point on the tube the ray toward the light stays inside the tube until 2s (it crosses the
    strip halfway), so another yarn's strip lies beyond 2s + r. Where the yarn bends within Δ tan θ of the receiver
    its strip is not there, so s is capped at ``OWN_STRIP_MAX``·|o| (6: the light within 9.6° of the yarn's axis;
    the bake's θ grids end at 78.75°, 1/cos θ = 5.1). Exactly along the axis the strip is edge-on: s = 0."""
    offset = np.ascontiguousarray(offset, np.float64).reshape(-1, 3)
    tangent = np.ascontiguousarray(tangent, np.float64).reshape(-1, 3)
    d = np.asarray(direction, np.float64).reshape(3)
    out = np.empty(len(offset))
    _own_strip_depth(offset, tangent, d[0], d[1], d[2], out)
    return out


@njit(parallel=True, cache=True)
def _own_strip_depth(offset, tangent, d0, d1, d2, out):
    """``own_strip_depth`` per receiver (each writes its own entry); 0 where it is not finite."""
    for k in prange(offset.shape[0]):
        t0, t1, t2 = tangent[k, 0], tangent[k, 1], tangent[k, 2]
        length = math.sqrt(t0 * t0 + t1 * t1 + t2 * t2)
        if not length > 0.0:
            out[k] = 0.0
            continue
        t0, t1, t2 = t0 / length, t1 / length, t2 / length
        o0, o1, o2 = offset[k, 0], offset[k, 1], offset[k, 2]
        c = t0 * d0 + t1 * d1 + t2 * d2
        toward = -(o0 * d0 + o1 * d1 + o2 * d2 - (o0 * t0 + o1 * t1 + o2 * t2) * c)
        cap = OWN_STRIP_MAX * math.sqrt(o0 * o0 + o1 * o1 + o2 * o2)
        den = 1.0 - c * c
        s = toward / den if den > 1e-12 else (cap if toward > 0.0 else 0.0)
        out[k] = min(max(s, 0.0), cap) if math.isfinite(s) and math.isfinite(cap) else 0.0


@dataclass
class ShadowMap:
    """Depth map of the yarns seen from a distant light (module docstring)."""

    view: np.ndarray  # (3, 3) rows (right, up, fwd) of the light camera; fwd = −direction
    origin: np.ndarray  # (3,) light-camera position; view coordinates of p are view @ (p − origin)
    ortho_height: float  # side of the square view, scene units
    size: int  # texels per side
    depth: np.ndarray  # (size, size) float32 view depth of the nearest yarn strip, +inf where none
    behind: np.ndarray | None = None  # (size, size) float32 view depth of the second yarn, +inf where none


def behind_map(sm: ShadowMap) -> ShadowMap:
    """The map of the second yarn layer of ``sm`` (built with ``layers`` = 2), for ``shadow_visibility``."""
    if sm.behind is None:
        raise ValueError("behind_map: the shadow map was built with one layer")
    return replace(sm, depth=sm.behind, behind=None)


def build_shadow_map(points, offsets, closed, rest_arclength, radius, direction, size, bounds_lo, bounds_hi,
                     closing_length=None, out=None, layers=1) -> ShadowMap:
    """Render the yarn curves (as in ``rasterize_strips``; ``radius`` (C,) or a scalar) into a ``size`` × ``size``
    shadow map for a light toward unit-izable ``direction`` (3,), framing the box [bounds_lo, bounds_hi] (yarn
    beyond it may fall off the map and cast no shadow); ``out`` a (size, size) float32 array to reuse for the depth;
    ``layers`` = 2 adds the second yarn layer (``behind``, module docstring). ValueError for size < 1, a zero or
    non-finite direction, bad bounds or layers other than 1 and 2."""
    if layers not in (1, 2):
        raise ValueError(f"layers = {layers}, expected 1 or 2")
    direction = np.asarray(direction, np.float64).reshape(3)
    norm = np.linalg.norm(direction)
    if not (np.isfinite(direction).all() and norm > 0):
        raise ValueError(f"direction = {direction.tolist()}, expected a non-zero finite vector")
    if int(size) != size or size < 1:
        raise ValueError(f"size = {size}, expected an integer >= 1")
    lo, hi = np.asarray(bounds_lo, np.float64).reshape(3), np.asarray(bounds_hi, np.float64).reshape(3)
    if not (np.isfinite(lo).all() and np.isfinite(hi).all() and np.all(lo <= hi)):
        raise ValueError(f"bounds [{lo.tolist()}, {hi.tolist()}]: expected finite with lo <= hi")
    direction = direction / norm
    size = int(size)
    radius_max = float(np.max(radius, initial=0.0))
    sphere = 0.5 * float(np.linalg.norm(hi - lo)) + radius_max
    if not sphere > 0:  # no extent at all (an empty scene in a point box): any scale frames it
        sphere = 1.0
    centre = 0.5 * (lo + hi)
    up = np.eye(3)[int(np.argmin(np.abs(direction)))]  # the axis least aligned with the light: never parallel
    camera = Camera(centre + 2 * sphere * direction, centre, up, size, size, ortho_height=2 * sphere)
    # the second layer peeled behind the first one's radius (``rasterize_behind``'s rule, without its buffers)
    depth = rasterize_depth(points, offsets, closed, rest_arclength, radius, camera, near=0.5 * sphere,
                            closing_length=closing_length, out=out, behind_gap=radius if layers == 2 else None)
    depth, behind = depth if layers == 2 else (depth, None)
    return ShadowMap(view_matrix(camera), np.asarray(camera.position, np.float64), 2 * sphere, size, depth, behind)


def shadow_visibility(sm: ShadowMap, positions, bias, light_angular_radius: float,
                      pcf_radius_texels: float = 1.5) -> np.ndarray:
    """Visibility (N,) float64 in [0, 1] of the light from world ``positions`` (N, 3), by PCSS (module docstring);
    ``bias`` (N,) or a scalar, scene units. ValueError for a non-finite or negative bias, an angular radius outside
    [0, π/2), or a negative or non-finite PCF radius."""
    positions = np.ascontiguousarray(positions, dtype=np.float64).reshape(-1, 3)
    bias = np.ascontiguousarray(np.broadcast_to(np.asarray(bias, np.float64), (len(positions),)))
    bad = np.flatnonzero(~(np.isfinite(bias) & (bias >= 0)))
    if bad.size:
        raise ValueError(f"bias[{bad[0]}] = {bias[bad[0]]}, expected finite and >= 0")
    if not 0 <= light_angular_radius < HALF_PI:
        raise ValueError(f"light_angular_radius = {light_angular_radius}, expected in [0, pi/2)")
    if not (math.isfinite(pcf_radius_texels) and pcf_radius_texels >= 0):
        raise ValueError(f"pcf_radius_texels = {pcf_radius_texels}, expected finite and >= 0")
    depth = np.ascontiguousarray(sm.depth, dtype=np.float32)
    d_min = float(np.min(depth, initial=np.inf))
    visibility = np.ones(len(positions))
    if math.isfinite(d_min):  # an empty map shadows nothing
        _pcss(depth, np.ascontiguousarray(sm.view, np.float64), np.asarray(sm.origin, np.float64),
              sm.ortho_height / sm.size, d_min, positions, bias, math.tan(light_angular_radius),
              float(pcf_radius_texels), visibility)
    return visibility


RECEIVER_BLOCK = 256  # receivers per prange iteration: they share one set of tap scratch arrays


@njit(parallel=True, cache=True, error_model="numpy")
def _pcss(depth, view, origin, texel, d_min, positions, bias, tan_angle, pcf_radius, visibility):
    """visibility[k] for every receiver k (module docstring); each iteration writes only its own entry. The taps lie
    on a grid, so a filter's column and row texels (and bilinear fractions) are found once per axis, not per tap."""
    size = depth.shape[0]
    for block in prange((positions.shape[0] + RECEIVER_BLOCK - 1) // RECEIVER_BLOCK):
        cols, rows = np.empty(MAX_TAPS, np.int64), np.empty(MAX_TAPS, np.int64)
        col_f, row_f = np.empty(MAX_TAPS), np.empty(MAX_TAPS)
        for k in range(block * RECEIVER_BLOCK, min(positions.shape[0], (block + 1) * RECEIVER_BLOCK)):
            px, py, pz = positions[k, 0] - origin[0], positions[k, 1] - origin[1], positions[k, 2] - origin[2]
            x = view[0, 0] * px + view[0, 1] * py + view[0, 2] * pz
            y = view[1, 0] * px + view[1, 1] * py + view[1, 2] * pz
            z = view[2, 0] * px + view[2, 1] * py + view[2, 2] * pz
            u, w = x / texel + 0.5 * size, 0.5 * size - y / texel
            reach = MAX_FILTER_TEXELS + 2.0
            if not (math.isfinite(z) and -reach < u < size + reach and -reach < w < size + reach):
                continue  # non-finite or off the map: lit
            threshold = z - bias[k]
            r = min(max(pcf_radius, (z - d_min) * tan_angle / texel), MAX_FILTER_TEXELS)
            n = min(MAX_TAPS, int(math.ceil(2.0 * r)) + 1)
            for a in range(n):
                tu = u - r + (2.0 * r * a / (n - 1) if n > 1 else r)
                tw = w - r + (2.0 * r * a / (n - 1) if n > 1 else r)
                cols[a], rows[a] = int(math.floor(tu)), int(math.floor(tw))
            found, total = 0, 0.0
            for b in range(n):  # along rows: the map is row-major
                for a in range(n):
                    d = _fetch(depth, rows[b], cols[a])
                    if d < threshold:
                        found += 1
                        total += d
            if found == 0:
                continue
            r = min(max(pcf_radius, (z - total / found) * tan_angle / texel), MAX_FILTER_TEXELS)
            n = min(MAX_TAPS, max(1, int(math.ceil(2.0 * r))))
            for a in range(n):
                fu = u - r + 2.0 * r * (a + 0.5) / n - 0.5  # relative to texel centres
                fw = w - r + 2.0 * r * (a + 0.5) / n - 0.5
                cols[a], rows[a] = int(math.floor(fu)), int(math.floor(fw))
                col_f[a], row_f[a] = fu - cols[a], fw - rows[a]
            lit = 0.0
            for b in range(n):
                i, sw = rows[b], row_f[b]
                for a in range(n):
                    j, su = cols[a], col_f[a]
                    top = (1.0 - su) * _lit(depth, i, j, threshold) + su * _lit(depth, i, j + 1, threshold)
                    bottom = (1.0 - su) * _lit(depth, i + 1, j, threshold) + su * _lit(depth, i + 1, j + 1, threshold)
                    lit += (1.0 - sw) * top + sw * bottom
            visibility[k] = min(max(lit / (n * n), 0.0), 1.0)


@njit(cache=True, error_model="numpy", inline="always")
def _fetch(depth, i, j):
    """depth[i, j], +inf outside the map."""
    if 0 <= i < depth.shape[0] and 0 <= j < depth.shape[1]:
        return depth[i, j]
    return np.inf


@njit(cache=True, error_model="numpy", inline="always")
def _lit(depth, i, j, threshold):
    """1.0 where texel (i, j) does not occlude a receiver whose biased depth is ``threshold``, else 0.0."""
    return 1.0 if _fetch(depth, i, j) >= threshold else 0.0
