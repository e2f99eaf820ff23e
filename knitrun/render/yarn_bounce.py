"""Yarn-level multiple scattering under directional lights: the light neighbouring yarns scatter onto a yarn (beyond
Huang et al. 2025).

The baked tables describe one yarn alone: everything its own fibers do to a light, nothing the other yarns do but
block it (the shadow maps, ``shadow_map``). In a fabric the other yarns also scatter the light they intercept: a
cotton yarn returns ρ_Y ≈ 0.75 of the light around it (its hull albedo, ``knitbake.stages.yarn_hull``), and from a
yarn's surface in the example knit patch other yarns fill about half of the (cosine-weighted) hemisphere within a
stitch. Under an environment the inter-reflection of ``knitrun.render.interreflection`` returns that light per lobe;
under a directional light nothing did.

Model (derived here), per polyline vertex i of the yarn centre lines, at yarn level (tubes of radius r), for
directional lights of irradiance E_L toward ω_L:

* **What the neighbours cover.** A neighbouring segment j (another curve's, or this curve's with its midpoint more
  than ``reach`` of arc length away) seen from the vertex x is a strip of width 2r along its axis: with h its axis's
  distance from x (at least ``CONTACT_RADII``·r: tubes touch, they do not interpenetrate) and s_a < s_b its end
  points' positions along the axis from the foot of the perpendicular,

      Ω_ij = (2r / h) · (s_b / √(h² + s_b²) − s_a / √(h² + s_a²))          (∫ 2r sin β / d² along the segment)

  over the segments within ``reach`` = ``REACH_RADII``·r; Ω_i = Σ_j Ω_ij, and the fraction of the sphere they
  cover, overlaps counted as for randomly placed occluders, f_i = 1 − exp(−Ω_i / 4π). Each segment's share is
  w_ij = Ω_ij · 4π f_i / Ω_i (so Σ_j w_ij = 4π f_i).
* **A tube's phase.** A tube lit by a distant light of irradiance E at angle θ to its normal plane intercepts
  E·2r·cos θ per unit length. It scatters R_Y = ρ_Y − T_Y of it back toward the light's side and S_Y = T_Y − τ_Y
  forward through itself (``tube_optics``; ρ_Y and T_Y the pack's hull albedo and transmittance, ASSET_PACK.md §10,
  τ_Y its gap transmittance, ``yarn_look.gap_transmittance``). The rest of T_Y, τ_Y, is light that crossed between
  the fibers unscattered: it goes on along the light's direction, where the receiving yarn's own direct term
  already has it (``strip_shading.past_blockers`` lets τ_Y through a blocker), and toward the camera it is the
  layer behind the strip (``pipeline``, ``render.layers``), so it is not spread again here. (Spreading all of T_Y
  counted cotton's τ_Y ≈ 0.16 of its T_Y ≈ 0.46 twice: the white-yarn knit patches came out 10–18 % too bright
  with the bounce, BENCHMARKS.md "Issue 13: the default model of stop 49".) Each part is spread over the
  directions in the tube's normal plane as a Lambertian cylinder spreads its light: seen at angle α (in the normal
  plane) from the direction toward the light, the back-scattered part has radiance R_Y·E·cos θ/π² · g(α) and the
  forward part S_Y·E·cos θ/π² · g(π − α), with

      g(α) = (π/4) (sin α + (π − α) cos α),   α ∈ [0, π]                   (mean 1 over the circle; g(0) = π²/4)

  so the tube's mean scattered radiance over all directions is (ρ_Y − τ_Y)·E·cos θ/π²: in a uniform environment
  of radiance L it intercepts 2π² r L and scatters (ρ_Y − τ_Y) L, the hull albedo less what passes between its
  fibers. P(α) = R_Y g(α) + S_Y g(π − α) below.
* **Neighbour to receiver.** Segment j sends toward vertex i (direction d from j to i) the radiance
  L_ji = Σ_L E_L V_d cos θ_L P_j(α_jL) / π², α_jL the angle between ω_L and d in j's normal plane, V_d = V + (1 −
  V) τ_Y the light reaching j past the other yarns (``strip_shading.past_blockers``; the mean of j's two vertices).
* **Receiver to camera.** Vertex i receives L_ji over w_ij from −d and sends toward the camera (ω_o, in its normal
  plane at angle α'_ij from −d) what a tube lit by an irradiance L_ji w_ij from −d sends there:

      B_i = Σ_j w_ij L_ji cos θ'_ij P_i(α'_ij) / π² / (1 − ρ f_i)           (RGB)

  θ'_ij the angle of d to i's normal plane; the last factor adds the further bounces, self-similarly (the
  neighbours are among neighbours too: L_n = ē + ρ f L_n, ρ = R_Y + S_Y the scattered albedo).

The shading points take B interpolated along their curve by rest arc length (``bounce_at_points``) and add it to
their radiance before the fiber-level detail (``strip_shading.shade_regular``): a yarn-level term, not corrected by
ξ (which corrects the dual-scattering estimate of the light's own path). R_Y and T_Y per channel are the pack's,
in the entry's colour (``yarn_look.hull_colour``: read off the pack's curves against the colour, or the white
yarn's times the colour for a pack without them); a pack without ρ_Y and T_Y has no bounce. The environment takes none
here: its lobes' inter-reflection carries that light.

Implementation: what a pair needs that does not depend on the receiver (the segment's axis and length, mean
tangent, the light projected on its normal plane and what it sends, E V_d cos θ_L R_Y and … S_Y) is computed once
per segment (``_senders``); the segments are sorted by the cell of their midpoint on a uniform grid of cell
``reach`` (a counting sort), so a vertex finds every segment whose midpoint lies within reach in its own and the
26 neighbouring cells; each vertex's sums are its own (``prange`` over vertices, no shared output). Angles enter
the phase by their cosines (``lambert_pair``: one arc cosine per phase).
"""

