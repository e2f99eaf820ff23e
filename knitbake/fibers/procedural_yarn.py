"""Procedural fibers of a straight yarn (Zhao et al. 2016 as in Wu and Yuksel 2019 §2.2/§3.1; flyaways after Huang et
al. 2025 §4.4).

Conventions
-----------
* Yarn space, lengths in the spec's units: the yarn axis is +z. Angles grow counter-clockwise seen from +z looking
  back at the origin; a ``*_clockwise`` flag flips the sense of that twist.
* Ply j has centre angle ψ_j(z) = 2πj/K ± 2πz/α_yarn, centre c_j = d·(cos ψ_j, sin ψ_j, z), normal
  N_j = (cos ψ_j, sin ψ_j, 0) and binormal B_j = ẑ × N_j. A regular fiber at angle χ(z) = χ_0 ± 2πz/α_f and
  normalised radius R(z) = R_i/2·(ρ_max + ρ_min + (ρ_max − ρ_min)·cos(φ_0 + 2π s z/α_f)) sits at
  c_j + R(z)·(e_N cos χ N_j + e_B sin χ B_j), with (e_B, e_N) = ``ply_semi_axes``; R_i by rejection sampling of
  p(R) on the unit disk, χ_0 and φ_0 uniform.
* The **period** is one ply-twist pitch α_yarn. Regular fibers tile seamlessly across it: the state (R_i, χ, φ)
  a fiber reaches at the end of a period is paired, by an optimal assignment per ply, with the start state of a
  fiber of the same ply (``info["successor"]``), and each fiber absorbs the small mismatch (ΔR, Δχ, Δφ) linearly
  over the period. A fiber of a long yarn therefore follows a chain of period members; its mean pitch stays α_f
  (``info["fiber_pitch_change_mean"]`` reports the deviation) and its radius changes by at most
  ``info["radius_change_max"]`` per period — a slow extra migration.
* Flyaways are not periodic. Loops: a Poisson process of rate ρ_loop per ply along z; each follows a host fiber for
  one migration cycle (α_f/s long) with its radius raised smoothly to ``loop_radius`` (absolute distance from the
  ply centre) and back. Hairs: a Poisson process of rate ρ_hair per ply; Huang et al. 2025 eqs. 12–13 in the ply frame,
  R(t) = R_0 + R_e(1 − (1 − t)^α), θ(t) = θ_0 + θ_e t, z(t) = z_0 + z_e t, then the direction of progress of each
  segment takes a random walk of ``hair_direction_noise`` rad per unit t (segment lengths kept).
* Deterministic for a seed whatever the thread count: every random number is drawn up front from one numpy
  PCG64 stream; the Numba kernel only evaluates positions, each fiber into its own output rows.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit, prange

from data_formats.memory_budget import check_memory
from data_formats.yarn_spec import YarnSpec
from knitbake.fibers.fiber_set import KIND_HAIR, KIND_LOOP, KIND_REGULAR, FiberSet

SEGMENTS_PER_TURN = 24  # default sampling: segments per full turn of a fiber around the yarn axis
FLYAWAY_POINTS = 17  # points per loop or hair polyline
FLYAWAY_STREAM = 0x666C79  # the flyaways' own random stream: SeedSequence([seed, FLYAWAY_STREAM, flyaway_seed])
# peak bytes of generate_fibers per item, bounds of what tracemalloc measured on cotton1 (48 B per regular point;
# 5.4 KiB per hair, 3.0 KiB per loop): checked against the memory budget before anything is allocated
REGULAR_POINT_BYTES = 64
FLYAWAY_BYTES = 6144


def density(r, eps, beta):
    """Cross-section density p(R) of Wu and Yuksel 2019 / Zhao et al. 2016 on the unit disk (R in [0, 1], p ≤ 1)."""
    r = np.asarray(r, dtype=float)
    return (1 - 2 * eps) * ((math.e - np.exp(r)) / (math.e - 1)) ** beta + eps


def sample_radii(rng: np.random.Generator, n: int, eps: float, beta: float) -> np.ndarray:
    """n fiber-centre radii by rejection sampling: uniform on the unit disk, accepted with probability p(R)."""
    out = np.empty(0)
    while out.size < n:
        m = 2 * (n - out.size) + 16
        r = np.sqrt(rng.random(m))
        out = np.concatenate([out, r[rng.random(m) < density(r, eps, beta)]])
    return out[:n]


def _wrap(a):
    """Angle to (−π, π]."""
    return np.pi - np.mod(np.pi - a, 2 * np.pi)


def match_period(r0, chi0, phase0, chi_turn, phase_turn, migration_amplitude):
    """Pair each fiber's state at the end of a period with a fiber's start state (one ply).

    A fiber state (R, χ, φ) is the 4-vector R·(cos χ, sin χ, a cos φ, a sin φ), a the migration amplitude; the
    pairing minimises the summed squared distance (optimal assignment) plus λ·Σ Δχ, with the multiplier λ found by
    bisection so that the mean twist mismatch Σ Δχ / m is as close to zero as the pairing allows (it keeps the mean
    fiber pitch at α_f). Returns the successor of every fiber and the (ΔR, Δχ, Δφ) each fiber absorbs over the
    period to end exactly on its successor's start."""
    from scipy.optimize import linear_sum_assignment

    def vec(r, chi, phi):
        return np.stack([r * np.cos(chi), r * np.sin(chi), r * migration_amplitude * np.cos(phi),
                         r * migration_amplitude * np.sin(phi)], axis=-1)

    dist2 = ((vec(r0, chi0 + chi_turn, phase0 + phase_turn)[:, None, :] - vec(r0, chi0, phase0)[None]) ** 2).sum(-1)
    d_chi = _wrap(chi0[None, :] - chi0[:, None] - chi_turn)  # [i, j]: twist fiber i absorbs if j follows it
    rows = np.arange(r0.size)

    def solve(lam):
        succ = linear_sum_assignment(dist2 + lam * d_chi)[1]
        return succ, float(d_chi[rows, succ].mean())

    best = solve(0.0)
    lo, hi = -4.0, 4.0  # dist2 ≤ 4·(1 + a²); |λ| = 4 dominates it
    for _ in range(40):
        if abs(best[1]) < 1e-12:
            break
        mid = 0.5 * (lo + hi)
        cand = solve(mid)
        if abs(cand[1]) < abs(best[1]):
            best = cand
        lo, hi = (mid, hi) if cand[1] > 0 else (lo, mid)
    succ = best[0]
    return succ, r0[succ] - r0, d_chi[rows, succ], _wrap(phase0[succ] - phase0 - phase_turn)


