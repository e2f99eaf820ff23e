"""Software rasterizer core of the strip renderer: yarn polylines → camera-facing strips → a multisampled G-buffer.

Geometry (``ASSET_PACK.md`` §3, ``DESIGN.md`` §3):

* Every control point i of a curve gets a unit tangent t_i, the normalized sum of the unit directions of its two
  segments (one at the ends of an open curve; closed curves wrap; zero-length segments are ignored; at an exact
  hairpin the outgoing direction), and the half-width direction b_i = normalize(ω_o × t_i) = n × t_i with
  n = normalize(ω_o − (ω_o·t_i) t_i), ω_o the unit direction from p_i toward the camera (−fwd when orthographic).
* Segment (a, b) becomes the quad p_a − r b_a, p_a + r b_a, p_b + r b_b, p_b − r b_b (2 triangles) for the yarn
  radius r of its curve; neighbouring segments share their joint's two corners, so strips have no cracks.
* Skipped: zero-length segments and segments with an end where |ω_o × t| < 1e-6 (looking along the yarn; the spec's
  degenerate strip). Culled: segments whose bounding sphere (midpoint, half length + r) lies outside one of the
  planes near (z = ``near``), far (z = ``far``) or the four sides of the view. Triangles are clipped against the
  near plane (so the camera may sit inside a yarn); the far plane only culls.

Sample attributes (all interpolated perspective-correctly over each triangle; view z by 1/z for a pinhole):

* ``depth``: camera distance in scene units (pinhole: |sample point − camera position|; orthographic: the distance
  in front of the camera plane); the depth test keeps the nearest (smallest view z); on equal z the triangle with the
  lower slot (k·S + segment index for the k-th triangle of a segment, S segments) wins.
* ``curve`` (curve index), ``yarn`` (its ``yarn_id``), ``segment`` (global index of the segment's first control
  point, so a closed curve's closing segment has the index of its last point).
* ``arclength``: the rest arc length s (scene units; the spec's u is s / period); on a closed curve's closing
  segment s runs from the last point's rest arc length to that plus ``closing_length`` of the curve.
* ``v`` ∈ [−1, 1]: −1 on the −b edge, +1 on the +b edge.
* ``tangent``: unit world tangent (the interpolated vertex tangents, renormalized).

Samples (``SAMPLE_PATTERNS``, positions inside the pixel, x right and y down, in pixels): k = 1 the centre; k = 2,
4, 8 and 16 the standard Direct3D 11 patterns (offsets from the centre in 1/16 px: 2: (4,4) (−4,−4); 4: (−2,−6)
(6,−2) (−6,2) (2,6); 8: (1,−3) (−1,3) (5,1) (−3,−5) (−5,5) (−7,−1) (3,7) (7,−7); 16: the D3D 16× pattern); the 8
x positions are distinct, so a vertical strip
w px wide covers 8·w samples per row up to one. Coverage is exact per sample: edge functions are evaluated in a
canonical order of each edge's end points and ties follow a top-left rule, so a sample on an edge shared by two
triangles belongs to exactly one of them.

Pipeline: ``_vertex_frames`` (per point; serial: 2 ms for 60K points, where ``parallel=True`` cost 0.8 s more to
compile on a cold start) and ``_setup`` (per segment: cull, build, clip, project; up to 4 triangles, in parallel);
``_bin`` (serial, in triangle order) lists the triangles overlapping each square tile of ``tile`` px; ``_raster``
(parallel over tiles, each tile owns its pixels) depth-tests (``_depth_test``) and writes a visibility buffer:
triangle slot, curve and depth per sample (``rasterize_visibility``). ``_attributes`` interpolates the other
attributes at the samples asked for (``sample_attributes``; the renderer asks at its shading points, about a tenth
of the samples of a knit at MSAA 4; ``rasterize_strips`` at every covered sample). ``rasterize_depth`` runs the same
depth test and writes the depth alone (``_raster_depth``: shadow maps); ``rasterize_behind`` runs it again on a
buffer's own binned triangles, keeping at each sample the nearest strip beyond a floor behind the first (depth
peeling); ``rasterize_before`` keeps the K nearest strips in front of a ceiling that another buffer sets, in one
depth test (a sorted list of K per sample). Buffers are identical for any thread count.
"""

import math
from dataclasses import dataclass
from typing import NamedTuple

import numpy as np
from numba import njit, prange

from knitrun.render.camera import Camera, tan_half_fov, view_matrix

SAMPLE_PATTERNS = {
    1: np.array([[0.5, 0.5]]),
    2: 0.5 + np.array([[4, 4], [-4, -4]]) / 16.0,
    4: 0.5 + np.array([[-2, -6], [6, -2], [-6, 2], [2, 6]]) / 16.0,
    8: 0.5 + np.array([[1, -3], [-1, 3], [5, 1], [-3, -5], [-5, 5], [-7, -1], [3, 7], [7, -7]]) / 16.0,
    16: 0.5 + np.array([[1, 1], [-1, -3], [-3, 2], [4, -1], [-5, -2], [2, 5], [5, 3], [3, -5], [-2, 6], [0, -7],
                        [-4, -6], [-6, 4], [-8, 0], [7, -4], [6, 7], [-7, -8]]) / 16.0,
}
DEGENERATE_SIN = 1e-6  # |ω_o × t| below this: the strip is skipped (ASSET_PACK.md §3)

# Per clipped-triangle vertex record: screen X, Y (px), q (1/z pinhole, 1 orthographic), then q·(z, s, v, tx, ty, tz).
_NREC = 9
NO_BOUND, FLOOR, CEILING = 0, 1, 2  # what a depth test's bound is (``_depth_test``)
_NO_BOUND = np.zeros((1, 1, 1))  # the bound of a depth test without one (never read)


@dataclass
class StripGBuffer:
    """Per-sample G-buffer, every array (H, W, k) (``tangent`` (H, W, k, 3)); see the module docstring.
    Uncovered samples: ``coverage`` False, ids −1, every float 0. Pixel coverage is ``coverage.mean(axis=2)``."""

    coverage: np.ndarray  # bool
    depth: np.ndarray  # float32, scene units
    curve: np.ndarray  # int32
    yarn: np.ndarray  # int32
    segment: np.ndarray  # int32
    arclength: np.ndarray  # float32, scene units
    v: np.ndarray  # float32
    tangent: np.ndarray  # float32


