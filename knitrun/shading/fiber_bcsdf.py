"""The fiber BCSDF f = Σ_{p ∈ R, TT, D} A_p M_p N_p (Huang et al. 2025 eq. 7): the one definition baker and renderer
share.

Angle conventions (the same as ``data_formats/ASSET_PACK.md`` §3)
-----------------------------------------------------------------
* Local frame of a fiber: x = the fiber tangent t; y, z span its normal plane (any orthonormal choice).
* For a unit direction ω pointing away from the fiber: sin θ = ω·t (θ ∈ [−π/2, π/2], longitudinal) and
  φ = atan2(ω_z, ω_y) (azimuth). ω_i points toward the light, ω_o toward the viewer; θ_h = (θ_i + θ_o)/2,
  θ_d = (θ_o − θ_i)/2, φ = φ_o − φ_i.
* Scattered radiance: L_o(ω_o) = ∫ f(ω_i, ω_o) L_i(ω_i) cos θ_i dω_i, with dω = cos θ dθ dφ.

Lobes
-----
* M_R, M_TT: Gaussians in θ_h with shift α_p and width β_p, i.e. exp(−(θ_i − μ_p)² / (2σ_p²)) with
  μ_p = 2α_p − θ_o and σ_p = 2β_p, divided by Z_p(θ_o) = ∫ exp(−(θ_i − μ_p)²/(2σ_p²)) cos² θ_i dθ_i over
  [−π/2, π/2]. This normalisation makes ∫ A_p M_p N_p cos θ_i dω_i = A_p exactly for every ω_o, so with
  A_R + A_TT + A_D = 1 (no absorption) the white furnace returns 1. The lobe centre is clamped to at most 4σ_p
  beyond ±π/2 (only reached at grazing θ_o with a shift), which keeps Z_p well conditioned.
* N_R = 1/(2π) (reflection from the whole fiber width spreads over all azimuths); N_TT: a logistic lobe around
  φ = π, trimmed to [−π, π] and renormalised, whose standard deviation is γ_TT.
* D: A_D/π² for every pair of directions (isotropic in-fiber multiple scattering; ∫ cos θ_i dω_i = π²).
* A_p are RGB lobe albedos in [0, 1]; A_R + A_TT + A_D is the fiber's albedo (1 − absorption).

The BCSDF is not exactly reciprocal: Z_p depends on θ_o, so f(ω_i, ω_o)/f(ω_o, ω_i) = Z_p(θ_i)/Z_p(θ_o), which
is 1 wherever the lobe lies inside (−π/2, π/2) and drifts only at grazing angles.

Sampling picks a lobe with probability ∝ mean(A_p), then θ_i from the truncated Gaussian exp(−(θ_i − μ_p)²/(2σ_p²))
on [−π/2, π/2] (inverse CDF), φ from N_p exactly; D samples the sphere uniformly. ``pdf`` is the mixture density
over solid angle, so weight = f cos θ_i / pdf. Parameters are a float64 vector (``N_PARAMS``, layout ``P_*``) and
a per-ω_o context (``context``), so kernels pay for Z_p once per shading point. ``context_into``, ``evaluate``,
``pdf`` and ``sample`` are inlined into the kernels that call them (Numba ``inline='always'``): a call would
increment and decrement the reference count of every array it is passed, which cost the path tracer 16 % of its
time (``knitbake.trace.path_tracer``, "Threads").
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit, prange

from data_formats.conventions import HALF_PI
from data_formats.yarn_spec import fiber_bcsdf_attrs
from knitrun.shading.fiber_frame import clamped_asin, wrap_angle

# Parameter vector layout (radians).
P_A_R, P_A_TT, P_A_D = 0, 3, 6
P_BETA_R, P_BETA_TT, P_GAMMA_TT, P_ALPHA_R, P_ALPHA_TT = 9, 10, 11, 12, 13
N_PARAMS = 14
# Context layout: per outgoing direction.
C_SIN_O, C_COS_O, C_PHI_O = 0, 1, 2
C_MU, C_SIGMA, C_Z, C_MASS = 3, 5, 7, 9  # two entries each: [R, TT]
C_PROB = 11  # three entries: R, TT, D
N_CONTEXT = 14

INV_PI2 = 1.0 / (math.pi * math.pi)
SQRT2 = math.sqrt(2.0)
LOBE_WINDOW = 9.0  # a longitudinal lobe is integrated over μ ± LOBE_WINDOW σ (beyond it: < e^{−40} of its peak)
COS_FLOOR = 1e-12  # cos θ_i floor in the solid-angle pdf (θ_i = ±π/2 exactly)
_GL_X, _GL_W = np.polynomial.legendre.leggauss(32)  # Z to < 1e-9 relative for every σ ≥ 1e-4, μ
FADDEEVA_TERMS = 32  # Weideman's expansion: |w| to 3e-13 relative over the half plane the normaliser uses
NORMALISER_CLOSED_SIGMA = 0.03  # rad: narrower lobes cut by an end are normalised by quadrature
NORMALISER_WIDE_SIGMA = 0.5  # rad: wider lobes cut at both ends by the 16-node rule on [−π/2, π/2] (4e-11 relative)
# where the table below does not reach them (σ > 8 rad, or a centre beyond the clamp of ``lobe_centre``)
_WIDE_X, _WIDE_W = np.polynomial.legendre.leggauss(16)
_WIDE_X, _WIDE_W = HALF_PI * _WIDE_X, HALF_PI * _WIDE_W * np.cos(HALF_PI * _WIDE_X) ** 2  # nodes, weights × cos²
NORMALISER_TABLE_SIGMA = (0.1, 8.0)  # rad: lobes of σ in this range are normalised from a table of log Z
NORMALISER_TABLE_SHAPE = (129, 129)  # nodes in a = |μ|/(π/2 + 4σ) ∈ [0, 1] and in log σ
NORMALISER_TABLE_ERROR = 7e-7  # bound on the table's relative error (5.7e-7 measured): a lobe's ∫ M cos²θ dθ is 1 to it


def params_from_optics(optics) -> np.ndarray:
    """Parameter vector from a yarn spec's ``Optics`` (angles in degrees there, converted by
    ``data_formats.yarn_spec.fiber_bcsdf_attrs``)."""
    return params_from_pack(fiber_bcsdf_attrs(optics))


def params_from_pack(fiber_bcsdf: dict) -> np.ndarray:
    """Parameter vector from an asset pack's ``/fiber_bcsdf`` attributes (radians there)."""
    b = fiber_bcsdf
    return params_from_values(b["r_color"], b["tt_color"], b["d_color"], b["beta_r"], b["beta_tt"], b["gamma_tt"],
                              b["alpha_r"], b["alpha_tt"])


