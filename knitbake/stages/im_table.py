"""Bake the environment-light table I_M^{TT,D} (Huang et al. 2025 §4.5, eq. 16; ASSET_PACK.md §9) by deterministic
quadrature, and integrate I_M directly (``im_direct``, the ground truth of the tests).

I_M(θ_o, θ_j, Δφ, λ) = ∫ G(ω_i; ω_j, λ) f(ω_i, ω_o) cos θ_i dω_i with G = exp(λ(ω_i·ω_j − 1)), Δφ = φ_j − φ_o;
parameterisation and lookup in ``knitrun.shading.im_lookup``, BCSDF in ``knitrun.shading.fiber_bcsdf`` (dω = cos θ dθ
dφ). The pack's table holds the TT and D lobes only: the renderer integrates the narrow R lobe itself
(``im_lookup.r_lobe_integral``, the R formula below with a fixed 4-node Hermite or 12-node Legendre rule), because no grid of practical size
resolves a 1° R lobe under a sharp SRBF (see ``knitrun.shading.im_lookup``).

Quadrature
----------
Put φ_o = 0 and write Δ = φ_i − φ_j. Then ω_i·ω_j = cos(θ_i − θ_j) + cos θ_i cos θ_j (cos Δ − 1), so
G = S(θ_i) · exp(κ(cos Δ − 1)) with S(θ_i) = exp(λ(cos(θ_i − θ_j) − 1)) and κ = λ cos θ_i cos θ_j ≥ 0. Every lobe
of f is a product of a θ_i factor and a φ factor, so per lobe (A_p the RGB lobe albedo)

* R:  A_R ∫ M_R(θ_i) cos²θ_i S(θ_i) I0e(κ) dθ_i       (N_R = 1/2π; ∫ e^{κ(cos Δ − 1)} dΔ = 2π I0e(κ))
* D:  A_D (2/π) ∫ cos²θ_i S(θ_i) I0e(κ) dθ_i          (f_D = A_D/π²)
* TT: A_TT ∫ M_TT(θ_i) cos²θ_i S(θ_i) Φ(κ) dθ_i,  Φ(κ) = ∫ N_TT(φ_o − φ_i) e^{κ(cos Δ − 1)} dΔ over the circle,

with I0e(x) = e^{−x} I_0(x). R and D are exact 1-D integrals; TT is a 2-D integral. Each integral runs over the
intersection of its factors' windows, outside which a factor is below e^{−tail} of its peak: the SG window
|θ_i − θ_j| ≤ δ(λ) with λ(1 − cos δ) = tail (the whole range for small λ), the lobe window |θ_i − μ_p| ≤ √(2 tail)
σ_p, and in Δ the window δ(κ) around 0 and |Δ − Δ_TT| ≤ tail·s around the TT centre (s the logistic scale; the
logistic tail is ≤ 4e^{−x/s}). The window is cut into equal panels no wider than two of the smallest scale there
(σ_p, 1/√λ or 1/√κ, s, 0.5 rad for the slow factors cos²θ_i and I0e, and the fall-off length of a lobe cut off at
θ_i = ±π/2), each integrated by n-point Gauss–Legendre. This adapts to both ends of λ: at λ = 10⁴ the SG is 0.01 rad
wide and gets panels of 0.02 rad; at λ = 0.5 the lobes set the panels. The bake takes Φ from a per-Δφ table over
u = ln(1 + κ) (``_azimuth_table``) instead of one azimuthal quadrature per θ_i node (much faster: BENCHMARKS.md,
section "The bake: speed and error per quality"); ``im_direct`` integrates Φ directly. Nothing is random: a bake is
bit-for-bit reproducible.

Error estimate (per entry, returned by ``bake_im_table``; the pack stores its maximum, ``ERROR_KIND``):
Σ_p A_p |J_p(n) − J_p(n/2)| — per lobe, the same panels
with n and n/2 nodes — plus A_TT times the Φ table's largest interpolation error (measured at the midpoints between
its nodes). Gauss–Legendre converges geometrically on these smooth panels, so |J(n) − J(n/2)| is about the error of
the n/2 rule: a conservative bound for the stored n-node value (typically by orders of magnitude). Windows drop
less than e^{−30} of each factor's peak. The table's accuracy as a *lookup* is set by interpolation between the
samples, not by quadrature: ``lookup_accuracy`` measures it (every bake stores the result),
``knitrun.shading.im_lookup`` (Accuracy) explains it, BENCHMARKS.md (section "The bake: speed and error per quality")
reports it per quality and preset, and ``tests/test_im_table.py`` holds it to the issue's target.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit, prange

from data_formats.asset_pack import AXES, IM_AXES
from data_formats.conventions import HALF_PI, cell_centres
from knitbake.stages.stage_result import StageResult
from knitrun.shading import fiber_bcsdf as fb
from knitrun.shading.fiber_bcsdf import params_from_optics
from knitrun.shading.fiber_frame import wrap_angle
from knitrun.shading.im_lookup import i0e

DEFAULT_SHAPE = (24, 48, 24, 96)  # (θ_o, θ_j, |φ_j − φ_o|, log10 λ): the standard quality; see bake_im_table
LAMBDA_RANGE = (0.5, 1.0e4)
NODES = 8  # Gauss–Legendre nodes per panel in the bake (error estimate: NODES // 2)
TAIL = 30.0  # windows end where a factor falls below e^{−TAIL} of its peak
DIRECT_NODES = 16
AZIMUTH_SAMPLES = 1025  # nodes of the per-Δφ table of the TT azimuthal integral Φ(κ)
DIRECT_TAIL = 40.0
LOOKUP_CHECK_POINTS = 2000  # random points at which ``lookup_accuracy`` checks every baked table
ERROR_KIND = ("quadrature, max over entries of Σ_lobes A_p |J_p(n) − J_p(n/2)| between Gauss–Legendre rules with n "
              "and n/2 nodes per panel plus the TT azimuth-table error (per-entry values not stored: deterministic "
              "and far below the interpolation error); the lookup's interpolation error, measured against direct "
              f"quadrature at {LOOKUP_CHECK_POINTS} points, is in lookup_rel_error (where I_M > 1% of its maximum) and "
              "lookup_error_per_decade (relative to each λ decade's maximum)")


@njit(cache=True)
def _sg_half_width(kappa, tail):
    """δ with κ(1 − cos δ) = tail: beyond angle δ from its centre exp(κ(cos − 1)) < e^{−tail}; π if it never is."""
    if 2.0 * kappa <= tail:
        return math.pi
    return math.acos(1.0 - tail / kappa)


@njit(cache=True)
def _azimuth_tt(kappa, centre, s, gx, gw, tail):
    """Φ(κ) = ∫ N_TT e^{κ(cos Δ − 1)} dΔ over the circle, N_TT the trimmed logistic of scale s centred at Δ = centre.

    The von Mises factor's window [−δ(κ), δ(κ)] is intersected with the logistic's window around each copy
    centre + 2πm (m = −1, 0, 1): the copies' windows are disjoint, so the pieces cover the circular intersection
    once, and the logistic's kink at ±π from its centre is always a piece end."""
    h_v = _sg_half_width(kappa, tail)
    h_l = min(math.pi, tail * s)
    scale = min(s, 0.5)
    if kappa > 0.0:
        scale = min(scale, 1.0 / math.sqrt(kappa))
    total = 0.0
    for m in range(-1, 2):
        mid = centre + 2.0 * math.pi * m
        lo = max(-h_v, mid - h_l)
        hi = min(h_v, mid + h_l)
        if hi <= lo:
            continue
        k = int(math.ceil((hi - lo) / (2.0 * scale)))
        half = 0.5 * (hi - lo) / k
        for panel in range(k):
            a = lo + (2 * panel + 1) * half
            for q in range(gx.shape[0]):
                d = a + half * gx[q]
                total += half * gw[q] * fb.logistic_trimmed(d - mid, s) * math.exp(kappa * (math.cos(d) - 1.0))
    return total


