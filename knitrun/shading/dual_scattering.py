"""Dual scattering (Zinke, Yuksel, Weber, Keyser 2008, "Dual scattering approximation for fast multiple scattering in
hair", ACM TOG 27(3); Huang et al. 2025 eq. 8: Ψ_DS = Ψ_G (1 + Ψ_L)) for the fiber BCSDF of
``knitrun.shading.fiber_bcsdf``: the one runtime definition that the baker (ξ = Ψ_*/Ψ_DS) and the renderer share. The
tables come from ``knitbake.stages.ds_precompute`` (or an asset pack's ``/dual_scattering/*``, ASSET_PACK.md §5).

Conventions (ASSET_PACK.md §3, fiber frame): θ = asin(ω·t) against the fiber tangent, φ = φ_o − φ_i wrapped to
[−π, π); φ = 0 is light from the camera's side (back-scattering), φ = ±π light from behind (forward scattering).
ω_i points toward the light, ω_o toward the camera. θ_h = (θ_i + θ_o)/2. Angles in radians.

What ``evaluate_ds`` returns
----------------------------
For a distant light of irradiance E (normal to ω_i) reaching a fiber through ``n`` fibers in front of it (a count,
or a shadow-map depth proxy; any real n ≥ 0), the DS estimate of the scattered radiance per unit irradiance,
L_o/E in 1/sr, RGB: the integral ∫ Ψ_DS(ω_i, ω') f(ω', ω_o) cos θ' dω' of Zinke §3 collapsed by his
approximations (his pseudo-code F(T_f, σ̄_f², directFraction) times cos θ_i):

    T_f   = d_f · ā_f(θ_i)^n                       forward-scattering transmittance (Zinke §4.1, mean ā_f)
    σ̄_f² = n · β̄_f(θ_i)²                         accumulated forward spread, θ_h variance (Zinke §4.1)
    D     = clamp(1 − n, 0, 1)                     direct fraction (1 unoccluded, 0 behind ≥ 1 fiber), overridable
    f_back^direct  = Ā_b M(Δ̄_b, σ̄_b) N_b(φ)                          local back-scattering (Zinke §4.2)
    f_back^scatter = Ā_b M(Δ̄_b, √(σ̄_b² + σ̄_f²)) N_b^G(φ)
    f_s^scatter    = Σ_{p∈R,TT} A_p M(α_p, √(β_p² + σ̄_f²)) N_p^G(φ) + A_D/π²
    F_direct  = D (f + d_b f_back^direct)                             f: the BCSDF (single scattering)
    F_scatter = (1 − D) T_f (f_s^scatter + d_b f_back^scatter)
    L_o/E     = (F_direct + F_scatter) cos θ_i

M(α, w) is the BCSDF's longitudinal lobe: a Gaussian in θ_h of mean α and standard deviation w, i.e.
exp(−(θ_i − μ)²/(2σ²))/Z(μ, σ) with μ = 2α − θ_o, σ = 2w and Z = ∫ exp(·) cos²θ_i dθ_i over [−π/2, π/2]
(``fiber_bcsdf.cos2_normaliser``, the same centre clamp), so ∫ M cos²θ_i dθ_i = 1. Azimuthal functions:
N_R = 1/(2π), N_TT the BCSDF's trimmed logistic around φ = π, N_b = 1/π on the back half |φ| < π/2.
Forward-scattered light arrives spread uniformly over ±π/2 of azimuth around the light (Zinke's S_f, density 1/π),
so every global azimuthal function is that convolution, N^G(φ) = (1/π) ∫_{−π/2}^{π/2} N(φ − u) du:
N_R^G = 1/(2π), N_b^G = (π − |φ|)/π², N_TT^G in closed form from the logistic CDF (``n_tt_global``).
The back-scattering terms Ā_b, Δ̄_b, σ̄_b follow from the averages by Zinke eqs. 14–17 (``backscatter_terms``).

Departures from Zinke's pseudo-code, all normalisations: (1) lobes are normalised like the BCSDF, so f_back carries
exactly the energy Ā_b over the back half (Zinke's Marschner-style 2/(π cos²θ_d) does not transfer to this BCSDF);
(2) N^G is the convolution above for every lobe, which replaces the ad-hoc factor π on f_back^scatter;
(3) F_scatter is (1 − D)·T_f(…) instead of (T_f − D)·d_f(…): with T_f = d_f ā_f^n the latter is negative at
n = 0 and counts d_f twice. The density factors d_f = d_b = 0.7 are Zinke's defaults.

Guards: 1 − ā_f² is floored at ``ONE_MINUS_AF2_FLOOR`` in eqs. 14–16 (the geometric series of forward scattering
diverges as ā_f → 1); eq. 17 takes its ā_b → 0 limit when ā_b = 0; ā_f is clamped to [0, 1] in T_f; lobe widths
are floored at ``WIDTH_FLOOR`` so a zero-roughness table stays finite.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit, prange

from data_formats.conventions import HALF_PI, LUMINANCE, THETA_RANGE
from knitrun.shading.fiber_bcsdf import (INV_PI2, N_CONTEXT, P_A_D, P_A_R, P_A_TT, P_ALPHA_R, P_ALPHA_TT, P_BETA_R,
                                         P_BETA_TT, P_GAMMA_TT, context_into, evaluate, lobe_centre_at,
                                         log_cos2_normaliser, tt_logistic_scale)
from knitrun.shading.fiber_frame import wrap_angle
from knitrun.shading.table_lookup import axis_cell

D_F = 0.7  # forward-scattering density factor (Zinke §4.1)
D_B = 0.7  # back-scattering density factor (Zinke §4.2)
ONE_MINUS_AF2_FLOOR = 1e-4
WIDTH_FLOOR = 1e-7  # rad, θ_h standard deviation

DS_NAMES = ("a_f", "a_b", "alpha_f", "alpha_b", "beta_f", "beta_b", "A_b", "Delta_b", "sigma_b")
TABLE_NAMES = tuple(f"dual_scattering/{n}" for n in DS_NAMES)
# The tables the runtime reads, in the order of ``pack_tables``' first axis.
RUNTIME_NAMES = tuple(f"dual_scattering/{n}" for n in ("a_f", "beta_f", "A_b", "Delta_b", "sigma_b"))
R_A_F, R_BETA_F, R_A_BACK, R_DELTA_B, R_SIGMA_B = range(5)
# Rows of ``ds_kernel``'s output.
COMPONENTS = ("T_f", "sigma_f2", "f_back_direct", "f_back_scatter", "F_direct", "F_scatter", "L_over_E")
K_T_F, K_SIGMA_F2, K_F_BACK_DIRECT, K_F_BACK_SCATTER, K_F_DIRECT, K_F_SCATTER, K_TOTAL = range(7)

INV_PI = 1.0 / math.pi


# --- Zinke eqs. 14–17: back-scattering from the averages ---------------------------------------------------------

def backscatter_terms(a_f, a_b, alpha_f, alpha_b, beta_f, beta_b, d_b=D_B):
    """(Ā_b, Δ̄_b, σ̄_b) from the forward/backward averages (arrays, broadcast), Zinke eqs. 14–17:

        A_1 = ā_b ā_f² / (1 − ā_f²),   A_3 = ā_b³ ā_f² / (1 − ā_f²)³,   Ā_b = A_1 + A_3                 (eq. 14)
        Δ̄_b = ᾱ_b (1 − 2ā_b²/(1 − ā_f²)²) + ᾱ_f (2(1 − ā_f²)² + 4ā_f²ā_b²)/(1 − ā_f²)³            (eq. 16)
        σ̄_b = (1 + d_b ā_f²) (ā_b √(2β̄_f² + β̄_b²) + ā_b³ √(2β̄_f² + 3β̄_b²)) / (ā_b + ā_b³(2β̄_f + 3β̄_b))  (eq. 17)

    (eq. 15, the spread S_b, is applied at run time as the back lobe M(Δ̄_b, σ̄_b)). 1 − ā_f² is floored at
    ``ONE_MINUS_AF2_FLOOR``; σ̄_b takes its ā_b → 0 limit (1 + d_b ā_f²)√(2β̄_f² + β̄_b²) where ā_b = 0.
    Widths are standard deviations (rad). Eq. 17 is used as printed, including its d_b."""
    a_f, a_b, alpha_f, alpha_b, beta_f, beta_b = np.broadcast_arrays(
        *(np.asarray(v, dtype=np.float64) for v in (a_f, a_b, alpha_f, alpha_b, beta_f, beta_b)))
    af2, ab2, ab3 = a_f * a_f, a_b * a_b, a_b ** 3
    den = np.maximum(1.0 - af2, ONE_MINUS_AF2_FLOOR)
    big_a_b = a_b * af2 / den + ab3 * af2 / den ** 3
    delta_b = alpha_b * (1.0 - 2.0 * ab2 / den ** 2) + alpha_f * (2.0 * den ** 2 + 4.0 * af2 * ab2) / den ** 3
    first = np.sqrt(2.0 * beta_f ** 2 + beta_b ** 2)
    num = a_b * first + ab3 * np.sqrt(2.0 * beta_f ** 2 + 3.0 * beta_b ** 2)
    dnm = a_b + ab3 * (2.0 * beta_f + 3.0 * beta_b)
    ratio = np.where(dnm > 0.0, num / np.where(dnm > 0.0, dnm, 1.0), first)
    return big_a_b, delta_b, (1.0 + d_b * af2) * ratio


# --- azimuthal functions -----------------------------------------------------------------------------------------

@njit(cache=True)
def _tt_cdf(x, s):
    """CDF of the trimmed logistic N_TT on x = φ − π ∈ [−π, π]: (tanh(x/2s) + tanh(π/2s)) / (2 tanh(π/2s))."""
    t = math.tanh(0.5 * math.pi / s)
    return 0.5 * (math.tanh(0.5 * x / s) + t) / t


@njit(cache=True)
def tt_front_fraction(gamma_tt):
    """∫ N_TT dφ over the front half |φ| > π/2 = tanh(π/4s) / tanh(π/2s)."""
    s = tt_logistic_scale(gamma_tt)
    return math.tanh(0.25 * math.pi / s) / math.tanh(0.5 * math.pi / s)


@njit(cache=True)
def n_tt_global(phi, gamma_tt):
    """N_TT^G(φ) = (1/π) ∫_{−π/2}^{π/2} N_TT(φ − u) du: the N_TT mass on the arc of length π centred at φ."""
    s = tt_logistic_scale(gamma_tt)
    c = wrap_angle(phi - math.pi)
    lo, hi = c - HALF_PI, c + HALF_PI
    if hi > math.pi:
        mass = 1.0 - _tt_cdf(lo, s) + _tt_cdf(hi - 2.0 * math.pi, s)
    elif lo < -math.pi:
        mass = _tt_cdf(hi, s) + 1.0 - _tt_cdf(lo + 2.0 * math.pi, s)
    else:
        mass = _tt_cdf(hi, s) - _tt_cdf(lo, s)
    return max(mass, 0.0) * INV_PI


@njit(cache=True)
def n_back(phi):
    """N_b: uniform over the back half |φ| < π/2."""
    return INV_PI if abs(wrap_angle(phi)) < HALF_PI else 0.0


@njit(cache=True)
def n_back_global(phi):
    """N_b^G(φ) = (1/π) ∫_{−π/2}^{π/2} N_b(φ − u) du = (π − |φ|)/π²."""
    return (math.pi - abs(wrap_angle(phi))) * INV_PI2


# --- the runtime kernel ------------------------------------------------------------------------------------------

@njit(cache=True)
def _lobe(theta_i, theta_o, alpha, width):
    """M(α, w): the BCSDF's longitudinal lobe with θ_h mean α and standard deviation w (1/rad, w.r.t. cos²θ_i dθ_i),
    centred by ``fiber_bcsdf.lobe_centre_at``."""
    sigma = 2.0 * max(width, WIDTH_FLOOR)
    mu = lobe_centre_at(alpha, sigma, theta_o)
    return math.exp(-0.5 * ((theta_i - mu) / sigma) ** 2 - log_cos2_normaliser(mu, sigma))


@njit(cache=True)
def forward_fraction(tab, theta, out):
    """ā_f(θ) per channel, clamped to [0, 1]: the fraction of the light that meets a fiber at θ (against its tangent)
    and leaves it on the far side (Zinke et al. 2008 §4.1), from ``pack_tables``' a_f row. A thin hair in front of a
    bright body passes this fraction of the body's radiance on toward the camera (``strip_shading.shade_flyaway``)."""
    i0, i1, fr = axis_cell(theta, THETA_RANGE[0], THETA_RANGE[1], tab.shape[1], False)
    for ch in range(3):
        out[ch] = min(max((1.0 - fr) * tab[R_A_F, i0, ch] + fr * tab[R_A_F, i1, ch], 0.0), 1.0)