class StripTriangles(NamedTuple):
    """The clipped triangles a visibility buffer's slots index, with what ``_attributes`` needs to interpolate at a
    sample."""

    records: np.ndarray  # (T, 3, _NREC) vertex records
    seg_first: np.ndarray  # int32 (S,): global index of each segment's first control point
    seg_curve: np.ndarray  # int32 (S,)
    yarn_id: np.ndarray  # int32 (C,)
    pattern: np.ndarray  # (k, 2) sample positions in the pixel


class SampleAttributes(NamedTuple):
    """G-buffer attributes of N samples (module docstring)."""

    yarn: np.ndarray  # int32 (N,)
    segment: np.ndarray  # int32 (N,)
    arclength: np.ndarray  # float32 (N,), scene units
    v: np.ndarray  # float32 (N,)
    tangent: np.ndarray  # float32 (N, 3)


@dataclass
class StripVisibility:
    """Per-sample visibility buffer: the nearest triangle at each sample (``slot``, −1 uncovered), its ``curve``
    (−1 uncovered) and ``depth`` (float32 scene units, 0 uncovered), each (H, W, k), with the triangles they index.
    ``sample_attributes`` derives the other G-buffer attributes at the samples that need them, bit for bit as
    ``rasterize_strips`` writes them for every sample. ``bins`` (tile_start, tile_tris, tile px): the triangles'
    tile lists, which ``rasterize_behind`` depth-tests again."""

    slot: np.ndarray  # int32
    curve: np.ndarray  # int32
    depth: np.ndarray  # float32
    triangles: StripTriangles
    bins: tuple

    @property
    def pattern(self):
        return self.triangles.pattern

    @property
    def coverage(self):
        return self.slot >= 0


def rasterize_visibility(points, offsets, closed, rest_arclength, radius, yarn_id, camera: Camera, msaa=1,
                         near=1e-3, far=math.inf, closing_length=None, tile=32):
    """The strips' ``StripVisibility`` of camera.height × camera.width × ``msaa`` samples (arguments as
    ``rasterize_strips``): the depth test of ``rasterize_strips`` writing 12 bytes per sample instead of 37, for a
    renderer that shades a fraction of the samples (``strip_shading.shading_points``)."""
    triangles, bins = _binned_strips(points, offsets, closed, rest_arclength, radius, yarn_id, camera, msaa, near, far,
                                     closing_length, tile)
    return _draw(triangles, bins, camera, (int(camera.height), int(camera.width), msaa), _NO_BOUND, NO_BOUND)[0]


def _binned_strips(points, offsets, closed, rest_arclength, radius, yarn_id, camera, msaa, near, far, closing_length,
                   tile):
    """The strips' ``StripTriangles`` and their tile lists (``StripVisibility.bins``)."""
    if msaa not in SAMPLE_PATTERNS:
        raise ValueError(f"msaa = {msaa}, expected one of {sorted(SAMPLE_PATTERNS)}")
    n_curves = len(offsets) - 1
    yarn_id = np.ascontiguousarray(np.broadcast_to(np.asarray(yarn_id, dtype=np.int32), (max(n_curves, 0),)))
    tri, tile_start, tile_tris, seg_a, seg_curve = _triangles(points, offsets, closed, rest_arclength, radius, camera,
                                                              near, far, closing_length, tile)
    triangles = StripTriangles(tri, seg_a.astype(np.int32), seg_curve.astype(np.int32), yarn_id, SAMPLE_PATTERNS[msaa])
    return triangles, (tile_start, tile_tris, tile)


def rasterize_behind(front: StripVisibility, camera: Camera, gap):
    """Depth peeling: the ``StripVisibility`` of the strips behind ``front`` (``rasterize_visibility``'s buffer of
    the same ``camera``), from its own triangles: each sample keeps the nearest strip more than gap[c] (scene units,
    (C,) per curve or a scalar) behind the view depth of the strip c that ``front`` has there (the next layer: what
    shows through a strip of partial coverage), and nothing where ``front`` has none. A gap of the front yarn's
    radius skips the front strip itself and any strip within its tube."""
    return _draw(front.triangles, front.bins, camera, front.slot.shape, _view_floor(front, camera, gap), FLOOR)[0]


def rasterize_before(points, offsets, closed, rest_arclength, radius, yarn_id, camera: Camera, front: StripVisibility,
                     reach, layers=1, near=1e-3, far=math.inf, closing_length=None, tile=32):
    """The ``layers`` nearest strips at each sample, nearest first, as that many ``StripVisibility`` buffers of the
    strips ``rasterize_visibility`` draws from the same arguments (at ``front``'s msaa), keeping only strips less
    than reach[c] (scene units, (C,) per curve or a scalar) behind the view depth of the strip c that ``front``
    (another buffer of the same camera, e.g. the regular strips') has at the sample, and any strip where ``front``
    has none. One depth test keeps the K nearest: each triangle is tested once per sample, so a strip counts twice
    at a sample only where it overlaps itself (a fold at a bend tighter than its half-width)."""
    msaa = front.slot.shape[2]
    triangles, bins = _binned_strips(points, offsets, closed, rest_arclength, radius, yarn_id, camera, msaa, near, far,
                                     closing_length, tile)
    return _draw(triangles, bins, camera, front.slot.shape, _view_floor(front, camera, reach), CEILING, layers)


def _view_floor(front: StripVisibility, camera: Camera, gap) -> np.ndarray:
    """The view z of ``front``'s strip at each sample plus gap[c] of its curve c (+inf where it has none)."""
    n_curves = len(front.triangles.yarn_id)
    gap = np.array(np.broadcast_to(np.asarray(gap, np.float64), (n_curves,)))  # a writable copy: one kernel type
    floor = np.empty(front.slot.shape)
    _peel_floor(front.depth, front.curve, gap, front.pattern, float(camera.ortho_height) > 0, tan_half_fov(camera),
                floor)
    return floor


