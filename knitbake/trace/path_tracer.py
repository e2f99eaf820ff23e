"""Path tracer over explicit fibers (the reference renderer and the bake's ground truth).

Design
------
* Two geometries (``TracerScene``). **Curves**: the fibers as Embree's round linear curves (``embree_curves``), and
  whole paths in one Numba kernel (``_trace_curves``: camera ray, hits, next-event estimation with its shadow rays,
  BCSDF sampling), ``prange`` over paths, no Python between rays. **Tubes** (the validation path): the fibers
  tessellated, and waves: all live paths advance one bounce per wave; Numba kernels generate camera rays, shade hits
  and write each path's own slots only; ``RayScene`` intersects the wave's rays on 2 Python threads (Embree
  releases the GIL). Both run the same scattering event (``_escaped``, ``_scatter``) with the same random numbers.
  No kernel runs while another Python thread runs one.
* Fibers scatter as far-field curves: at a hit on fiber f the BCSDF of f's yarn type (``knitrun.shading.fiber_bcsdf``)
  is evaluated in the frame of the hit segment's axis (x = tangent); the scattered or shadow ray leaves from the far
  side of that segment's tube (the point at the tube radius, at the hit's axial position, on the side the new
  direction points to), so a fiber never shadows or re-hits itself. This is the convention of a BCSDF, which
  already integrates over the fiber's width.
* Lights: directional lights (``direction`` toward the light, ``irradiance`` RGB on a plane facing it) and an
  optional environment (``env_light.EnvLight``). Environment NEE and BCSDF sampling are combined with the power
  heuristic; a directional light is a delta light (NEE only).
* Camera rays that miss see ``background`` (if None: the environment, else black). Paths that escape after a
  bounce see the environment (black without one).
* ``max_depth`` counts scattering events; Russian roulette from ``rr_depth`` on, survival probability
  min(0.95, max throughput). ``yarn_only_radius`` > 0 is the bake's "no global scattering" mode for a yarn along
  the z axis: a path that reaches geometry outside that cylinder ends there without scattering (no light it would
  bring back is counted; escaping to the environment is still counted). ``own_yarn`` is the reference's "no light
  between yarns" diagnostic: with the yarn (curve) of each fiber and the rest arc length σ of each fiber point along
  it, a path ends where it would scatter off another yarn than the one its camera ray hit, or off the same yarn more
  than ``reach`` of σ away (another part of a yarn that loops back: the strip renderer's yarn-level bounce counts
  those as neighbours, ``knitrun.render.yarn_bounce``). The light the yarns send each other is left out; they still
  block every shadow ray. The full image less this one is the light that reached the seen yarn through scattering
  by other yarns. ``first_seen`` (a bool per fiber type) is the "light by the surface seen first" diagnostic: a path
  whose camera ray first hits a fiber of a type it marks False ends there and counts nothing, so the image holds the
  light leaving the fibers of the other types toward the camera (a camera ray that misses sees the background in
  every image); the images of complementary masks sum to the full image and the background where camera rays miss
  (the same paths and random numbers). ``knitbake.trace.reference`` gives the flyaways their own types for it.
* Threads: ``_trace_curves`` runs ``prange`` over blocks of ``PATH_BLOCK`` paths, each block with its own scratch
  arrays (``scatter_scratch``; per-path arrays made the allocator 8 % of the render). Hot loops copy rows of the
  shared inputs (the BCSDF parameters, a light's direction) instead of taking views of them: a view bumps the
  shared array's reference count with an atomic instruction, and two cores bumping one count took 12 % of the
  render (``benchmarks/profile_tracer.py``, BENCHMARKS.md). For the same reason the per-event functions (here
  ``_scatter``, ``_escaped``, ``_leave_point``, ``_frame``, ``_to_local``; the BCSDF's ``context_into``,
  ``evaluate``, ``pdf``, ``sample``) are inlined by Numba (``inline='always'``): a call increfs and decrefs every
  array it is passed, and those pairs were 16 % of the render. The price is compile time, paid once per cache:
  the tracer's first use on an empty cache takes ~4 s longer (14 → 18 s) for ~10 % more rays/s.
* Determinism: every random number is a hash of (seed, path id, depth, dimension), path id = sample·pixels +
  pixel; results do not depend on thread count or batching.

Units: lengths in scene units; radiance in the lights' units. Images are (H, W, 3) float64 means over spp.
"""

from __future__ import annotations

import dataclasses
import math
import time
from dataclasses import dataclass, field

import numpy as np
from numba import njit, prange