def tinted(params, colour) -> np.ndarray:
    """A copy of ``params`` with every lobe albedo A_R, A_TT, A_D multiplied by the RGB ``colour`` (a scene entry's
    yarn colour: f is linear in the albedos)."""
    p = np.array(params, dtype=np.float64)
    colour = np.asarray(colour, np.float64)
    for base in (P_A_R, P_A_TT, P_A_D):
        p[base:base + 3] *= colour
    return p


@njit(cache=True)
def spread_params(p, spread2, phi, out):
    """``out`` = ``p`` with the longitudinal widths widened for a bundle of fibers whose tangents scatter about the
    shading tangent with variance ``spread2`` (rad², per axis normal to it), seen at azimuth difference φ.

    A tangent tilted by a small δ normal to it moves θ_i by (ω̂_i·δ) and θ_o by (ω̂_o·δ), ω̂ the unit projection of ω
    on the normal plane; a lobe is a Gaussian in θ_i − (2α − θ_o), which moves by (ω̂_i + ω̂_o)·δ, of variance
    spread2·|ω̂_i + ω̂_o|² = 4 spread2 cos²(φ/2). With σ_p = 2β_p that is β_p² → β_p² + spread2 cos²(φ/2): a tilt
    spreads reflection (φ near 0) fully and forward transmission (φ near ±π) not at all. The lobe stays normalised
    (Z_p is computed from the widened σ_p), so the widening moves energy in θ and never adds any (Toksvig 2005 and
    Olano and Baker 2010 filter normal-mapped highlights by the same variance sum)."""
    for k in range(p.shape[0]):  # element by element: a whole-array assignment compiles a shape check
        out[k] = p[k]
    grow = spread2 * math.cos(0.5 * phi) ** 2
    out[P_BETA_R] = math.sqrt(p[P_BETA_R] ** 2 + grow)
    out[P_BETA_TT] = math.sqrt(p[P_BETA_TT] ** 2 + grow)


