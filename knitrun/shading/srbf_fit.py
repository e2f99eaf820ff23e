"""Fit J spherical Gaussians (SRBFs) to an equirectangular HDR environment (Huang et al. 2025 §4.5, eq. 14).

Model: L(ω) ≈ Σ_j W_j G(ω; ω_j, λ_j), G the SRBF of ``knitrun.shading.im_lookup.sg`` (G(ω_j) = 1, unnormalised), ω_j
unit directions in the world frame of ``knitrun.shading.equirect`` (+y up), λ_j ∈ [0.5, λ_max], W_j linear RGB radiance
(same units as the image), W_j ≥ 0. λ_max = min(1e4, 4/Δ²), Δ = π/H the texel's angular height (0.5 for H = 1,
where the joint refinement is skipped: λ has no range): a lobe's angular
standard deviation 1/√λ stays ≥ Δ/2, so the texel samples integrate it to < 1 % (a narrower lobe could match a sun
texel's radiance at its centre while carrying a fraction of its energy; 1e4 is the top of the I_M table's λ range).

Fitted error measure: Σ_t Ω_t ‖L_t − M(ω_t)‖², ω_t a texel centre and Ω_t its exact solid angle — a quadrature of
∫_S² ‖L − M‖² dω, the square of the reported relative L2 error's numerator (see ``SRBFFit``). A small bright sun
would dominate it (its squared radiance outweighs the sky), which is why compact sources are taken out first.

Method (deterministic):

0a. Compact sources (a sun, a lamp): a texel is bright if its luminance exceeds ``SOURCE_CONTRAST`` times the map's
   mean (solid-angle weighted); the brightest bright texel seeds a source whose texels are the bright ones within
   ``SOURCE_RADIUS_DEG`` of it, provided none lies in the ring out to 1.5 × that radius and the ring's mean luminance
   is below 1/``SOURCE_CONTRAST`` of the seed's (else the region is not compact — a broad bright area, or the core of
   a lobe wider than ~4° — and is left to step 1). The source's excess over the level around it (the ring's mean)
   becomes one lobe of exactly that energy E (W = E/∫G, ∫G = (2π/λ)(1 − e^{−2λ})), centred on the excess-weighted
   mean direction, with λ from the excess's mean resultant length R̄ (the von Mises–Fisher κ ≈ R̄(3 − R̄²)/(1 − R̄²),
   Banerjee et al. 2005) clamped to [0.5, λ_max]; its texels are set to the ring level and the next source is sought,
   up to J//4 sources. Why: the squared-radiance error of steps 1–3 is dominated by a sun disk (radiance ~500× the
   sky's), so without this step ten of sixteen lobes tile a 2.5° disk and the sky that lights most of a fabric is
   left to one hemisphere-wide lobe: the patch under the built-in sky rendered at 0.73× the reference, its sky part
   at 0.61× (BENCHMARKS.md, "The environment's sun as one lobe"). The price: the radiance L2 error of a map with a
   sun is bounded by the disk's shape (0.52 for the built-in sky at any J ≥ 4, 0.24 before), the error that matters
   for shading, the irradiance error, falls (0.082 → 0.0074 at J = 16).
0b. Samples: the image is area-averaged to a coarse grid of at most 32 × 64 cells; the cells with the largest
   solid-angle-weighted within-cell variance are then split back into their full-resolution texels until
   ``max_samples`` samples are used (the horizon comes back at full resolution; a small image is used whole).
1. Greedy matching pursuit, on the map with the sources removed, for the J lobes they leave: candidate centres are
   the 8 samples of largest weighted positive residual luminance plus 64 fixed Fibonacci directions, candidate λ are
   the 13 log-spaced values in [0.5, 1e4] below λ_max, and λ_max; the (centre, λ) whose best non-negative single-lobe
   fit removes the most squared residual is added, then all weights are re-solved by non-negative least squares
   (NNLS, per channel). Lobes stop being added once nothing positive is left; the rest get zero weight, λ = 0.5 and
   Fibonacci directions under a random rotation drawn from ``seed`` (its only use).
2. Joint refinement of (ω_j, log λ_j, W_j) of the active lobes by ``scipy.optimize.least_squares`` (trust-region
   reflective, analytic Jacobian, bounds W ≥ 0 and λ in range) on the samples. Each ω_j moves in its tangent
   plane: ω_j = normalise(ω_j⁰ + u e₁ + v e₂).
3. Final NNLS of W on all full-resolution texels (sources removed) for the refined (ω_j, λ_j); the source lobes come
   first in the fit. The errors of ``SRBFFit`` are against the map as given.
"""