def _segments(spec: YarnSpec, length: float, segments_per_period: int | None) -> int:
    """Segments of each regular fiber over ``length`` (``generate_fibers`` explains the default sampling)."""
    g = spec.geometry
    if segments_per_period is None:
        turns = g.ply_pitch / min(g.fiber_pitch, g.ply_pitch) + 1.0
        segments_per_period = max(32, int(math.ceil(SEGMENTS_PER_TURN * turns)))
    return max(1, int(math.ceil(length / g.ply_pitch * segments_per_period - 1e-9)))


def check_fiber_budget(spec: YarnSpec, length: float, segments_per_period: int | None = None,
                       flyaways: bool = True) -> None:
    """Refuse (FormatError, one line naming the fields) a window whose fibers would not fit in memory
    (``data_formats.memory_budget``); ``generate_fibers`` calls it before allocating, bakes before their first stage.
    """
    g, fl = spec.geometry, spec.flyaways
    n_seg = _segments(spec, length, segments_per_period)
    fibers = g.plies * g.fibers_per_ply
    flyaway_count = (fl.hair_density + fl.loop_density) * length * g.plies if flyaways else 0.0
    regular = float(fibers) * (n_seg + 1) * REGULAR_POINT_BYTES
    causes = (f"{g.plies} plies × fibers_per_ply {g.fibers_per_ply} × {n_seg + 1} points: {length / g.ply_pitch:.3g} "
              f"periods of ply_pitch {g.ply_pitch:g} at {n_seg / (length / g.ply_pitch):.3g} points per period from "
              f"ply_pitch/fiber_pitch = {g.ply_pitch / g.fiber_pitch:.3g} turns")
    if flyaway_count * FLYAWAY_BYTES > regular:
        causes = (f"~{flyaway_count:.3g} flyaways: (hair_density {fl.hair_density:g} + loop_density "
                  f"{fl.loop_density:g}) × {length:g} {spec.units} × {g.plies} plies")
    check_memory(regular + flyaway_count * FLYAWAY_BYTES, f"the fibers of {spec.name!r} over {length:.4g} "
                 f"{spec.units}", causes)