def params_from_values(a_r, a_tt, a_d, beta_r, beta_tt, gamma_tt, alpha_r=0.0, alpha_tt=0.0) -> np.ndarray:
    p = np.zeros(N_PARAMS)
    p[P_A_R:P_A_R + 3], p[P_A_TT:P_A_TT + 3], p[P_A_D:P_A_D + 3] = a_r, a_tt, a_d
    p[P_BETA_R], p[P_BETA_TT], p[P_GAMMA_TT] = beta_r, beta_tt, gamma_tt
    p[P_ALPHA_R], p[P_ALPHA_TT] = alpha_r, alpha_tt
    if not np.all(np.isfinite(p)) or min(beta_r, beta_tt, gamma_tt) <= 0 or np.any(p[:9] < 0):
        raise ValueError(f"fiber BCSDF parameters must be finite, widths > 0 and colours ≥ 0: {p.tolist()}")
    return p


# --- special functions -------------------------------------------------------------------------------------------

@njit(cache=True)
def _erfcinv(y):
    """Inverse complementary error function for y in (0, 2): Giles' single-precision start, Newton to convergence."""
    if y >= 2.0:
        return -30.0
    if y <= 0.0:
        return 30.0
    if y > 1.0:
        return -_erfcinv(2.0 - y)
    w = -math.log(y * (2.0 - y))
    x = 1.0 - y
    if w < 5.0:
        w -= 2.5
        p = 2.81022636e-08
        p = 3.43273939e-07 + p * w
        p = -3.5233877e-06 + p * w
        p = -4.39150654e-06 + p * w
        p = 0.00021858087 + p * w
        p = -0.00125372503 + p * w
        p = -0.00417768164 + p * w
        p = 0.246640727 + p * w
        p = 1.50140941 + p * w
    else:
        w = math.sqrt(w) - 3.0
        p = -0.000200214257
        p = 0.000100950558 + p * w
        p = 0.00134934322 + p * w
        p = -0.00367342844 + p * w
        p = 0.00573950773 + p * w
        p = -0.0076224613 + p * w
        p = 0.00943887047 + p * w
        p = 1.00167406 + p * w
        p = 2.83297682 + p * w
    x = p * x
    for _ in range(8):
        d = 1.1283791670955126 * math.exp(-x * x)
        if d <= 0.0:
            break
        step = (math.erfc(x) - y) / d
        x += step
        if abs(step) <= 1e-15 * max(1.0, abs(x)):
            break
    return x


@njit(cache=True)
def _normal_mass(a, b):
    """Φ(b) − Φ(a) for standard normal Φ, accurate when both bounds lie in the same tail."""
    if a >= 0.0:
        return 0.5 * (math.erfc(a / SQRT2) - math.erfc(b / SQRT2))
    if b <= 0.0:
        return 0.5 * (math.erfc(-b / SQRT2) - math.erfc(-a / SQRT2))
    return 0.5 * (math.erf(b / SQRT2) - math.erf(a / SQRT2))


@njit(cache=True)
def _normal_sample(a, b, u):
    """Standard normal restricted to [a, b], by inverse CDF with u in [0, 1)."""
    if a >= 0.0:  # upper tail: mirror into the lower tail, where Φ is accurate
        return -_normal_sample(-b, -a, 1.0 - u)
    lo = 0.5 * math.erfc(-a / SQRT2)  # Φ(a)
    p = lo + u * _normal_mass(a, b)
    if p <= 0.5:
        x = -SQRT2 * _erfcinv(2.0 * p)
    else:  # 1 − p from the upper side to keep precision
        q = 0.5 * math.erfc(a / SQRT2) - u * _normal_mass(a, b)
        x = SQRT2 * _erfcinv(2.0 * q)
    return min(max(x, a), b)


@njit(cache=True)
def lobe_centre(alpha, sigma, sin_o):
    """Centre μ = 2α − θ_o of a longitudinal lobe (θ_o = asin(sin_o)), clamped to at most 4σ beyond ±π/2."""
    return lobe_centre_at(alpha, sigma, clamped_asin(sin_o))


