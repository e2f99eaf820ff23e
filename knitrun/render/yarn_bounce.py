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

Neighbours are found on a uniform grid of cell ``reach`` (a counting sort of the vertices by cell); each vertex's
sums are its own (``prange`` over vertices, no shared output).
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
    cell = float(reach_radii * yarns.radius.max())
    ijk = np.floor((yarns.points - yarns.points.min(axis=0)) / cell).astype(np.int64)
    dims = ijk.max(axis=0) + 1
    key = (ijk[:, 0] * dims[1] + ijk[:, 1]) * dims[2] + ijk[:, 2]
    order = np.argsort(key, kind="stable")
    start = np.zeros(int(dims.prod()) + 1, np.int64)
    np.cumsum(np.bincount(key, minlength=int(dims.prod())), out=start[1:])
    _vertex_bounce(yarns, lights, ijk, dims, order, start, float(reach_radii), out, covered)
    return out, covered


@njit(cache=True)
def segment_solid_angle(x, a, b, width, nearest):
    """Solid angle of a strip of ``width`` along the segment a → b seen from x (module docstring), its axis's distance
    from x taken as at least ``nearest``; 0 for a segment of zero length."""
    u0, u1, u2 = b[0] - a[0], b[1] - a[1], b[2] - a[2]
    length = math.sqrt(u0 * u0 + u1 * u1 + u2 * u2)
    if length <= 0.0:
        return 0.0
    u0, u1, u2 = u0 / length, u1 / length, u2 / length
    d0, d1, d2 = a[0] - x[0], a[1] - x[1], a[2] - x[2]
    s_a = d0 * u0 + d1 * u1 + d2 * u2
    p0, p1, p2 = d0 - s_a * u0, d1 - s_a * u1, d2 - s_a * u2
    h = max(math.sqrt(p0 * p0 + p1 * p1 + p2 * p2), nearest)
    s_b = s_a + length
    return width / h * (s_b / math.sqrt(h * h + s_b * s_b) - s_a / math.sqrt(h * h + s_a * s_a))


@njit(cache=True)
def lambert_pair(alpha):
    """(g(α), g(π − α)), α ∈ [0, π]: the radiance of a Lambertian cylinder seen at α from its light over its mean,
    g(α) = (π/4)(sin α + (π − α) cos α) (module docstring), and at π − α, the back and forward parts of a tube's
    phase from one sine and cosine (sin(π − α) = sin α, cos(π − α) = −cos α)."""
    sin_a, cos_a = math.sin(alpha), math.cos(alpha)
    return 0.25 * math.pi * (sin_a + (math.pi - alpha) * cos_a), 0.25 * math.pi * (sin_a - alpha * cos_a)


@njit(cache=True)
def _across(t0, t1, t2, d0, d1, d2, w0, w1, w2):
    """(cos θ of d to the normal plane of t, the angle between d and w projected into that plane; −1 when either
    projection vanishes)."""
    c = d0 * t0 + d1 * t1 + d2 * t2
    a0, a1, a2 = d0 - c * t0, d1 - c * t1, d2 - c * t2
    e = w0 * t0 + w1 * t1 + w2 * t2
    b0, b1, b2 = w0 - e * t0, w1 - e * t1, w2 - e * t2
    na, nb = math.sqrt(a0 * a0 + a1 * a1 + a2 * a2), math.sqrt(b0 * b0 + b1 * b1 + b2 * b2)
    if na < 1e-12 or nb < 1e-12:
        return na, -1.0
    cos_angle = min(max((a0 * b0 + a1 * b1 + a2 * b2) / (na * nb), -1.0), 1.0)
    return na, math.acos(cos_angle)


