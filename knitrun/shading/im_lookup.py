"""Environment light: the spherical Gaussian (SRBF) and the runtime lookup of the I_M table (Huang et al. 2025 §4.5).

Definitions (angles as in ``knitrun.shading.fiber_bcsdf`` and ``data_formats/ASSET_PACK.md`` §3, radians)
--------------------------------------------------------------------------------------------------
* SRBF: G(ω; ω_j, λ) = exp(λ(ω·ω_j − 1)) (Huang et al. 2025 eq. 14), unnormalised: G(ω_j) = 1 and
  ∫ G dω = (2π/λ)(1 − e^{−2λ}).
* I_M(ω_o; ω_j, λ_j) = ∫ G(ω_i; ω_j, λ_j) f(ω_i, ω_o) cos θ_i dω_i (eq. 16), linear RGB, dimensionless;
  f the fiber BCSDF of ``knitrun.shading.fiber_bcsdf``. I_M = I_M^R + I_M^{TT,D}, one term per group of lobes.

Two parts (``im_kernel`` adds them)
-----------------------------------
* I_M^{TT,D}, the TT and D lobes: interpolated in the pack's table ``environment/I_M_TT_D`` (axes below). These
  lobes are wide (β_TT ≥ 10°, γ_TT ≥ 20° in every preset; D is isotropic), so a 4-D table resolves them.
* I_M^R, the R lobe: integrated at lookup time (``r_lobe_integral``). N_R = 1/2π is constant, so the azimuthal
  integral is closed-form and I_M^R is a 1-D integral over θ_i (``knitbake.stages.im_table`` derives it):

      I_M^R = A_R/Z_R ∫ exp(−(θ_i − μ_R)²/(2σ_R²)) cos²θ_i exp(λ(cos(θ_i − θ_j) − 1)) I0e(λ cos θ_i cos θ_j) dθ_i

  over [−π/2, π/2], with μ_R, σ_R, Z_R of the view (``fiber_bcsdf.context``) and I0e(x) = e^{−x} I_0(x). The
  integrand is close to a Gaussian of precision P = 1/σ_R² + λ centred at m = (μ_R/σ_R² + λθ_j)/P. Where that
  Gaussian lies inside the domain (m ± ``R_HERMITE_REACH``/√P within [−π/2, π/2], almost every lookup) the rule is
  ``R_HERMITE_NODES``-point Gauss–Hermite for that Gaussian: the integrand over it is a smooth, slowly varying
  factor (cos²θ_i, I0e, and exp(λ(cos x − 1 + x²/2)) ≈ exp(λx⁴/24) of x = θ_i − θ_j); where the domain cuts it
  (the lobe or the SRBF at a pole) the rule is ``R_NODES``-point Gauss–Legendre on the window m ± ``R_WINDOW``/√P
  clipped to [−π/2, π/2]. Why not a table:
  the presets' R lobe is 1° (σ_R = 2°) wide, and under a sharp SRBF (the sun: λ ≈ 6600, 0.7°) I^R is a 2°-wide
  ridge along θ_j = μ_R(θ_o) in a 3-D domain; resolving it to 2 % takes ~0.015 rad samples on two angle axes, and a
  lobe-centred axis fails where the ridge meets the poles. The rules are within 0.25 % of direct quadrature for
  β_R from 0.001° to 25°, λ from 0.5 to 10⁴ and θ_o, θ_j up to ±π/2 (``tests/test_im_table.py``; measured: the
  4-node Hermite rule within 4.4e-4 wherever it is used, the 12-node Legendre rule within 1.5e-3 at the poles;
  the Hermite rule has a third of the Legendre rule's nodes: BENCHMARKS.md, "Stop 34: the sky's frame from 6.8 to
  4.6 s").

Parameterisation of the I_M^{TT,D} table (the axes ``knitbake.stages.im_table`` writes)
-------------------------------------------------------------------------------
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

Accuracy (random points with λ log-uniform in [0.5, 10⁴], plus λ = 0.5, λ = 10⁴, the R ridge and θ_o, θ_j within
1e-3 rad of ±π/2)
---------------------------------------------------------------------------------------------------------------
Multilinear interpolation reproduces a feature to ~2% when its standard deviation spans ≳ 2.5 sample spacings.
The features of the TT and D table are: the TT lobe, √(4β_TT² + 1/λ) wide in θ_j and moving with θ_o (centre
2α − θ_o); N_TT in |Δφ| (logistic scale γ_TT√3/π, widened by the SG); in log λ, the fall-off exp(−λ(1 − cos γ))
of an SRBF at angle γ from the lobes, which needs ~0.07 decades for λ ≲ 20; and near θ_j = ±π/2 the cos θ_j factor,
which levels off at ~1/√λ, so the cell at the pole has large *relative* errors at large λ where I_M is a few % of its
peak.

I_M as evaluated here (table + R rule) against direct quadrature, by ``knitbake.stages.im_table.lookup_accuracy`` (2000
points; "rel" = max relative error where I_M > 1% of its maximum, "decade" = max error over each λ decade's largest
I_M). Every bake stores these two figures with its table; their values for the bake's quality shapes
(``knitbake.bake.QUALITY``) and several presets are measured in BENCHMARKS.md, section "The bake: speed and error per
quality" (schema 2.0 re-bake).

cotton1's TT lobe is wide (β_TT 27°); silk1, the rayons and polyester1 have β_TT = 10° (σ_TT = 20°) and γ_TT ≈ 20°,
which the standard grid samples at ~2.6 and ~1.7 spacings per standard deviation, so they err more than cotton1 at
the same shape, mostly in the lobes' tails (BENCHMARKS.md). ``tests/test_im_table.py`` holds the issue's target
(rel < 2%, decade < 1%) for a rough fiber (β_R 25°, β_TT 35°, γ_TT 80°) at (16, 40, 12, 64) and for cotton1 at the
standard shape. Schema 1.x tabulated the R lobe too, which no grid of practical size resolves (above; ASSET_PACK.md
§1 history and §9).
"""