DS_WORK = 9 + N_CONTEXT  # ``ds_kernel``'s scratch: ω_o, ω_i, f (3 each) and a BCSDF context


@njit(cache=True)
def ds_scratch():
    """Scratch for ``ds_kernel``: (``K_TOTAL`` + 1, 3) output rows and ``DS_WORK`` floats. Kernels allocate them once
    per block of points, not per evaluation."""
    return np.empty((K_TOTAL + 1, 3)), np.empty(DS_WORK)


@njit(cache=True)
def ds_kernel(p, tab, theta_i, theta_o, phi, n_front, d_f, d_b, direct, out, work, single=True):
    """One DS evaluation. ``p``: BCSDF parameters; ``tab``: ``pack_tables`` output (5, N_theta, 3); ``direct``: D in
    [0, 1]; ``out`` (7, 3) receives the rows of ``COMPONENTS`` (the last is L_o/E); ``work``: ``DS_WORK`` floats of
    scratch (``ds_scratch``). Terms of weight zero are not evaluated and read 0: f and f_back^direct (in F_direct)
    when D = 0, f_back^scatter and f_s^scatter when D = 1 (nor their azimuthal functions), f_back^direct on the front
    half (N_b = 0). ``single`` False leaves f
    out too (F_direct and L_o/E then lack it), for callers that take single scattering from elsewhere (the
    renderer's multiple-scattering lights: f is in I_M)."""
    i0, i1, fr = axis_cell(theta_i, THETA_RANGE[0], THETA_RANGE[1], tab.shape[1], False)
    sin_o = math.sin(theta_o)
    cos_i = math.cos(theta_i)
    wo, wi, f_single, ctx = work[0:3], work[3:6], work[6:9], work[9:]
    f_single[:] = 0.0
    if direct > 0.0 and single:  # f; a point wholly in shadow skips it (weight D = 0)
        wo[0], wo[1], wo[2] = sin_o, math.cos(theta_o), 0.0  # φ_o = 0, so φ_i = −φ
        wi[0], wi[1], wi[2] = math.sin(theta_i), cos_i * math.cos(phi), -cos_i * math.sin(phi)
        context_into(p, wo, ctx, False)
        evaluate(p, ctx, wi, f_single)
    n_b = n_back(phi)
    n_r_g = n_tt_g = n_b_g = 0.0
    if direct < 1.0:  # the global azimuthal functions weigh only the scattered terms (weight 1 − D)
        n_r_g = 0.5 * INV_PI
        n_tt_g = n_tt_global(phi, p[P_GAMMA_TT])
        n_b_g = n_back_global(phi)
    theta_o = math.asin(sin_o)  # θ_o clamped to [−π/2, π/2] as the caller's lobes see it
    for ch in range(3):
        a_f = (1.0 - fr) * tab[R_A_F, i0, ch] + fr * tab[R_A_F, i1, ch]
        beta_f = (1.0 - fr) * tab[R_BETA_F, i0, ch] + fr * tab[R_BETA_F, i1, ch]
        a_back = (1.0 - fr) * tab[R_A_BACK, i0, ch] + fr * tab[R_A_BACK, i1, ch]
        delta_b = (1.0 - fr) * tab[R_DELTA_B, i0, ch] + fr * tab[R_DELTA_B, i1, ch]
        sigma_b = (1.0 - fr) * tab[R_SIGMA_B, i0, ch] + fr * tab[R_SIGMA_B, i1, ch]
        t_f = d_f * min(max(a_f, 0.0), 1.0) ** n_front
        s2 = n_front * beta_f * beta_f
        back_direct = 0.0
        if n_b > 0.0 and direct > 0.0:  # the local back-scattering (weight D)
            back_direct = a_back * _lobe(theta_i, theta_o, delta_b, sigma_b) * n_b
        back_scatter = single_scatter = 0.0
        if direct < 1.0:  # the scattered terms (weight 1 − D)
            back_scatter = a_back * _lobe(theta_i, theta_o, delta_b, math.sqrt(sigma_b * sigma_b + s2)) * n_b_g
            single_scatter = (p[P_A_R + ch] * _lobe(theta_i, theta_o, p[P_ALPHA_R], math.sqrt(p[P_BETA_R] ** 2 + s2))
                              * n_r_g + p[P_A_TT + ch] * n_tt_g
                              * _lobe(theta_i, theta_o, p[P_ALPHA_TT], math.sqrt(p[P_BETA_TT] ** 2 + s2))
                              + p[P_A_D + ch] * INV_PI2)
        f_direct = direct * (f_single[ch] + d_b * back_direct)
        f_scatter = (1.0 - direct) * t_f * (single_scatter + d_b * back_scatter)
        out[K_T_F, ch] = t_f
        out[K_SIGMA_F2, ch] = s2
        out[K_F_BACK_DIRECT, ch] = back_direct
        out[K_F_BACK_SCATTER, ch] = back_scatter
        out[K_F_DIRECT, ch] = f_direct
        out[K_F_SCATTER, ch] = f_scatter
        out[K_TOTAL, ch] = (f_direct + f_scatter) * cos_i