@njit(parallel=True, cache=True)
def _vertex_bounce(yarns, lights, ijk, dims, order, start, reach_radii, out, covered):
    points, tangent, curve, offsets, rest = yarns.points, yarns.tangent, yarns.curve, yarns.offsets, yarns.rest
    for i in prange(points.shape[0]):
        c = curve[i]
        reach = reach_radii * yarns.radius[c]
        ti0, ti1, ti2 = tangent[i, 0], tangent[i, 1], tangent[i, 2]
        v0, v1, v2 = yarns.toward_camera[i, 0], yarns.toward_camera[i, 1], yarns.toward_camera[i, 2]
        total, s0, s1, s2 = 0.0, 0.0, 0.0, 0.0
        for di in range(-1, 2):
            ci = ijk[i, 0] + di
            if ci < 0 or ci >= dims[0]:
                continue
            for dj in range(-1, 2):
                cj = ijk[i, 1] + dj
                if cj < 0 or cj >= dims[1]:
                    continue
                for dk in range(-1, 2):
                    ck = ijk[i, 2] + dk
                    if ck < 0 or ck >= dims[2]:
                        continue
                    key = (ci * dims[1] + cj) * dims[2] + ck
                    for m in range(start[key], start[key + 1]):
                        j = order[m]  # segment j → j + 1, if it is one
                        cn = curve[j]
                        if j + 1 >= offsets[cn + 1]:
                            continue
                        if cn == c and abs(0.5 * (rest[j] + rest[j + 1]) - rest[i]) < reach:
                            continue  # this yarn itself, locally: the baked tables' part
                        d0 = points[i, 0] - 0.5 * (points[j, 0] + points[j + 1, 0])  # from the neighbour to i
                        d1 = points[i, 1] - 0.5 * (points[j, 1] + points[j + 1, 1])
                        d2 = points[i, 2] - 0.5 * (points[j, 2] + points[j + 1, 2])
                        dist = math.sqrt(d0 * d0 + d1 * d1 + d2 * d2)
                        if dist > reach or dist <= 0.0:
                            continue
                        rn = yarns.radius[cn]
                        w = segment_solid_angle(points[i], points[j], points[j + 1], 2.0 * rn, CONTACT_RADII * rn)
                        if not w > 0.0:
                            continue
                        total += w
                        d0, d1, d2 = d0 / dist, d1 / dist, d2 / dist
                        tj0 = tangent[j, 0] + tangent[j + 1, 0]
                        tj1 = tangent[j, 1] + tangent[j + 1, 1]
                        tj2 = tangent[j, 2] + tangent[j + 1, 2]
                        norm = math.sqrt(tj0 * tj0 + tj1 * tj1 + tj2 * tj2)
                        if norm > 0.0:
                            tj0, tj1, tj2 = tj0 / norm, tj1 / norm, tj2 / norm
                        # the receiver: light from −d, seen from the view
                        cos_r, alpha_r = _across(ti0, ti1, ti2, -d0, -d1, -d2, v0, v1, v2)
                        if alpha_r < 0.0:
                            continue
                        g_r, g_rf = lambert_pair(alpha_r)
                        for light in range(lights.direction.shape[0]):
                            l0, l1, l2 = (lights.direction[light, 0], lights.direction[light, 1],
                                          lights.direction[light, 2])
                            cos_l, alpha_l = _across(tj0, tj1, tj2, l0, l1, l2, d0, d1, d2)
                            if alpha_l < 0.0:
                                continue
                            lit = 0.5 * (lights.direct[light, j] + lights.direct[light, j + 1]) * cos_l
                            g_l, g_lf = lambert_pair(alpha_l)
                            for ch in range(3):
                                sent = lights.irradiance[light, ch] * lit * (
                                    0.5 * (yarns.reflect[j, ch] + yarns.reflect[j + 1, ch]) * g_l
                                    + 0.5 * (yarns.transmit[j, ch] + yarns.transmit[j + 1, ch]) * g_lf)
                                back = w * sent * cos_r * (yarns.reflect[i, ch] * g_r + yarns.transmit[i, ch] * g_rf)
                                if ch == 0:
                                    s0 += back
                                elif ch == 1:
                                    s1 += back
                                else:
                                    s2 += back
        if total <= 0.0:
            continue
        f = -math.expm1(-total / (4.0 * math.pi))
        covered[i] = f
        share = 4.0 * math.pi * f / total * INV_PI2 * INV_PI2
        for ch, s in ((0, s0), (1, s1), (2, s2)):
            rho = min(max(yarns.reflect[i, ch] + yarns.transmit[i, ch], 0.0), 1.0)
            out[i, ch] = s * share / max(1.0 - rho * f, 1e-6)


@njit(parallel=True, cache=True)
def bounce_at_points(segment, arclength, rest, vertex, out):
    """out[k] (N, 3): the per-vertex ``vertex`` (P, 3) values interpolated at shading point k by rest arc length along
    its polyline segment ``segment[k]`` (vertex index of its start)."""
    for k in prange(segment.shape[0]):
        i = segment[k]
        ds = rest[i + 1] - rest[i]
        f = min(max((arclength[k] - rest[i]) / ds, 0.0), 1.0) if ds > 0.0 else 0.0
        for ch in range(3):
            out[k, ch] = (1.0 - f) * vertex[i, ch] + f * vertex[i + 1, ch]