from __future__ import annotations

import math
from typing import NamedTuple

import numpy as np
from numba import njit, prange
from numpy.polynomial import chebyshev
from scipy import special

from data_formats.asset_pack import IM_AXES
from data_formats.conventions import HALF_PI
from knitrun.shading import fiber_bcsdf as fb
from knitrun.shading.table_lookup import axis_cell

R_HERMITE_NODES = 4  # Gauss–Hermite nodes of the R-lobe integral (``r_lobe_integral``) inside the domain
R_HERMITE_REACH = 4.0  # ... used where the product Gaussian's centre ± this many standard deviations is inside it
R_NODES = 12  # Gauss–Legendre nodes of the R-lobe integral where the domain cuts the product Gaussian
R_WINDOW = 6.0  # their window: the product Gaussian's centre ± R_WINDOW standard deviations (e^{−18} of the peak)
R_NEGLIGIBLE = 1e-10  # I_M^R / A_R below which (by a bound) the rule is not evaluated
_R_GX, _R_GW = np.polynomial.legendre.leggauss(R_NODES)
_R_HX, _R_HW = np.polynomial.hermite.hermgauss(R_HERMITE_NODES)
_R_HW = _R_HW * np.exp(_R_HX ** 2)  # weights for ∫ g(x) dx = Σ w_k e^{x_k²} g(x_k) (g itself carries its Gaussian)


def sg(omega, omega_j, lam):
    """Spherical Gaussian G(ω; ω_j, λ) = exp(λ(ω·ω_j − 1)) for unit vectors (last axis 3); broadcasting."""
    return np.exp(np.asarray(lam, float) * (np.sum(np.asarray(omega, float) * np.asarray(omega_j, float), axis=-1)
                                            - 1.0))