def _draw(triangles, bins, camera, shape, bound, bound_kind, layers=1):
    """Depth-test the binned ``triangles`` into ``layers`` new ``StripVisibility`` buffers of ``shape``, the nearest
    first (``_raster``)."""
    slot, curve = np.empty((layers, *shape), np.int32), np.empty((layers, *shape), np.int32)
    depth = np.empty((layers, *shape), np.float32)
    tile_start, tile_tris, tile = bins
    height, width = shape[:2]
    _raster(triangles.records, tile_start, tile_tris, triangles.seg_curve, width, height, tile, -(-width // tile),
            triangles.pattern, float(camera.ortho_height) > 0, tan_half_fov(camera), bound, bound_kind, slot, curve,
            depth)
    return [StripVisibility(slot[m], curve[m], depth[m], triangles, bins) for m in range(layers)]


@njit(parallel=True, cache=True, error_model="numpy")
def _peel_floor(depth, curve, gap, pattern, ortho, tan_half, floor):
    """floor = the view z of each sample's ``depth`` (``_sample_depth`` inverted) + gap[curve]; +inf where no curve
    covers the sample (a peeled layer has nothing there)."""
    height, width, k = depth.shape
    for py in prange(height):
        for px in range(width):
            for s in range(k):
                c = curve[py, px, s]
                if c < 0:
                    floor[py, px, s] = np.inf
                else:
                    floor[py, px, s] = _sample_depth(1.0, px, py, pattern[s], width, height, ortho, tan_half)
                    floor[py, px, s] = depth[py, px, s] / floor[py, px, s] + gap[c]


def sample_attributes(vis: StripVisibility, i, j, a):
    """The G-buffer attributes of the covered samples (i, j, a) (row, column, sample index arrays of one length N)
    of ``vis``: a dict of ``yarn``, ``segment`` (int32 (N,)), ``arclength``, ``v`` (float32 (N,)) and ``tangent``
    (float32 (N, 3)), as the module docstring defines them. ValueError if a sample is not covered."""
    slot = vis.slot[i, j, a]
    if np.any(slot < 0):
        raise ValueError("sample_attributes: a requested sample is not covered")
    n = len(slot)
    out = SampleAttributes(np.empty(n, np.int32), np.empty(n, np.int32), np.empty(n, np.float32),
                           np.empty(n, np.float32), np.empty((n, 3), np.float32))
    _attributes(vis.triangles, slot, np.asarray(i, np.int64), np.asarray(j, np.int64), np.asarray(a, np.int64), out)
    return out._asdict()


def rasterize_strips(points, offsets, closed, rest_arclength, radius, yarn_id, camera: Camera, msaa=1, near=1e-3,
                     far=math.inf, closing_length=None, tile=32):
    """Rasterize the strips of polylines into a ``StripGBuffer`` of camera.height × camera.width × ``msaa`` samples.

    ``points`` (P, 3) and ``offsets`` (C+1,) as in ``YarnCurves`` (one frame; curve c is points[offsets[c]:
    offsets[c+1]]); ``closed`` (C,) bool; ``rest_arclength`` (P,) scene units; ``radius`` (C,) or a scalar, the
    yarn radius (strip half-width) in scene units; ``yarn_id`` (C,) ints; ``msaa`` ∈ {1, 2, 4, 8, 16}; ``near`` > 0 and
    ``far`` view depths in scene units; ``closing_length`` (C,) the rest length of each closed curve's closing
    segment (default: its current length); ``tile`` the tile size in px. ValueError for non-finite points (naming
    the curve) or bad arguments. Every sample's attributes: ``rasterize_visibility`` then ``sample_attributes``.
    """
    vis = rasterize_visibility(points, offsets, closed, rest_arclength, radius, yarn_id, camera, msaa, near, far,
                               closing_length, tile)
    shape = vis.slot.shape
    out = StripGBuffer(vis.coverage, vis.depth, vis.curve, np.full(shape, -1, np.int32),
                       np.full(shape, -1, np.int32), np.zeros(shape, np.float32), np.zeros(shape, np.float32),
                       np.zeros(shape + (3,), np.float32))
    covered = np.nonzero(out.coverage)
    for name, value in sample_attributes(vis, *covered).items():
        getattr(out, name)[covered] = value
    return out


def rasterize_depth(points, offsets, closed, rest_arclength, radius, camera: Camera, near=1e-3, far=math.inf,
                    closing_length=None, tile=32, out=None, behind_gap=None):
    """The ``depth`` of ``rasterize_strips`` at msaa 1 alone, as a (camera.height, camera.width) float32 map with
    +inf where no strip covers the pixel centre: what a shadow map needs, without writing the other attributes
    (the same depth test, so the same values bit for bit). ``out`` an array of that shape and dtype to reuse.

    ``behind_gap`` (scene units, (C,) per curve or a scalar): (depth, the depth of the layer behind it), the second
    map peeled as ``rasterize_behind`` peels a ``rasterize_visibility`` buffer with that gap, bit for bit, +inf where
    there is none, without writing either buffer's slots."""
    tri, tile_start, tile_tris, _, seg_curve = _triangles(points, offsets, closed, rest_arclength, radius, camera,
                                                          near, far, closing_length, tile)
    w, h = int(camera.width), int(camera.height)
    if out is None or out.shape != (h, w) or out.dtype != np.float32:
        out = np.empty((h, w), np.float32)
    ortho, tan_half, pattern = float(camera.ortho_height) > 0, tan_half_fov(camera), SAMPLE_PATTERNS[1]
    peel = behind_gap is not None
    curve = np.empty((h, w) if peel else (0, 0), np.int32)
    _raster_depth(tri, tile_start, tile_tris, seg_curve, w, h, tile, -(-w // tile), pattern, ortho, tan_half,
                  _NO_BOUND, NO_BOUND, out, curve)
    if not peel:
        return out
    n_curves = len(offsets) - 1
    gap = np.array(np.broadcast_to(np.asarray(behind_gap, np.float64), (n_curves,)))
    floor = np.empty((h, w, 1))
    _peel_floor(out.reshape(h, w, 1), curve.reshape(h, w, 1), gap, pattern, ortho, tan_half, floor)
    behind = np.empty((h, w), np.float32)
    _raster_depth(tri, tile_start, tile_tris, seg_curve, w, h, tile, -(-w // tile), pattern, ortho, tan_half,
                  floor, FLOOR, behind, np.empty((0, 0), np.int32))
    return out, behind


def _triangles(points, offsets, closed, rest_arclength, radius, camera, near, far, closing_length, tile):
    """Validate the arguments (``rasterize_strips``) and build, clip, project and bin the strips' triangles:
    (tri, tile_start, tile_tris, seg_a, seg_curve)."""
    points = np.ascontiguousarray(points, dtype=np.float64).reshape(-1, 3)
    offsets = np.asarray(offsets, dtype=np.int64)
    n_curves = len(offsets) - 1
    closed = np.broadcast_to(np.asarray(closed, dtype=np.bool_), (n_curves,))
    rest = np.ascontiguousarray(rest_arclength, dtype=np.float64)
    radius = np.broadcast_to(np.asarray(radius, dtype=np.float64), (n_curves,))
    if n_curves < 0 or offsets.ndim != 1 or offsets[0] != 0 or offsets[-1] != len(points) \
            or np.any(np.diff(offsets) < 0):
        raise ValueError(f"offsets must run non-decreasing from 0 to the point count {len(points)}")
    if rest.shape != (len(points),):
        raise ValueError(f"rest_arclength has shape {rest.shape}, expected ({len(points)},)")
    if not (near > 0 and far > near) or tile < 1:
        raise ValueError(f"near = {near}, far = {far}, tile = {tile}: expected 0 < near < far and tile >= 1")
    bad = np.flatnonzero(~(np.isfinite(radius) & (radius > 0)))
    if bad.size:
        raise ValueError(f"curve {bad[0]}: radius = {radius[bad[0]]}, expected a positive finite number")
    finite = np.isfinite(points).all(axis=1) & np.isfinite(rest)
    if not finite.all():
        p = int(np.flatnonzero(~finite)[0])
        c = int(np.searchsorted(offsets, p, side="right") - 1)
        raise ValueError(f"curve {c}: point {p - offsets[c]} has non-finite coordinates or rest arc length "
                         f"({points[p].tolist()}, {rest[p]})")

    first, last = offsets[:-1], offsets[1:] - 1
    nonempty = last >= first
    curve_of = np.repeat(np.arange(n_curves, dtype=np.int64), np.diff(offsets))
    nxt = np.arange(1, len(points) + 1, dtype=np.int64)
    prev = np.arange(-1, len(points) - 1, dtype=np.int64)
    nxt[last[nonempty]] = np.where(closed[nonempty], first[nonempty], -1)
    prev[first[nonempty]] = np.where(closed[nonempty], last[nonempty], -1)
    seg_a = np.flatnonzero(nxt >= 0)
    seg_b = nxt[seg_a]
    seg_curve = curve_of[seg_a]
    s_a = rest[seg_a]
    s_b = rest[seg_b].copy()
    wrap = seg_b <= seg_a  # closing segments (a 1-point closed curve closes onto itself)
    if closing_length is None:
        s_b[wrap] = s_a[wrap] + np.linalg.norm(points[seg_b[wrap]] - points[seg_a[wrap]], axis=1)
    else:
        s_b[wrap] = s_a[wrap] + np.broadcast_to(np.asarray(closing_length, np.float64), (n_curves,))[seg_curve[wrap]]

    w, h = int(camera.width), int(camera.height)
    view = view_matrix(camera)
    pos = np.asarray(camera.position, np.float64)
    ortho_h = float(camera.ortho_height)
    tan_half = tan_half_fov(camera)
    tangent, bvec, ok = _vertex_frames(points, prev, nxt, pos, view[2].copy(), ortho_h > 0)
    n_seg = len(seg_a)
    tri = np.empty((4 * n_seg, 3, _NREC))  # slot k·S + segment: pages of slots 2, 3 (clipped quads) stay untouched
    count = np.empty(n_seg, np.int64)
    boxes = np.empty((4 * n_seg, 4), np.int64)
    _setup(points, seg_a, seg_b, s_a, s_b, radius[seg_curve].copy(), tangent, bvec, ok, view, pos, float(near),
           float(far), ortho_h, tan_half, w, h, tile, tri, count, boxes)
    tile_start, tile_tris = _bin(count, boxes, -(-w // tile), -(-h // tile))
    return tri, tile_start, tile_tris, seg_a, seg_curve


@njit(cache=True, error_model="numpy")
def _vertex_frames(points, prev, nxt, cam_pos, fwd, ortho):
    """Unit vertex tangents (P, 3), half-width directions b (P, 3) and whether the strip frame exists (P,)."""
    n = points.shape[0]
    tangent = np.zeros((n, 3))
    bvec = np.zeros((n, 3))
    ok = np.zeros(n, np.bool_)
    for i in range(n):
        px, py, pz = points[i, 0], points[i, 1], points[i, 2]
        tx, ty, tz = vertex_tangent(points, i, prev[i], nxt[i])
        if ortho:
            wx, wy, wz = -fwd[0], -fwd[1], -fwd[2]
        else:
            wx, wy, wz = _unit(cam_pos[0] - px, cam_pos[1] - py, cam_pos[2] - pz)
        cx, cy, cz = wy * tz - wz * ty, wz * tx - wx * tz, wx * ty - wy * tx
        sin = math.sqrt(cx * cx + cy * cy + cz * cz)  # 0 for a zero tangent or a camera on the point
        if sin < DEGENERATE_SIN:
            continue
        tangent[i, 0], tangent[i, 1], tangent[i, 2] = tx, ty, tz
        bvec[i, 0], bvec[i, 1], bvec[i, 2] = cx / sin, cy / sin, cz / sin
        ok[i] = True
    return tangent, bvec, ok


@njit(cache=True, inline='always')
def vertex_tangent(points, i, before, after):
    """The unit tangent of polyline vertex i whose neighbours are the vertices ``before`` and ``after`` (−1: none): the
    sum of the unit directions of its two segments; where that vanishes (an end of a zero-length run, an exact
    hairpin) the one side that exists; (0, 0, 0) when neither does."""
    px, py, pz = points[i, 0], points[i, 1], points[i, 2]
    ix = iy = iz = ox = oy = oz = 0.0
    if before >= 0:
        ix, iy, iz = _unit(px - points[before, 0], py - points[before, 1], pz - points[before, 2])
    if after >= 0:
        ox, oy, oz = _unit(points[after, 0] - px, points[after, 1] - py, points[after, 2] - pz)
    tx, ty, tz = ix + ox, iy + oy, iz + oz
    if tx * tx + ty * ty + tz * tz < 1e-18:
        tx, ty, tz = (ox, oy, oz) if ox != 0.0 or oy != 0.0 or oz != 0.0 else (ix, iy, iz)
    return _unit(tx, ty, tz)


def vertex_tangents(points, offsets):
    """(P, 3) unit tangents of the vertices of open polylines (curve c: points offsets[c] … offsets[c + 1] − 1) by
    ``vertex_tangent``'s rule, the tangents the strips are built with."""
    points = np.ascontiguousarray(points, np.float64).reshape(-1, 3)
    out = np.zeros_like(points)
    _vertex_tangents(points, np.ascontiguousarray(offsets, np.int64), out)
    return out


@njit(parallel=True, cache=True)
def _vertex_tangents(points, offsets, out):
    for c in prange(offsets.shape[0] - 1):
        lo, hi = offsets[c], offsets[c + 1]
        for i in range(lo, hi):
            out[i, 0], out[i, 1], out[i, 2] = vertex_tangent(points, i, i - 1 if i > lo else -1,
                                                             i + 1 if i + 1 < hi else -1)


@njit(cache=True, error_model="numpy")
def _unit(x, y, z):
    """(x, y, z) normalized; (0, 0, 0) stays (0, 0, 0)."""
    length = math.sqrt(x * x + y * y + z * z)
    if length == 0.0:
        return 0.0, 0.0, 0.0
    return x / length, y / length, z / length


@njit(parallel=True, cache=True, error_model="numpy")
def _setup(points, seg_a, seg_b, s_a, s_b, seg_radius, tangent, bvec, ok, view, cam_pos, near, far, ortho_h,
           tan_half, width, height, tile, tri, count, boxes):
    """Per segment: cull, build the quad in view space, clip it against z = near, project; writes up to 4
    triangles (positively oriented on screen) into tri[k·S + seg] (S segments), their number into count[seg] and
    the span of tiles each overlaps into boxes[k·S + seg] = (first x, last x, first y, last y) (first x = −1: not on
    screen)."""
    aspect = width / height
    tan_x, tan_y = tan_half * aspect, tan_half
    cos_x, cos_y = 1.0 / math.sqrt(1.0 + tan_x * tan_x), 1.0 / math.sqrt(1.0 + tan_y * tan_y)
    n_seg = seg_a.shape[0]
    n_chunks = min(n_seg, 256)
    for chunk in prange(n_chunks):
        quad = np.empty((4, 8))  # corners in view space: x, y, z, s, v, tx, ty, tz
        poly = np.empty((4, 8))
        for g in range(chunk * n_seg // n_chunks, (chunk + 1) * n_seg // n_chunks):
            count[g] = 0
            a, b = seg_a[g], seg_b[g]
            if not (ok[a] and ok[b]):
                continue
            dx, dy, dz = points[b, 0] - points[a, 0], points[b, 1] - points[a, 1], points[b, 2] - points[a, 2]
            half = 0.5 * math.sqrt(dx * dx + dy * dy + dz * dz)
            if half == 0.0:
                continue
            r = seg_radius[g]
            sphere = r + half
            _to_view(view, points[a, 0] + 0.5 * dx - cam_pos[0], points[a, 1] + 0.5 * dy - cam_pos[1],
                     points[a, 2] + 0.5 * dz - cam_pos[2], quad[0])
            cx, cy, cz = quad[0, 0], quad[0, 1], quad[0, 2]
            if cz + sphere < near or cz - sphere > far:
                continue
            if ortho_h > 0.0:
                if abs(cx) - sphere > 0.5 * ortho_h * aspect or abs(cy) - sphere > 0.5 * ortho_h:
                    continue
            elif (abs(cx) - cz * tan_x) * cos_x > sphere or (abs(cy) - cz * tan_y) * cos_y > sphere:
                continue
            for k in range(4):
                p = b if k >= 2 else a
                side = 1.0 if k == 1 or k == 2 else -1.0
                _to_view(view, points[p, 0] + side * r * bvec[p, 0] - cam_pos[0],
                         points[p, 1] + side * r * bvec[p, 1] - cam_pos[1],
                         points[p, 2] + side * r * bvec[p, 2] - cam_pos[2], quad[k])
                quad[k, 3] = s_b[g] if k >= 2 else s_a[g]
                quad[k, 4] = side
                quad[k, 5], quad[k, 6], quad[k, 7] = tangent[p, 0], tangent[p, 1], tangent[p, 2]
            n_out = 0
            for half_quad in range(2):
                n_poly = 0
                for e in range(3):  # Sutherland-Hodgman against z >= near: triangle (0, 1, 2) or (0, 2, 3)
                    ia = 0 if e == 0 else e + half_quad
                    ib = 0 if e == 2 else e + 1 + half_quad
                    da, db = quad[ia, 2] - near, quad[ib, 2] - near
                    if da >= 0.0:
                        for m in range(8):  # element by element: a row assignment compiles a shape check
                            poly[n_poly, m] = quad[ia, m]
                        n_poly += 1
                    if (da >= 0.0) != (db >= 0.0):
                        f = da / (da - db)
                        for m in range(8):
                            poly[n_poly, m] = quad[ia, m] + f * (quad[ib, m] - quad[ia, m])
                        n_poly += 1
                for f in range(n_poly - 2):
                    slot = n_out * n_seg + g
                    if _emit(poly, f + 1, ortho_h, tan_half, width, height, tri[slot]):
                        rec = tri[slot]
                        boxes[slot, 0] = -1
                        x0, x1 = _pixel_span(rec[0, 0], rec[1, 0], rec[2, 0], 0, width)
                        y0, y1 = _pixel_span(rec[0, 1], rec[1, 1], rec[2, 1], 0, height)
                        if x0 < x1 and y0 < y1:
                            boxes[slot, 0], boxes[slot, 1] = x0 // tile, (x1 - 1) // tile
                            boxes[slot, 2], boxes[slot, 3] = y0 // tile, (y1 - 1) // tile
                        n_out += 1
            count[g] = n_out


@njit(cache=True, error_model="numpy")
def _emit(poly, i, ortho_h, tan_half, width, height, rec):
    """Project view-space triangle (poly[0], poly[i], poly[i + 1]) into rec (3, _NREC), oriented so its edge
    functions are positive inside; False if its screen area is zero or not finite."""
    for k in range(3):
        vtx = poly[0] if k == 0 else poly[i + k - 1]
        z = vtx[2]
        if ortho_h > 0.0:
            q, sx, sy = 1.0, 2.0 * vtx[0] / ortho_h, 2.0 * vtx[1] / ortho_h
        else:
            q = 1.0 / z
            sx, sy = vtx[0] * q / tan_half, vtx[1] * q / tan_half
        rec[k, 0] = 0.5 * (sx * height + width)
        rec[k, 1] = 0.5 * (1.0 - sy) * height
        rec[k, 2] = q
        rec[k, 3] = z * q
        for m in range(5):
            rec[k, 4 + m] = vtx[3 + m] * q
    area = _edge(rec[0, 0], rec[0, 1], rec[1, 0], rec[1, 1], rec[2, 0], rec[2, 1])
    if not (math.isfinite(area) and area != 0.0):
        return False
    if area < 0.0:
        for m in range(_NREC):
            rec[1, m], rec[2, m] = rec[2, m], rec[1, m]
    return True


@njit(cache=True, error_model="numpy")
def _edge_setup(ax, ay, bx, by):
    """Edge a→b as (base x, base y, dx, dy, sign, tie): its edge function at p is
    sign·((px − base x)·dy − (py − base y)·dx), positive on the interior side of a positively oriented triangle,
    evaluated from the lexicographically smaller end so that reversing the edge negates it exactly; tie (the
    top-left rule) says whether a sample exactly on the edge is inside, and is the opposite for the reversed edge."""
    tie = by - ay > 0.0 or (by == ay and bx < ax)
    if ax < bx or (ax == bx and ay <= by):
        return ax, ay, bx - ax, by - ay, 1.0, tie
    return bx, by, ax - bx, ay - by, -1.0, tie


@njit(cache=True, error_model="numpy")
def _row_limit(lo, hi, bx, by, slope, side, row):
    """Narrow the screen x range [lo, hi] (px, within the triangle's pixel span) to where the edge function of
    ``_edge_setup`` (base point (bx, by), slope dx/dy, side = sign·dy) can be ≥ 0 for some y in pixel row
    [row, row + 1]; padded so that it never excludes a sample."""
    if side == 0.0:
        return lo, hi
    xa, xb = (row - by) * slope, (row + 1.0 - by) * slope
    pad = 1e-9 * (1.0 + abs(bx) + abs(xa) + abs(xb))
    if side > 0.0:
        return min(max(lo, bx + min(xa, xb) - pad), hi), hi
    return lo, max(min(hi, bx + max(xa, xb) + pad), lo)


@njit(cache=True, error_model="numpy")
def _edge(ax, ay, bx, by, px, py):
    """The edge function of ``_edge_setup`` for edge a→b at p."""
    x, y, dx, dy, sign, _ = _edge_setup(ax, ay, bx, by)
    return sign * ((px - x) * dy - (py - y) * dx)


@njit(cache=True, error_model="numpy")
def _to_view(view, dx, dy, dz, out):
    """out[:3] = view @ (dx, dy, dz) (a world offset from the camera to view coordinates)."""
    for r in range(3):
        out[r] = view[r, 0] * dx + view[r, 1] * dy + view[r, 2] * dz


@njit(cache=True, error_model="numpy")
def _pixel_span(c0, c1, c2, lo, hi):
    """Pixel indices [first, end) within [lo, hi) whose cells meet [min(c), max(c)] (coordinates in px, clamped
    before rounding so huge off-screen values stay finite)."""
    first = int(math.floor(min(max(min(c0, c1, c2), lo), hi)))
    end = int(math.floor(min(max(max(c0, c1, c2), lo - 1.0), hi - 1.0))) + 1
    return first, end


@njit(cache=True, error_model="numpy")
def _bin(count, boxes, tiles_x, tiles_y):
    """Triangles (in slot order) overlapping each tile: tile t owns tile_tris[tile_start[t]:tile_start[t + 1]]."""
    n_seg = count.shape[0]
    valid = np.zeros(boxes.shape[0], np.bool_)
    for slot in range(boxes.shape[0]):
        valid[slot] = slot // n_seg < count[slot % n_seg] and boxes[slot, 0] >= 0
    per_tile = np.zeros(tiles_x * tiles_y + 1, np.int64)
    for slot in range(boxes.shape[0]):
        if valid[slot]:
            for ty in range(boxes[slot, 2], boxes[slot, 3] + 1):
                for tx in range(boxes[slot, 0], boxes[slot, 1] + 1):
                    per_tile[ty * tiles_x + tx + 1] += 1
    tile_start = np.cumsum(per_tile)
    fill = tile_start[:-1].copy()
    tile_tris = np.empty(tile_start[-1], np.int64)
    for slot in range(boxes.shape[0]):
        if valid[slot]:
            for ty in range(boxes[slot, 2], boxes[slot, 3] + 1):
                for tx in range(boxes[slot, 0], boxes[slot, 1] + 1):
                    t = ty * tiles_x + tx
                    tile_tris[fill[t]] = slot
                    fill[t] += 1
    return tile_start, tile_tris


@njit(cache=True, error_model="numpy")
def _depth_test(tri, tile_tris, first, stop, x_lo, y_lo, x_hi, y_hi, pattern, bound, bound_kind, best_z, best_tri):
    """Depth-test triangles tile_tris[first:stop] at the ``pattern`` samples of the pixels [x_lo, x_hi) × [y_lo,
    y_hi): for each sample the K nearest view z (1/q-interpolated), nearest first, and their triangle slots (−1:
    none), K = best_z.shape[3]. The barycentrics are e_k/area (``_barycentrics`` repeats the arithmetic for a kept
    sample). ``bound`` (a full-frame array of view z; unread with ``bound_kind`` NO_BOUND): with FLOOR a fragment
    counts only beyond it, view z > bound[py, px, s] (depth peeling); with CEILING only before it, view z <
    bound[py, px, s]."""
    k_samples = pattern.shape[0]
    n_keep = best_z.shape[3]
    best_z[:] = np.inf
    best_tri[:] = -1
    for idx in range(first, stop):
        slot = tile_tris[idx]
        rec = tri[slot]
        x0, y0, x1, y1, x2, y2 = rec[0, 0], rec[0, 1], rec[1, 0], rec[1, 1], rec[2, 0], rec[2, 1]
        bx0, by0, dx0, dy0, sg0, tie0 = _edge_setup(x1, y1, x2, y2)  # edges 1→2, 2→0, 0→1
        bx1, by1, dx1, dy1, sg1, tie1 = _edge_setup(x2, y2, x0, y0)
        bx2, by2, dx2, dy2, sg2, tie2 = _edge_setup(x0, y0, x1, y1)
        inv_area = 1.0 / (sg2 * ((x2 - bx2) * dy2 - (y2 - by2) * dx2))
        slope0 = dx0 / dy0 if dy0 != 0.0 else 0.0
        slope1 = dx1 / dy1 if dy1 != 0.0 else 0.0
        slope2 = dx2 / dy2 if dy2 != 0.0 else 0.0
        px_lo, px_hi = _pixel_span(x0, x1, x2, x_lo, x_hi)
        py_lo, py_hi = _pixel_span(y0, y1, y2, y_lo, y_hi)
        for py in range(py_lo, py_hi):
            lo, hi = float(px_lo), float(px_hi)
            lo, hi = _row_limit(lo, hi, bx0, by0, slope0, sg0 * dy0, py)
            lo, hi = _row_limit(lo, hi, bx1, by1, slope1, sg1 * dy1, py)
            lo, hi = _row_limit(lo, hi, bx2, by2, slope2, sg2 * dy2, py)
            for px in range(int(math.floor(lo)), min(int(math.floor(hi)) + 1, px_hi)):
                for s in range(k_samples):
                    sx, sy = px + pattern[s, 0], py + pattern[s, 1]
                    e0 = sg0 * ((sx - bx0) * dy0 - (sy - by0) * dx0)
                    if e0 < 0.0 or (e0 == 0.0 and not tie0):
                        continue
                    e1 = sg1 * ((sx - bx1) * dy1 - (sy - by1) * dx1)
                    if e1 < 0.0 or (e1 == 0.0 and not tie1):
                        continue
                    e2 = sg2 * ((sx - bx2) * dy2 - (sy - by2) * dx2)
                    if e2 < 0.0 or (e2 == 0.0 and not tie2):
                        continue
                    l0, l1, l2 = e0 * inv_area, e1 * inv_area, e2 * inv_area
                    z = (l0 * rec[0, 3] + l1 * rec[1, 3] + l2 * rec[2, 3]) / \
                        (l0 * rec[0, 2] + l1 * rec[1, 2] + l2 * rec[2, 2])
                    j, i = px - x_lo, py - y_lo
                    if bound_kind == FLOOR and z <= bound[py, px, s]:
                        continue
                    if bound_kind == CEILING and z >= bound[py, px, s]:
                        continue
                    if z < best_z[i, j, s, n_keep - 1]:  # insert into the sample's sorted list of the K nearest
                        m = n_keep - 1
                        while m > 0 and z < best_z[i, j, s, m - 1]:
                            best_z[i, j, s, m] = best_z[i, j, s, m - 1]
                            best_tri[i, j, s, m] = best_tri[i, j, s, m - 1]
                            m -= 1
                        best_z[i, j, s, m] = z
                        best_tri[i, j, s, m] = slot


@njit(cache=True, error_model="numpy")
def _sample_depth(z, px, py, pattern_s, width, height, ortho, tan_half):
    """Depth of a sample at view z: z itself orthographic, the distance to the camera for a pinhole."""
    if ortho:
        return z
    sx = (2.0 * (px + pattern_s[0]) - width) / height * tan_half
    sy = (1.0 - 2.0 * (py + pattern_s[1]) / height) * tan_half
    return z * math.sqrt(1.0 + sx * sx + sy * sy)


@njit(parallel=True, cache=True, error_model="numpy")
def _raster_depth(tri, tile_start, tile_tris, seg_curve, width, height, tile, tiles_x, pattern, ortho, tan_half,
                  bound, bound_kind, depth, curve):
    """``_raster``'s depth test alone: depth[py, px] of the nearest strip at the pixel's single sample, +inf where
    none covers it, and its curve in curve[py, px] (−1 none) unless ``curve`` has no rows. ``bound`` and
    ``bound_kind`` come as arguments (``_NO_BOUND``, ``NO_BOUND``), not as the module's constants: as constants Numba
    typed them as a read-only array and a literal 0 and compiled ``_depth_test`` a second time for them (~0.6 s of a
    cold first frame)."""
    n_tiles = tile_start.shape[0] - 1
    n_seg = seg_curve.shape[0]
    for t in prange(n_tiles):
        x_lo, y_lo = (t % tiles_x) * tile, (t // tiles_x) * tile
        x_hi, y_hi = min(x_lo + tile, width), min(y_lo + tile, height)
        best_z = np.empty((y_hi - y_lo, x_hi - x_lo, 1, 1))
        best_tri = np.empty((y_hi - y_lo, x_hi - x_lo, 1, 1), np.int64)
        _depth_test(tri, tile_tris, tile_start[t], tile_start[t + 1], x_lo, y_lo, x_hi, y_hi, pattern, bound,
                    bound_kind, best_z, best_tri)
        for i in range(y_hi - y_lo):
            for j in range(x_hi - x_lo):
                kept = best_tri[i, j, 0, 0]
                depth[y_lo + i, x_lo + j] = np.inf if kept < 0 else \
                    _sample_depth(best_z[i, j, 0, 0], x_lo + j, y_lo + i, pattern[0], width, height, ortho, tan_half)
                if curve.shape[0] > 0:
                    curve[y_lo + i, x_lo + j] = -1 if kept < 0 else seg_curve[kept % n_seg]


@njit(parallel=True, cache=True, error_model="numpy")
def _raster(tri, tile_start, tile_tris, seg_curve, width, height, tile, tiles_x, pattern, ortho, tan_half, bound,
            bound_kind, slot, curve, depth):
    """Depth-test every tile's triangles at the ``pattern`` samples and write the visibility buffers of its pixels:
    slot[m], curve[m] and depth[m] (each (K, H, W, k)) of the m-th nearest strip (``_depth_test``, its ``bound``)."""
    n_keep, k_samples = slot.shape[0], pattern.shape[0]
    n_tiles = tile_start.shape[0] - 1
    n_seg = seg_curve.shape[0]
    for t in prange(n_tiles):
        x_lo, y_lo = (t % tiles_x) * tile, (t // tiles_x) * tile
        x_hi, y_hi = min(x_lo + tile, width), min(y_lo + tile, height)
        best_z = np.empty((y_hi - y_lo, x_hi - x_lo, k_samples, n_keep))
        best_tri = np.empty((y_hi - y_lo, x_hi - x_lo, k_samples, n_keep), np.int64)
        _depth_test(tri, tile_tris, tile_start[t], tile_start[t + 1], x_lo, y_lo, x_hi, y_hi, pattern, bound,
                    bound_kind, best_z, best_tri)
        for m in range(n_keep):
            for i in range(y_hi - y_lo):
                for j in range(x_hi - x_lo):
                    py, px = y_lo + i, x_lo + j
                    for s in range(k_samples):
                        kept = best_tri[i, j, s, m]
                        slot[m, py, px, s] = kept
                        if kept < 0:
                            curve[m, py, px, s] = -1
                            depth[m, py, px, s] = 0.0
                        else:
                            curve[m, py, px, s] = seg_curve[kept % n_seg]
                            depth[m, py, px, s] = _sample_depth(best_z[i, j, s, m], px, py, pattern[s], width, height,
                                                                ortho, tan_half)


@njit(cache=True, error_model="numpy")
def _barycentrics(rec, sx, sy):
    """(l0, l1, l2) of the sample (sx, sy) px in the triangle ``rec``: ``_depth_test``'s arithmetic, so a kept
    sample gets the barycentrics its depth was interpolated with, bit for bit."""
    x0, y0, x1, y1, x2, y2 = rec[0, 0], rec[0, 1], rec[1, 0], rec[1, 1], rec[2, 0], rec[2, 1]
    bx0, by0, dx0, dy0, sg0, _ = _edge_setup(x1, y1, x2, y2)
    bx1, by1, dx1, dy1, sg1, _ = _edge_setup(x2, y2, x0, y0)
    bx2, by2, dx2, dy2, sg2, _ = _edge_setup(x0, y0, x1, y1)
    inv_area = 1.0 / (sg2 * ((x2 - bx2) * dy2 - (y2 - by2) * dx2))
    e0 = sg0 * ((sx - bx0) * dy0 - (sy - by0) * dx0)
    e1 = sg1 * ((sx - bx1) * dy1 - (sy - by1) * dx1)
    e2 = sg2 * ((sx - bx2) * dy2 - (sy - by2) * dx2)
    return e0 * inv_area, e1 * inv_area, e2 * inv_area


@njit(parallel=True, cache=True, error_model="numpy")
def _attributes(triangles, slot, row, col, sample, out):
    """``out`` (``SampleAttributes``): the interpolated attributes of the samples (row, col, sample) whose nearest
    triangle of ``triangles`` (``StripTriangles``) is ``slot``."""
    pattern, n_seg = triangles.pattern, triangles.seg_first.shape[0]
    yarn, segment, arclength, v, tangent = out  # bound before the loop: a parfor's writes through ``out.x[m]`` are lost
    for m in prange(slot.shape[0]):
        rec = triangles.records[slot[m]]
        l0, l1, l2 = _barycentrics(rec, col[m] + pattern[sample[m], 0], row[m] + pattern[sample[m], 1])
        inv_q = 1.0 / (l0 * rec[0, 2] + l1 * rec[1, 2] + l2 * rec[2, 2])
        g = slot[m] % n_seg
        yarn[m] = triangles.yarn_id[triangles.seg_curve[g]]
        segment[m] = triangles.seg_first[g]
        arclength[m] = (l0 * rec[0, 4] + l1 * rec[1, 4] + l2 * rec[2, 4]) * inv_q
        v[m] = min(max((l0 * rec[0, 5] + l1 * rec[1, 5] + l2 * rec[2, 5]) * inv_q, -1.0), 1.0)
        tx = l0 * rec[0, 6] + l1 * rec[1, 6] + l2 * rec[2, 6]
        ty = l0 * rec[0, 7] + l1 * rec[1, 7] + l2 * rec[2, 7]
        tz = l0 * rec[0, 8] + l1 * rec[1, 8] + l2 * rec[2, 8]
        norm = math.sqrt(tx * tx + ty * ty + tz * tz)
        if norm > 0.0:
            tx, ty, tz = tx / norm, ty / norm, tz / norm
        tangent[m, 0], tangent[m, 1], tangent[m, 2] = tx, ty, tz
