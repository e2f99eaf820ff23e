"""Image error metrics for comparing a fast image with its reference (``knitrun compare``, benchmarks).

* FLIP (Andersson et al. 2020, NVIDIA's ``flip-evaluator`` package): LDR-FLIP on the images as shown, i.e. after
  the same tone mapping as our PNG files (``data_formats.images.tonemap``: exposure, clamp to [0, 1], sRGB), at the
  package's default 67 pixels per degree. The mean of the per-pixel error map, in [0, 1], 0 = identical.
* RMSE: root mean square of the linear RGB difference (radiance units).
* relMSE: mean of (test − ref)² / (ref² + 0.01) over pixels and channels (the 0.01 keeps dark pixels from
  dominating), the usual relative MSE of rendering papers.
"""

from __future__ import annotations

import numpy as np

from data_formats.images import tonemap

REL_MSE_EPSILON = 0.01


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