@njit(cache=True)
def _azimuth_table(centre, s, u_max, n, gx, gw, tail):
    """ψ_k = Φ(κ_k) √(1 + κ_k) at u_k = k u_max/(n − 1), κ_k = e^{u_k} − 1 (``_azimuth_tt`` for one TT centre).

    Φ depends on κ alone once the TT centre is fixed, and √(1 + κ) Φ(κ) is smooth in u = ln(1 + κ) from Φ(0) = 1
    to the narrow-SG limit √(2π) N_TT(centre), so a bake evaluates Φ by cubic interpolation in u
    (``_azimuth_lookup``) instead of one azimuthal quadrature per θ_i node."""
    tab = np.empty(n)
    for k in range(n):
        kappa = math.expm1(k * u_max / (n - 1))
        tab[k] = _azimuth_tt(kappa, centre, s, gx, gw, tail) * math.sqrt(1.0 + kappa)
    return tab


@njit(cache=True)
def _azimuth_lookup(tab, u_max, kappa):
    """Φ(κ) from ``_azimuth_table`` by 4-point Lagrange interpolation in u = ln(1 + κ), 0 ≤ κ ≤ e^{u_max} − 1."""
    n = tab.shape[0]
    x = math.log1p(kappa) / u_max * (n - 1)
    i = min(max(int(x), 1), n - 3)
    t = x - i
    v = (-t * (t - 1.0) * (t - 2.0) * tab[i - 1] + 3.0 * (t + 1.0) * (t - 1.0) * (t - 2.0) * tab[i]
         - 3.0 * (t + 1.0) * t * (t - 2.0) * tab[i + 1] + (t + 1.0) * t * (t - 1.0) * tab[i + 2]) / 6.0
    return v / math.sqrt(1.0 + kappa)


