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
* **A tube's phase.** Φ(ω_i → ω_o; t) is the mean radiance over a yarn's projected width seen from ω_o when a
  distant light of unit irradiance shines on it from ω_i, by the angles of ``fiber_frame`` (θ_i, θ_o, φ against the
  tangent t): the pack's ``correction/radiance_view`` averaged over v (ASSET_PACK.md §6: the bake's straight yarn,
  path traced, every order of scattering, the light that crosses between the fibers not in it), in the entry's
  colour (``yarn_look.tube_phase``). Where the pack lacks it, the phase of a Lambertian cylinder that scatters
  R_Y = ρ_Y − T_Y back toward the light's side and S_Y = T_Y − τ_Y forward through itself (``tube_optics``,
  ``lambert_phase``):

      Φ = cos θ_i (R_Y g(|φ|) + S_Y g(π − |φ|)) / π²,   g(α) = (π/4) (sin α + (π − α) cos α)   (mean 1 over α)

  Both send, over all directions, the tube's hull albedo less the light between its fibers, ρ_Y − τ_Y (cotton1
  standard: the table's ∫Φ dω_i, cos²-weighted over θ_o, 0.60 / 0.56 / 0.46 against ρ_Y − τ_Y = 0.62 / 0.58 / 0.48),
  but not alike: cotton's fibers send more sideways and less straight back than a Lambertian cylinder (at φ = 90°,
  θ = 0: 0.070 against 0.050), and a neighbour sits beside a yarn, its light arriving from the side. With the
  Lambertian phase the bounce was 0.27–0.46 of the light two parallel or crossing yarns send each other in the
  reference and 0.45–0.56 of the example patches' (BENCHMARKS.md, stop 70). τ_Y, the light that crosses between
  the fibers unscattered, goes on along the light's direction, where the receiving yarn's own direct term already
  has it (``strip_shading.past_blockers`` lets τ_Y through a blocker); spreading it again counted it twice
  (BENCHMARKS.md "Issue 13: the default model of stop 49").