@njit(parallel=True, cache=True)
def _ds_batch(p, tab, theta_i, theta_o, phi, n_front, direct, d_f, d_b):
    out = np.empty((theta_i.shape[0], 3))
    for k in prange(theta_i.shape[0]):
        comp, work = ds_scratch()
        ds_kernel(p, tab, theta_i[k], theta_o[k], phi[k], n_front[k], d_f, d_b, direct[k], comp, work)
        out[k] = comp[K_TOTAL]
    return out


def fiber_counts(geometry, radius: float) -> tuple:
    """(n_cross, n_occluded): the fiber counts the runtime uses for n (no fibers are drawn). ``geometry``: a yarn
    spec's ``Geometry`` (plies K, fibers_per_ply m, fiber_radius r_f), ``radius``: the yarn radius R, same units.

    * n_cross = 4·K·m·r_f/(π R): the mean number of fibers a chord through the yarn's centre crosses (uniformly
      spread fibers): the count for light passing through another yarn.
    * n_occluded = max(1, n_cross/2): the count assumed between a visible fiber and the light when that fiber is in
      its own yarn's shadow. The bake's ξ divides by the DS estimate with exactly this count for every shadowed hit
      (``knitbake.stages.correction``), so ξ corrects the estimate the renderer evaluates. On the bake's straight
      yarn, ``benchmarks/check_n_occluded.py`` compares the bin-averaged DS with this count, and with other fractions
      of n_cross, against the per-hit DS (each hit's own count): n_cross/2 has the smallest worst error over cotton1
      and rayon1 of the fractions measured in BENCHMARKS.md, section "The renderer's n_occluded". The choice matters
      where ξ is not applied."""
    n_cross = 4.0 * geometry.plies * geometry.fibers_per_ply * geometry.fiber_radius / (math.pi * radius)
    return n_cross, max(1.0, 0.5 * n_cross)