@njit(cache=True)
def _theta_integral(lobe, c, theta_j, cos_j, lam, tt_centre, s, tt_tab, u_max, gx, gw, tail):
    """The θ_i integral of lobe 0 (R), 1 (TT) or 2 (D), without its albedo (see the module docstring). TT's Φ comes
    from ``tt_tab`` (an ``_azimuth_table`` for ``tt_centre``) when it is not empty, else by direct quadrature."""
    h = _sg_half_width(lam, tail)
    lo = max(-HALF_PI, theta_j - h)
    hi = min(HALF_PI, theta_j + h)
    scale = min(0.5, 1.0 / math.sqrt(lam))
    mu, sigma, z = 0.0, 1.0, 1.0
    if lobe < 2:
        mu, sigma, z = c[fb.C_MU + lobe], c[fb.C_SIGMA + lobe], c[fb.C_Z + lobe]
        reach = math.sqrt(2.0 * tail) * sigma
        lo = max(lo, mu - reach)
        hi = min(hi, mu + reach)
        scale = min(scale, sigma)
        # the product M S is near a Gaussian of centre m and width w; cut off beyond the window (a grazing view puts
        # the lobe past ±π/2), it falls off from the window's end with length w²/distance: resolve that too
        prec = 1.0 / (sigma * sigma) + lam
        m = (mu / (sigma * sigma) + lam * theta_j) / prec
        if m < lo:
            scale = min(scale, 1.0 / (prec * (lo - m)))
        elif m > hi:
            scale = min(scale, 1.0 / (prec * (m - hi)))
    if hi <= lo:
        return 0.0
    k = int(math.ceil((hi - lo) / (2.0 * scale)))
    half = 0.5 * (hi - lo) / k
    total = 0.0
    for panel in range(k):
        a = lo + (2 * panel + 1) * half
        for q in range(gx.shape[0]):
            t = a + half * gx[q]
            ct = math.cos(t)
            kappa = lam * max(ct, 0.0) * cos_j
            w = ct * ct * math.exp(lam * (math.cos(t - theta_j) - 1.0))
            if lobe == 0:
                w *= fb.gauss(t, mu, sigma) / z * i0e(kappa)
            elif lobe == 1:
                phi = _azimuth_lookup(tt_tab, u_max, kappa) if tt_tab.shape[0] else _azimuth_tt(kappa, tt_centre, s,
                                                                                                  gx, gw, tail)
                w *= fb.gauss(t, mu, sigma) / z * phi
            else:
                w *= 2.0 / math.pi * i0e(kappa)
            total += half * gw[q] * w
    return total


@njit(cache=True)
def _lobe_integrals(p, c, theta_j, dphi, lam, tt_tab, u_max, gx, gw, tail, first, out):
    """out[0:3] = the R, TT, D integrals J_p (I_M = Σ_p A_p J_p) for the view of context ``c`` (built with φ_o = 0),
    θ_j ∈ [−π/2, π/2] (clamped), Δφ = φ_j − φ_o. tt_tab: ``_azimuth_table`` for this Δφ (covering κ ≤ λ), or empty
    for direct azimuthal quadrature. Lobes before ``first`` (0 R, 1 TT) and lobes with zero albedo are skipped
    (J_p = 0)."""
    theta_j = min(max(theta_j, -HALF_PI), HALF_PI)
    cos_j = max(math.cos(theta_j), 0.0)
    tt_centre = wrap_angle(math.pi - dphi)  # N_TT peaks where φ_o − φ_i = π, i.e. Δ = π − Δφ
    s = fb.tt_logistic_scale(p[fb.P_GAMMA_TT])
    for lobe in range(3):
        base = (fb.P_A_R, fb.P_A_TT, fb.P_A_D)[lobe]
        out[lobe] = 0.0
        if lobe >= first and max(p[base], p[base + 1], p[base + 2]) > 0.0:
            out[lobe] = _theta_integral(lobe, c, theta_j, cos_j, lam, tt_centre, s, tt_tab, u_max, gx, gw, tail)