* **Neighbour to receiver.** Segment j sends toward vertex i (direction d from j to i) the radiance
  L_ji = Σ_L E_L V_d Φ_j(ω_L → d), V_d = V + (1 − V) τ_Y the light reaching j past the other yarns
  (``strip_shading.past_blockers``; the mean of j's two vertices).
* **Receiver to camera.** Vertex i receives L_ji over w_ij from −d and sends toward the camera ω_o what a tube lit
  by an irradiance L_ji w_ij from −d sends there:

      B_i = Σ_j w_ij L_ji Φ_i(−d → ω_o) / (1 − ρ f_i)           (RGB)

  the last factor adds the further bounces, self-similarly (the neighbours are among neighbours too: L_n = ē + ρ f
  L_n, ρ = R_Y + S_Y the scattered albedo).

The shading points take B interpolated along their curve by rest arc length (``bounce_at_points``) and add it to
their radiance before the fiber-level detail (``strip_shading.shade_regular``): a yarn-level term, not corrected by
ξ (which corrects the dual-scattering estimate of the light's own path). R_Y and T_Y per channel are the pack's,
in the entry's colour (``yarn_look.hull_colour``: read off the pack's curves against the colour, or the white
yarn's times the colour for a pack without them); a pack without ρ_Y and T_Y has no bounce. The environment takes none
here: its lobes' inter-reflection carries that light.

Implementation: what a pair needs that does not depend on the receiver (the segment's axis and length, mean
tangent, its yarn's phase table, each light's θ_i and E V_d) is computed once per segment (``sender_segments``); the
phase tables of every yarn entry share one grid (``PHASE_THETA`` × ``PHASE_THETA`` × ``PHASE_PHI`` cells,
``phase_grid``) and are read trilinearly by the pack's interpolation rule (``phase_at``, ``table_lookup.axis_cell``);
the segments are sorted by the cell of their midpoint on a uniform grid of cell ``reach`` (a counting sort), so a
vertex finds every segment whose midpoint lies within reach in its own and the 26 neighbouring cells; each vertex's
sums are its own (``prange`` over vertices, no shared output). The GL backend runs the same sums in a compute shader
on these inputs (``knitrun.render.gl.gl_bounce``).

**Hairs.** The sum without the receiver's phase, I_i = Σ_j w_ij L_ji / (1 − ρ f_i), is the neighbours' light
arriving at vertex i over all directions: the hairs of the flyaway layer take it (``strip_shading.hair_bounce``,
``Features.hair_bounce``).
"""

from __future__ import annotations

import math
from typing import NamedTuple

import numpy as np
from numba import njit, prange

from data_formats.conventions import PHI_RANGE, THETA_RANGE, cell_centres
from knitrun.shading.fiber_frame import azimuth_difference, longitudinal_angle
from knitrun.shading.table_lookup import axis_cell, lookup_axis

REACH_RADII = 8.0  # neighbours counted within this many yarn radii of a vertex (about one stitch of a knit)
CONTACT_RADII = 2.0  # the nearest a neighbouring axis counts: touching tubes
INV_PI2 = 1.0 / (math.pi * math.pi)
PHASE_THETA = 33  # cells per θ axis of the shared phase grid (a standard pack's 17 and a draft's 9 fall on it)
PHASE_PHI = 36  # cells of its φ axis (10° each)


class BounceYarns(NamedTuple):
    """The polylines as the bounce kernel reads them: ``points`` (P, 3), ``tangent`` (P, 3) unit, ``curve`` (P,) int64
    curve of each vertex, ``offsets`` (C + 1,), ``rest`` (P,) rest arc length, ``radius`` (C,), ``scattered`` (P, 3)
    the tube's scattered albedo R_Y + S_Y at each vertex (in its colour, ``tube_optics``), ``toward_camera`` (P, 3)
    unit, ``phase`` (K, ``PHASE_THETA``, ``PHASE_THETA``, ``PHASE_PHI``, 3) the tube phases Φ on the shared grid
    (``phase_grid``; axes θ_i, θ_o, φ, channel) and ``phase_of`` (C,) int64 each curve's."""

    points: np.ndarray
    tangent: np.ndarray
    curve: np.ndarray
    offsets: np.ndarray
    rest: np.ndarray
    radius: np.ndarray
    scattered: np.ndarray
    toward_camera: np.ndarray
    phase: np.ndarray
    phase_of: np.ndarray


def tube_optics(albedo, transmittance, gap):
    """(R_Y, S_Y): what a yarn tube scatters back toward a light's side, ρ_Y − T_Y, and forward through itself,
    T_Y − τ_Y (module docstring, "A tube's phase"), each clipped to [0, 1]. ``albedo`` ρ_Y and ``transmittance`` T_Y
    (…, 3) in the yarn's colour, ``gap`` τ_Y broadcastable to them: the light that crosses between the fibers
    unscattered, which the bounce does not spread again."""
    albedo, transmittance = np.asarray(albedo, np.float64), np.asarray(transmittance, np.float64)
    return np.clip(albedo - transmittance, 0.0, 1.0), np.clip(transmittance - gap, 0.0, 1.0)


def lambert_phase(reflect, transmit) -> np.ndarray:
    """(``PHASE_THETA``, ``PHASE_THETA``, ``PHASE_PHI``, 3): the phase Φ of a Lambertian cylinder that scatters
    ``reflect`` R_Y (3,) back toward the light's side and ``transmit`` S_Y (3,) forward (module docstring), at the
    shared grid's cell centres: the bounce's phase for a pack without ``correction/radiance_view``."""
    theta = cell_centres(*THETA_RANGE, PHASE_THETA)
    alpha = np.abs(cell_centres(*PHI_RANGE, PHASE_PHI))
    g = np.array([lambert_pair(math.cos(a)) for a in alpha])  # (N_φ, 2): g(|φ|), g(π − |φ|)
    lobe = g[:, :1] * np.asarray(reflect, np.float64) + g[:, 1:] * np.asarray(transmit, np.float64)  # (N_φ, 3)
    out = np.cos(theta)[:, None, None, None] * lobe[None, None] * INV_PI2
    return np.ascontiguousarray(np.broadcast_to(out, (PHASE_THETA, PHASE_THETA, PHASE_PHI, 3)))


def phase_grid(table) -> np.ndarray:
    """A phase table (N_θi, N_θo, N_φ, 3) on any grid of cell centres (θ over ``THETA_RANGE``, clamp; φ over
    ``PHI_RANGE``, repeat) resampled to the shared grid's centres by the pack's interpolation rule."""
    out = np.asarray(table, np.float64)
    for axis, (n, lo, hi, wrap) in enumerate(((PHASE_THETA, *THETA_RANGE, "clamp"),
                                              (PHASE_THETA, *THETA_RANGE, "clamp"),
                                              (PHASE_PHI, *PHI_RANGE, "repeat"))):
        moved = np.moveaxis(out, axis, 0)
        out = np.moveaxis(lookup_axis(moved, cell_centres(lo, hi, n), lo, hi, wrap), 0, axis)
    return np.ascontiguousarray(out)


@njit(cache=True)
def phase_at(table, theta_i, theta_o, phi, out):
    """out[:3] = the phase ``table`` (``PHASE_THETA``, ``PHASE_THETA``, ``PHASE_PHI``, 3) at (θ_i, θ_o, φ), trilinear
    by ASSET_PACK.md §4.3 (θ clamp, φ repeat)."""
    a0, a1, fa = axis_cell(theta_i, THETA_RANGE[0], THETA_RANGE[1], table.shape[0], False)
    b0, b1, fb = axis_cell(theta_o, THETA_RANGE[0], THETA_RANGE[1], table.shape[1], False)
    c0, c1, fc = axis_cell(phi, PHI_RANGE[0], PHI_RANGE[1], table.shape[2], True)
    for ch in range(3):
        lo = ((1.0 - fb) * ((1.0 - fc) * table[a0, b0, c0, ch] + fc * table[a0, b0, c1, ch]) +
              fb * ((1.0 - fc) * table[a0, b1, c0, ch] + fc * table[a0, b1, c1, ch]))
        hi = ((1.0 - fb) * ((1.0 - fc) * table[a1, b0, c0, ch] + fc * table[a1, b0, c1, ch]) +
              fb * ((1.0 - fc) * table[a1, b1, c0, ch] + fc * table[a1, b1, c1, ch]))
        out[ch] = (1.0 - fa) * lo + fa * hi


class BounceLights(NamedTuple):
    """Directional lights: ``direction`` (L, 3) unit toward the light, ``irradiance`` (L, 3), ``direct`` (L, P) the
    light reaching each vertex past the other yarns (V_d)."""

    direction: np.ndarray
    irradiance: np.ndarray
    direct: np.ndarray


def vertex_bounce(yarns: BounceYarns, lights: BounceLights, reach_radii: float = REACH_RADII):
    """(B (P, 3), f (P,), I (P, 3)): the bounce radiance toward the camera at each vertex, the fraction of its sphere
    the neighbours cover and the neighbours' light arriving there over all directions, I = Σ_j w_ij L_ji / (1 − ρ f)
    (module docstring, "Hairs"). Zero where no neighbour lies within ``reach_radii`` radii."""
    n = len(yarns.points)
    out, covered, arriving = np.zeros((n, 3)), np.zeros(n), np.zeros((n, 3))
    if n < 2 or len(yarns.radius) == 0 or len(lights.direction) == 0:
        return out, covered, arriving
    senders = sender_segments(yarns, lights, float(reach_radii * yarns.radius.max()))
    if len(senders.length):
        _vertex_bounce(yarns, senders, np.ascontiguousarray(lights.direction, np.float64), float(reach_radii), out,
                       covered, arriving)
    return out, covered, arriving


class SenderSegments(NamedTuple):
    """The polyline segments j → j + 1 (within one curve) as senders, sorted by the cell of their midpoint on a grid
    of cell ``cell`` (S segments; ``cell_start`` (cells + 1,) the first segment of each cell by key (i·ny + j)·nz + k,
    ``dims`` (3,) the grid's cells per axis, ``origin`` (3,) its corner). Per segment: ``start`` (S, 3) its first
    point, ``axis`` (S, 3) unit and ``length``, ``mid`` (S, 3), ``tangent`` (S, 3) the mean of its vertices' tangents
    (normalised; zero where they cancel), ``curve``, ``rest_mid`` its midpoint's rest arc length, ``radius``,
    ``phase_of`` its yarn's phase table; per light L, ``theta_light`` (S, L) the light's θ_i against the tangent and
    ``power`` (S, L, 3) E V_d (module docstring, "Neighbour to receiver": the radiance it sends toward d is
    power · Φ(θ_i, θ_d, φ)). Everything a pair needs that does not depend on the pair, computed once per segment
    instead of once per receiving vertex."""

    start: np.ndarray
    axis: np.ndarray
    length: np.ndarray
    mid: np.ndarray
    tangent: np.ndarray
    curve: np.ndarray
    rest_mid: np.ndarray
    radius: np.ndarray
    phase_of: np.ndarray
    theta_light: np.ndarray
    power: np.ndarray
    cell_start: np.ndarray
    dims: np.ndarray
    origin: np.ndarray
    cell: float


def sender_segments(yarns: BounceYarns, lights: BounceLights, cell: float) -> SenderSegments:
    """The segments of ``yarns`` as ``SenderSegments`` under ``lights``, on a grid of cell ``cell``."""
    j = np.flatnonzero(yarns.curve[:-1] == yarns.curve[1:]).astype(np.int64)  # segment j → j + 1 within a curve
    a, b = yarns.points[j], yarns.points[j + 1]
    length = np.linalg.norm(b - a, axis=1)
    axis = (b - a) / np.where(length > 0.0, length, 1.0)[:, None]
    mid = 0.5 * (a + b)
    tangent = yarns.tangent[j] + yarns.tangent[j + 1]
    norm = np.linalg.norm(tangent, axis=1, keepdims=True)
    tangent = np.where(norm > 0.0, tangent / np.where(norm > 0.0, norm, 1.0), tangent)
    light = np.asarray(lights.direction, np.float64)  # (L, 3)
    theta_light = np.arcsin(np.clip(tangent @ light.T, -1.0, 1.0))  # (S, L)
    direct = 0.5 * (lights.direct[:, j] + lights.direct[:, j + 1]).T  # (S, L) V_d, the mean of the two vertices
    power = direct[:, :, None] * np.asarray(lights.irradiance, np.float64)[None]
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

    return SenderSegments(c(a), c(axis), c(length), c(mid), c(tangent), c(curve).astype(np.int64),
                    c(0.5 * (yarns.rest[j] + yarns.rest[j + 1])), c(yarns.radius[curve]),
                    c(np.asarray(yarns.phase_of, np.int64)[curve]), c(theta_light), c(power), cell_start,
                    dims.astype(np.int64), origin, float(cell))


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


@njit(parallel=True, cache=True)
def _vertex_bounce(yarns, senders, light_dir, reach_radii, out, covered, arriving):
    points, tangent, curve = yarns.points, yarns.tangent, yarns.curve
    dims, cell = senders.dims, senders.cell
    for i in prange(points.shape[0]):
        c = curve[i]
        reach = reach_radii * yarns.radius[c]
        x0, x1, x2 = points[i, 0], points[i, 1], points[i, 2]
        ti = tangent[i]
        view = yarns.toward_camera[i]
        theta_view = longitudinal_angle(ti, view)
        received = yarns.phase[yarns.phase_of[c]]
        sent_phase, seen_phase = np.empty(3), np.empty(3)
        toward = np.empty(3)  # from i toward the neighbour, −d: where its light comes from
        away = np.empty(3)  # d, from the neighbour toward i
        gi = int(math.floor((x0 - senders.origin[0]) / cell))
        gj = int(math.floor((x1 - senders.origin[1]) / cell))
        gk = int(math.floor((x2 - senders.origin[2]) / cell))
        total, s0, s1, s2, a0, a1, a2 = 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0
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
                        away[0], away[1], away[2] = d0 / dist, d1 / dist, d2 / dist
                        toward[0], toward[1], toward[2] = -away[0], -away[1], -away[2]
                        # the receiver: lit from −d, seen from the view
                        phase_at(received, longitudinal_angle(ti, toward), theta_view,
                                 azimuth_difference(ti, view, toward), seen_phase)
                        tj = senders.tangent[m]
                        sent = yarns.phase[senders.phase_of[m]]
                        theta_d = longitudinal_angle(tj, away)
                        for light in range(senders.power.shape[1]):
                            wl = light_dir[light]
                            # what the neighbour sends toward i: lit from the light, seen from d
                            phase_at(sent, senders.theta_light[m, light], theta_d,
                                     azimuth_difference(tj, away, wl), sent_phase)
                            e0 = w * senders.power[m, light, 0] * sent_phase[0]
                            e1 = w * senders.power[m, light, 1] * sent_phase[1]
                            e2 = w * senders.power[m, light, 2] * sent_phase[2]
                            a0, a1, a2 = a0 + e0, a1 + e1, a2 + e2
                            s0, s1, s2 = s0 + e0 * seen_phase[0], s1 + e1 * seen_phase[1], s2 + e2 * seen_phase[2]
        if total <= 0.0:
            continue
        f = -math.expm1(-total / (4.0 * math.pi))
        covered[i] = f
        share = 4.0 * math.pi * f / total
        rho = yarns.scattered[i]
        k0 = share / max(1.0 - min(max(rho[0], 0.0), 1.0) * f, 1e-6)
        k1 = share / max(1.0 - min(max(rho[1], 0.0), 1.0) * f, 1e-6)
        k2 = share / max(1.0 - min(max(rho[2], 0.0), 1.0) * f, 1e-6)
        out[i, 0], out[i, 1], out[i, 2] = s0 * k0, s1 * k1, s2 * k2
        arriving[i, 0], arriving[i, 1], arriving[i, 2] = a0 * k0, a1 * k1, a2 * k2


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
