"""Dual-scattering precomputation (Zinke et al. 2008 §4; Huang et al. 2025 eq. 8; ASSET_PACK.md §5) for the fiber BCSDF
of ``knitrun.shading.fiber_bcsdf``: the nine ``/dual_scattering/*`` tables over the cell centres θ of [−π/2, π/2], per
RGB channel, each with a per-entry error.

Definitions
-----------
θ is the longitudinal angle of the light direction (the tables' ``theta_i`` axis). For each half
H ∈ {front: |φ| > π/2, back: |φ| < π/2} (φ = φ_o − φ_i; φ = 0 back-scattering, φ = ±π forward) and channel:

    ā_H(θ)   = ∫_H f(ω', ω_θ) cos θ' dω'                         the fraction of the light from θ scattered into H
    ᾱ_H(θ)   = (1/ā_H) ∫_H f(ω', ω_θ) cos θ' θ_h dω'             mean longitudinal half angle θ_h = (θ + θ')/2
    β̄_H(θ)²  = (1/ā_H) ∫_H f(ω', ω_θ) cos θ' (θ_h − ᾱ_H)² dω'    its variance; the table stores β̄_H (rad)

with dω' = cos θ' dθ' dφ'. ω_θ sits in the ω_o slot of f: the BCSDF is normalised per ω_o
(∫ f cos θ_i dω_i = A_R + A_TT + A_D exactly) and reciprocal up to its grazing-angle drift, so this is the scattered
fraction and ā_f + ā_b is exactly the fiber albedo (1 for lossless fibers). f depends on φ_o − φ_i only, so the
average over φ_i that Zinke takes is the value at any φ_i. Zinke's ᾱ_H, β̄_H are the ā-weighted averages of the lobe
shifts α_p and widths β_p; the moments above are the same numbers for Gaussian lobes inside the domain (β̄² adds the
spread of the lobe centres) and also give the D lobe its θ-dependent shift θ/2 and its width. Then Ā_b, Δ̄_b,
σ̄_b by Zinke eqs. 14–17 (``knitrun.shading.dual_scattering.backscatter_terms``, σ̄_b with the density factor d_b).

Evaluation
----------
f = Σ_p A_p M_p(θ'|θ) N_p(φ) separates, so every integral is a sum over lobes of (azimuthal fraction of the half) ×
(longitudinal moment):

* azimuthal fractions, closed form: R and D put 1/2 in each half; TT puts tanh(π/4s)/tanh(π/2s) in the front half
  (s = √3 γ_TT/π, the logistic scale) and the rest in the back;
* longitudinal moments of R and TT: Gauss–Legendre with ``quality`` nodes over the lobe's ±9σ window clipped to
  [−π/2, π/2] (``fiber_bcsdf.lobe_window``, the window of the BCSDF's own normaliser), as ratios to
  ∫ M_p cos²θ' dθ' (= 1);
* the D lobe's θ' density is cos²θ'/(π/2): θ_h mean θ/2 and variance (π²/12 − 1/2)/4, exact.

Per channel the lobe weights are w_p = A_p × (fraction in H): ā_H = Σ w_p, ᾱ_H = Σ w_p m_p / ā_H and
β̄_H² = Σ w_p (v_p + (m_p − ᾱ_H)²) / ā_H (m_p, v_p the lobe's θ_h mean and variance). A half that receives no energy
in a channel (ā_H = 0) takes the moments of the unit-albedo fiber, so its shift and width stay finite.

Error estimate (``ERROR_KIND``): quadrature, not Monte Carlo. Every table is computed with ``quality`` and
``quality // 2`` Gauss–Legendre nodes and the per-entry error is their absolute difference (the error bar of the
``quality`` result, conservative); the azimuthal fractions and the D moments are exact. It does not include the
float32 rounding of a stored pack (relative 6e-8).
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit, prange

from data_formats.conventions import THETA_RANGE, cell_centres
from knitbake.stages.stage_result import StageResult
from knitrun.shading.dual_scattering import D_B, TABLE_NAMES, backscatter_terms, tt_front_fraction
from knitrun.shading.fiber_bcsdf import (N_PARAMS, P_A_D, P_A_R, P_A_TT, P_ALPHA_R, P_ALPHA_TT, P_BETA_R, P_BETA_TT,
                                         P_GAMMA_TT, gauss, lobe_centre, lobe_window, params_from_optics)

D_THETA_H_VAR = (math.pi ** 2 / 12.0 - 0.5) / 4.0  # variance of θ_h = (θ + θ')/2 for θ' ~ cos²θ'/(π/2)
ERROR_KIND = ("quadrature: |T(q) − T(q/2)| between Gauss–Legendre rules with q and q/2 nodes per lobe window "
              "(azimuthal fractions and the D lobe exact); float32 storage rounding not included")


@njit(parallel=True, cache=True)
def _lobe_moments(alpha, beta, theta, x, w):
    """θ_h mean and variance of one Gaussian lobe (shift α, width β) under M(θ'|θ) cos²θ' dθ', per θ (the lobe's
    centre and window exactly as in ``fiber_bcsdf``: ``lobe_centre``, ``lobe_window``); x, w: Gauss–Legendre nodes
    and weights on [−1, 1]."""
    mean = np.empty(theta.shape[0])
    var = np.empty(theta.shape[0])
    sigma = 2.0 * beta
    for k in prange(theta.shape[0]):
        mu = lobe_centre(alpha, sigma, math.sin(theta[k]))
        lo, hi = lobe_window(mu, sigma)
        half, mid = 0.5 * (hi - lo), 0.5 * (hi + lo)
        s0 = 0.0
        s1 = 0.0
        for j in range(x.shape[0]):
            t = mid + half * x[j]
            c = math.cos(t)
            wt = w[j] * gauss(t, mu, sigma) * c * c
            s0 += wt
            s1 += wt * 0.5 * (theta[k] + t)
        m = s1 / s0
        s2 = 0.0
        for j in range(x.shape[0]):
            t = mid + half * x[j]
            c = math.cos(t)
            s2 += w[j] * gauss(t, mu, sigma) * c * c * (0.5 * (theta[k] + t) - m) ** 2
        mean[k] = m
        var[k] = s2 / s0
    return mean, var


def _tables(p, theta, n_nodes, d_b):
    """The nine tables (9, N_theta, 3) in ``TABLE_NAMES`` order with an n_nodes-point rule."""
    x, w = np.polynomial.legendre.leggauss(n_nodes)
    mean = np.empty((3, theta.size))
    var = np.empty((3, theta.size))
    for k, (a_idx, b_idx) in enumerate(((P_ALPHA_R, P_BETA_R), (P_ALPHA_TT, P_BETA_TT))):
        mean[k], var[k] = _lobe_moments(p[a_idx], p[b_idx], theta, x, w)
    mean[2], var[2] = 0.5 * theta, D_THETA_H_VAR
    albedo = np.stack([p[P_A_R:P_A_R + 3], p[P_A_TT:P_A_TT + 3], p[P_A_D:P_A_D + 3]])  # (lobe, channel)
    tt_front = tt_front_fraction(p[P_GAMMA_TT])
    halves = []
    for frac in (np.array([0.5, tt_front, 0.5]), np.array([0.5, 1.0 - tt_front, 0.5])):  # front, back
        weight = albedo * frac[:, None]
        a = weight.sum(axis=0)
        wm = np.where(a > 0.0, weight, frac[:, None])
        norm = wm.sum(axis=0)
        m = np.einsum("lc,lt->tc", wm, mean) / norm
        v = np.einsum("lc,ltc->tc", wm, var[:, :, None] + (mean[:, :, None] - m[None]) ** 2) / norm
        halves.append((np.broadcast_to(a, m.shape), m, np.sqrt(v)))
    (a_f, alpha_f, beta_f), (a_b, alpha_b, beta_b) = halves
    back = backscatter_terms(a_f, a_b, alpha_f, alpha_b, beta_f, beta_b, d_b)
    return np.stack([a_f, a_b, alpha_f, alpha_b, beta_f, beta_b, *back])


def precompute_dual_scattering(params, n_theta: int = 64, quality: int = 64, d_b: float = D_B) -> dict:
    """The ``/dual_scattering/*`` tables for BCSDF parameters ``params`` (``fiber_bcsdf`` vector): name (the asset
    pack's, e.g. ``"dual_scattering/a_f"``) → (table (n_theta, 3) float64, per-entry error (n_theta, 3) float64).
    ``quality``: Gauss–Legendre nodes per lobe window (≥ 8); ``d_b``: the back-scattering density factor that
    Zinke eq. 17 bakes into σ̄_b (use the renderer's). For ``write_pack``: ``tables={k: v[0]}``,
    ``errors={k: v[1]}``, ``table_attrs={k: {"error_kind": ERROR_KIND}}``."""
    p = np.asarray(params, dtype=np.float64)
    if p.shape != (N_PARAMS,) or not np.all(np.isfinite(p)):
        raise ValueError(f"params must be a finite fiber BCSDF parameter vector of length {N_PARAMS}")
    if int(n_theta) < 1 or int(quality) < 8:
        raise ValueError(f"n_theta must be ≥ 1 and quality ≥ 8, got {n_theta}, {quality}")
    if not (math.isfinite(d_b) and d_b >= 0):
        raise ValueError(f"d_b must be finite and ≥ 0, got {d_b}")
    theta = cell_centres(*THETA_RANGE, int(n_theta))
    fine = _tables(p, theta, int(quality), d_b)
    coarse = _tables(p, theta, int(quality) // 2, d_b)
    return {name: (np.ascontiguousarray(fine[k]), np.abs(fine[k] - coarse[k])) for k, name in enumerate(TABLE_NAMES)}


def bake_dual_scattering_stage(spec, settings, seed, progress=None) -> StageResult:
    """Stage ``dual_scattering`` of ``knitbake.bake`` (deterministic: the seed is unused); settings: n_theta."""
    del seed
    out = precompute_dual_scattering(params_from_optics(spec.optics), **settings)
    if progress:
        progress(1, 1)
    return StageResult({k: v[0] for k, v in out.items()}, {k: v[1] for k, v in out.items()},
                       {k: {"error_kind": ERROR_KIND} for k in out}, {"quadrature": dict(settings)})