@njit(parallel=True, cache=True)
def _azimuth_tables(dphi, s, u_max, n, gx, gw, tail):
    """One ``_azimuth_table`` per Δφ sample, and per table the largest |Φ_interpolated − Φ| at the midpoints between
    its nodes (the interpolation error estimate added to every entry's TT error)."""
    tabs = np.empty((dphi.shape[0], n))
    eps = np.zeros(dphi.shape[0])
    for k in prange(dphi.shape[0]):
        centre = wrap_angle(math.pi - dphi[k])
        tabs[k] = _azimuth_table(centre, s, u_max, n, gx, gw, tail)
        for m in range(n - 1):
            kappa = math.expm1((m + 0.5) * u_max / (n - 1))
            eps[k] = max(eps[k], abs(_azimuth_lookup(tabs[k], u_max, kappa)
                                     - _azimuth_tt(kappa, centre, s, gx, gw, tail)))
    return tabs, eps


@njit(parallel=True, cache=True)
def _bake_slab(p, theta_o, theta_j, dphi, lam, tt_tabs, tt_eps, u_max, gx, gw, gx_half, gw_half, tail, table, err):
    """One θ_o: table[j, k, l] = I_M^{TT,D}(θ_o, θ_j[j], dphi[k], lam[l]) with n nodes; err = Σ_p A_p |J_p(n) −
    J_p(n/2)| over TT and D plus the azimuth-table error A_TT ε_k (∫ M_TT cos²θ_i S dθ_i ≤ 1 bounds its weight)."""
    c = fb.view_context(p, theta_o)
    nj, nk, nl = theta_j.shape[0], dphi.shape[0], lam.shape[0]
    for e in prange(nj * nk * nl):
        j, rest = e // (nk * nl), e % (nk * nl)
        k, l = rest // nl, rest % nl
        fine, coarse = np.empty(3), np.empty(3)
        _lobe_integrals(p, c, theta_j[j], dphi[k], lam[l], tt_tabs[k], u_max, gx, gw, tail, 1, fine)
        _lobe_integrals(p, c, theta_j[j], dphi[k], lam[l], tt_tabs[k], u_max, gx_half, gw_half, tail, 1, coarse)
        for ch in range(3):
            table[j, k, l, ch] = 0.0
            err[j, k, l, ch] = p[fb.P_A_TT + ch] * tt_eps[k]
            for lobe in range(1, 3):
                albedo = p[(fb.P_A_R, fb.P_A_TT, fb.P_A_D)[lobe] + ch]
                table[j, k, l, ch] += albedo * fine[lobe]
                err[j, k, l, ch] += albedo * abs(fine[lobe] - coarse[lobe])


@njit(parallel=True, cache=True)
def _direct_batch(p, theta_o, theta_j, dphi, lam, gx, gw, tail, out):
    no_table = np.empty(0)
    for n in prange(theta_o.shape[0]):
        c = fb.view_context(p, min(max(theta_o[n], -HALF_PI), HALF_PI))
        j = np.empty(3)
        _lobe_integrals(p, c, theta_j[n], dphi[n], lam[n], no_table, 1.0, gx, gw, tail, 0, j)
        for ch in range(3):
            out[n, ch] = p[fb.P_A_R + ch] * j[0] + p[fb.P_A_TT + ch] * j[1] + p[fb.P_A_D + ch] * j[2]