from __future__ import annotations

import math
from typing import NamedTuple

import numpy as np
from numba import njit, prange


REACH_RADII = 8.0  # neighbours counted within this many yarn radii of a vertex (about one stitch of a knit)
CONTACT_RADII = 2.0  # the nearest a neighbouring axis counts: touching tubes
INV_PI2 = 1.0 / (math.pi * math.pi)


class BounceYarns(NamedTuple):
    """The polylines as the bounce kernel reads them: ``points`` (P, 3), ``tangent`` (P, 3) unit, ``curve`` (P,) int64
    curve of each vertex, ``offsets`` (C + 1,), ``rest`` (P,) rest arc length, ``radius`` (C,), ``reflect`` and
    ``transmit`` (P, 3) the tube's R_Y and S_Y at each vertex (in its colour, ``tube_optics``), ``toward_camera``
    (P, 3) unit."""

    points: np.ndarray
    tangent: np.ndarray
    curve: np.ndarray
    offsets: np.ndarray
    rest: np.ndarray
    radius: np.ndarray
    reflect: np.ndarray
    transmit: np.ndarray
    toward_camera: np.ndarray


def tube_optics(albedo, transmittance, gap):
    """(R_Y, S_Y): what a yarn tube scatters back toward a light's side, ρ_Y − T_Y, and forward through itself,
    T_Y − τ_Y (module docstring, "A tube's phase"), each clipped to [0, 1]. ``albedo`` ρ_Y and ``transmittance`` T_Y
    (…, 3) in the yarn's colour, ``gap`` τ_Y broadcastable to them: the light that crosses between the fibers
    unscattered, which the bounce does not spread again."""
    albedo, transmittance = np.asarray(albedo, np.float64), np.asarray(transmittance, np.float64)
    return np.clip(albedo - transmittance, 0.0, 1.0), np.clip(transmittance - gap, 0.0, 1.0)


class BounceLights(NamedTuple):
    """Directional lights: ``direction`` (L, 3) unit toward the light, ``irradiance`` (L, 3), ``direct`` (L, P) the
    light reaching each vertex past the other yarns (V_d)."""

    direction: np.ndarray
    irradiance: np.ndarray
    direct: np.ndarray


def vertex_bounce(yarns: BounceYarns, lights: BounceLights, reach_radii: float = REACH_RADII):
    """(B (P, 3), f (P,)): the bounce radiance toward the camera at each vertex and the fraction of its sphere the
    neighbours cover (module docstring). Zero where no neighbour lies within ``reach_radii`` radii."""
    n = len(yarns.points)
    out, covered = np.zeros((n, 3)), np.zeros(n)
    if n < 2 or len(yarns.radius) == 0 or len(lights.direction) == 0:
        return out, covered
    senders = _senders(yarns, lights, float(reach_radii * yarns.radius.max()))
    if len(senders.length):
        _vertex_bounce(yarns, senders, float(reach_radii), out, covered)
    return out, covered


