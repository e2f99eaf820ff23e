"""Image error metrics for comparing a fast image with its reference (``knitrun compare``, benchmarks).

* FLIP (Andersson et al. 2020, NVIDIA's ``flip-evaluator`` package): LDR-FLIP on the images as shown, i.e. after
  the same tone mapping as our PNG files (``data_formats.images.tonemap``: exposure, clamp to [0, 1], sRGB), at the
  package's default 67 pixels per degree. The mean of the per-pixel error map, in [0, 1], 0 = identical.
* RMSE: root mean square of the linear RGB difference (radiance units).
* relMSE: mean of (test − ref)² / (ref² + 0.01) over pixels and channels (the 0.01 keeps dark pixels from
  dominating), the usual relative MSE of rendering papers.

At the yarn scale (``yarn_scale_metrics``): a strip image cannot match one path-traced fiber instance pixel for
pixel (two references with different fiber seeds differ by as much as a model), so both images are first box-filtered
to the yarn's projected diameter d in pixels (``yarn_filter``: the mean over a d × d window centred on each pixel,
edges extended), and at 2d:

* rel L1 = Σ |F(test) − F(ref)| / Σ |F(ref)| over pixels and channels;
* relMSE as above, of the filtered images;
* FLIP of the filtered images (as shown at full resolution);
* mean radiance ratio: mean luminance of test over ref (``data_formats.conventions.LUMINANCE``), over the image and
  per tile of ``TILE_DIAMETERS`` · d pixels; tiles where the reference's mean luminance is below ``SIGNAL`` of its
  brightest tile's are skipped; the worst tile is the one whose ratio is farthest from 1 (in log).

Sub-yarn contrast (``sub_yarn_contrast``; the look, which the yarn-scale errors filter away): how much a yarn's
brightness varies inside its own width, against the reference's. Of the luminance L, the band B = F_a(L) − F_b(L)
between two box filters (``CONTRAST_BANDS``, in yarn diameters: the **ply scale** d/6 to d/2, where the plies'
grooves and the fibers' glints lie, and **across the yarn**, d/2 to d, the shading across a tube), and the contrast
C = √var(B) / mean(L) (so a brightness error does not count). The reference's var(B) holds the path tracer's noise,
at the examples' spp 1–17 % of it at the ply scale (17 % on the patch under the sky): given the Monte Carlo floor M
(the same fibers, another sampling seed, same spp) it is taken off, var(B(ref)) − var(B(ref) − B(M))/2. The ratio C(test)/C(ref) is 1 for an
image with the reference's sub-yarn contrast; above 1 it is harder (tubes, grooves, chrome streaks), below it flatter.
Measured on the patch under the sky: the noise-corrected C of the 64-spp reference, of the same fibers at 512 spp
and of another fiber instance agree to 0.5 % at the ply scale (BENCHMARKS.md, "Issue 13: … sub-yarn contrast").

Against an ensemble of K ≥ 3 fiber instances I_1 … I_K of the reference (``ensemble_metrics``; a strip image models
what the yarn looks like on average over its fibers, which one instance shows only with its own draw's deviations):

* mean radiance ratio: mean luminance of test over the instances' mean, with the instances' spread — the standard
  deviation of their means over that mean (what one reference's mean may be off by) and its standard error
  sd/√K (what the ensemble's may);
* rel L1 at the yarn scale, leave one out: the mean over k of rel L1(F(test), F(mean of the instances but k)); the
  same for instance k itself in place of the test is the **ensemble floor** (``ensemble_floor``), and the test's
  ratio to it reads like the ratio to the instance floor: 1 is as close to the other draws as a draw is.
"""

from __future__ import annotations

import math

import numpy as np
from scipy.ndimage import uniform_filter

from data_formats.conventions import LUMINANCE
from data_formats.images import tonemap

REL_MSE_EPSILON = 0.01
TILE_DIAMETERS = 2  # tile side of the radiance ratio, in yarn diameters
SIGNAL = 0.1  # tiles darker than this fraction of the brightest reference tile are not compared
CONTRAST_BANDS = {"ply": (1 / 6, 1 / 2), "across": (1 / 2, 1.0)}  # box sizes of the contrast bands, in diameters


def _ldr(img, exposure_stops):
    return tonemap(img, exposure_stops).astype(np.float32) / 255.0


def flip_error(test, reference, exposure_stops: float = 0.0, magma: bool = False):
    """(mean LDR-FLIP, error map) of two linear RGB images of the same shape: the map is (H, W) float32 in [0, 1],
    or with ``magma`` FLIP's magma colouring as (H, W, 3) sRGB values in [0, 1]."""
    import flip_evaluator

    test, reference = _checked(test, reference)
    error_map, mean, _ = flip_evaluator.evaluate(_ldr(reference, exposure_stops), _ldr(test, exposure_stops), "LDR",
                                                 inputsRGB=True, applyMagma=magma)
    error_map = np.asarray(error_map, np.float32)
    return float(mean), error_map if magma else error_map.reshape(test.shape[:2])