def im_direct(params, theta_o, theta_j, dphi, lam, nodes: int = DIRECT_NODES, tail: float = DIRECT_TAIL):
    """I_M (RGB) by direct quadrature, no table: ground truth for tests. Inputs broadcast; result (…, 3).

    θ_o, θ_j in [−π/2, π/2] (clamped), dphi = φ_j − φ_o (any real, radians), lam > 0. The bake's panels with twice
    its nodes, windows to e^{−40} and the azimuthal integral of TT done directly: agrees with a dense brute-force
    grid within 1e-4 relative (tests/test_im_table.py holds that bound and checks the limits; the measured agreement
    is in BENCHMARKS.md, section "The bake: speed and error per quality")."""
    args = np.broadcast_arrays(*[np.asarray(x, float) for x in (theta_o, theta_j, dphi, lam)])
    if np.any(~(args[3] > 0)) or not all(np.all(np.isfinite(a)) for a in args):
        raise ValueError("im_direct: angles must be finite and λ > 0")
    shape = args[0].shape
    flat = [np.ascontiguousarray(a.ravel()) for a in args]
    gx, gw = np.polynomial.legendre.leggauss(nodes)
    out = np.empty((flat[0].size, 3))
    _direct_batch(np.asarray(params, float), *flat, gx, gw, float(tail), out)
    return out.reshape(shape + (3,))


def end_centred_range(a: float, b: float, n: int) -> tuple:
    """The axis range whose n cell centres (ASSET_PACK.md §4.2) are a, a + h, …, b with h = (b − a)/(n − 1)."""
    h = (b - a) / (n - 1)
    return a - 0.5 * h, b + 0.5 * h


def im_axes(shape, lam_range=LAMBDA_RANGE) -> list:
    """The per-axis dicts (name, range, wrap, units, definition) of a table of ``shape`` (4 sampled axes), as
    ``write_pack``'s ``table_attrs['environment/I_M']['axes']`` expects. Domains: θ_o, θ_j ∈ [−π/2, π/2],
    |Δφ| ∈ [0, π], log10 λ ∈ log10(lam_range); every range puts its outermost cell centres on the domain ends."""
    if len(shape) != 4 or min(shape) < 2:
        raise ValueError(f"I_M shape {tuple(shape)}: expected 4 axes of ≥ 2 samples")
    if not 0 < lam_range[0] < lam_range[1]:
        raise ValueError(f"λ range {lam_range}: expected 0 < λ_min < λ_max")
    axes = []
    for name, n in zip(IM_AXES, shape):  # the schema's axes (data_formats.asset_pack.AXES): domain, wrap, units
        axis = AXES[name]
        a, b = (math.log10(lam_range[0]), math.log10(lam_range[1])) if name == "log10_lambda" else axis.range
        lo, hi = end_centred_range(a, b, n)
        axes.append({"name": name, "range": [lo, hi], "wrap": axis.wrap, "units": axis.units,
                     "definition": axis.definition})
    return axes