class _Senders(NamedTuple):
    """The polyline segments j → j + 1 (within one curve) as senders, sorted by the cell of their midpoint on a grid
    of cell ``cell`` (S segments; ``cell_start`` (cells + 1,) the first segment of each cell by key (i·ny + j)·nz + k,
    ``dims`` (3,) the grid's cells per axis, ``origin`` (3,) its corner). Per segment: ``start`` (S, 3) its first
    point, ``axis`` (S, 3) unit and ``length``, ``mid`` (S, 3), ``tangent`` (S, 3) the mean of its vertices' tangents
    (normalised; zero where they cancel), ``curve``, ``rest_mid`` its midpoint's rest arc length, ``radius``; per
    light L, ``toward_light`` (S, L, 3) the light's direction projected on the segment's normal plane, unit (zero
    where the light runs along it), and what the segment sends toward a direction at angle α from it in that plane
    over the phase factors: ``back`` (S, L, 3) E V_d cos θ_L R_Y and ``forward`` E V_d cos θ_L S_Y (module docstring,
    "Neighbour to receiver"; the radiance is back·g(α) + forward·g(π − α)). Everything a pair needs that does not
    depend on the pair, computed once per segment instead of once per receiving vertex."""

    start: np.ndarray
    axis: np.ndarray
    length: np.ndarray
    mid: np.ndarray
    tangent: np.ndarray
    curve: np.ndarray
    rest_mid: np.ndarray
    radius: np.ndarray
    toward_light: np.ndarray
    back: np.ndarray
    forward: np.ndarray
    cell_start: np.ndarray
    dims: np.ndarray
    origin: np.ndarray
    cell: float


def _senders(yarns: BounceYarns, lights: BounceLights, cell: float) -> _Senders:
    """The segments of ``yarns`` as ``_Senders`` under ``lights``, on a grid of cell ``cell``."""
    j = np.flatnonzero(yarns.curve[:-1] == yarns.curve[1:]).astype(np.int64)  # segment j → j + 1 within a curve
    a, b = yarns.points[j], yarns.points[j + 1]
    length = np.linalg.norm(b - a, axis=1)
    axis = (b - a) / np.where(length > 0.0, length, 1.0)[:, None]
    mid = 0.5 * (a + b)
    tangent = yarns.tangent[j] + yarns.tangent[j + 1]
    norm = np.linalg.norm(tangent, axis=1, keepdims=True)
    tangent = np.where(norm > 0.0, tangent / np.where(norm > 0.0, norm, 1.0), tangent)
    light = np.asarray(lights.direction, np.float64)  # (L, 3)
    along = tangent @ light.T  # (S, L)
    across = light[None, :, :] - along[:, :, None] * tangent[:, None, :]  # (S, L, 3)
    cos_l = np.linalg.norm(across, axis=2)  # cos θ_L: the light's part normal to the segment
    lit = cos_l > 1e-12
    toward_light = np.where(lit[:, :, None], across / np.where(lit, cos_l, 1.0)[:, :, None], 0.0)
    direct = 0.5 * (lights.direct[:, j] + lights.direct[:, j + 1]).T  # (S, L) V_d, the mean of the two vertices
    power = np.where(lit, direct * cos_l, 0.0)[:, :, None] * np.asarray(lights.irradiance, np.float64)[None]
    back = power * (0.5 * (yarns.reflect[j] + yarns.reflect[j + 1]))[:, None, :]
    forward = power * (0.5 * (yarns.transmit[j] + yarns.transmit[j + 1]))[:, None, :]
    origin = mid.min(axis=0) if len(j) else np.zeros(3)
    ijk = np.floor((mid - origin) / cell).astype(np.int64)
    dims = ijk.max(axis=0) + 1 if len(j) else np.ones(3, np.int64)
    key = (ijk[:, 0] * dims[1] + ijk[:, 1]) * dims[2] + ijk[:, 2]
    order = np.argsort(key, kind="stable")
    cell_start = np.zeros(int(dims.prod()) + 1, np.int64)
    np.cumsum(np.bincount(key, minlength=int(dims.prod())), out=cell_start[1:])
    curve = yarns.curve[j]

    def c(x):
        return np.ascontiguousarray(x[order])

    return _Senders(c(a), c(axis), c(length), c(mid), c(tangent), c(curve).astype(np.int64),
                    c(0.5 * (yarns.rest[j] + yarns.rest[j + 1])), c(yarns.radius[curve]), c(toward_light), c(back),
                    c(forward), cell_start, dims.astype(np.int64), origin, float(cell))


