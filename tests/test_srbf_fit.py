"""SRBF environment fit (knitrun.shading.srbf_fit): recovery of known lobes, the built-in sky, determinism, edge
cases."""

import numpy as np
import pytest

from knitrun.shading.builtin_sky import sky_image
from knitrun.shading.equirect import texel_directions
from knitrun.shading.im_lookup import sg
from knitrun.shading.srbf_fit import lambda_max, evaluate_srbf, fit_srbf, srbf_image


def _sg_image(directions, sharpness, weights, h=48, w=96):
    d = texel_directions(h, w)
    c = np.asarray(directions, float)
    c = c / np.linalg.norm(c, axis=1, keepdims=True)
    return sg(d[..., None, :], c, np.asarray(sharpness, float)) @ np.asarray(weights, float)


@pytest.mark.parametrize("lobes", [
    ([[0, 1, 0]], [3.0], [[1.0, 0.8, 0.6]]),
    ([[0.3, 0.8, 0.5], [-0.6, 0.2, -0.7], [0.1, -0.9, 0.3]], [40.0, 8.0, 2.0],
     [[5.0, 4.0, 3.0], [0.5, 1.0, 2.0], [0.2, 0.2, 0.1]]),
])
def test_known_lobes_recovered(lobes):
    fit = fit_srbf(_sg_image(*lobes), n_lobes=4, max_iterations=30)
    assert fit.relative_l2_error < 0.01
    assert fit.irradiance_error < 0.01


def test_sky_errors_decrease_with_lobes():
    """At the renderer's sky resolution (128 × 256, where the 2.5° sun spans several texels)."""
    img = sky_image(128, 256)
    fits = [fit_srbf(img, n_lobes=j, max_iterations=m) for j, m in ((1, 10), (16, 10), (64, 0))]
    l2 = [f.relative_l2_error for f in fits]
    irr = [f.irradiance_error for f in fits]
    assert l2[0] > l2[1] > l2[2]
    assert irr[0] > irr[1] > irr[2]
    assert irr[1] < 0.15  # 16 lobes: diffuse-relevant irradiance within 15 %


def test_lobes_keep_the_suns_energy_at_low_resolution():
    """A sun smaller than a texel: λ is capped (``lambda_max``) so the lobes carry the energy of the texels they
    fit, ∫ Σ W G dω (closed form per lobe) within 25 % of ∫ L dω (measured: +20 % at 32 rows), instead of matching the
    sun texel's radiance with a needle that holds a fraction of it."""
    for height in (32, 64):
        img = sky_image(height, 2 * height)
        dirs = texel_directions(height, 2 * height).reshape(-1, 3)
        omega = (np.pi / height) ** 2 * np.sqrt(1 - dirs[:, 1] ** 2)
        energy = (img.reshape(-1, 3) * omega[:, None]).sum(axis=0)
        fit = fit_srbf(img, n_lobes=16, max_iterations=10)
        lam = fit.sharpness
        fitted = (fit.weights * (2 * np.pi / lam * (1 - np.exp(-2 * lam)))[:, None]).sum(axis=0)
        assert np.all(lam <= lambda_max(height) * (1 + 1e-9))
        assert np.allclose(fitted, energy, rtol=0.25), height
    assert np.isclose(lambda_max(128), 4 / (np.pi / 128) ** 2) and lambda_max(10 ** 4) == 1e4


def test_fit_fields_and_image():
    fit = fit_srbf(sky_image(32, 64), n_lobes=5, max_iterations=5)
    assert fit.directions.shape == (5, 3) and fit.sharpness.shape == (5,) and fit.weights.shape == (5, 3)
    assert np.allclose(np.linalg.norm(fit.directions, axis=1), 1)
    assert np.all((fit.sharpness >= 0.5) & (fit.sharpness <= 1e4)) and np.all(fit.weights >= 0)
    img = srbf_image(fit, 8, 16)
    assert img.shape == (8, 16, 3) and img.dtype == np.float32
    assert np.allclose(img.reshape(-1, 3), evaluate_srbf(fit, texel_directions(8, 16).reshape(-1, 3)), rtol=1e-5)


def test_deterministic():
    img = sky_image(32, 64)
    a, b = fit_srbf(img, n_lobes=6, max_iterations=5, seed=3), fit_srbf(img, n_lobes=6, max_iterations=5, seed=3)
    assert np.array_equal(a.directions, b.directions) and np.array_equal(a.weights, b.weights)
    assert np.array_equal(a.sharpness, b.sharpness) and a.relative_l2_error == b.relative_l2_error


def test_black_image():
    fit = fit_srbf(np.zeros((16, 32, 3)), n_lobes=16)
    assert fit.directions.shape == (16, 3) and np.all(fit.weights == 0)
    assert np.allclose(np.linalg.norm(fit.directions, axis=1), 1)
    assert fit.relative_l2_error == fit.irradiance_error == fit.max_abs_error == 0.0


def test_constant_image():
    fit = fit_srbf(np.full((16, 32, 3), 2.0), n_lobes=16, max_iterations=10)
    assert np.all(np.isfinite(fit.weights)) and fit.irradiance_error < 0.05


def test_single_bright_texel():
    img = np.zeros((32, 64, 3))
    img[10, 20] = 1e4
    fit = fit_srbf(img, n_lobes=16, max_iterations=10)
    values = [fit.directions, fit.sharpness, fit.weights, fit.relative_l2_error, fit.irradiance_error]
    assert all(np.all(np.isfinite(v)) for v in values)
    assert fit.relative_l2_error < 1.0


@pytest.mark.parametrize("bad, match", [
    (np.zeros((4, 8)), "shape"),
    (np.zeros((4, 8, 4)), "shape"),
    (-np.ones((4, 8, 3)), "negative"),
    (np.full((4, 8, 3), np.nan), "not finite"),
])
def test_invalid_input(bad, match):
    with pytest.raises(ValueError, match=match):
        fit_srbf(bad)