@njit(cache=True)
def lobe_centre_at(alpha, sigma, theta_o):
    """``lobe_centre`` for a known θ_o ∈ [−π/2, π/2]."""
    return min(max(2.0 * alpha - theta_o, -HALF_PI - 4.0 * sigma), HALF_PI + 4.0 * sigma)


@njit(cache=True)
def lobe_window(mu, sigma):
    """(lo, hi): the lobe's window μ ± ``LOBE_WINDOW``·σ clipped to [−π/2, π/2]."""
    return max(-HALF_PI, mu - LOBE_WINDOW * sigma), min(HALF_PI, mu + LOBE_WINDOW * sigma)


def _weideman_coefficients(n):
    """Coefficients (highest power first) and scale L of Weideman's rational expansion of the Faddeeva function
    (Weideman 1994, "Computation of the complex error function", SIAM J. Numer. Anal. 31(5), eq. 3.8): w(z) =
    2 p(Z)/(L − iz)² + (1/√π)/(L − iz), Z = (L + iz)/(L − iz), p of degree n − 1, for Im z ≥ 0."""
    m = 2 * n
    k = np.arange(-m + 1, m)
    scale = math.sqrt(n / math.sqrt(2.0))
    t = scale * np.tan(0.5 * k * math.pi / m)
    f = np.concatenate([[0.0], np.exp(-t * t) * (scale * scale + t * t)])
    a = np.real(np.fft.fft(np.fft.fftshift(f))) / (2 * m)
    return np.ascontiguousarray(a[1:n + 1][::-1]), scale


_W_COEF, _W_L = _weideman_coefficients(FADDEEVA_TERMS)
_INV_SQRT_PI = 1.0 / math.sqrt(math.pi)


def _normaliser_table(shape=NORMALISER_TABLE_SHAPE):
    """(log Z on the nodes, a step, first log σ, log σ step) for ``_tabulated_normaliser``: nodes a = i·h_a
    (i = −1 … n_a, one node beyond each end so that every cell has four nodes per axis; a < 0 mirrors a > 0, Z being
    even in μ) and log σ evenly over ``NORMALISER_TABLE_SIGMA``, likewise extended. Z by 400-point Gauss–Legendre
    over the lobe's window inside [−π/2, π/2] (``lobe_window``; exact to rounding for σ ≥ 0.09)."""
    n_a, n_s = shape
    h_a = 1.0 / (n_a - 1)
    log_lo, log_hi = math.log(NORMALISER_TABLE_SIGMA[0]), math.log(NORMALISER_TABLE_SIGMA[1])
    h_s = (log_hi - log_lo) / (n_s - 1)
    sigma = np.exp(log_lo + h_s * np.arange(-1, n_s + 1))[None, :]
    mu = h_a * np.arange(-1, n_a + 1)[:, None] * (HALF_PI + 4.0 * sigma)
    lo, hi = np.maximum(-HALF_PI, mu - LOBE_WINDOW * sigma), np.minimum(HALF_PI, mu + LOBE_WINDOW * sigma)
    x, w = np.polynomial.legendre.leggauss(400)
    t = 0.5 * (hi + lo)[..., None] + 0.5 * (hi - lo)[..., None] * x
    z = 0.5 * (hi - lo) * ((np.exp(-0.5 * ((t - mu[..., None]) / sigma[..., None]) ** 2) * np.cos(t) ** 2) @ w)
    return np.ascontiguousarray(np.log(z)), h_a, log_lo, h_s


_LOG_Z, _Z_HA, _Z_S0, _Z_HS = _normaliser_table()


@njit(cache=True, inline='always')
def _lagrange4(t, k):
    """Weight of node k ∈ {0, 1, 2, 3} (at −1, 0, 1, 2) in the cubic through four equispaced nodes, at t ∈ [0, 1]."""
    if k == 0:
        return -t * (t - 1.0) * (t - 2.0) / 6.0
    if k == 1:
        return 0.5 * (t + 1.0) * (t - 1.0) * (t - 2.0)
    if k == 2:
        return -0.5 * (t + 1.0) * t * (t - 2.0)
    return (t + 1.0) * t * (t - 1.0) / 6.0