from data_formats.scene import RENDER_FIELDS
from knitbake.fibers.fiber_set import FiberSet
from knitbake.fibers.tessellate import TubeMesh
from knitbake.trace.embree_curves import TFAR, CurveScene, any_hits, closest_hits, intersect, occluded, ray_buffer
from knitbake.trace.env_light import EnvLight, env_pdf, env_pixel, env_sample
from knitbake.trace.ray_scene import RayHits, RayScene
from knitrun.render.camera import Camera, tan_half_fov
from knitrun.shading.fiber_bcsdf import N_CONTEXT, N_PARAMS, context_into, evaluate, pdf, sample

_MASK = np.uint64(0xFFFFFFFFFFFFFFFF)
# Scattering events per path where a caller does not say: the scene format's default ``render.max_depth``, which the
# references use, so that the bake's traces (correction, closure, yarn hull) hold the orders of scattering the
# references hold. At 16 (the bake's until stop 66) a knitted course of cotton1 kept 5 % less multiple scattering
# than at 32 and 64 (BENCHMARKS.md, "Issue 13: the bake's paths as long as the reference's").
MAX_DEPTH = RENDER_FIELDS["max_depth"][0]


@dataclass
class TracerScene:
    """Everything the tracer needs: geometry, per-fiber material, lights. The geometry is either ``mesh``, the fibers
    tessellated into tubes (traced by waves through embreex), or the fibers as Embree's round linear curves, traced
    by whole paths in one kernel (``embree_curves``): ``fibers`` (their scene built here, then ``fibers`` is
    dropped) or ``curves`` (built by the caller); give one geometry."""

    mesh: TubeMesh | None
    fiber_type: np.ndarray  # (F,) int32 index into params
    params: np.ndarray  # (types, N_PARAMS) fiber BCSDF parameters
    light_dirs: np.ndarray = field(default_factory=lambda: np.zeros((0, 3)))  # toward the light, unit
    light_irradiance: np.ndarray = field(default_factory=lambda: np.zeros((0, 3)))
    env: EnvLight | None = None
    background: np.ndarray | None = None
    ray_scene: RayScene | None = None
    fibers: FiberSet | None = None
    curves: CurveScene | None = None

    def __post_init__(self):
        if self.fibers is not None and self.curves is None:
            self.curves = CurveScene(self.fibers)
        self.fibers = None  # Embree holds the curves' own copy: the FiberSet's float64 points need not stay alive
        if (self.mesh is None) == (self.curves is None):
            raise ValueError("TracerScene needs one geometry: a tube mesh, or fibers (or their curve scene)")
        if self.mesh is not None and self.ray_scene is None:
            self.ray_scene = RayScene(self.mesh)
        self.params = np.ascontiguousarray(self.params, dtype=np.float64).reshape(-1, N_PARAMS)
        self.light_dirs = np.asarray(self.light_dirs, float).reshape(-1, 3)
        norms = np.linalg.norm(self.light_dirs, axis=1, keepdims=True)
        if np.any(norms <= 0):
            raise ValueError("a directional light has a zero direction")
        self.light_dirs = self.light_dirs / norms
        self.light_irradiance = np.asarray(self.light_irradiance, float).reshape(-1, 3)

    def with_lights(self, light_dirs, light_irradiance) -> "TracerScene":
        """The same geometry (not rebuilt) and materials under other directional lights."""
        return dataclasses.replace(self, light_dirs=light_dirs, light_irradiance=light_irradiance)

    # geometry queries for the bake stages, the same for curves and tubes; "prim" is a curve segment or a triangle

    def intersect(self, origins, directions) -> RayHits:
        """First hits of N rays (``ray_scene.RayHits``; for curves ``prim`` is the segment, ``v`` = 0)."""
        if self.curves is None:
            return self.ray_scene.intersect(origins, directions)
        t, prim, normal, u = closest_hits(self.curves, origins, directions)
        hit = prim >= 0
        fiber = np.where(hit, self.curves.segment_fiber[np.maximum(prim, 0)], -1).astype(np.int32)
        return RayHits(t, prim.astype(np.int32), fiber, normal, u, np.zeros_like(u))

    def occluded(self, origins, directions, tmax=np.inf) -> np.ndarray:
        """Whether a fiber lies on each ray within ``tmax`` (bool (N,))."""
        if self.curves is None:
            return self.ray_scene.occluded(origins, directions, tmax)
        return any_hits(self.curves, origins, directions, tmax)

    def leave_points(self, prims, hits, dirs) -> np.ndarray:
        """Where a ray in each direction leaves the fiber hit at ``hits`` on ``prims`` (the tracer's own rule)."""
        out = np.empty_like(np.asarray(hits, float))
        prims = np.asarray(prims, np.int64)
        if self.curves is None:
            m = self.mesh
            leave_points(prims, hits, dirs, m.tri_fiber, m.tri_segment, m.axis_points, m.tube_radius, out)
        else:
            _leave_points_curves(prims, np.asarray(hits, float), np.asarray(dirs, float), self.curves.segment_start,
                                 self.curves.vertices, out)
        return out

    def fiber_tangents(self, prims) -> np.ndarray:
        """Unit fiber tangents of the hit segments (N, 3)."""
        prims = np.asarray(prims, np.int64)
        if self.curves is None:
            seg = self.mesh.tri_segment[prims]
            t = self.mesh.axis_points[seg + 1] - self.mesh.axis_points[seg]
        else:
            v = self.curves.segment_start[prims].astype(np.int64)
            t = self.curves.vertices[v + 1, :3].astype(np.float64) - self.curves.vertices[v, :3]
        return t / np.linalg.norm(t, axis=1, keepdims=True)