def bake_im_table(params, shape=DEFAULT_SHAPE, nodes: int = NODES, lam_range=LAMBDA_RANGE, progress=None):
    """Bake I_M^{TT,D} (the TT and D lobes of I_M) for the fiber BCSDF ``params`` (``knitrun.shading.fiber_bcsdf``
    vector) on the grid of ``im_axes(shape)``.

    shape: samples along (θ_o, θ_j, |φ_j − φ_o|, log10 λ), each ≥ 2. The default (24, 48, 24, 96) — 2.65 M entries,
    32 MB as float32 plus as much for the per-entry errors — puts 7.8° between θ_o and |Δφ| samples, 3.8° between
    θ_j samples and 0.045 decades between λ samples. Its bake time and the lookup accuracy it buys, which depends on
    the lobe widths (``knitrun.shading.im_lookup``, Accuracy), are measured in BENCHMARKS.md, section "The bake: speed
    and error per quality". nodes: Gauss–Legendre nodes per panel (even; the error estimate uses nodes // 2; 4 nodes
    halve the cost of 8 and are less accurate, measured in the same section). lam_range: the λ domain (the end
    samples lie on it). progress(done, total) is called after each θ_o slab. Returns (table (N_a, N_b, N_c, N_d, 3)
    float64, per-entry error (same shape, ≥ 0), axes_attrs (``im_axes(shape)``)). Deterministic: the same inputs give
    the same table bit for bit."""
    if nodes < 2 or nodes % 2:
        raise ValueError(f"nodes {nodes}: expected an even number ≥ 2")
    p = np.asarray(params, float)
    axes = im_axes(shape, lam_range)
    theta_o, theta_j, dphi, log_lam = [cell_centres(*ax["range"], n) for ax, n in zip(axes, shape)]
    lam = 10.0 ** log_lam
    gx, gw = np.polynomial.legendre.leggauss(nodes)
    gx_half, gw_half = np.polynomial.legendre.leggauss(nodes // 2)
    u_max = math.log1p(lam[-1])
    s = fb.tt_logistic_scale(p[fb.P_GAMMA_TT])
    tt_tabs, tt_eps = _azimuth_tables(dphi, s, u_max, AZIMUTH_SAMPLES, gx, gw, TAIL)
    table = np.empty(tuple(shape) + (3,))
    err = np.empty_like(table)
    for i, t_o in enumerate(theta_o):
        _bake_slab(p, float(t_o), theta_j, dphi, lam, tt_tabs, tt_eps, u_max, gx, gw, gx_half, gw_half, TAIL,
                   table[i], err[i])
        if progress is not None:
            progress(i + 1, len(theta_o))
    return table, err, axes


def lookup_accuracy(table, axes, params, n: int = LOOKUP_CHECK_POINTS, seed: int = 0) -> dict:
    """The accuracy of I_M as a renderer evaluates it (``knitrun.shading.im_lookup.im_lookup``: this table plus the
    R-lobe rule) against ``im_direct``, at ``n`` points: θ_o, θ_j uniform, |Δφ| uniform, λ log-uniform over the
    table's λ range, with 10 % at each λ end, 10 % on the R ridge θ_j ≈ 2α_R − θ_o and 10 % within 1e-3 rad of the
    poles. Returns {"lookup_rel_error": max relative error where I_M > 1 % of its largest value over the points,
    "lookup_error_per_decade": max over λ decades of (max error / that decade's largest I_M)} (worst channel).
    Deterministic for a seed; costs about as much as baking a table of 10⁵ entries."""
    from knitrun.shading.im_lookup import im_lookup

    p = np.asarray(params, float)
    lam_axis = next(a for a in axes if a["name"] == "log10_lambda")
    lo, hi = cell_centres(*lam_axis["range"], table.shape[3])[[0, -1]]
    rng = np.random.default_rng(seed)
    theta_o, theta_j = rng.uniform(-HALF_PI, HALF_PI, n), rng.uniform(-HALF_PI, HALF_PI, n)
    dphi, log_lam = rng.uniform(0.0, math.pi, n), rng.uniform(lo, hi, n)
    k = n // 10
    log_lam[:k], log_lam[k:2 * k] = lo, hi
    width = np.sqrt((2.0 * p[fb.P_BETA_R]) ** 2 + 10.0 ** -log_lam[2 * k:3 * k])
    theta_j[2 * k:3 * k] = np.clip(2.0 * p[fb.P_ALPHA_R] - theta_o[2 * k:3 * k] + rng.normal(0.0, 2.0, k) * width,
                                   -HALF_PI, HALF_PI)
    pole = HALF_PI * np.sign(rng.normal(size=k)) * (1.0 - rng.uniform(0.0, 1e-3 / HALF_PI, k))
    theta_o[3 * k:3 * k + k // 2], theta_j[3 * k + k // 2:4 * k] = pole[:k // 2], pole[k // 2:]
    lam = 10.0 ** log_lam
    ref = im_direct(p, theta_o, theta_j, dphi, lam)
    got = im_lookup(table, axes, p, theta_o, theta_j, dphi, lam)
    peak = ref.max(axis=0)
    counted = ref > 0.01 * peak
    rel = np.abs(got - ref) / np.where(counted, ref, 1.0)
    decade = np.floor(log_lam - lo + 1e-9)
    per_decade = max(float(np.max(np.abs(got[m] - ref[m]) / np.maximum(ref[m].max(axis=0), 1e-300)))
                     for m in (decade == d for d in np.unique(decade)))
    return {"lookup_rel_error": float(rel[counted].max()) if counted.any() else 0.0,
            "lookup_error_per_decade": per_decade}


def bake_environment_stage(spec, settings, seed, progress=None) -> StageResult:
    """Stage ``environment`` of ``knitbake.bake``: the I_M^{TT,D} table by deterministic quadrature (the seed is
    unused), with its lookup accuracy measured by ``lookup_accuracy``; settings: shape."""
    del seed
    params = params_from_optics(spec.optics)
    table, err, axes = bake_im_table(params, shape=tuple(settings["shape"]), progress=progress)
    accuracy = lookup_accuracy(table, axes, params)
    return StageResult({"environment/I_M_TT_D": table}, {"environment/I_M_TT_D": float(err.max())},
                       {"environment/I_M_TT_D": {"axes": axes, "error_kind": ERROR_KIND, **accuracy}},
                       {"shape": list(settings["shape"]), "lookup_check_points": LOOKUP_CHECK_POINTS})