def sg_integral(lam):
    """∫ G(ω; ω_j, λ) dω = (2π/λ)(1 − e^{−2λ}) over the sphere, for λ > 0 (arrays broadcast)."""
    lam = np.asarray(lam, float)
    return 2.0 * np.pi / np.maximum(lam, 1e-300) * -np.expm1(-2.0 * lam)


# axis name (the asset pack schema's ``IM_AXES``, defined there) → the axis code of ``im_kernel``
AXIS_CODES = {name: code for code, name in enumerate(IM_AXES)}  # theta_o, theta_j, |Δφ|, log10 λ


def _field(axis, key):
    """An axis description as a dict (``bake_im_table``'s axes_attrs) or an ``AxisInfo`` (``read_pack``)."""
    return axis[key] if isinstance(axis, dict) else getattr(axis, key)


class IMTable(NamedTuple):
    """The I_M^{TT,D} table as ``im_kernel`` reads it: ``table`` (N_a, N_b, N_c, N_d, 3) float64 and, per sampled
    axis, ``lo``, ``hi`` (float64), ``repeat`` (bool) and ``codes`` (int64, ``AXIS_CODES``)."""

    table: np.ndarray
    lo: np.ndarray
    hi: np.ndarray
    repeat: np.ndarray
    codes: np.ndarray


class IMSlices(NamedTuple):
    """The I_M^{TT,D} table interpolated at each of J SRBF lobes' λ (``im_slices``), as ``im_slice_kernel`` reads it:
    ``table`` (J, N_1, N_2, N_3, 3) float64 over the three other sampled axes in the table's order, and their ``lo``,
    ``hi`` (float64), ``repeat`` (bool), ``codes`` (int64, ``AXIS_CODES``)."""

    table: np.ndarray
    lo: np.ndarray
    hi: np.ndarray
    repeat: np.ndarray
    codes: np.ndarray


def im_slices(im: IMTable, lambdas) -> IMSlices:
    """The ``IMTable`` interpolated along its log10 λ axis at each λ of ``lambdas`` (J,), > 0: the rule of
    ``im_kernel`` on that axis (``table_lookup.axis_cell``), applied once per lobe instead of per lookup.

    Why: a lobe's λ is the same at every shading point, and multilinear interpolation is separable, so
    ``im_slice_kernel`` on the slice gives ``im_kernel``'s value (to rounding) from 8 corners of a table of a
    ~100th of the size: cotton1's standard table is 64 MB in float64, one slice 0.66 MB, and the shading kernel's
    16 corners per lookup were mostly cache misses."""
    lambdas = np.asarray(lambdas, np.float64).reshape(-1)
    if np.any(~(lambdas > 0)) or not np.all(np.isfinite(lambdas)):
        raise ValueError("I_M slices: every λ must be finite and > 0")
    k = int(np.flatnonzero(im.codes == AXIS_CODES["log10_lambda"])[0])
    other = [a for a in range(4) if a != k]
    out = np.empty((len(lambdas),) + tuple(im.table.shape[a] for a in other) + (3,))
    for j, lam in enumerate(lambdas):
        i0, i1, f = axis_cell(math.log10(lam), im.lo[k], im.hi[k], im.table.shape[k], bool(im.repeat[k]))
        out[j] = (1.0 - f) * np.take(im.table, i0, axis=k) + f * np.take(im.table, i1, axis=k)
    return IMSlices(out, im.lo[other].copy(), im.hi[other].copy(), im.repeat[other].copy(), im.codes[other].copy())


def im_table_from(table, axes) -> IMTable:
    """An ``IMTable`` from a table and its axes (``kernel_axes``)."""
    return IMTable(np.ascontiguousarray(table, np.float64), *kernel_axes(axes))


def no_im_table() -> IMTable:
    """A table of zeros: the stand-in a kernel receives when the scene has no environment light."""
    return IMTable(np.zeros((1, 1, 1, 1, 3)), np.zeros(4), np.ones(4), np.zeros(4, np.bool_),
                   np.arange(4, dtype=np.int64))


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