def transmittance_count(transmittance, a_f0, n_cross: float, gap: float = 0.0) -> float:
    """The fiber count n_T for light crossing a yarn that gives the yarn's measured transmittance T_Y (ASSET_PACK.md
    §10) together with its gap transmittance τ (the part that passes between the fibers unscattered, which the
    renderer counts as direct light, ``yarn_look.gap_transmittance``): τ + (1 − τ) ā_f^{n_T} = T_Y,
    n_T = ln((T_Y − τ)/(1 − τ)) / ln ā_f(θ = 0) per channel (RGB arrays ``transmittance`` and ``a_f0``, the
    untinted pack's), luminance-weighted over the channels and clipped to [0, ``n_cross``] (a yarn lets through at
    least what evenly spread fibers would). τ = 0 gives ā_f^{n_T} = T_Y. A channel with T_Y ≥ 1 counts 0 fibers; one
    whose ā_f is 0 or 1, or whose T_Y is at most τ (no count reproduces T_Y), counts ``n_cross``.

    Why: ``fiber_counts``' n_cross assumes fibers that fill the tube evenly, so a beam through a yarn meets ~8 of them
    (cotton1) and keeps ā_f^8 ≈ 6 % of its light; the path-traced yarn lets ~44 % through, mostly between fibers and
    plies (``knitbake.stages.yarn_hull``), and a yarn in another's shadow was drawn near black."""
    if not 0.0 <= gap < 1.0:
        raise ValueError(f"gap transmittance {gap} is outside [0, 1)")
    t = np.asarray(transmittance, np.float64).reshape(3)
    a = np.asarray(a_f0, np.float64).reshape(3)
    scattered = (t - gap) / (1.0 - gap)  # what the scattered part must let through: ā_f^{n_T}
    count = np.full(3, float(n_cross))
    count[t >= 1.0] = 0.0
    solvable = (scattered > 0.0) & (t < 1.0) & (a > 0.0) & (a < 1.0)
    count[solvable] = np.log(np.minimum(scattered[solvable], 1.0)) / np.log(a[solvable])
    return float(np.clip(count @ LUMINANCE, 0.0, n_cross))