@njit(cache=True)
def _tabulated_log_normaliser(a, log_sigma):
    """log Z at a = |μ|/(π/2 + 4σ) ∈ [0, 1] and log σ inside the table (``_normaliser_table``), interpolated by the
    cubic through 4 × 4 nodes (error O(h⁴); Z within 6e-7 relative at most, 1e-8 median)."""
    fa = a / _Z_HA
    fb = (log_sigma - _Z_S0) / _Z_HS
    ia = min(int(fa), _LOG_Z.shape[0] - 4)
    ib = min(max(int(fb), 0), _LOG_Z.shape[1] - 4)
    ta, tb = fa - ia, fb - ib
    wb0, wb1, wb2, wb3 = _lagrange4(tb, 0), _lagrange4(tb, 1), _lagrange4(tb, 2), _lagrange4(tb, 3)
    log_z = 0.0
    for i in range(4):
        row = (wb0 * _LOG_Z[ia + i, ib] + wb1 * _LOG_Z[ia + i, ib + 1] + wb2 * _LOG_Z[ia + i, ib + 2]
               + wb3 * _LOG_Z[ia + i, ib + 3])
        log_z += _lagrange4(ta, i) * row
    return log_z


@njit(cache=True)
def _faddeeva_upper(x, y):
    """Re w(x + iy) for y ≥ 0, w(z) = e^{−z²} erfc(−iz) the Faddeeva function (``_weideman_coefficients``)."""
    iz = complex(-y, x)
    den = _W_L - iz
    zz = (_W_L + iz) / den
    p = complex(0.0, 0.0)
    for k in range(_W_COEF.shape[0]):
        p = p * zz + _W_COEF[k]
    return (2.0 * p / (den * den) + _INV_SQRT_PI / den).real


@njit(cache=True)
def _cos2_tail(d, sigma):
    """∫_{π/2}^{∞} exp(−(θ − μ)²/(2σ²)) cos²θ dθ for d = π/2 − μ (the lobe's part beyond one end of the domain):
    with y = θ − π/2, cos²θ = (1 − cos 2y)/2, and completing the square,
    ½σ√(π/2) [erfc(d/(σ√2)) − Re(e^{−d²/(2σ²)} w(√2σ + i d/(σ√2)))], w the Faddeeva function; for d < 0 through
    w(z) = 2e^{−z²} − w(−z) and w(−z̄) = conj w(z), so nothing overflows."""
    x = SQRT2 * sigma
    y = d / (SQRT2 * sigma)
    if y >= 0.0:
        scaled = math.exp(-y * y) * _faddeeva_upper(x, y)
    else:
        scaled = 2.0 * math.exp(-x * x) * math.cos(2.0 * x * y) - math.exp(-y * y) * _faddeeva_upper(x, -y)
    return 0.5 * sigma * math.sqrt(0.5 * math.pi) * (math.erfc(y) - scaled)


@njit(cache=True)
def cos2_normaliser(mu, sigma):
    """Z = ∫_{−π/2}^{π/2} exp(−(θ − μ)²/(2σ²)) cos²θ dθ over the lobe's window (``lobe_window``), in closed form:
    over the whole line it is ½√(2π)σ (1 + e^{−2σ²} cos 2μ) (cos²θ = (1 + cos 2θ)/2 against the Gaussian's
    characteristic function), exact when the window lies inside [−π/2, π/2]; a window cut by an end loses that end's
    tail (``_cos2_tail``, through the Faddeeva function). Both parts lose digits to cancellation for a narrow lobe at
    an end (Z ∝ σ³ there), so below ``NORMALISER_CLOSED_SIGMA`` a cut window is integrated by Gauss–Legendre instead;
    a lobe wider than ``NORMALISER_WIDE_SIGMA`` cut at both ends is a smooth integrand on the whole domain, where 16
    fixed nodes (cos² folded into their weights) are cheaper than two tails. For σ in ``NORMALISER_TABLE_SIGMA``
    (the TT, back-scattering and forward-spread lobes of a matte yarn, and R lobes widened by a tangent spread: most
    of a shading point's normalisers) a table of log Z built at import is cheaper than either (a log, an exp and 16
    multiply-adds instead of 16 exps or two Faddeeva tails: 26 ns against 50–190 ns a call on one core).
    Agrees with direct quadrature to 3e-8 relative, the table to 6e-7 (``tests/test_fiber_bcsdf.py``)."""
    if NORMALISER_TABLE_SIGMA[0] <= sigma <= NORMALISER_TABLE_SIGMA[1]:
        a = abs(mu) / (HALF_PI + 4.0 * sigma)
        if a <= 1.0:
            return math.exp(_tabulated_log_normaliser(a, math.log(sigma)))
    return _computed_normaliser(mu, sigma)