@dataclass
class RenderStats:
    rays: int = 0
    seconds: float = 0.0
    spp: int = 0

    @property
    def rays_per_second(self):
        return self.rays / self.seconds if self.seconds > 0 else 0.0


# --- random numbers ----------------------------------------------------------------------------------------------

@njit(cache=True)
def _mix(x):
    """splitmix64 finaliser."""
    x = (x ^ (x >> np.uint64(30))) * np.uint64(0xBF58476D1CE4E5B9)
    x = (x ^ (x >> np.uint64(27))) * np.uint64(0x94D049BB133111EB)
    return x ^ (x >> np.uint64(31))


@njit(cache=True)
def uniform(seed, path, depth, dim):
    """A uniform in [0, 1) from (seed, path, depth, dim), independent of evaluation order."""
    x = _mix(np.uint64(seed) * np.uint64(0x9E3779B97F4A7C15) + np.uint64(path))
    x = _mix(x + np.uint64(depth) * np.uint64(0xD1B54A32D192ED03) + np.uint64(dim))
    return float(x >> np.uint64(11)) * (1.0 / 9007199254740992.0)


# --- camera ------------------------------------------------------------------------------------------------------

@njit(cache=True)
def _camera_ray(pos, fwd, right, up, width, height, tan_half, ortho_h, seed, path, pix, org, d):
    """The camera ray of path ``path`` through pixel ``pix`` (jittered in the pixel by the path's random numbers)."""
    px = (pix % width + uniform(seed, path, 0, 0)) / width
    py = (pix // width + uniform(seed, path, 0, 1)) / height
    sx = (2.0 * px - 1.0) * width / height
    sy = 1.0 - 2.0 * py
    for k in range(3):
        if ortho_h > 0.0:
            org[k] = pos[k] + 0.5 * ortho_h * (sx * right[k] + sy * up[k])
            d[k] = fwd[k]
        else:
            org[k] = pos[k]
            d[k] = fwd[k] + tan_half * (sx * right[k] + sy * up[k])
    norm = math.sqrt(d[0] ** 2 + d[1] ** 2 + d[2] ** 2)
    for k in range(3):
        d[k] /= norm


@njit(parallel=True, cache=True)
def camera_rays(pos, fwd, right, up, width, height, tan_half, ortho_h, seed, first_sample, n_samples, org, dirs):
    n_pix = width * height
    for n in prange(n_samples * n_pix):
        pix = n % n_pix
        _camera_ray(pos, fwd, right, up, width, height, tan_half, ortho_h, seed, (first_sample + n // n_pix) * n_pix
                    + pix, pix, org[n], dirs[n])


# --- shading -----------------------------------------------------------------------------------------------------

@njit(cache=True, inline='always')
def _frame(t, e1, e2):
    """Writes into e1, e2 two unit vectors completing the unit tangent t to an orthonormal frame."""
    ax = 1.0 if abs(t[0]) < 0.9 else 0.0  # the helper axis a: x, or y when t is close to x
    ay = 1.0 - ax
    # e1 = a − (a·t) t term for term as the vector expression it replaced (zeros included: the same bits)
    dot = ax * t[0] + ay * t[1] + 0.0 * t[2]
    e1[0], e1[1], e1[2] = ax - dot * t[0], ay - dot * t[1], 0.0 - dot * t[2]
    norm = math.sqrt(e1[0] ** 2 + e1[1] ** 2 + e1[2] ** 2)
    for k in range(3):
        e1[k] /= norm
    e2[0] = t[1] * e1[2] - t[2] * e1[1]
    e2[1] = t[2] * e1[0] - t[0] * e1[2]
    e2[2] = t[0] * e1[1] - t[1] * e1[0]


@njit(cache=True, inline='always')
def _to_local(w, t, e1, e2, out):
    out[0] = w[0] * t[0] + w[1] * t[1] + w[2] * t[2]
    out[1] = w[0] * e1[0] + w[1] * e1[1] + w[2] * e1[2]
    out[2] = w[0] * e2[0] + w[1] * e2[1] + w[2] * e2[2]


@njit(cache=True, inline='always')
def _leave_point(axis_pt, t, radius, hit, w, out):
    """Start point for a ray in direction w leaving the tube (axis through axis_pt along t, given radius) from
    the side w points to, at the axial position of ``hit``."""
    s = (hit[0] - axis_pt[0]) * t[0] + (hit[1] - axis_pt[1]) * t[1] + (hit[2] - axis_pt[2]) * t[2]
    wt = w[0] * t[0] + w[1] * t[1] + w[2] * t[2]
    v0, v1, v2 = w[0] - wt * t[0], w[1] - wt * t[1], w[2] - wt * t[2]
    norm = v0 * v0 + v1 * v1 + v2 * v2
    if norm < 1e-18:  # along the axis: leave from the hit's own side
        v0 = hit[0] - axis_pt[0] - s * t[0]
        v1 = hit[1] - axis_pt[1] - s * t[1]
        v2 = hit[2] - axis_pt[2] - s * t[2]
        norm = v0 * v0 + v1 * v1 + v2 * v2
    norm = math.sqrt(max(norm, 1e-300))
    out[0] = axis_pt[0] + s * t[0] + radius * v0 / norm
    out[1] = axis_pt[1] + s * t[1] + radius * v1 / norm
    out[2] = axis_pt[2] + s * t[2] + radius * v2 / norm


@njit(parallel=True, cache=True)
def leave_points(prims, hits, dirs, tri_fiber, tri_segment, axis_points, tube_radius, out):
    """Batch form of the leave-point rule: out[n] is where a ray in direction dirs[n] leaves the fiber hit at
    hits[n] (triangle prims[n])."""
    for n in prange(prims.shape[0]):
        s = tri_segment[prims[n]]
        a = axis_points[s]
        t = axis_points[s + 1] - a
        t /= math.sqrt(t[0] ** 2 + t[1] ** 2 + t[2] ** 2)
        _leave_point(a, t, tube_radius[tri_fiber[prims[n]]] * 1.0001, hits[n], dirs[n], out[n])


@njit(cache=True, inline='always')
def _escaped(depth, d, throughput, prev_pdf, has_env, env_rad, env_prob, background, camera_background, radiance):
    """Radiance a path gathers when its ray (direction d) escapes: the background at depth 0 when the camera sees
    one, the environment otherwise (MIS-weighted against the BCSDF sample that sent it, of density prev_pdf)."""
    if depth == 0 and camera_background:
        for k in range(3):
            radiance[k] += throughput[k] * background[k]
    if has_env and (depth > 0 or not camera_background):
        r, c = env_pixel(env_rad, d)
        w = 1.0
        if prev_pdf > 0.0:
            pe = env_pdf(env_rad, env_prob, d)
            w = prev_pdf ** 2 / (prev_pdf ** 2 + pe * pe)
        for k in range(3):
            radiance[k] += throughput[k] * env_rad[r, c, k] * w


PATH_BLOCK = 64  # paths per prange iteration of ``_trace_curves``: they share one set of scratch arrays

# rows of the per-thread scratch that ``_scatter`` works in (``scatter_scratch``)
S_E1, S_E2, S_WO, S_WO_L, S_WI_L, S_WI, S_F = 0, 1, 2, 3, 4, 5, 6
N_SCRATCH_ROWS = 7


@njit(cache=True)
def scatter_scratch():
    """What ``_scatter`` writes its intermediates into: (rows ``S_*`` × 3, a BCSDF context). Kernels allocate one per
    thread's block of paths, not one per event: the allocator cost 8 % of the render (BENCHMARKS.md)."""
    return np.empty((N_SCRATCH_ROWS, 3)), np.empty(N_CONTEXT)


@njit(cache=True, inline='always')
def _scatter(seed, pid, depth, hit, d, a, t, rad, p, light_dirs, light_irr, has_env, env_rad, env_row, env_col,
             env_prob, rr_depth, throughput, shadow_org, shadow_dirs, shadow_val, new_org, new_dir, work, ctx):
    """A scattering event at ``hit`` on the fiber whose hit segment starts at ``a`` with unit tangent ``t`` (leave
    radius ``rad``), for a ray of direction ``d``: next-event estimation toward every light (row j of ``shadow_org``,
    ``shadow_dirs``, ``shadow_val``: the shadow ray and the radiance it brings if unblocked; the environment's in
    row ``len(light_dirs)``), then a BCSDF sample with Russian roulette, which updates ``throughput`` and writes the
    next ray. ``work``, ``ctx``: scratch (``scatter_scratch``). Returns the sample's density, or 0 when the path
    ends."""
    n_lights = light_dirs.shape[0]
    e1, e2 = work[S_E1], work[S_E2]
    _frame(t, e1, e2)
    wo = work[S_WO]
    for k in range(3):
        wo[k] = -d[k]
    wo_l = work[S_WO_L]
    _to_local(wo, t, e1, e2, wo_l)
    context_into(p, wo_l, ctx)
    wi_l = work[S_WI_L]
    fval = work[S_F]
    # next-event estimation: directional lights
    for j in range(n_lights):
        wl = work[S_WI]
        for k in range(3):  # a copy, not a view of the shared array (module docstring, "Threads")
            wl[k] = light_dirs[j, k]
        _to_local(wl, t, e1, e2, wi_l)
        evaluate(p, ctx, wi_l, fval)
        cos_i = math.sqrt(max(0.0, 1.0 - wi_l[0] * wi_l[0]))
        _leave_point(a, t, rad, hit, wl, shadow_org[j])
        for k in range(3):
            shadow_dirs[j, k] = light_dirs[j, k]
            shadow_val[j, k] = throughput[k] * fval[k] * cos_i * light_irr[j, k]
    # next-event estimation: environment (MIS with the BCSDF)
    if has_env:
        wi = work[S_WI]
        pe = env_sample(env_rad, env_row, env_col, env_prob, uniform(seed, pid, depth + 1, 0),
                        uniform(seed, pid, depth + 1, 1), uniform(seed, pid, depth + 1, 2),
                        uniform(seed, pid, depth + 1, 3), wi)
        if pe > 0.0:
            _to_local(wi, t, e1, e2, wi_l)
            evaluate(p, ctx, wi_l, fval)
            pb = pdf(p, ctx, wi_l)
            cos_i = math.sqrt(max(0.0, 1.0 - wi_l[0] * wi_l[0]))
            r, c = env_pixel(env_rad, wi)
            mis = pe * pe / (pe * pe + pb * pb)
            _leave_point(a, t, rad, hit, wi, shadow_org[n_lights])
            for k in range(3):
                shadow_dirs[n_lights, k] = wi[k]
                shadow_val[n_lights, k] = throughput[k] * fval[k] * cos_i * env_rad[r, c, k] * mis / pe
    # continue the path: sample the BCSDF
    pb = sample(p, ctx, uniform(seed, pid, depth + 1, 4), uniform(seed, pid, depth + 1, 5),
                uniform(seed, pid, depth + 1, 6), wi_l)
    if not pb > 0.0:
        return 0.0
    evaluate(p, ctx, wi_l, fval)
    cos_i = math.sqrt(max(0.0, 1.0 - wi_l[0] * wi_l[0]))
    best = 0.0
    for k in range(3):
        throughput[k] *= fval[k] * cos_i / pb
        best = max(best, throughput[k])
    if depth + 1 >= rr_depth:
        q = min(0.95, best)
        if uniform(seed, pid, depth + 1, 7) >= q:
            return 0.0
        for k in range(3):
            throughput[k] /= q
    for k in range(3):
        new_dir[k] = wi_l[0] * t[k] + wi_l[1] * e1[k] + wi_l[2] * e2[k]
    _leave_point(a, t, rad, hit, new_dir, new_org)
    return pb


@njit(parallel=True, cache=True)
def _leave_points_curves(prims, hits, dirs, segment_start, vertices, out):
    """``leave_points`` for fibers as curves: the segment's axis from its two vertices, its radius from the first."""
    for n in prange(prims.shape[0]):
        v = segment_start[prims[n]]
        a = vertices[v, :3].astype(np.float64)
        t = vertices[v + 1, :3].astype(np.float64) - a
        t /= math.sqrt(t[0] ** 2 + t[1] ** 2 + t[2] ** 2)
        _leave_point(a, t, float(vertices[v, 3]) * 1.0001, hits[n], dirs[n], out[n])


@njit(parallel=True, cache=True)
def _shade(seed, depth, scatter, path_id, org, dirs, hit_t, hit_prim, throughput, radiance, prev_pdf, tri_fiber,
           tri_segment, axis_points, tube_radius, fiber_type, params, light_dirs, light_irr, has_env, env_rad, env_row,
           env_col, env_prob, background, camera_background, rr_depth, yarn_only_r2, new_org, new_dirs, alive,
           shadow_org, shadow_dirs, shadow_val):
    """One wave of the tube tracer: escaped paths gather the environment/background (``_escaped``); hit paths (when
    ``scatter``) queue shadow rays for every light and sample their next direction (``_scatter``). Each path n
    writes only row n of every output."""
    for n in prange(org.shape[0]):
        alive[n] = False
        for j in range(shadow_val.shape[1]):
            for k in range(3):
                shadow_val[n, j, k] = 0.0
        d = dirs[n]
        if hit_prim[n] < 0:  # escaped
            _escaped(depth, d, throughput[n], prev_pdf[n], has_env, env_rad, env_prob, background, camera_background,
                     radiance[n])
            continue
        if not scatter:  # depth limit reached: a hit adds nothing and ends the path
            continue
        prim = hit_prim[n]
        f = tri_fiber[prim]
        s = tri_segment[prim]
        a = axis_points[s]
        t = axis_points[s + 1] - a
        t /= math.sqrt(t[0] ** 2 + t[1] ** 2 + t[2] ** 2)
        hit = np.empty(3)
        for k in range(3):
            hit[k] = org[n, k] + hit_t[n] * d[k]
        if yarn_only_r2 > 0.0 and hit[0] ** 2 + hit[1] ** 2 > yarn_only_r2:
            continue  # scattering outside the yarn's cylinder is global scattering: the path ends
        work, ctx = scatter_scratch()  # the tube path is the validation option: per-path scratch is fine here
        pb = _scatter(seed, path_id[n], depth, hit, d, a, t, tube_radius[f] * 1.0001, params[fiber_type[f]],
                      light_dirs, light_irr, has_env, env_rad, env_row, env_col, env_prob, rr_depth, throughput[n],
                      shadow_org[n], shadow_dirs[n], shadow_val[n], new_org[n], new_dirs[n], work, ctx)
        if pb > 0.0:
            prev_pdf[n] = pb
            alive[n] = True


@njit(parallel=True, cache=True)
def _trace_curves(scene, segment_start, segment_fiber, vertices, fiber_type, params, light_dirs, light_irr, has_env,
                  env_rad, env_row, env_col, env_prob, background, camera_background, pos, fwd, right, up, width,
                  height, tan_half, ortho_h, seed, first_sample, n_samples, max_depth, rr_depth, yarn_only_r2,
                  own_yarn, own_sigma, own_reach, first_seen, radiance, rays):
    """Whole paths over the fibers as Embree curves (``embree_curves``), one path per iteration, shadow rays traced
    as they are made: no Python between rays. Path n = sample·pixels + pixel writes ``radiance[n]`` and
    ``rays[n]`` (rays it traced). The same events and random numbers as the tube tracer's waves. ``own_yarn``: the
    yarn of each fiber, or empty; ``own_sigma`` the σ of each vertex, ``own_reach`` (module docstring). ``first_seen``
    (types,) bool: paths whose camera ray first hits a type marked False end there (module docstring)."""
    n_pix = width * height
    n_paths = n_samples * n_pix
    n_shadow = light_dirs.shape[0] + (1 if has_env else 0)
    for block in prange((n_paths + PATH_BLOCK - 1) // PATH_BLOCK):
        # scratch owned by this block of paths (each path overwrites it: the results do not depend on the blocking)
        buf = ray_buffer()
        work, ctx = scatter_scratch()
        p = np.empty(params.shape[1])
        vec = np.empty((8, 3))
        org, d, hit, a, t, new_org, new_dir, throughput = vec[0], vec[1], vec[2], vec[3], vec[4], vec[5], vec[6], \
            vec[7]
        out = np.empty(3)
        shadow_org, shadow_dirs = np.empty((max(n_shadow, 1), 3)), np.empty((max(n_shadow, 1), 3))
        shadow_val = np.empty((max(n_shadow, 1), 3))
        for n in range(block * PATH_BLOCK, min(n_paths, (block + 1) * PATH_BLOCK)):
            pix = n % n_pix
            pid = (first_sample + n // n_pix) * n_pix + pix
            _camera_ray(pos, fwd, right, up, width, height, tan_half, ortho_h, seed, pid, pix, org, d)
            for k in range(3):
                throughput[k] = 1.0
                out[k] = 0.0
            prev_pdf = 0.0
            traced = 0
            first_yarn, first_sigma = -1, 0.0
            for depth in range(max_depth + 1):
                prim = intersect(scene, buf, org[0], org[1], org[2], d[0], d[1], d[2], 0.0, np.inf)
                traced += 1
                if prim < 0:
                    _escaped(depth, d, throughput, prev_pdf, has_env, env_rad, env_prob, background,
                             camera_background, out)
                    break
                if depth == max_depth:
                    break
                for k in range(3):
                    hit[k] = org[k] + buf[TFAR] * d[k]
                if yarn_only_r2 > 0.0 and hit[0] ** 2 + hit[1] ** 2 > yarn_only_r2:
                    break
                if own_yarn.shape[0] > 0:  # light from other yarns left out (module docstring)
                    yarn, sigma = own_yarn[segment_fiber[prim]], own_sigma[segment_start[prim]]
                    if depth == 0:
                        first_yarn, first_sigma = yarn, sigma
                    elif yarn != first_yarn or abs(sigma - first_sigma) > own_reach:
                        break
                v = segment_start[prim]
                for k in range(3):
                    a[k] = np.float64(vertices[v, k])
                for k in range(3):
                    t[k] = np.float64(vertices[v + 1, k]) - a[k]
                norm = math.sqrt(t[0] ** 2 + t[1] ** 2 + t[2] ** 2)
                for k in range(3):
                    t[k] /= norm
                shadow_val[:] = 0.0
                ft = fiber_type[segment_fiber[prim]]
                if depth == 0 and not first_seen[ft]:  # the "surface seen first" diagnostic (module docstring)
                    break
                for k in range(p.shape[0]):  # a copy, not a view of the shared array (module docstring, "Threads")
                    p[k] = params[ft, k]
                pb = _scatter(seed, pid, depth, hit, d, a, t, float(vertices[v, 3]) * 1.0001, p, light_dirs,
                              light_irr, has_env, env_rad, env_row, env_col, env_prob, rr_depth, throughput,
                              shadow_org, shadow_dirs, shadow_val, new_org, new_dir, work, ctx)
                for j in range(n_shadow):
                    if shadow_val[j, 0] > 0.0 or shadow_val[j, 1] > 0.0 or shadow_val[j, 2] > 0.0:
                        traced += 1
                        if not occluded(scene, buf, shadow_org[j, 0], shadow_org[j, 1], shadow_org[j, 2],
                                        shadow_dirs[j, 0], shadow_dirs[j, 1], shadow_dirs[j, 2], 0.0, np.inf):
                            for k in range(3):
                                out[k] += shadow_val[j, k]
                if not pb > 0.0:
                    break
                for k in range(3):
                    org[k] = new_org[k]
                    d[k] = new_dir[k]
                prev_pdf = pb
            for k in range(3):
                radiance[n, k] = out[k]
            rays[n] = traced


def render(scene: TracerScene, camera: Camera, spp: int, seed: int = 0, max_depth: int = MAX_DEPTH, rr_depth: int = 3,
           yarn_only_radius: float = 0.0, samples_per_pass: int | None = None, progress=None):
    """Render ``spp`` samples per pixel; returns (image (H, W, 3), RenderStats). ``progress(done, total)`` is
    called after every pass of ``samples_per_pass`` samples per pixel."""
    total, stats = render_samples(scene, camera, 0, spp, seed, max_depth, rr_depth, yarn_only_radius,
                                  samples_per_pass, progress)
    return total / spp, stats


def render_samples(scene: TracerScene, camera: Camera, first_sample: int, spp: int, seed: int = 0,
                   max_depth: int = MAX_DEPTH, rr_depth: int = 3, yarn_only_radius: float = 0.0,
                   samples_per_pass: int | None = None, progress=None, own_yarn=None, first_seen=None):
    """The sum (H, W, 3) float64 of samples ``first_sample`` … ``first_sample + spp − 1`` of every pixel, added in
    sample order, and RenderStats: ``render`` is this over samples 0 … spp − 1, divided by spp. A sample's random
    numbers depend only on (seed, its index, pixel), so batches of samples can run anywhere (``knitbake.scale_out``).
    ``progress(done, spp)`` after every pass. ``own_yarn`` = (yarn of each fiber (F,), σ of each fiber point (P,),
    reach): no light between yarns (module docstring; fibers as curves only). ``first_seen`` (types,) bool or None (all
    True): only the light of paths whose camera ray first hits a fiber of a type marked True (module docstring;
    fibers as curves only)."""
    if spp < 1 or max_depth < 1 or first_sample < 0:
        raise ValueError(f"spp = {spp}, max_depth = {max_depth} must be ≥ 1, first_sample = {first_sample} ≥ 0")
    if own_yarn is not None and scene.curves is None:
        raise ValueError("own_yarn (no light between yarns) needs the fibers as curves, not tubes")
    n_types = scene.params.shape[0]
    seen = np.ones(n_types, np.bool_) if first_seen is None else np.asarray(first_seen, np.bool_).reshape(-1)
    if seen.shape[0] != n_types:
        raise ValueError(f"first_seen has {seen.shape[0]} entries for {n_types} fiber types")
    if not seen.all() and scene.curves is None:
        raise ValueError("first_seen (light by the surface seen first) needs the fibers as curves, not tubes")
    own = (np.zeros(0, np.int32), np.zeros(0), 0.0) if own_yarn is None else \
        (np.ascontiguousarray(own_yarn[0], np.int32), np.ascontiguousarray(own_yarn[1], np.float64),
         float(own_yarn[2]))
    w, h = int(camera.width), int(camera.height)
    n_pix = w * h
    if samples_per_pass is None:
        samples_per_pass = max(1, min(spp, (1 << 21) // n_pix))
    fwd, right, up = camera.basis()
    tan_half = tan_half_fov(camera)
    env = scene.env
    has_env = env is not None
    env_arrays = (env.radiance, env.row_cdf, env.col_cdf, env.pixel_prob) if has_env else \
        (np.zeros((1, 1, 3)), np.zeros(2), np.zeros((1, 2)), np.zeros((1, 1)))
    camera_background = scene.background is not None or not has_env
    background = np.zeros(3) if scene.background is None else np.asarray(scene.background, float)
    n_shadow = scene.light_dirs.shape[0] + (1 if has_env else 0)
    accum = np.zeros((n_pix, 3))
    stats = RenderStats()
    t_start = time.perf_counter()
    done, end = int(first_sample), int(first_sample) + spp
    while done < end:
        n_s = min(samples_per_pass, end - done)
        n = n_s * n_pix
        if scene.curves is not None:
            radiance, rays = np.empty((n, 3)), np.empty(n, np.int64)
            _trace_curves(scene.curves.handle, scene.curves.segment_start, scene.curves.segment_fiber,
                          scene.curves.vertices, scene.fiber_type, scene.params, scene.light_dirs,
                          scene.light_irradiance, has_env, *env_arrays, background, camera_background,
                          np.asarray(camera.position, float), fwd, right, up, w, h, tan_half,
                          float(camera.ortho_height), seed, done, n_s, max_depth, rr_depth,
                          float(yarn_only_radius) ** 2, *own, seen, radiance, rays)
            stats.rays += int(rays.sum())
            for sample_image in radiance.reshape(n_s, n_pix, 3):  # in sample order, as below
                accum += sample_image
            done += n_s
            if progress is not None:
                progress(done - first_sample, spp)
            continue
        org = np.empty((n, 3))
        dirs = np.empty((n, 3))
        camera_rays(np.asarray(camera.position, float), fwd, right, up, w, h, tan_half, float(camera.ortho_height),
                     seed, done, n_s, org, dirs)
        path_id = (done * n_pix + np.arange(n)).astype(np.int64)
        slot = np.arange(n)
        throughput = np.ones((n, 3))
        radiance = np.zeros((n, 3))
        prev_pdf = np.zeros(n)
        for depth in range(max_depth + 1):
            if slot.size == 0:
                break
            hits = scene.ray_scene.intersect(org, dirs)
            stats.rays += slot.size
            m = slot.size
            new_org, new_dirs = np.empty((m, 3)), np.empty((m, 3))
            alive = np.zeros(m, np.bool_)
            sh_org, sh_dirs, sh_val = np.empty((m, max(n_shadow, 1), 3)), np.empty((m, max(n_shadow, 1), 3)), \
                np.zeros((m, max(n_shadow, 1), 3))
            tp, rad, pp = throughput[slot], np.zeros((m, 3)), prev_pdf[slot]
            _shade(seed, depth, depth < max_depth, path_id[slot], org, dirs, hits.t, hits.prim.astype(np.int64), tp,
                   rad, pp,
                   scene.mesh.tri_fiber, scene.mesh.tri_segment, scene.mesh.axis_points, scene.mesh.tube_radius,
                   scene.fiber_type,
                   scene.params, scene.light_dirs, scene.light_irradiance, has_env, *env_arrays, background,
                   camera_background, rr_depth, float(yarn_only_radius) ** 2, new_org, new_dirs, alive, sh_org,
                   sh_dirs, sh_val)
            radiance[slot] += rad
            if n_shadow and depth < max_depth:
                live = np.any(sh_val[:, :n_shadow] > 0, axis=2)
                idx = np.nonzero(live)
                if idx[0].size:
                    blocked = scene.ray_scene.occluded(sh_org[idx], sh_dirs[idx], np.inf)
                    stats.rays += idx[0].size
                    contrib = np.where(blocked[:, None], 0.0, sh_val[idx])
                    np.add.at(radiance, slot[idx[0]], contrib)
            throughput[slot] = tp
            prev_pdf[slot] = pp
            slot = slot[alive]
            org, dirs = new_org[alive], new_dirs[alive]
        for sample_image in radiance.reshape(n_s, n_pix, 3):  # in sample order: the sum ignores the batching
            accum += sample_image
        done += n_s
        if progress is not None:
            progress(done - first_sample, spp)
    stats.seconds = time.perf_counter() - t_start
    stats.spp = spp
    return accum.reshape(h, w, 3), stats