# --- Python entry points -----------------------------------------------------------------------------------------

def pack_tables(tables) -> np.ndarray:
    """The runtime tables as one (5, N_theta, 3) float64 array in ``RUNTIME_NAMES`` order. ``tables``: name → array
    (e.g. ``read_pack(...).tables``) or name → (array, stderr) (``precompute_dual_scattering``'s output)."""
    rows = []
    for name in RUNTIME_NAMES:
        if name not in tables:
            raise KeyError(f"dual scattering needs table {name!r}")
        value = tables[name]
        rows.append(np.asarray(value[0] if isinstance(value, tuple) else value, dtype=np.float64))
    shapes = {r.shape for r in rows}
    if len(shapes) != 1 or len(rows[0].shape) != 2 or rows[0].shape[1] != 3 or rows[0].shape[0] < 1:
        raise ValueError(f"dual scattering tables must share one shape (N_theta, 3), got {sorted(shapes)}")
    tab = np.stack(rows)
    if not np.all(np.isfinite(tab)):
        raise ValueError("dual scattering tables contain non-finite values")
    return tab


def _inputs(tables, theta_i, theta_o, phi, n_front, d_f, d_b, direct_fraction):
    tab = pack_tables(tables)
    if direct_fraction is None:
        direct_fraction = np.clip(1.0 - np.asarray(n_front, dtype=np.float64), 0.0, 1.0)
    ti, to, ph, n, direct = np.broadcast_arrays(
        *(np.asarray(v, dtype=np.float64) for v in (theta_i, theta_o, phi, n_front, direct_fraction)))
    if not all(np.all(np.isfinite(v)) for v in (ti, to, ph, n, direct)):
        raise ValueError("angles, n_front and direct_fraction must be finite")
    if np.any(n < 0) or np.any((direct < 0) | (direct > 1)):
        raise ValueError("n_front must be ≥ 0 and direct_fraction in [0, 1]")
    if not (math.isfinite(d_f) and math.isfinite(d_b) and d_f >= 0 and d_b >= 0):
        raise ValueError(f"density factors must be finite and ≥ 0, got d_f={d_f}, d_b={d_b}")
    return tab, np.clip(ti, *THETA_RANGE), np.clip(to, *THETA_RANGE), ph, n, direct