def im_lookup(table, axes, params, theta_o, theta_j, dphi, lam):
    """I_M (RGB) as the renderer evaluates it (``im_kernel``): the I_M^{TT,D} table by multilinear interpolation
    (ASSET_PACK.md §4.2–4.3) plus the R lobe by ``r_lobe_integral``; inputs broadcast, result (…, 3).

    table: (N_a, N_b, N_c, N_d, 3), the TT and D lobes; axes: its four sampled axes, as dicts with name, range, wrap
    (the axes_attrs of ``knitbake.stages.im_table.bake_im_table``) or as ``AxisInfo`` of a read pack
    (``pack.info['environment/I_M_TT_D'].axes``; the channel axis is ignored). params: the fiber BCSDF vector the
    table was baked for (its R lobe is integrated here). θ_o, θ_j in [−π/2, π/2], dphi = φ_j − φ_o (any real),
    lam > 0 (values outside the table's λ range take its end samples). A parameterisation with an axis not in
    ``data_formats.asset_pack.IM_AXES`` is refused."""
    im = im_table_from(table, axes)
    args = np.broadcast_arrays(*[np.asarray(x, np.float64) for x in (theta_o, theta_j, dphi, lam)])
    if np.any(~(args[3] > 0)):
        raise ValueError("I_M lookup: λ must be > 0")
    flat = [np.ascontiguousarray(x.ravel()) for x in args]
    out = _im_batch(im, np.asarray(params, np.float64), *flat)
    return out.reshape(args[0].shape + (3,))


@njit(parallel=True, cache=True)
def _im_batch(im, params, theta_o, theta_j, dphi, lam):
    out = np.empty((theta_o.shape[0], 3))
    for k in prange(theta_o.shape[0]):
        c = fb.view_context(params, theta_o[k])
        im_kernel(im, params, c, theta_o[k], theta_j[k], dphi[k], lam[k], out[k])
    return out


def _i0e_chebyshev():
    """Chebyshev coefficients of e^{−x} I_0(x) on [0, ``I0E_SPLIT``] in y = 2x/split − 1, and of √x e^{−x} I_0(x)
    on [split, ∞) in y = 2·split/x − 1, interpolated at Chebyshev points from ``scipy.special.i0e`` (degrees for
    ~2e-14 relative, ``tests/test_im_table.py``)."""
    near = chebyshev.chebinterpolate(lambda y: special.i0e(0.5 * I0E_SPLIT * (y + 1.0)), 26)
    far = chebyshev.chebinterpolate(
        lambda y: np.sqrt(2.0 * I0E_SPLIT / (y + 1.0)) * special.i0e(2.0 * I0E_SPLIT / (y + 1.0)), 16)
    return np.ascontiguousarray(near), np.ascontiguousarray(far)


I0E_SPLIT = 8.0
_I0E_NEAR, _I0E_FAR = _i0e_chebyshev()


@njit(cache=True, inline='always')
def _clenshaw(coef, y):
    """Σ coef[k] T_k(y) by Clenshaw's recurrence."""
    b1, b2 = 0.0, 0.0
    for k in range(coef.shape[0] - 1, 0, -1):
        b1, b2 = 2.0 * y * b1 - b2 + coef[k], b1
    return y * b1 - b2 + coef[0]


@njit(cache=True)
def i0e(x):
    """Exponentially scaled modified Bessel function e^{−x} I_0(x) for x ≥ 0, to ~2e-14 relative: Chebyshev series
    (``_i0e_chebyshev``) on [0, 8] and, times 1/√x, beyond; a fixed number of multiply-adds, no loop to
    convergence (the R rule evaluates it at each of its nodes)."""
    if x <= I0E_SPLIT:
        return _clenshaw(_I0E_NEAR, x * (2.0 / I0E_SPLIT) - 1.0)
    return _clenshaw(_I0E_FAR, 2.0 * I0E_SPLIT / x - 1.0) / math.sqrt(x)


