"""Environment light from an equirectangular HDR image, importance sampled (piecewise-constant 2-D distribution).

The direction ↔ texel mapping is ``knitrun.shading.equirect`` (+y up). Radiance is the texel value times ``scale``
(linear RGB); lookups are nearest-texel, so the distribution sampled is exactly the one evaluated.
Sampling density ∝ luminance(texel)·sin θ; the solid-angle pdf of a direction in texel (r, c) is
p(r, c) / (Δθ Δφ sin θ), p the discrete probability of that texel (uniform within it in θ and φ).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numba import njit

from data_formats.conventions import LUMINANCE
from knitrun.shading import equirect



@dataclass
class EnvLight:
    radiance: np.ndarray  # (H, W, 3) float64, already scaled
    row_cdf: np.ndarray  # (H + 1,) marginal CDF over rows
    col_cdf: np.ndarray  # (H, W + 1) conditional CDF over columns per row
    pixel_prob: np.ndarray  # (H, W) discrete probability of each pixel


def env_from_image(image, scale=(1.0, 1.0, 1.0)) -> EnvLight:
    img = np.asarray(image, dtype=np.float64) * np.asarray(scale, dtype=np.float64)
    if img.ndim != 3 or img.shape[2] != 3 or not np.all(np.isfinite(img)) or np.any(img < 0):
        raise ValueError("environment image must be (H, W, 3), finite and non-negative")
    h, w, _ = img.shape
    sin_theta = np.sin((np.arange(h) + 0.5) * np.pi / h)
    weight = (img @ LUMINANCE) * sin_theta[:, None]
    if weight.sum() <= 0:  # black environment: sample uniformly, contributes nothing anyway
        weight = np.ones((h, w)) * sin_theta[:, None]
    prob = weight / weight.sum()
    row = prob.sum(axis=1)
    row_cdf = np.concatenate([[0.0], np.cumsum(row)])
    row_cdf /= row_cdf[-1]
    col = np.where(row[:, None] > 0, prob / np.maximum(row[:, None], 1e-300), 1.0 / w)
    col_cdf = np.concatenate([np.zeros((h, 1)), np.cumsum(col, axis=1)], axis=1)
    col_cdf /= col_cdf[:, -1:]
    return EnvLight(img, row_cdf, col_cdf, prob)


def uniform_env(radiance, height=8, width=16) -> EnvLight:
    return env_from_image(np.broadcast_to(np.asarray(radiance, np.float64), (height, width, 3)).copy())


@njit(cache=True)
def env_pixel(radiance, d):
    return equirect.pixel(radiance.shape[0], radiance.shape[1], d)


@njit(cache=True)
def env_pdf(radiance, pixel_prob, d):
    """Solid-angle pdf (1/sr) of direction d under the environment's sampling distribution."""
    h, w = radiance.shape[0], radiance.shape[1]
    r, c = env_pixel(radiance, d)
    sin_t = math.sqrt(max(0.0, 1.0 - d[1] * d[1]))
    if sin_t <= 1e-12:
        sin_t = 1e-12
    return pixel_prob[r, c] / ((math.pi / h) * (2.0 * math.pi / w) * sin_t)


@njit(cache=True)
def env_sample(radiance, row_cdf, col_cdf, pixel_prob, u1, u2, u3, u4, out):
    """Direction into ``out`` drawn from the environment's distribution; returns its solid-angle pdf."""
    h, w = radiance.shape[0], radiance.shape[1]
    r = min(max(np.searchsorted(row_cdf, u1, side="right") - 1, 0), h - 1)
    c = min(max(np.searchsorted(col_cdf[r], u2, side="right") - 1, 0), w - 1)
    # uniform in θ and φ inside the pixel (the pdf formula above assumes exactly this)
    theta = (r + u3) * math.pi / h
    phi = -math.pi + (c + u4) * 2.0 * math.pi / w
    equirect.direction(theta, phi, out)
    return pixel_prob[r, c] / ((math.pi / h) * (2.0 * math.pi / w) * max(math.sin(theta), 1e-12))