@njit(cache=True)
def segment_solid_angle(x, a, b, width, nearest):
    """Solid angle of a strip of ``width`` along the segment a → b seen from x (module docstring), its axis's distance
    from x taken as at least ``nearest``; 0 for a segment of zero length."""
    u0, u1, u2 = b[0] - a[0], b[1] - a[1], b[2] - a[2]
    length = math.sqrt(u0 * u0 + u1 * u1 + u2 * u2)
    if length <= 0.0:
        return 0.0
    return _strip_solid_angle(x[0] - a[0], x[1] - a[1], x[2] - a[2], u0 / length, u1 / length, u2 / length, length,
                              width, nearest)


@njit(cache=True)
def _strip_solid_angle(x0, x1, x2, u0, u1, u2, length, width, nearest):
    """``segment_solid_angle`` from x − a (x0, x1, x2), the unit axis u and the length."""
    s_a = -(x0 * u0 + x1 * u1 + x2 * u2)
    p0, p1, p2 = -x0 - s_a * u0, -x1 - s_a * u1, -x2 - s_a * u2
    h = max(math.sqrt(p0 * p0 + p1 * p1 + p2 * p2), nearest)
    s_b = s_a + length
    return width / h * (s_b / math.sqrt(h * h + s_b * s_b) - s_a / math.sqrt(h * h + s_a * s_a))


@njit(cache=True)
def lambert_pair(cos_alpha):
    """(g(α), g(π − α)) from cos α, α ∈ [0, π]: the radiance of a Lambertian cylinder seen at α from its light over
    its mean, g(α) = (π/4)(sin α + (π − α) cos α) (module docstring), and at π − α, the back and forward parts of a
    tube's phase from one arc cosine (sin(π − α) = sin α, cos(π − α) = −cos α)."""
    c = min(max(cos_alpha, -1.0), 1.0)
    alpha, sin_a = math.acos(c), math.sqrt(1.0 - c * c)
    return 0.25 * math.pi * (sin_a + (math.pi - alpha) * c), 0.25 * math.pi * (sin_a - alpha * c)


@njit(cache=True)
def _cos_across(t0, t1, t2, d0, d1, d2, w0, w1, w2):
    """(|d projected on the normal plane of t|, the cosine of the angle between that projection and ``w``, a unit
    vector in the plane; 2 when the projection vanishes: no angle)."""
    c = d0 * t0 + d1 * t1 + d2 * t2
    a0, a1, a2 = d0 - c * t0, d1 - c * t1, d2 - c * t2
    na = math.sqrt(a0 * a0 + a1 * a1 + a2 * a2)
    if na < 1e-12:
        return na, 2.0
    return na, (a0 * w0 + a1 * w1 + a2 * w2) / na