@njit(cache=True)
def r_lobe_integral(c, theta_j, lam):
    """∫ M_R N_R G cos θ_i dω_i without the albedo A_R (the module docstring's I_M^R / A_R) for the view of context
    ``c`` (``fiber_bcsdf.context``), θ_j ∈ [−π/2, π/2], λ > 0: ``R_HERMITE_NODES``-point Gauss–Hermite for the product
    of the R lobe and the SRBF where it lies inside the domain, else ``R_NODES``-point Gauss–Legendre on its clipped
    window (module docstring), or 0 when a bound puts the integral below
    ``R_NEGLIGIBLE`` (the lobe and the SRBF far apart, the common case under a sun-sized SRBF). Finite and ≥ 0 for
    every input in range."""
    mu, sigma, z = c[fb.C_MU], c[fb.C_SIGMA], c[fb.C_Z]
    # A bound first: with cos²θ_i ≤ 1, I0e ≤ 1 and 1 − cos x ≥ 2x²/π² (|x| ≤ π), the integrand is at most the product
    # of two Gaussians in θ_i, whose peak is exp(−(μ − θ_j)²/(2σ² + π²/(2λ))), so the integral is at most π/Z times
    # that: below ``R_NEGLIGIBLE`` the lobe and the SRBF do not meet and the rule is skipped.
    if (mu - theta_j) ** 2 > -math.log(R_NEGLIGIBLE * z / math.pi) * (2.0 * sigma * sigma + math.pi ** 2 / (2.0 * lam)):
        return 0.0
    precision = 1.0 / (sigma * sigma) + lam
    centre = (mu / (sigma * sigma) + lam * theta_j) / precision
    sd = 1.0 / math.sqrt(precision)
    cos_j = max(math.cos(theta_j), 0.0)
    if -HALF_PI <= centre - R_HERMITE_REACH * sd and centre + R_HERMITE_REACH * sd <= HALF_PI:
        scale = math.sqrt(2.0) * sd  # θ_i = m + √2 sd x: the Hermite weight e^{−x²} is the product Gaussian
        total = 0.0
        for q in range(_R_HX.shape[0]):
            total += _R_HW[q] * _r_integrand(centre + scale * _R_HX[q], mu, sigma, theta_j, cos_j, lam)
        return scale * total / z
    lo = max(-HALF_PI, centre - R_WINDOW * sd)
    hi = min(HALF_PI, centre + R_WINDOW * sd)
    if hi <= lo:
        return 0.0
    half, mid = 0.5 * (hi - lo), 0.5 * (hi + lo)
    total = 0.0
    for q in range(_R_GX.shape[0]):
        total += _R_GW[q] * _r_integrand(mid + half * _R_GX[q], mu, sigma, theta_j, cos_j, lam)
    return half * total / z


@njit(cache=True, inline='always')
def _r_integrand(t, mu, sigma, theta_j, cos_j, lam):
    """The R rule's integrand at θ_i = t (module docstring) without 1/Z_R; cos_j = max(cos θ_j, 0)."""
    ct = math.cos(t)
    return (math.exp(-0.5 * ((t - mu) / sigma) ** 2 + lam * (math.cos(t - theta_j) - 1.0))
            * ct * ct * i0e(lam * max(ct, 0.0) * cos_j))


@njit(cache=True, inline='always')
def _axis_at(code, lo, hi, n, repeat, theta_o, theta_j, dphi, lam):
    """(i0, i1, fraction) on a sampled axis of code ``code`` (``AXIS_CODES``) and n samples over [lo, hi]."""
    if code == 0:
        x = theta_o
    elif code == 1:
        x = theta_j
    elif code == 2:
        x = abs((dphi + math.pi) % (2.0 * math.pi) - math.pi)
    else:
        x = math.log10(lam)
    return axis_cell(x, lo, hi, n, repeat)