@njit(cache=True)
def log_cos2_normaliser(mu, sigma):
    """log Z of ``cos2_normaliser``: the table's value itself where the table applies (no exp and log), so a
    normalised lobe exp(−(θ − μ)²/(2σ²))/Z costs one exp."""
    if NORMALISER_TABLE_SIGMA[0] <= sigma <= NORMALISER_TABLE_SIGMA[1]:
        a = abs(mu) / (HALF_PI + 4.0 * sigma)
        if a <= 1.0:
            return _tabulated_log_normaliser(a, math.log(sigma))
    return math.log(_computed_normaliser(mu, sigma))


@njit(cache=True)
def _computed_normaliser(mu, sigma):
    """``cos2_normaliser`` where the table does not apply: closed form, tails, or quadrature."""
    lo_cut = mu - LOBE_WINDOW * sigma < -HALF_PI
    hi_cut = mu + LOBE_WINDOW * sigma > HALF_PI
    if (lo_cut or hi_cut) and sigma < NORMALISER_CLOSED_SIGMA:
        return _cos2_quadrature(mu, sigma)
    if lo_cut and hi_cut and sigma >= NORMALISER_WIDE_SIGMA:
        z = 0.0
        for k in range(_WIDE_X.shape[0]):
            z += _WIDE_W[k] * math.exp(-0.5 * ((_WIDE_X[k] - mu) / sigma) ** 2)
        return z
    z = 0.5 * math.sqrt(2.0 * math.pi) * sigma * (1.0 + math.exp(-2.0 * sigma * sigma) * math.cos(2.0 * mu))
    if hi_cut:
        z -= _cos2_tail(HALF_PI - mu, sigma)
    if lo_cut:
        z -= _cos2_tail(HALF_PI + mu, sigma)
    return z


@njit(cache=True)
def _cos2_quadrature(mu, sigma):
    """Z of ``cos2_normaliser`` by ``_GL_X``-point Gauss–Legendre over the window's part inside [−π/2, π/2]."""
    lo, hi = lobe_window(mu, sigma)
    half, mid = 0.5 * (hi - lo), 0.5 * (hi + lo)
    z = 0.0
    for k in range(_GL_X.shape[0]):
        t = mid + half * _GL_X[k]
        c = math.cos(t)
        z += _GL_W[k] * math.exp(-0.5 * ((t - mu) / sigma) ** 2) * c * c
    return z * half


@njit(cache=True)
def tt_logistic_scale(gamma_tt):
    """Scale s of the TT lobe's logistic N_TT, whose standard deviation is γ_TT = sπ/√3: s = γ_TT √3/π."""
    return gamma_tt * math.sqrt(3.0) / math.pi


@njit(cache=True)
def logistic_trimmed(x, s):
    """Logistic density of scale s on [−π, π], renormalised."""
    ax = abs(x)
    e = math.exp(-ax / s)
    norm = 1.0 - 2.0 / (1.0 + math.exp(math.pi / s))
    return e / (s * (1.0 + e) ** 2) / norm


@njit(cache=True)
def _logistic_sample(u, s):
    lo = 1.0 / (1.0 + math.exp(math.pi / s))
    v = lo + u * (1.0 - 2.0 * lo)
    v = min(max(v, 1e-300), 1.0 - 1e-16)
    return min(max(-s * math.log(1.0 / v - 1.0), -math.pi), math.pi)


# --- the BCSDF ---------------------------------------------------------------------------------------------------

@njit(cache=True)
def context(p, wo, sampling=True):
    """Per-ω_o quantities (local frame, unit wo): angles, lobe centres, widths, normalisers, lobe probabilities.
    ``sampling`` False skips what only ``pdf`` and ``sample`` read (lobe masses and probabilities: NaN then), for
    callers that only ``evaluate``."""
    c = np.empty(N_CONTEXT)
    context_into(p, wo, c, sampling)
    return c