@njit(parallel=True, cache=True)
def _vertex_bounce(yarns, senders, reach_radii, out, covered):
    points, tangent, curve = yarns.points, yarns.tangent, yarns.curve
    dims, cell = senders.dims, senders.cell
    for i in prange(points.shape[0]):
        c = curve[i]
        reach = reach_radii * yarns.radius[c]
        x0, x1, x2 = points[i, 0], points[i, 1], points[i, 2]
        ti0, ti1, ti2 = tangent[i, 0], tangent[i, 1], tangent[i, 2]
        # the view projected on the receiver's normal plane, unit (the receiver's phase angle is measured from it)
        v0, v1, v2 = yarns.toward_camera[i, 0], yarns.toward_camera[i, 1], yarns.toward_camera[i, 2]
        e = v0 * ti0 + v1 * ti1 + v2 * ti2
        v0, v1, v2 = v0 - e * ti0, v1 - e * ti1, v2 - e * ti2
        nv = math.sqrt(v0 * v0 + v1 * v1 + v2 * v2)
        seen = nv >= 1e-12  # a view along the yarn: no phase angle, the vertex sends nothing toward the camera
        if seen:
            v0, v1, v2 = v0 / nv, v1 / nv, v2 / nv
        r0, r1, r2 = yarns.reflect[i, 0], yarns.reflect[i, 1], yarns.reflect[i, 2]
        f0, f1, f2 = yarns.transmit[i, 0], yarns.transmit[i, 1], yarns.transmit[i, 2]
        gi = int(math.floor((x0 - senders.origin[0]) / cell))
        gj = int(math.floor((x1 - senders.origin[1]) / cell))
        gk = int(math.floor((x2 - senders.origin[2]) / cell))
        total, s0, s1, s2 = 0.0, 0.0, 0.0, 0.0
        for ci in range(max(gi - 1, 0), min(gi + 2, dims[0])):
            for cj in range(max(gj - 1, 0), min(gj + 2, dims[1])):
                for ck in range(max(gk - 1, 0), min(gk + 2, dims[2])):
                    key = (ci * dims[1] + cj) * dims[2] + ck
                    for m in range(senders.cell_start[key], senders.cell_start[key + 1]):
                        cn = senders.curve[m]
                        if cn == c and abs(senders.rest_mid[m] - yarns.rest[i]) < reach:
                            continue  # this yarn itself, locally: the baked tables' part
                        d0 = x0 - senders.mid[m, 0]  # from the neighbour to i
                        d1 = x1 - senders.mid[m, 1]
                        d2 = x2 - senders.mid[m, 2]
                        dist = math.sqrt(d0 * d0 + d1 * d1 + d2 * d2)
                        if dist > reach or dist <= 0.0 or senders.length[m] <= 0.0:
                            continue
                        rn = senders.radius[m]
                        w = _strip_solid_angle(x0 - senders.start[m, 0], x1 - senders.start[m, 1],
                                               x2 - senders.start[m, 2], senders.axis[m, 0], senders.axis[m, 1],
                                               senders.axis[m, 2], senders.length[m], 2.0 * rn, CONTACT_RADII * rn)
                        if not w > 0.0:
                            continue
                        total += w
                        if not seen:
                            continue
                        d0, d1, d2 = d0 / dist, d1 / dist, d2 / dist
                        # the receiver: light from −d, seen from the view
                        cos_r, cos_alpha_r = _cos_across(ti0, ti1, ti2, -d0, -d1, -d2, v0, v1, v2)
                        if cos_alpha_r > 1.5:
                            continue
                        g_r, g_rf = lambert_pair(cos_alpha_r)
                        tj0, tj1, tj2 = senders.tangent[m, 0], senders.tangent[m, 1], senders.tangent[m, 2]
                        for light in range(senders.back.shape[1]):
                            _, cos_alpha_l = _cos_across(tj0, tj1, tj2, d0, d1, d2, senders.toward_light[m, light, 0],
                                                         senders.toward_light[m, light, 1],
                                                         senders.toward_light[m, light, 2])
                            if cos_alpha_l > 1.5:
                                continue
                            g_l, g_lf = lambert_pair(cos_alpha_l)
                            k = w * cos_r
                            s0 += k * (senders.back[m, light, 0] * g_l + senders.forward[m, light, 0] * g_lf) * (
                                r0 * g_r + f0 * g_rf)
                            s1 += k * (senders.back[m, light, 1] * g_l + senders.forward[m, light, 1] * g_lf) * (
                                r1 * g_r + f1 * g_rf)
                            s2 += k * (senders.back[m, light, 2] * g_l + senders.forward[m, light, 2] * g_lf) * (
                                r2 * g_r + f2 * g_rf)
        if total <= 0.0:
            continue
        f = -math.expm1(-total / (4.0 * math.pi))
        covered[i] = f
        share = 4.0 * math.pi * f / total * INV_PI2 * INV_PI2
        out[i, 0] = s0 * share / max(1.0 - min(max(r0 + f0, 0.0), 1.0) * f, 1e-6)
        out[i, 1] = s1 * share / max(1.0 - min(max(r1 + f1, 0.0), 1.0) * f, 1e-6)
        out[i, 2] = s2 * share / max(1.0 - min(max(r2 + f2, 0.0), 1.0) * f, 1e-6)


@njit(parallel=True, cache=True)
def bounce_at_points(segment, arclength, rest, vertex, out):
    """out[k] (N, C): the per-vertex ``vertex`` (P, C) values interpolated at shading point k by rest arc length along
    its polyline segment ``segment[k]`` (vertex index of its start). The bounce's radiance (C = 3), and any other
    per-vertex value (``hair_canopy``'s transmittance, C = 1)."""
    for k in prange(segment.shape[0]):
        i = segment[k]
        ds = rest[i + 1] - rest[i]
        f = min(max((arclength[k] - rest[i]) / ds, 0.0), 1.0) if ds > 0.0 else 0.0
        for ch in range(vertex.shape[1]):
            out[k, ch] = (1.0 - f) * vertex[i, ch] + f * vertex[i + 1, ch]