@njit(cache=True)
def _member_offset(zp, u, r0, chi0, phase0, d_r, d_chi, d_phase, e_b, e_n, fiber_rate, mig_rate, rho_min,
                   rho_max):
    """(N, B) offset from the ply centre of a regular fiber member, at z' = z − period start, u = z'/period."""
    chi = chi0 + fiber_rate * zp + u * d_chi
    phase = phase0 + mig_rate * zp + u * d_phase
    rad = 0.5 * (r0 + u * d_r) * (rho_max + rho_min + (rho_max - rho_min) * np.cos(phase))
    return rad * e_n * np.cos(chi), rad * e_b * np.sin(chi)


@njit(parallel=True, cache=True)
def _regular_kernel(z, period, first_period, chain, ply, n_plies, ply_dist, ply_rate, r0, chi0, phase0, d_r, d_chi,
                    d_phase, e_b, e_n, fiber_rate, mig_rate, rho_min, rho_max, out):
    """out[f, k] = position of fiber chain f at z[k]; chain[f, n] is the member it follows in period
    first_period + n. One chain per iteration: each writes only its own rows."""
    n_periods = chain.shape[1]
    for f in prange(chain.shape[0]):
        for k in range(z.shape[0]):
            n = min(max(int(np.floor(z[k] / period)) - first_period, 0), n_periods - 1)
            zp = z[k] - (first_period + n) * period
            i = chain[f, n]
            a, b = _member_offset(zp, zp / period, r0[i], chi0[i], phase0[i], d_r[i], d_chi[i], d_phase[i], e_b, e_n,
                                  fiber_rate, mig_rate, rho_min, rho_max)
            psi = 2.0 * np.pi * ply[i] / n_plies + ply_rate * z[k]
            cp, sp = np.cos(psi), np.sin(psi)
            out[f, k, 0] = ply_dist * cp + a * cp - b * sp
            out[f, k, 1] = ply_dist * sp + a * sp + b * cp
            out[f, k, 2] = z[k]


def _ply_frame(ply, z, n_plies, ply_dist, ply_rate):
    """Ply centre, normal and binormal at (ply, z) arrays of equal shape."""
    psi = 2 * np.pi * ply / n_plies + ply_rate * z
    n = np.stack([np.cos(psi), np.sin(psi), np.zeros_like(psi)], axis=-1)
    b = np.stack([-np.sin(psi), np.cos(psi), np.zeros_like(psi)], axis=-1)
    c = ply_dist * n
    c[..., 2] = z
    return c, n, b