import math
from dataclasses import dataclass

import numpy as np
from scipy.optimize import least_squares, nnls

from data_formats.conventions import LUMINANCE
from knitrun.shading.equirect import fibonacci_directions, texel_directions
from knitrun.shading.im_lookup import sg, sg_integral

LAMBDA_MIN = 0.5
LAMBDA_MAX = 1e4
SOURCE_CONTRAST = 20.0  # a texel this many times the map's mean luminance may belong to a compact source (step 0a)
SOURCE_RADIUS_DEG = 10.0  # a compact source lies within this angle of its brightest texel
_LAMBDA_CANDIDATES = np.geomspace(LAMBDA_MIN, LAMBDA_MAX, 13)
_PLANE_NORMALS = np.vstack([np.eye(3), -np.eye(3)])


@dataclass(frozen=True)
class SRBFFit:
    """J fitted lobes and their errors against the image they were fitted to (full resolution).

    directions: (J, 3) unit ω_j (+y up). sharpness: (J,) λ_j (1/sr-like, dimensionless). weights: (J, 3) linear RGB
    W_j ≥ 0, radiance units of the image. relative_l2_error: ‖L − M‖ / ‖L‖ with ‖f‖² = ∫ ‖f(ω)‖² dω (solid-angle
    weighted, RGB summed); 0 when both vanish. irradiance_error: ‖E_M − E_L‖_F / ‖E_L‖_F over the RGB irradiance
    E(n) = ∫ L(ω) max(0, ω·n) dω on the 6 axis-aligned planes n = ±x, ±y, ±z (18 numbers); 0 when both vanish.
    max_abs_error: max over texels and channels of |L − M| (radiance units).
    """

    directions: np.ndarray
    sharpness: np.ndarray
    weights: np.ndarray
    relative_l2_error: float
    irradiance_error: float
    max_abs_error: float


def evaluate_srbf(fit: SRBFFit, directions) -> np.ndarray:
    """(N, 3) radiance Σ_j W_j G(ω; ω_j, λ_j) for (N, 3) unit directions."""
    d = np.asarray(directions, float).reshape(-1, 3)
    return sg(d[:, None, :], fit.directions[None], fit.sharpness[None]) @ fit.weights


def srbf_image(fit: SRBFFit, height: int, width: int) -> np.ndarray:
    """(H, W, 3) float32 equirectangular image of the fitted lobes at the texel centres."""
    return evaluate_srbf(fit, texel_directions(height, width).reshape(-1, 3)).reshape(height, width, 3).astype(
        np.float32)