@njit(cache=True, inline='always')
def context_into(p, wo, c, sampling=True):
    """``context`` written into ``c`` (length ``N_CONTEXT``), for kernels that reuse one buffer per thread."""
    s = min(max(wo[0], -1.0), 1.0)
    c[C_SIN_O] = s
    c[C_COS_O] = math.sqrt(max(0.0, 1.0 - s * s))
    c[C_PHI_O] = math.atan2(wo[2], wo[1])
    for k in range(2):
        _lobe_entries(p, k, s, c)
        c[C_MASS + k] = math.nan
        if sampling:
            mu, sigma = c[C_MU + k], c[C_SIGMA + k]
            c[C_MASS + k] = sigma * math.sqrt(2.0 * math.pi) * _normal_mass((-HALF_PI - mu) / sigma,
                                                                            (HALF_PI - mu) / sigma)
    if not sampling:
        for k in range(3):
            c[C_PROB + k] = math.nan
        return
    w_r = (p[P_A_R] + p[P_A_R + 1] + p[P_A_R + 2]) / 3.0
    w_tt = (p[P_A_TT] + p[P_A_TT + 1] + p[P_A_TT + 2]) / 3.0
    w_d = (p[P_A_D] + p[P_A_D + 1] + p[P_A_D + 2]) / 3.0
    total = w_r + w_tt + w_d
    if total <= 0.0:
        w_r, total = 1.0, 1.0
    c[C_PROB], c[C_PROB + 1], c[C_PROB + 2] = w_r / total, w_tt / total, w_d / total


@njit(cache=True, inline='always')
def _lobe_entries(p, k, s, c):
    """Centre, width and normaliser of longitudinal lobe k (0: R, 1: TT) of a view with sin θ_o = s, into ``c``."""
    sigma = 2.0 * (p[P_BETA_R] if k == 0 else p[P_BETA_TT])
    mu = lobe_centre(p[P_ALPHA_R] if k == 0 else p[P_ALPHA_TT], sigma, s)
    c[C_MU + k] = mu
    c[C_SIGMA + k] = sigma
    c[C_Z + k] = cos2_normaliser(mu, sigma)


@njit(cache=True)
def r_lobe_context_into(p, sin_o, c):
    """Only the R lobe's entries of ``context`` (``C_MU``, ``C_SIGMA``, ``C_Z`` of lobe 0) for a view with
    sin θ_o = ``sin_o``: all that I_M's R rule (``knitrun.shading.im_lookup.r_lobe_integral``) reads. The other
    entries of ``c`` are left as they were; the TT lobe's normaliser, the costly part of a context, is skipped."""
    _lobe_entries(p, 0, min(max(sin_o, -1.0), 1.0), c)


@njit(cache=True)
def view_context(p, theta_o):
    """``context`` of a view at longitudinal angle θ_o and azimuth 0: enough for every quantity that depends on the
    view through θ_o alone (I_M, the dual-scattering averages)."""
    c = np.empty(N_CONTEXT)
    context_into(p, np.array([math.sin(theta_o), math.cos(theta_o), 0.0]), c, False)
    return c


@njit(cache=True)
def gauss(theta, mu, sigma):
    """exp(−(θ − μ)²/(2σ²)): the unnormalised longitudinal lobe."""
    return math.exp(-0.5 * ((theta - mu) / sigma) ** 2)


@njit(cache=True, inline='always')
def evaluate(p, c, wi, out):
    """out[:] = f(ω_i, ω_o) in RGB (1/sr), ω_o given through its context ``c``; wi unit, local frame."""
    theta_i = clamped_asin(wi[0])
    phi = wrap_angle(c[C_PHI_O] - math.atan2(wi[2], wi[1]))
    m_r = gauss(theta_i, c[C_MU], c[C_SIGMA]) / c[C_Z]
    m_tt = gauss(theta_i, c[C_MU + 1], c[C_SIGMA + 1]) / c[C_Z + 1]
    n_r = 0.5 / math.pi
    n_tt = logistic_trimmed(wrap_angle(phi - math.pi), tt_logistic_scale(p[P_GAMMA_TT]))
    for ch in range(3):
        out[ch] = p[P_A_R + ch] * m_r * n_r + p[P_A_TT + ch] * m_tt * n_tt + p[P_A_D + ch] * INV_PI2