def generate_fibers(spec: YarnSpec, length: float | None = None, z_start: float = 0.0, seed: int = 0,
                    segments_per_period: int | None = None, flyaways: bool = True,
                    flyaway_seed: int | None = None) -> FiberSet:
    """Fibers of a straight yarn along +z from ``z_start`` over ``length`` (default: one period = ply pitch).

    Regular fibers are sampled at ``segments_per_period`` uniform steps per period (default: SEGMENTS_PER_TURN
    per turn of the faster of the ply and fiber twists, at least 32). Flyaways are added when ``flyaways`` is true.
    The same seed gives the same yarn in every window: a window [z_start, z_start + length] shows the regular
    fibers of the infinite periodic yarn; flyaways are drawn for the window itself. ``flyaway_seed``: draw the
    flyaways from a stream of their own, (``seed``, ``flyaway_seed``), the regular fibers unchanged (another draw
    of the same yarn's flyaways, ``knitbake.stages.textures``); None: from the regular fibers' stream, after them.
    """
    g = spec.geometry
    period = g.ply_pitch
    length = period if length is None else float(length)
    if not (math.isfinite(length) and length > 0 and math.isfinite(z_start)):
        raise ValueError(f"length = {length!r} must be positive and z_start = {z_start!r} finite")
    check_fiber_budget(spec, length, segments_per_period, flyaways)
    n_seg = _segments(spec, length, segments_per_period)
    z = z_start + length * np.arange(n_seg + 1) / n_seg

    rng = np.random.Generator(np.random.PCG64(seed))
    m = g.fibers_per_ply
    fiber_rate = (-1.0 if g.fiber_clockwise else 1.0) * 2 * np.pi / g.fiber_pitch
    mig_rate = 2 * np.pi * g.migration_frequency / g.fiber_pitch
    ply_rate = (-1.0 if g.ply_clockwise else 1.0) * 2 * np.pi / period
    amplitude = 0.5 * (g.migration_rho_max - g.migration_rho_min)

    r0 = sample_radii(rng, g.plies * m, g.density_eps, g.density_beta)
    chi0 = rng.uniform(0, 2 * np.pi, g.plies * m)
    phase0 = rng.uniform(0, 2 * np.pi, g.plies * m)
    ply_reg = np.repeat(np.arange(g.plies), m)
    succ = np.empty(g.plies * m, dtype=np.int64)
    d_r, d_chi, d_phase = (np.empty(g.plies * m) for _ in range(3))
    for j in range(g.plies):
        sl = slice(j * m, (j + 1) * m)
        s_j, d_r[sl], d_chi[sl], d_phase[sl] = match_period(r0[sl], chi0[sl], phase0[sl], fiber_rate * period,
                                                             mig_rate * period, amplitude)
        succ[sl] = s_j + j * m

    first = int(math.floor(z[0] / period))
    n_periods = int(math.floor(z[-1] / period)) - first + 1
    chain = np.empty((succ.size, n_periods), dtype=np.int64)
    chain[:, 0] = np.arange(succ.size)
    for n in range(1, n_periods):
        chain[:, n] = succ[chain[:, n - 1]]
    member = (r0, chi0, phase0, d_r, d_chi, d_phase)
    shape = (g.ply_semi_axes[0], g.ply_semi_axes[1], fiber_rate, mig_rate, g.migration_rho_min,
             g.migration_rho_max)
    reg = np.empty((succ.size, z.size, 3))
    _regular_kernel(z, period, first, chain, ply_reg.astype(np.float64), g.plies, g.ply_distance, ply_rate, *member,
                    *shape, reg)
    polylines = list(reg)
    kinds = [KIND_REGULAR] * succ.size
    plies = list(ply_reg)

    frame = dict(n_plies=g.plies, ply_dist=g.ply_distance, ply_rate=ply_rate)
    n_loops = n_hairs = 0
    if flyaways:
        if flyaway_seed is not None:
            rng = np.random.Generator(np.random.PCG64(np.random.SeedSequence([seed, FLYAWAY_STREAM, flyaway_seed])))
        loops, loop_ply = _loops(spec, rng, length, z[0], period, member, shape, frame)
        hairs, hair_ply = _hairs(spec, rng, length, z[0], frame)
        n_loops, n_hairs = len(loops), len(hairs)
        polylines += loops + hairs
        kinds += [KIND_LOOP] * n_loops + [KIND_HAIR] * n_hairs
        plies += list(loop_ply) + list(hair_ply)

    counts = np.array([len(pl) for pl in polylines], dtype=np.int64)
    offsets = np.zeros(counts.size + 1, dtype=np.int64)
    np.cumsum(counts, out=offsets[1:])
    twist = 1.0 + d_chi / (fiber_rate * period)
    info = {
        "period": period, "length": length, "seed": seed, "segments_per_period": segments_per_period,
        "regular": int(succ.size), "loops": n_loops, "hairs": n_hairs,
        "successor": succ,
        "fiber_pitch_change_mean": float(1.0 / np.mean(twist) - 1.0),
        "fiber_pitch_change_max": float(np.max(np.abs(1.0 / twist - 1.0))),
        "radius_change_max": float(np.max(np.abs(d_r))),
    }
    return FiberSet(np.concatenate(polylines), offsets, np.full(counts.size, g.fiber_radius),
                    np.array(kinds, dtype=np.int8), np.array(plies, dtype=np.int16), float(z[0]), float(z[-1]), info)


@njit(cache=True)
def _host_offsets(zp, period, host, r0, chi0, phase0, d_r, d_chi, d_phase, e_b, e_n, fiber_rate, mig_rate, rho_min,
                  rho_max):
    """(N, B) offsets of host fibers host[i] at in-period coordinates zp[i, k]."""
    out = np.empty((zp.shape[0], zp.shape[1], 2))
    for i in range(zp.shape[0]):
        h = host[i]
        for k in range(zp.shape[1]):
            out[i, k, 0], out[i, k, 1] = _member_offset(zp[i, k], zp[i, k] / period, r0[h], chi0[h], phase0[h],
                                                        d_r[h], d_chi[h], d_phase[h], e_b, e_n, fiber_rate, mig_rate,
                                                        rho_min, rho_max)
    return out


def _to_yarn(ply, z, local_n, local_b, frame):
    """Yarn-space points from ply-frame offsets (along N and B) at axial positions z; arrays of equal shape."""
    c, nrm, bin_ = _ply_frame(ply, z, **frame)
    return c + local_n[..., None] * nrm + local_b[..., None] * bin_


def _split(points):
    return list(points) if points.shape[0] else []