def compare_images(test, reference, exposure_stops: float = 0.0, flip_mean: float | None = None) -> dict:
    """FLIP (tone-mapped, module docstring), RMSE and relMSE of ``test`` against ``reference``; ``flip_mean``: a
    FLIP mean already computed by ``flip_error`` for these images and exposure (not computed again)."""
    test, reference = _checked(test, reference)
    diff = test.astype(np.float64) - reference
    if flip_mean is None:
        flip_mean, _ = flip_error(test, reference, exposure_stops)
    return {"flip": flip_mean, "rmse": float(np.sqrt(np.mean(diff ** 2))),
            "rel_mse": float(np.mean(diff ** 2 / (reference.astype(np.float64) ** 2 + REL_MSE_EPSILON))),
            "flip_mode": f"LDR-FLIP after tone mapping at {exposure_stops:+g} stops (clamp, sRGB), 67 ppd"}


def _checked(test, reference):
    test, reference = np.asarray(test, np.float32), np.asarray(reference, np.float32)
    if test.shape != reference.shape or test.ndim != 3 or test.shape[2] != 3:
        raise ValueError(f"images of shapes {test.shape} and {reference.shape}: expected the same (H, W, 3)")
    if not (np.all(np.isfinite(test)) and np.all(np.isfinite(reference))):
        raise ValueError("images to compare must be finite")
    return test, reference


def yarn_filter(img, size: float) -> np.ndarray:
    """(H, W, 3) float64: the mean of ``img`` over a size × size pixel window around each pixel (size rounded, ≥ 1;
    the image's edge pixels extend beyond it)."""
    k = max(1, int(round(size)))
    return uniform_filter(np.asarray(img, np.float64), size=(k, k, 1), mode="nearest")


def _rel_l1(test, ref):
    den = np.abs(ref).sum()
    return float(np.abs(test - ref).sum() / den) if den > 0 else (0.0 if np.all(test == ref) else math.inf)