@njit(cache=True, inline='always')
def pdf(p, c, wi):
    """Solid-angle density of ``sample`` for ω_o's context ``c`` (1/sr)."""
    theta_i = clamped_asin(wi[0])
    cos_i = max(math.cos(theta_i), COS_FLOOR)
    phi = wrap_angle(c[C_PHI_O] - math.atan2(wi[2], wi[1]))
    q_r = gauss(theta_i, c[C_MU], c[C_SIGMA]) / c[C_MASS]
    q_tt = gauss(theta_i, c[C_MU + 1], c[C_SIGMA + 1]) / c[C_MASS + 1]
    n_tt = logistic_trimmed(wrap_angle(phi - math.pi), tt_logistic_scale(p[P_GAMMA_TT]))
    return (c[C_PROB] * q_r * 0.5 / math.pi + c[C_PROB + 1] * q_tt * n_tt) / cos_i + c[C_PROB + 2] / (4.0 * math.pi)


@njit(cache=True, inline='always')
def sample(p, c, u0, u1, u2, wi):
    """Draw ω_i into ``wi`` (local frame) from three uniforms; returns its pdf (solid angle)."""
    if u0 < c[C_PROB + 2] and c[C_PROB + 2] > 0.0:  # D: uniform sphere
        s = 1.0 - 2.0 * u1
        phi_i = 2.0 * math.pi * u2
    else:
        k = 0 if u0 < c[C_PROB + 2] + c[C_PROB] else 1
        mu, sigma = c[C_MU + k], c[C_SIGMA + k]
        theta = mu + sigma * _normal_sample((-HALF_PI - mu) / sigma, (HALF_PI - mu) / sigma, u1)
        s = math.sin(min(max(theta, -HALF_PI), HALF_PI))
        if k == 0:
            phi = 2.0 * math.pi * u2 - math.pi
        else:
            phi = math.pi + _logistic_sample(u2, tt_logistic_scale(p[P_GAMMA_TT]))
        phi_i = c[C_PHI_O] - phi
    cos_t = math.sqrt(max(0.0, 1.0 - s * s))
    wi[0] = s
    wi[1] = cos_t * math.cos(phi_i)
    wi[2] = cos_t * math.sin(phi_i)
    return pdf(p, c, wi)


# --- batch wrappers (tests, tables, Python callers) --------------------------------------------------------------

@njit(parallel=True, cache=True)
def eval_batch(p, wo, wi):
    """f for rows of unit local directions wo, wi (N, 3) → (N, 3)."""
    out = np.empty((wo.shape[0], 3))
    for n in prange(wo.shape[0]):
        evaluate(p, context(p, wo[n]), wi[n], out[n])
    return out


@njit(parallel=True, cache=True)
def pdf_batch(p, wo, wi):
    out = np.empty(wo.shape[0])
    for n in prange(wo.shape[0]):
        out[n] = pdf(p, context(p, wo[n]), wi[n])
    return out


@njit(parallel=True, cache=True)
def sample_batch(p, wo, u):
    """For each row: ω_i, its pdf, and the weight f cos θ_i / pdf (RGB). u: (N, 3) uniforms."""
    n_rows = wo.shape[0]
    wi = np.empty((n_rows, 3))
    pdfs = np.empty(n_rows)
    weight = np.empty((n_rows, 3))
    for n in prange(n_rows):
        f = np.empty(3)
        c = context(p, wo[n])
        pdfs[n] = sample(p, c, u[n, 0], u[n, 1], u[n, 2], wi[n])
        evaluate(p, c, wi[n], f)
        cos_i = math.sqrt(max(0.0, 1.0 - wi[n, 0] ** 2))
        for ch in range(3):
            weight[n, ch] = f[ch] * cos_i / pdfs[n] if pdfs[n] > 0.0 else 0.0
    return wi, pdfs, weight


def direction(theta, phi) -> np.ndarray:
    """Unit local direction(s) from longitudinal θ and azimuth φ (radians); broadcasting."""
    theta, phi = np.broadcast_arrays(np.asarray(theta, float), np.asarray(phi, float))
    return np.stack([np.sin(theta), np.cos(theta) * np.cos(phi), np.cos(theta) * np.sin(phi)], axis=-1)