@njit(cache=True, inline='always')
def _add_r_lobe(params, c, theta_j, lam, out):
    """out[:3] += A_R times ``r_lobe_integral`` (skipped for a fiber without an R lobe)."""
    if params[fb.P_A_R] > 0.0 or params[fb.P_A_R + 1] > 0.0 or params[fb.P_A_R + 2] > 0.0:
        r = r_lobe_integral(c, min(max(theta_j, -HALF_PI), HALF_PI), lam)
        for ch in range(3):
            out[ch] += params[fb.P_A_R + ch] * r


@njit(cache=True, inline='always')
def im_kernel(im, params, c, theta_o, theta_j, dphi, lam, out):
    """out[:3] = I_M at (θ_o, θ_j, φ_j − φ_o, λ > 0): the ``IMTable`` ``im`` by multilinear interpolation over its four
    sampled axes (the §4.3 rule per axis, ``table_lookup.axis_cell``) plus A_R times ``r_lobe_integral``. ``c`` is
    ``fiber_bcsdf.context`` of ``params`` for a view at θ_o (the caller's, so a shading point pays for it once); only
    its R-lobe entries are read, so ``fiber_bcsdf.r_lobe_context_into`` suffices."""
    table, lo, hi, repeat, codes = im
    a0, a1, fa = _axis_at(codes[0], lo[0], hi[0], table.shape[0], repeat[0], theta_o, theta_j, dphi, lam)
    b0, b1, fb_ = _axis_at(codes[1], lo[1], hi[1], table.shape[1], repeat[1], theta_o, theta_j, dphi, lam)
    c0, c1, fc = _axis_at(codes[2], lo[2], hi[2], table.shape[2], repeat[2], theta_o, theta_j, dphi, lam)
    d0, d1, fd = _axis_at(codes[3], lo[3], hi[3], table.shape[3], repeat[3], theta_o, theta_j, dphi, lam)
    out[:] = 0.0
    for bits in range(16):  # the 16 corners, each weight a product in axis order
        w = fa if bits & 1 else 1.0 - fa
        w *= fb_ if bits & 2 else 1.0 - fb_
        w *= fc if bits & 4 else 1.0 - fc
        w *= fd if bits & 8 else 1.0 - fd
        if w > 0.0:
            ia, ib = (a1 if bits & 1 else a0), (b1 if bits & 2 else b0)
            ic, id_ = (c1 if bits & 4 else c0), (d1 if bits & 8 else d0)
            for ch in range(3):
                out[ch] += w * table[ia, ib, ic, id_, ch]
    _add_r_lobe(params, c, theta_j, lam, out)


@njit(cache=True, inline='always')
def im_slice_kernel(im, j, params, c, theta_o, theta_j, dphi, lam, out):
    """``im_kernel`` for SRBF lobe j of the ``IMSlices`` ``im`` (built for the lobes' λ; ``lam`` is lobe j's λ, for the
    R rule): trilinear interpolation over the slice's three axes plus A_R times ``r_lobe_integral``."""
    table, lo, hi, repeat, codes = im
    a0, a1, fa = _axis_at(codes[0], lo[0], hi[0], table.shape[1], repeat[0], theta_o, theta_j, dphi, lam)
    b0, b1, fb_ = _axis_at(codes[1], lo[1], hi[1], table.shape[2], repeat[1], theta_o, theta_j, dphi, lam)
    c0, c1, fc = _axis_at(codes[2], lo[2], hi[2], table.shape[3], repeat[2], theta_o, theta_j, dphi, lam)
    out[:] = 0.0
    for bits in range(8):  # the 8 corners, each weight a product in axis order
        w = fa if bits & 1 else 1.0 - fa
        w *= fb_ if bits & 2 else 1.0 - fb_
        w *= fc if bits & 4 else 1.0 - fc
        if w > 0.0:
            ia, ib, ic = (a1 if bits & 1 else a0), (b1 if bits & 2 else b0), (c1 if bits & 4 else c0)
            for ch in range(3):
                out[ch] += w * table[j, ia, ib, ic, ch]
    _add_r_lobe(params, c, theta_j, lam, out)