def radiance_ratio(test, reference, tile: int) -> dict:
    """Mean luminance of ``test`` over ``reference``: over the whole image (``mean_ratio``) and per tile × tile block
    where the reference has signal (module docstring): the worst tile's ratio, its (row, column) in tiles and how
    many tiles were compared."""
    lt, lr = np.asarray(test, np.float64) @ LUMINANCE, np.asarray(reference, np.float64) @ LUMINANCE
    total = lr.mean()
    out = {"mean_ratio": float(lt.mean() / total) if total > 0 else math.nan}
    rows, cols = max(1, lr.shape[0] // tile), max(1, lr.shape[1] // tile)
    h, w = rows * tile, cols * tile
    if lr.shape[0] < tile or lr.shape[1] < tile:  # an image smaller than one tile is one tile
        h, w = lr.shape
    mt = lt[:h, :w].reshape(rows, h // rows, cols, w // cols).mean(axis=(1, 3))
    mr = lr[:h, :w].reshape(rows, h // rows, cols, w // cols).mean(axis=(1, 3))
    lit = mr > SIGNAL * mr.max() if mr.max() > 0 else np.zeros_like(mr, bool)
    if not lit.any():
        return {**out, "worst_tile_ratio": math.nan, "worst_tile": None, "tiles": 0}
    ratio = np.where(lit, mt / np.where(lit, mr, 1.0), 1.0)
    log_error = np.where(lit, np.abs(np.log(np.maximum(ratio, 1e-12))), -1.0)
    r, c = np.unravel_index(np.argmax(log_error), ratio.shape)
    return {**out, "worst_tile_ratio": float(ratio[r, c]), "worst_tile": [int(r), int(c)], "tiles": int(lit.sum())}


def yarn_scale_metrics(test, reference, diameter_px: float, exposure_stops: float = 0.0) -> dict:
    """The yarn-scale errors of ``test`` against ``reference`` (module docstring) for a yarn ``diameter_px`` pixels
    wide on screen: rel L1 and relMSE at the diameter and at twice it, FLIP at the diameter, the mean and worst-tile
    radiance ratios."""
    test, reference = _checked(test, reference)
    out = {"yarn_px": float(diameter_px)}
    for suffix, size in (("", diameter_px), ("_2x", 2 * diameter_px)):
        ft, fr = yarn_filter(test, size), yarn_filter(reference, size)
        out["rel_l1" + suffix] = _rel_l1(ft, fr)
        out["rel_mse" + suffix] = float(np.mean((ft - fr) ** 2 / (fr ** 2 + REL_MSE_EPSILON)))
        if not suffix:
            out["flip"], _ = flip_error(ft.astype(np.float32), fr.astype(np.float32), exposure_stops)
    return {**out, **radiance_ratio(test, reference, max(1, int(round(TILE_DIAMETERS * diameter_px))))}


def _band(luminance, diameter_px: float, band: str) -> np.ndarray | None:
    """B = F_a(L) − F_b(L) of ``CONTRAST_BANDS[band]`` (box sizes rounded, ≥ 1); None where both round alike."""
    a, b = (max(1, int(round(f * diameter_px))) for f in CONTRAST_BANDS[band])
    if a == b:
        return None
    return uniform_filter(luminance, a, mode="nearest") - uniform_filter(luminance, b, mode="nearest")


def sub_yarn_contrast(test, reference, diameter_px: float, monte_carlo=None, test_traced: bool = False) -> dict:
    """The sub-yarn contrast of ``test`` over the reference's per band of ``CONTRAST_BANDS`` (module docstring):
    ``<band>`` the ratio C(test)/C(ref) (None where the band is empty at this diameter or the reference has no
    contrast left), ``<band>_reference`` C(ref), and ``<band>_noise`` the share of the reference's band variance
    taken off as the path tracer's noise (0 without ``monte_carlo``, the Monte Carlo floor image).
    ``test_traced``: the test is path traced at the reference's spp too (a floor), and loses the same noise."""
    test, reference = _checked(test, reference)
    lt, lr = (np.asarray(img, np.float64) @ LUMINANCE for img in (test, reference))
    lm = None if monte_carlo is None else np.asarray(_checked(monte_carlo, reference)[0], np.float64) @ LUMINANCE
    out = {}
    for band in CONTRAST_BANDS:
        bt, br = _band(lt, diameter_px, band), _band(lr, diameter_px, band)
        if bt is None or not lt.mean() > 0 or not lr.mean() > 0:
            out.update({band: None, f"{band}_reference": None, f"{band}_noise": None})
            continue
        var_r = float(br.var())
        noise = 0.0 if lm is None else 0.5 * float((br - _band(lm, diameter_px, band)).var())
        signal = var_r - noise
        c_ref = math.sqrt(signal) / lr.mean() if signal > 0 else 0.0
        var_t = float(bt.var()) - (noise if test_traced else 0.0)
        c_test = math.sqrt(max(var_t, 0.0)) / lt.mean()
        out.update({band: c_test / c_ref if c_ref > 0 else None, f"{band}_reference": c_ref,
                    f"{band}_noise": noise / var_r if var_r > 0 else 0.0})
    return out


def _luminance_mean(img) -> float:
    """Mean luminance (``LUMINANCE``) of an (H, W, 3) image."""
    return float((np.asarray(img, np.float64) @ LUMINANCE).mean())


def ensemble_floor(instances, diameter_px: float) -> dict:
    """The ensemble of fiber instances (a list of K ≥ 3 (H, W, 3) images, module docstring): ``instances`` K, the
    mean luminance ``mean``, ``mean_sd`` the instances' means' standard deviation over it and ``mean_se`` = sd/√K,
    ``rel_l1`` the leave-one-out yarn-scale rel L1 of an instance against the others' mean (averaged over k) and
    ``rel_l1_each`` per instance."""
    if len(instances) < 3:
        raise ValueError(f"an ensemble needs at least 3 fiber instances, got {len(instances)}")
    filtered = [yarn_filter(_checked(img, instances[0])[0], diameter_px) for img in instances]
    total, k = sum(filtered), len(filtered)
    each = [_rel_l1(f, (total - f) / (k - 1)) for f in filtered]
    means = np.array([_luminance_mean(img) for img in instances])
    mean = float(means.mean())
    sd = float(means.std(ddof=1) / mean) if mean > 0 else math.nan
    return {"instances": k, "mean": mean, "mean_sd": sd, "mean_se": sd / math.sqrt(k),
            "rel_l1": float(np.mean(each)), "rel_l1_each": [float(x) for x in each]}


def ensemble_metrics(test, instances, diameter_px: float, floor: dict | None = None, filtered=None) -> dict:
    """``test`` against an ensemble of K ≥ 3 fiber instances (module docstring): ``mean_ratio`` (its mean luminance
    over the instances'), ``rel_l1`` (leave-one-out, at the yarn scale) and ``to_floor``, rel_l1 over the ensemble
    floor's (``floor``: ``ensemble_floor(instances, diameter_px)``, computed when not given). ``filtered``: the
    instances' ``yarn_filter`` at ``diameter_px``, for a caller measuring many tests against one ensemble."""
    floor = floor or ensemble_floor(instances, diameter_px)
    test = _checked(test, instances[0])[0]
    if filtered is None:
        filtered = [yarn_filter(img, diameter_px) for img in instances]
    total, k = sum(filtered), len(filtered)
    ft = yarn_filter(test, diameter_px)
    rel_l1 = float(np.mean([_rel_l1(ft, (total - f) / (k - 1)) for f in filtered]))
    return {"mean_ratio": _luminance_mean(test) / floor["mean"] if floor["mean"] > 0 else math.nan,
            "rel_l1": rel_l1, "to_floor": rel_l1 / floor["rel_l1"] if floor["rel_l1"] > 0 else None}