def evaluate_ds(tables, theta_i, theta_o, phi, n_front, d_f=D_F, d_b=D_B, *, params, direct_fraction=None):
    """L_o/E of the DS estimate (1/sr, RGB; see the module docstring), vectorised: θ_i (light), θ_o (view),
    φ = φ_o − φ_i, n_front (fibers between the point and the light, real ≥ 0) and direct_fraction (default
    clamp(1 − n, 0, 1)) broadcast together; returns shape (..., 3). ``params``: the fiber BCSDF parameter vector
    the tables were baked for."""
    tab, ti, to, ph, n, direct = _inputs(tables, theta_i, theta_o, phi, n_front, d_f, d_b, direct_fraction)
    shape = ti.shape
    flat = [np.ascontiguousarray(v.ravel()) for v in (ti, to, ph, n, direct)]
    out = _ds_batch(np.asarray(params, dtype=np.float64), tab, *flat, float(d_f), float(d_b))
    return out.reshape(shape + (3,))


def ds_components(tables, theta_i, theta_o, phi, n_front, d_f=D_F, d_b=D_B, *, params, direct_fraction=None,
                  single=True):
    """The intermediate terms of one scalar evaluation: name (``COMPONENTS``) → RGB array (``single``: as in
    ``ds_kernel``)."""
    tab, ti, to, ph, n, direct = _inputs(tables, theta_i, theta_o, phi, n_front, d_f, d_b, direct_fraction)
    if ti.ndim != 0:
        raise ValueError("ds_components takes scalar angles; use evaluate_ds for arrays")
    out, work = ds_scratch()
    ds_kernel(np.asarray(params, dtype=np.float64), tab, float(ti), float(to), float(ph), float(n), float(d_f),
              float(d_b), float(direct), out, work, bool(single))
    return dict(zip(COMPONENTS, out))