def _loops(spec, rng, length, z_start, period, member, shape, frame):
    """Loop fibers: a host fiber's path over one migration cycle with its radius raised smoothly to loop_radius.
    The host is the fiber member of the period where the loop starts (followed through that period's frame)."""
    g, fl = spec.geometry, spec.flyaways
    n = rng.poisson(fl.loop_density * length * g.plies) if fl.loop_density > 0 else 0
    ply = rng.integers(0, g.plies, n)
    host = ply * g.fibers_per_ply + rng.integers(0, g.fibers_per_ply, n)
    z0 = z_start + rng.uniform(0, length, n)
    peak = np.abs(rng.normal(fl.loop_radius_mean, fl.loop_radius_std, n))
    cycle = g.fiber_pitch / g.migration_frequency if g.migration_frequency > 0 else g.fiber_pitch
    t = np.linspace(0.0, 1.0, FLYAWAY_POINTS)
    z = z0[:, None] + cycle * t
    zp = z - (np.floor(z0 / period) * period)[:, None]  # stay in the start period's member: a smooth loop
    local = _host_offsets(zp, period, host, *member, *shape)
    dist = np.linalg.norm(local, axis=-1)
    target = np.maximum(peak[:, None], dist)
    raised = dist + (target - dist) * np.sin(np.pi * t) ** 2
    local *= (raised / np.maximum(dist, 1e-300))[..., None]
    pts = _to_yarn(np.broadcast_to(ply[:, None], z.shape), z, local[..., 0], local[..., 1], frame)
    return _split(pts), ply.astype(np.int16)


def _hairs(spec, rng, length, z_start, frame):
    """Hair fibers (Huang et al. 2025 eqs. 12–13) in the ply frame, with a random walk on their direction of
    progress."""
    g, fl = spec.geometry, spec.flyaways
    n = rng.poisson(fl.hair_density * length * g.plies) if fl.hair_density > 0 else 0
    ply = rng.integers(0, g.plies, n)
    z0 = z_start + rng.uniform(0, length, n)
    theta0 = rng.uniform(0, 2 * np.pi, n)
    r_0 = np.abs(rng.normal(fl.hair_start_radius_mean, fl.hair_start_radius_std, n))
    r_e = rng.normal(fl.hair_radial_span_mean, fl.hair_radial_span_std, n)
    th_e = rng.normal(fl.hair_angular_span_mean, fl.hair_angular_span_std, n)
    z_e = rng.normal(fl.hair_z_span_mean, fl.hair_z_span_std, n)
    walk = rng.normal(0.0, 1.0, (n, FLYAWAY_POINTS - 1, 2))
    t = np.linspace(0.0, 1.0, FLYAWAY_POINTS)
    r = np.maximum(r_0[:, None] + r_e[:, None] * (1 - (1 - t) ** fl.hair_curvature_alpha), 0.0)
    th = theta0[:, None] + th_e[:, None] * t
    local = np.stack([r * np.cos(th), r * np.sin(th), z_e[:, None] * t], axis=-1)  # (N, B, z) coordinates
    local = perturb_directions(local, fl.hair_direction_noise * math.sqrt(t[1] - t[0]) * walk)
    z = z0[:, None] + local[..., 2]
    pts = _to_yarn(np.broadcast_to(ply[:, None], z.shape), z, local[..., 0], local[..., 1], frame)
    return _split(pts), ply.astype(np.int16)


def perturb_directions(pts, steps):
    """Polylines pts (n, k, 3) whose segment directions are turned by the accumulated random angles
    ``steps`` (n, k − 1, 2) about two axes perpendicular to each segment; segment lengths and first points kept."""
    seg = np.diff(pts, axis=1)
    lens = np.linalg.norm(seg, axis=-1, keepdims=True)
    u = seg / np.maximum(lens, 1e-300)
    helper = np.where(np.abs(u[..., 2:3]) < 0.9, [0.0, 0.0, 1.0], [1.0, 0.0, 0.0])
    e1 = np.cross(u, helper)
    e1 /= np.maximum(np.linalg.norm(e1, axis=-1, keepdims=True), 1e-300)
    e2 = np.cross(u, e1)
    ang = np.cumsum(steps, axis=1)
    mag = np.linalg.norm(ang, axis=-1, keepdims=True)
    sinc = np.where(mag > 1e-12, np.sin(mag) / np.maximum(mag, 1e-300), 1.0)
    v = u * np.cos(mag) + (ang[..., :1] * e1 + ang[..., 1:] * e2) * sinc
    d = lens * v / np.linalg.norm(v, axis=-1, keepdims=True)
    return np.concatenate([pts[:, :1], pts[:, :1] + np.cumsum(d, axis=1)], axis=1)
