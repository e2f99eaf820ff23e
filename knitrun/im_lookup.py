"""Environment light: the spherical Gaussian (SRBF) and the runtime lookup of the I_M table (seed 000 §4.5).

Definitions (angles as in ``knitrun.fiber_bcsdf`` and ``data_formats/ASSET_PACK.md`` §3, radians)
--------------------------------------------------------------------------------------------------
* SRBF: G(ω; ω_j, λ) = exp(λ(ω·ω_j − 1)) (seed 000 eq. 14), unnormalised: G(ω_j) = 1 and
  ∫ G dω = (2π/λ)(1 − e^{−2λ}).
* I_M(ω_o; ω_j, λ_j) = ∫ G(ω_i; ω_j, λ_j) f(ω_i, ω_o) cos θ_i dω_i (eq. 16), linear RGB, dimensionless;
  f the fiber BCSDF of ``knitrun.fiber_bcsdf``.

Parameterisation (the axes ``knitbake.im_table`` writes)
-------------------------------------------------------
f depends on θ_i, θ_o and φ_o − φ_i only, and G on ω_i·ω_j, so a common rotation about the fiber axis leaves the
integral unchanged: I_M is a function of exactly four numbers, θ_o, θ_j, φ_j − φ_o and λ. The table axes are

=========================  ==================================  =====  =====
name                       variable                            units  wrap
=========================  ==================================  =====  =====
``theta_o``                θ_o = asin(ω_o·t)                   rad    clamp
``theta_j``                θ_j = asin(ω_j·t)                   rad    clamp
``abs_phi_j_minus_phi_o``  |φ_j − φ_o| wrapped into [0, π]     rad    clamp
``log10_lambda``           log10 λ_j                           1      clamp
=========================  ==================================  =====  =====

* θ itself, not cos θ: the paper's (cos θ_j, cos θ_o, cos(θ_j − θ_o), 1/λ_j) cannot tell (θ_j, θ_o) from
  (−θ_j, −θ_o), which f distinguishes whenever a lobe is shifted (α ≠ 0: the M lobes are centred at
  θ_i = 2α − θ_o), and it drops the azimuth, on which the TT lobe depends. The M lobes are Gaussians in θ, so a
  uniform θ grid resolves them equally well at every latitude (a sin θ grid is coarsest at the poles).
* |φ_j − φ_o|: f is exactly even in φ (N_R and D are constant, N_TT depends on |φ − π|), so reflecting ω_i about
  the plane through the fiber axis and ω_o gives I_M(−Δφ) = I_M(Δφ); the half range halves the table.
* log10 λ: I_M falls like 2π/λ for large λ and the SRBF sweeps from wider than the sphere to narrower than the
  lobes over decades of λ; a logarithmic axis spends samples evenly over that sweep (the paper's 1/λ puts almost
  every sample at λ < 10).

Every axis range is chosen so that the first and last cell centres (ASSET_PACK.md §4.2) lie exactly on the ends
of the domain (θ = ±π/2, Δφ = 0 and π, the smallest and largest λ): a lookup inside the domain always
interpolates and never clamps.

Accuracy (lookup against ``knitbake.im_table.im_direct`` at 2000 random points with λ log-uniform in [0.5, 10⁴],
plus λ = 0.5, λ = 10⁴ and θ_o, θ_j within 1.6e-3 rad of ±π/2)
--------------------------------------------------------------------------------------------------------------
Multilinear interpolation reproduces a feature to ~2% when its standard deviation spans ≳ 2.5 sample spacings.
The features are: the M lobes, √(4β² + 1/λ) wide in θ_j and moving with θ_o (centre 2α − θ_o); N_TT in |Δφ|
(logistic scale γ_TT√3/π, widened by the SG); in log λ, the fall-off exp(−λ(1 − cos γ)) of an SRBF at angle γ from
the lobes, which needs ~0.07 decades for λ ≲ 20; and near θ_j = ±π/2 the cos θ_j factor, which levels off at
~1/√λ, so the cell at the pole has large *relative* errors at large λ where I_M is a few % of its peak.

* Rough fiber (β_R 25°, β_TT 35°, γ_TT 80°), shape (16, 40, 12, 64): relative error ≤ 1.2% / 1.6% / 0.5% for
  λ in [0.5, 2] / [2, 20] / [20, 200] wherever I_M > 1% of its overall maximum; at every λ decade up to 10⁴ the
  error is ≤ 0.6% of that decade's largest I_M. Default shape (24, 48, 24, 64): 0.9% / 1.2% / 0.3%, ≤ 0.5%.
* polyester1 (β_R 5.2°, γ_TT 25°), default shape: ≤ 7% / 11% / 16% relative; ≤ 4% of the decade maximum.
* cotton1, silk1 (β_R = 1°), default shape: the R highlight is narrower than the grid above λ ≈ 10 and aliases:
  errors 4–5% of the decade maximum up to λ = 200, 16% to 2000, 75% beyond (samples stay exact).
* β = γ = 1e-3°: samples exact and finite, lookups finite everywhere including θ = ±π/2; the error is 0.9% of the
  decade maximum at λ ≤ 2, 8% at 2–20, 13% at 20–200, 40% at 200–2000 and a multiple of it beyond: such a fiber
  is represented only for λ ≲ 1/(2.5 h)² ≈ 35 (h = 0.067 rad, the default θ_j spacing).
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit, prange

from .table_lookup import axis_cell


def sg(omega, omega_j, lam):
    """Spherical Gaussian G(ω; ω_j, λ) = exp(λ(ω·ω_j − 1)) for unit vectors (last axis 3); broadcasting."""
    return np.exp(np.asarray(lam, float) * (np.sum(np.asarray(omega, float) * np.asarray(omega_j, float), axis=-1)
                                            - 1.0))


# name → (definition written into the pack, units); the order is the axis code of ``im_kernel``
AXIS_VARIABLES = {
    "theta_o": ("θ_o = asin(ω_o·t), longitudinal angle of the view against the fiber tangent", "rad"),
    "theta_j": ("θ_j = asin(ω_j·t), longitudinal angle of the SRBF centre against the fiber tangent", "rad"),
    "abs_phi_j_minus_phi_o": ("|φ_j − φ_o| wrapped into [0, π]: azimuth of the SRBF centre minus azimuth of the view "
                              "(I_M is even in it because f is even in φ)", "rad"),
    "log10_lambda": ("log10 λ_j, λ_j the SRBF sharpness", "1"),
}
AXIS_CODES = {name: code for code, name in enumerate(AXIS_VARIABLES)}  # theta_o, theta_j, |Δφ|, log10 λ


def _field(axis, key):
    """An axis description as a dict (``bake_im_table``'s axes_attrs) or an ``AxisInfo`` (``read_pack``)."""
    return axis[key] if isinstance(axis, dict) else getattr(axis, key)


def kernel_axes(axes):
    """(lo, hi, repeat, codes) arrays for ``im_kernel`` from the four sampled axes of an I_M table (dicts or
    ``AxisInfo``; the channel axis is ignored); ValueError naming the axes for a parameterisation this renderer
    does not implement."""
    sampled = [a for a in axes if _field(a, "name") != "channel"]
    names = [_field(a, "name") for a in sampled]
    if len(sampled) != 4 or any(n not in AXIS_CODES for n in names):
        raise ValueError(f"I_M axes {names}: this renderer implements 4 axes from {sorted(AXIS_CODES)}")
    ranges = np.array([_field(a, "range") for a in sampled], np.float64)
    return (ranges[:, 0].copy(), ranges[:, 1].copy(), np.array([_field(a, "wrap") == "repeat" for a in sampled]),
            np.array([AXIS_CODES[n] for n in names], np.int64))


def im_lookup(table, axes, theta_o, theta_j, dphi, lam):
    """I_M (RGB) from a baked table by multilinear interpolation (ASSET_PACK.md §4.2–4.3, ``im_kernel``, the
    renderer's own lookup); inputs broadcast, result (…, 3).

    table: (N_a, N_b, N_c, N_d, 3); axes: the four sampled axes, as dicts with name, range, wrap (the axes_attrs of
    ``knitbake.im_table.bake_im_table``) or as ``AxisInfo`` of a read pack (``pack.info['environment/I_M'].axes``;
    the channel axis is ignored). θ_o, θ_j in [−π/2, π/2], dphi = φ_j − φ_o (any real), lam > 0 (values outside the
    table's λ range take its end samples). A parameterisation with an axis not in ``AXIS_VARIABLES`` is refused."""
    lo, hi, repeat, codes = kernel_axes(axes)
    args = np.broadcast_arrays(*[np.asarray(x, np.float64) for x in (theta_o, theta_j, dphi, lam)])
    if np.any(~(args[3] > 0)):
        raise ValueError("I_M lookup: λ must be > 0")
    flat = [np.ascontiguousarray(x.ravel()) for x in args]
    out = _im_batch(np.ascontiguousarray(table, np.float64), lo, hi, repeat, codes, *flat)
    return out.reshape(args[0].shape + (3,))


@njit(parallel=True, cache=True)
def _im_batch(table, lo, hi, repeat, codes, theta_o, theta_j, dphi, lam):
    out = np.empty((theta_o.shape[0], 3))
    for k in prange(theta_o.shape[0]):
        im_kernel(table, lo, hi, repeat, codes, theta_o[k], theta_j[k], dphi[k], lam[k], out[k])
    return out


@njit(cache=True)
def im_kernel(table, lo, hi, repeat, codes, theta_o, theta_j, dphi, lam, out):
    """out[:3] = I_M at (θ_o, θ_j, φ_j − φ_o, λ > 0) by multilinear interpolation over the table's four sampled axes
    (the §4.3 rule per axis, ``table_lookup.axis_cell``)."""
    i0 = np.empty(4, np.int64)
    i1 = np.empty(4, np.int64)
    fr = np.empty(4)
    for axis in range(4):
        code = codes[axis]
        if code == 0:
            x = theta_o
        elif code == 1:
            x = theta_j
        elif code == 2:
            x = abs((dphi + math.pi) % (2.0 * math.pi) - math.pi)
        else:
            x = math.log10(lam)
        i0[axis], i1[axis], fr[axis] = axis_cell(x, lo[axis], hi[axis], table.shape[axis], repeat[axis])
    out[:] = 0.0
    idx = np.empty(4, np.int64)
    for bits in range(16):
        w = 1.0
        for axis in range(4):
            if (bits >> axis) & 1:
                w *= fr[axis]
                idx[axis] = i1[axis]
            else:
                w *= 1.0 - fr[axis]
                idx[axis] = i0[axis]
        if w > 0.0:
            for ch in range(3):
                out[ch] += w * table[idx[0], idx[1], idx[2], idx[3], ch]