def fit_srbf(image, n_lobes: int = 16, max_iterations: int = 30, seed: int = 0,
             max_samples: int = 4096) -> SRBFFit:
    """Fit ``n_lobes`` SRBFs to an (H, W, 3) linear-RGB equirectangular image (method: module docstring).

    max_iterations bounds the function evaluations of the joint refinement (0 skips it); max_samples bounds the
    directions the greedy stage and the refinement see. Raises ValueError on invalid input.
    """
    img = _checked(image)
    if int(n_lobes) < 1 or int(max_iterations) < 0 or int(max_samples) < 1:
        raise ValueError(f"fit_srbf: need n_lobes >= 1, max_iterations >= 0, max_samples >= 1, got {n_lobes}, "
                         f"{max_iterations}, {max_samples}")
    h, w, _ = img.shape
    dirs, omega = _texels(h, w)
    radiance = img.reshape(-1, 3)
    lam_max = lambda_max(h)
    src_centres, src_lam, src_weights, rest = compact_sources(radiance, dirs, omega, int(n_lobes) // 4, lam_max)
    n_fit = int(n_lobes) - len(src_lam)
    sdirs, somega, sradiance = _samples(rest.reshape(img.shape), dirs, omega, int(max_samples))

    centres, lam = _greedy(sdirs, somega, sradiance, n_fit, lam_max)
    active = len(lam)
    if active and max_iterations and lam_max > LAMBDA_MIN:  # a one-row map leaves λ no range: keep the greedy fit
        centres, lam = _refine(sdirs, somega, sradiance, centres, lam, int(max_iterations), lam_max)
    weights = (_nnls_weights(sg(dirs[:, None, :], centres[None], lam[None]), omega, rest) if active
               else np.zeros((0, 3)))  # scipy's NNLS aborts on an empty matrix
    filler = n_fit - active
    fit = SRBFFit(np.vstack([src_centres, centres, fibonacci_directions(filler) @ _rotation(seed).T]),
                  np.concatenate([src_lam, lam, np.full(filler, LAMBDA_MIN)]),
                  np.vstack([src_weights, weights, np.zeros((filler, 3))]), 0.0, 0.0, 0.0)
    return _with_errors(fit, dirs, omega, radiance)


def compact_sources(radiance, dirs, omega, max_sources: int, lam_max: float):
    """Step 0a of the module docstring: (centres (S, 3), λ (S,), W (S, 3), the radiance (N, 3) with the sources
    replaced by the level around them), S ≤ ``max_sources``, for texel radiance (N, 3), directions (N, 3) and solid
    angles (N,). Each source lobe carries exactly the excess energy Σ (L_t − level) Ω_t of its texels (clipped at 0)."""
    rest = np.array(radiance, float)
    centres, lams, weights = [], [], []
    lum = rest @ LUMINANCE
    mean = float(omega @ lum) / float(omega.sum()) if omega.sum() > 0 else 0.0
    cos_in, cos_ring = math.cos(math.radians(SOURCE_RADIUS_DEG)), math.cos(math.radians(1.5 * SOURCE_RADIUS_DEG))
    for _ in range(max_sources):
        bright = lum > SOURCE_CONTRAST * mean
        if not mean > 0 or not bright.any():
            break
        peak = int(np.argmax(np.where(bright, lum, -np.inf)))
        cos = dirs @ dirs[peak]
        inside, ring = cos >= cos_in, (cos < cos_in) & (cos >= cos_ring)
        if np.any(bright & ring) or not ring.any():  # not compact (or a map too coarse to tell): left to the lobes
            break
        level = (omega[ring] @ rest[ring]) / omega[ring].sum()
        if not level @ LUMINANCE * SOURCE_CONTRAST < lum[peak]:  # a broad lobe's core, not a source on a backdrop
            break
        members = bright & inside
        excess = np.clip(rest[members] - level, 0.0, None) * omega[members, None]  # (M, 3) energy per texel
        energy = excess.sum(axis=0)
        pull = (excess @ LUMINANCE) @ dirs[members]
        total = float((excess @ LUMINANCE).sum())
        if not total > 0:
            break
        r_bar = min(float(np.linalg.norm(pull)) / total, 1.0 - 1e-12)
        lam = float(np.clip(r_bar * (3.0 - r_bar * r_bar) / (1.0 - r_bar * r_bar), LAMBDA_MIN, lam_max))
        centres.append(pull / np.linalg.norm(pull))
        lams.append(lam)
        weights.append(energy / sg_integral(lam))
        rest[members] = level
        lum = rest @ LUMINANCE
    return (np.array(centres, float).reshape(-1, 3), np.array(lams, float), np.array(weights, float).reshape(-1, 3),
            rest)


def _checked(image) -> np.ndarray:
    img = np.asarray(image)
    if img.ndim != 3 or img.shape[2] != 3 or img.shape[0] < 1 or img.shape[1] < 1:
        raise ValueError(f"fit_srbf: image must have shape (H, W, 3), got {img.shape}")
    if not np.issubdtype(img.dtype, np.number):
        raise ValueError(f"fit_srbf: image must be numeric, got dtype {img.dtype}")
    img = img.astype(float)
    if not np.all(np.isfinite(img)):
        row, col, _ = np.argwhere(~np.isfinite(img))[0]
        raise ValueError(f"fit_srbf: image texel (row {row}, column {col}) is not finite")
    if np.any(img < 0):
        row, col, _ = np.argwhere(img < 0)[0]
        raise ValueError(f"fit_srbf: image texel (row {row}, column {col}) is negative; radiance must be >= 0")
    return img


def _texels(h, w):
    """(H·W, 3) texel-centre directions and (H·W,) exact texel solid angles (sr, summing to 4π)."""
    edges = np.cos(np.arange(h + 1) * np.pi / h)
    omega = np.repeat((edges[:-1] - edges[1:]) * (2 * np.pi / w), w)
    return texel_directions(h, w).reshape(-1, 3), omega


def _samples(img, dirs, weight, max_samples):
    """Adaptive samples (directions (S, 3), fit weights (S,), radiance (S, 3)); see the module docstring, step 0.

    A coarse cell's sample is its weighted mean radiance at its weighted mean direction (normalised), with the sum
    of its texels' weights.
    """
    H, W, _ = img.shape
    radiance = img.reshape(-1, 3)
    if H * W <= max_samples:
        return dirs, weight, radiance
    h, w = min(H, 32), min(W, 64)
    cell = (((np.arange(H) + 0.5) * h / H).astype(int)[:, None] * w
            + ((np.arange(W) + 0.5) * w / W).astype(int)[None, :]).ravel()
    cell_weight = np.bincount(cell, weight, h * w)
    safe = np.where(cell_weight > 0, cell_weight, 1.0)[:, None]
    mean = np.stack([np.bincount(cell, weight * radiance[:, c], h * w) for c in range(3)], axis=1) / safe
    centre = np.stack([np.bincount(cell, weight * dirs[:, c], h * w) for c in range(3)], axis=1)
    centre /= np.maximum(np.linalg.norm(centre, axis=1, keepdims=True), 1e-300)
    spread = np.bincount(cell, weight * ((radiance - mean[cell]) ** 2).sum(axis=1), h * w)
    order = np.argsort(-spread, kind="stable")
    extra = np.cumsum(np.bincount(cell, minlength=h * w)[order] - 1)
    split = np.zeros(h * w, bool)
    split[order[(extra <= max_samples - h * w) & (spread[order] > 0)]] = True
    fine = split[cell]
    return (np.vstack([centre[~split], dirs[fine]]), np.concatenate([cell_weight[~split], weight[fine]]),
            np.vstack([mean[~split], radiance[fine]]))


def _nnls_weights(g, weight, radiance):
    """(J, 3) W ≥ 0 minimising Σ_t weight_t ‖L_t − Σ_j W_j G_tj‖², one NNLS per channel."""
    a = g * np.sqrt(weight)[:, None]
    b = radiance * np.sqrt(weight)[:, None]
    return np.stack([nnls(a, b[:, c])[0] for c in range(3)], axis=1)


def lambda_max(height: int) -> float:
    """The largest λ fitted to an equirectangular image of ``height`` rows (module docstring)."""
    return max(LAMBDA_MIN, min(LAMBDA_MAX, 4.0 / (np.pi / height) ** 2))  # one row (4/π² < 0.5): λ_min


def _greedy(dirs, weight, radiance, n_lobes, lam_max):
    """Matching pursuit with NNLS re-fits: (K, 3) centres and (K,) λ, K ≤ n_lobes active lobes."""
    candidates = np.append(_LAMBDA_CANDIDATES[_LAMBDA_CANDIDATES < lam_max], lam_max)
    centres = np.zeros((0, 3))
    lam = np.zeros(0)
    residual = radiance
    fixed = fibonacci_directions(64)
    scale = radiance.max(initial=0.0)
    for _ in range(n_lobes):
        score = np.clip(residual @ LUMINANCE, 0, None) * np.sqrt(weight)
        if not score.max(initial=0.0) > 0 or not np.max(residual @ LUMINANCE) > 1e-9 * scale:
            break
        peaks = np.argsort(-score, kind="stable")[:8]
        cand = np.vstack([dirs[peaks], fixed])  # (C, 3)
        g = sg(dirs[:, None, None, :], cand[None, :, None, :], candidates[None, None, :])  # (N, C, L)
        proj = np.clip(np.einsum("ncl,n,nk->clk", g, weight, residual), 0, None)
        gain = (proj ** 2).sum(axis=2) / np.einsum("ncl,n->cl", g * g, weight)
        c, k = np.unravel_index(np.argmax(gain), gain.shape)
        centres = np.vstack([centres, cand[c]])
        lam = np.append(lam, candidates[k])
        basis = sg(dirs[:, None, :], centres[None], lam[None])
        residual = radiance - basis @ _nnls_weights(basis, weight, radiance)
    return centres, lam


def _tangent_frame(c):
    """Two (K, 3) unit vectors orthogonal to each unit centre and to each other."""
    helper = np.where(np.abs(c[:, 1:2]) < 0.9, [[0.0, 1.0, 0.0]], [[1.0, 0.0, 0.0]])
    e1 = np.cross(c, helper)
    e1 /= np.linalg.norm(e1, axis=1, keepdims=True)
    return e1, np.cross(c, e1)


def _refine(dirs, weight, radiance, centres, lam, max_iterations, lam_max):
    """Joint least-squares refinement of (ω_j, λ_j, W_j); returns refined (centres, λ)."""
    k = len(lam)
    e1, e2 = _tangent_frame(centres)
    sw = np.sqrt(weight)[:, None]

    def unpack(x):
        u, v, s, wts = x[:k], x[k:2 * k], x[2 * k:3 * k], x[3 * k:].reshape(k, 3)
        p = centres + u[:, None] * e1 + v[:, None] * e2
        norm = np.linalg.norm(p, axis=1, keepdims=True)
        return p / norm, norm, np.exp(s), wts

    def residuals(x):
        c, _, lm, wts = unpack(x)
        return ((sg(dirs[:, None, :], c[None], lm[None]) @ wts - radiance) * sw).ravel()

    def jacobian(x):
        c, norm, lm, wts = unpack(x)
        cos = dirs @ c.T  # (N, K)
        g = np.exp(lm * (cos - 1.0))
        # d(ω·d)/du = d·(e1 − ω(ω·e1))/|p|, likewise for v
        du = (dirs @ e1.T - cos * np.sum(c * e1, axis=1)) / norm[:, 0]
        dv = (dirs @ e2.T - cos * np.sum(c * e2, axis=1)) / norm[:, 0]
        lg = (lm * g) * sw  # (N, K)
        jac = np.zeros((len(dirs), 3, 4 * k + 2 * k))
        for ch in range(3):
            jac[:, ch, :k] = lg * du * wts[:, ch]
            jac[:, ch, k:2 * k] = lg * dv * wts[:, ch]
            jac[:, ch, 2 * k:3 * k] = lg * (cos - 1.0) * wts[:, ch]
            jac[:, ch, 3 * k + ch:6 * k:3] = g * sw
        return jac.reshape(-1, 6 * k)

    weights = _nnls_weights(sg(dirs[:, None, :], centres[None], lam[None]), weight, radiance)
    x0 = np.concatenate([np.zeros(2 * k), np.log(lam), weights.ravel()])
    lower = np.concatenate([np.full(2 * k, -np.inf), np.full(k, np.log(LAMBDA_MIN)), np.zeros(3 * k)])
    upper = np.concatenate([np.full(2 * k, np.inf), np.full(k, np.log(lam_max)), np.full(3 * k, np.inf)])
    x0 = np.clip(x0, lower, upper)
    result = least_squares(residuals, x0, jac=jacobian, bounds=(lower, upper), method="trf", x_scale="jac",
                           max_nfev=max_iterations)
    c, _, lm, _ = unpack(result.x)
    return c, np.clip(lm, LAMBDA_MIN, lam_max)


def _rotation(seed):
    """A random 3×3 rotation drawn from ``seed``."""
    q, upper = np.linalg.qr(np.random.default_rng(seed).normal(size=(3, 3)))
    q = q * np.sign(np.diag(upper))
    return q * np.sign(np.linalg.det(q))


def _relative(diff, ref):
    ref_norm = np.sqrt(ref)
    return float(np.sqrt(diff) / ref_norm) if ref_norm > 0 else (0.0 if diff == 0 else float("inf"))


def _with_errors(fit, dirs, omega, radiance):
    """``fit`` with its full-resolution error metrics (see ``SRBFFit``)."""
    model = evaluate_srbf(fit, dirs)
    err = model - radiance
    cosine = np.clip(dirs @ _PLANE_NORMALS.T, 0, None) * omega[:, None]  # (N, 6)
    e_ref, e_err = cosine.T @ radiance, cosine.T @ err
    return SRBFFit(fit.directions, fit.sharpness, fit.weights,
                   relative_l2_error=_relative(omega @ (err ** 2).sum(axis=1), omega @ (radiance ** 2).sum(axis=1)),
                   irradiance_error=_relative((e_err ** 2).sum(), (e_ref ** 2).sum()),
                   max_abs_error=float(np.abs(err).max()))
