"""Fiber BCSDF invariants in the manner of pbrt-v4 and Mitsuba 3: white furnace, χ² sampling test, sample weights
consistent with eval/pdf, and finite values at the extremes."""

import math

import numpy as np
import pytest
from scipy import special, stats

from knitrun.shading import fiber_bcsdf as fb
from tests.chi2 import chi2_pvalue, direction_counts, pooled_pvalue
from tests.helpers import DEG

THETA_O = [0.0, 30 * DEG, -60 * DEG, 85 * DEG, -89.9 * DEG]


def lossless(beta_r, beta_tt, gamma_tt, alpha_r=-3 * DEG, alpha_tt=1.5 * DEG):
    """No absorption: the three lobe albedos sum to 1 in every channel."""
    return fb.params_from_values([0.3] * 3, [0.6] * 3, [0.1] * 3, beta_r, beta_tt, gamma_tt, alpha_r, alpha_tt)


ROUGHNESS = [(1 * DEG, 2 * DEG, 5 * DEG), (3 * DEG, 10 * DEG, 25 * DEG), (10 * DEG, 27 * DEG, 38 * DEG),
             (30 * DEG, 45 * DEG, 90 * DEG)]


def stratified_sphere(n_side, rng):
    """n_side² uniformly distributed directions, one jittered sample per (cos, φ) stratum."""
    i, j = np.meshgrid(np.arange(n_side), np.arange(n_side), indexing="ij")
    z = -1 + 2 * (i.ravel() + rng.random(i.size)) / n_side
    phi = 2 * np.pi * (j.ravel() + rng.random(i.size)) / n_side
    r = np.sqrt(1 - z * z)
    return np.stack([z, r * np.cos(phi), r * np.sin(phi)], axis=1)


@pytest.mark.parametrize("rough", ROUGHNESS)
def test_white_furnace_uniform_and_importance_sampling(rough):
    p = lossless(*rough)
    rng = np.random.default_rng(1)
    wi_uniform = stratified_sphere(1024, rng)
    for theta_o in THETA_O:
        wo = np.tile(fb.direction(theta_o, 0.7), (wi_uniform.shape[0], 1))
        f = fb.eval_batch(p, wo, wi_uniform)
        uniform = (f * np.sqrt(1 - wi_uniform[:, :1] ** 2) * 4 * np.pi).mean(axis=0)
        assert np.all((uniform > 0.95) & (uniform < 1.05)), (rough, theta_o, uniform)
        wo_is = wo[:300_000]
        _, _, weight = fb.sample_batch(p, wo_is, rng.random((wo_is.shape[0], 3)))
        importance = weight.mean(axis=0)
        assert np.all((importance > 0.99) & (importance < 1.01)), (rough, theta_o, importance)


def test_absorbing_fiber_returns_its_albedo():
    p = fb.params_from_values([0.05, 0.1, 0.2], [0.3, 0.5, 0.7], [0.0, 0.1, 0.05], 5 * DEG, 10 * DEG, 25 * DEG)
    wo = np.tile(fb.direction(0.4, 0.0), (200_000, 1))
    _, _, weight = fb.sample_batch(p, wo, np.random.default_rng(2).random((wo.shape[0], 3)))
    np.testing.assert_allclose(weight.mean(axis=0), [0.35, 0.7, 0.95], rtol=0.01)


def chi2_bins(p, theta_o, n_samples, rng):
    """Observed and expected counts of ``sample_batch`` for a view at (θ_o, φ_o = 0.4) (``tests.chi2``)."""
    wo_dir = fb.direction(theta_o, 0.4)
    wi, _, _ = fb.sample_batch(p, np.tile(wo_dir, (n_samples, 1)), rng.random((n_samples, 3)))
    return direction_counts(wi, lambda d: fb.pdf_batch(p, np.tile(wo_dir, (d.shape[0], 1)), d))


CHI2_CASES = [(lossless(5 * DEG, 10 * DEG, 25 * DEG), t) for t in (0.0, 45 * DEG, -80 * DEG, 89 * DEG)] + \
    [(lossless(15 * DEG, 25 * DEG, 60 * DEG), t) for t in (20 * DEG, -87 * DEG)] + \
    [(fb.params_from_values([0.8] * 3, [0.1] * 3, [0.1] * 3, 8 * DEG, 8 * DEG, 15 * DEG, -6 * DEG, 3 * DEG), 70 * DEG)]


def test_chi2_sampling_matches_pdf():
    alpha = 1 - (1 - 0.01) ** (1 / len(CHI2_CASES))  # Šidák correction over all cases
    rng = np.random.default_rng(3)
    for p, theta_o in CHI2_CASES:
        assert pooled_pvalue(*chi2_bins(p, theta_o, 400_000, rng)) > alpha, theta_o


def test_chi2_detects_a_wrong_pdf():
    """The test has power: sampling a 10 % wider TT lobe than the pdf describes is rejected."""
    p = lossless(5 * DEG, 10 * DEG, 25 * DEG)
    wide = p.copy()
    wide[fb.P_BETA_TT] *= 1.1
    rng = np.random.default_rng(4)
    wo_dir = fb.direction(0.3, 0.4)
    wi, _, _ = fb.sample_batch(wide, np.tile(wo_dir, (400_000, 1)), rng.random((400_000, 3)))
    assert chi2_pvalue(wi, lambda d: fb.pdf_batch(p, np.tile(wo_dir, (d.shape[0], 1)), d)) < 1e-6


def test_sample_weight_equals_eval_cos_over_pdf():
    p = lossless(4 * DEG, 12 * DEG, 30 * DEG)
    rng = np.random.default_rng(5)
    theta_o = rng.uniform(-np.pi / 2, np.pi / 2, 20_000)
    wo = fb.direction(theta_o, rng.uniform(0, 2 * np.pi, theta_o.size))
    wi, pdfs, weight = fb.sample_batch(p, wo, rng.random((theta_o.size, 3)))
    np.testing.assert_allclose(pdfs, fb.pdf_batch(p, wo, wi), rtol=1e-12)
    expected = fb.eval_batch(p, wo, wi) * np.sqrt(1 - wi[:, :1] ** 2) / pdfs[:, None]
    np.testing.assert_allclose(weight, expected, rtol=1e-12)
    assert np.all(pdfs > 0)


def test_lobes_peak_where_the_model_says():
    theta_o, phi_o = 0.5, 0.0
    theta = np.linspace(-np.pi / 2, np.pi / 2, 20001)
    # R lobe alone at φ = 0: peak at θ_i = 2α_R − θ_o; TT alone at φ = π: peak at θ_i = 2α_TT − θ_o
    for a_r, a_tt, phi_i, alpha in ((1, 0, 0.0, -4 * DEG), (0, 1, np.pi, 2 * DEG)):
        p = fb.params_from_values([a_r] * 3, [a_tt] * 3, [0, 0, 0], 3 * DEG, 3 * DEG, 10 * DEG, -4 * DEG, 2 * DEG)
        wi = fb.direction(theta, phi_o - phi_i)
        f = fb.eval_batch(p, np.tile(fb.direction(theta_o, phi_o), (theta.size, 1)), wi)[:, 0]
        assert theta[np.argmax(f)] == pytest.approx(2 * alpha - theta_o, abs=2e-4)
    # N_TT: normalised, standard deviation γ_TT
    p = fb.params_from_values([1, 1, 1], [1, 1, 1], [0, 0, 0], 3 * DEG, 3 * DEG, 10 * DEG)
    phi = np.linspace(-np.pi, np.pi, 200001)
    s = p[fb.P_GAMMA_TT] * math.sqrt(3) / math.pi
    dens = np.array([fb.logistic_trimmed(x, s) for x in phi[::10]])
    assert np.trapezoid(dens, phi[::10]) == pytest.approx(1.0, abs=1e-6)
    assert math.sqrt(np.trapezoid(dens * phi[::10] ** 2, phi[::10])) == pytest.approx(p[fb.P_GAMMA_TT], rel=1e-3)


def test_extremes_are_finite():
    """Roughness → 0, θ = ±π/2, φ = 0 and π, maximal shifts: f, pdf and weights stay finite."""
    params = [fb.params_from_values([0.3] * 3, [0.6] * 3, [0.1] * 3, 1e-3 * DEG, 1e-3 * DEG, 1e-3 * DEG),
              fb.params_from_values([0.3] * 3, [0.6] * 3, [0.1] * 3, 90 * DEG, 90 * DEG, 180 * DEG, 45 * DEG,
                                    -45 * DEG),
              fb.params_from_values([0, 0, 0], [0, 0, 0], [0, 0, 0], 5 * DEG, 5 * DEG, 5 * DEG)]
    thetas = [-np.pi / 2, -np.pi / 2 + 1e-9, 0.0, np.pi / 2 - 1e-9, np.pi / 2]
    phis = [0.0, np.pi, -np.pi]
    dirs = np.array([fb.direction(t, f) for t in thetas for f in phis])
    wo = np.repeat(dirs, len(dirs), axis=0)
    wi = np.tile(dirs, (len(dirs), 1))
    rng = np.random.default_rng(6)
    for p in params:
        assert np.all(np.isfinite(fb.eval_batch(p, wo, wi)))
        assert np.all(np.isfinite(fb.pdf_batch(p, wo, wi)))
        _, pdfs, weight = fb.sample_batch(p, wo, rng.random((wo.shape[0], 3)))
        assert np.all(np.isfinite(weight)) and np.all(np.isfinite(pdfs)) and np.all(pdfs > 0)


def test_erfcinv_against_scipy():
    y = np.concatenate([np.logspace(-15, 0, 60), 2 - np.logspace(-12, 0, 30)])
    ours = np.array([fb._erfcinv(v) for v in y])
    np.testing.assert_allclose(ours, special.erfcinv(y), rtol=1e-10, atol=1e-12)


def test_truncated_normal_sampler_matches_its_cdf():
    rng = np.random.default_rng(7)
    for a, b in ((-1.0, 2.0), (3.0, 6.0), (-7.0, -4.0), (-0.2, 0.1)):
        x = np.array([fb._normal_sample(a, b, u) for u in rng.random(20000)])
        assert np.all((x >= a) & (x <= b))
        cdf = lambda v, a=a, b=b: (stats.norm.cdf(v) - stats.norm.cdf(a)) / (stats.norm.cdf(b) - stats.norm.cdf(a))  # noqa
        if b <= 0:
            cdf = lambda v, a=a, b=b: (stats.norm.sf(-v) - stats.norm.sf(-a)) / (stats.norm.sf(-b) - stats.norm.sf(-a))  # noqa
        elif a >= 0:
            cdf = lambda v, a=a, b=b: (stats.norm.sf(a) - stats.norm.sf(v)) / (stats.norm.sf(a) - stats.norm.sf(b))  # noqa
        assert stats.kstest(x, cdf).pvalue > 0.001, (a, b)


def test_params_are_checked():
    with pytest.raises(ValueError, match="BCSDF"):
        fb.params_from_values([0.3] * 3, [0.6] * 3, [0.1] * 3, 0.0, 0.1, 0.1)
    with pytest.raises(ValueError, match="BCSDF"):
        fb.params_from_values([0.3] * 3, [np.nan] * 3, [0.1] * 3, 0.1, 0.1, 0.1)


def test_lobe_normaliser_matches_dense_quadrature_in_every_branch():
    """Z(μ, σ) = ∫ exp(−(θ−μ)²/2σ²) cos²θ dθ over the ±9σ window inside [−π/2, π/2]: closed form when the window
    fits, the closed form less the Faddeeva tails when it is cut (one end or both), Gauss–Legendre for a narrow cut
    lobe, 16 fixed nodes for a wide lobe cut at both ends, the log-Z table from σ = 0.1 to 8 rad; all against 400
    nodes, σ from 1e-4 to 20 rad and μ over the range ``lobe_centre`` allows (plus random points inside the table,
    away from its nodes)."""
    assert fb.LOBE_WINDOW == 9.0
    x, w = np.polynomial.legendre.leggauss(400)

    def dense(mu, sigma):
        lo, hi = max(-math.pi / 2, mu - 9 * sigma), min(math.pi / 2, mu + 9 * sigma)
        t = 0.5 * (hi + lo) + 0.5 * (hi - lo) * x
        return 0.5 * (hi - lo) * np.sum(w * np.exp(-0.5 * ((t - mu) / sigma) ** 2) * np.cos(t) ** 2)

    worst, worst_table, branches = 0.0, 0.0, set()
    for sigma in np.geomspace(1e-4, 20.0, 50):
        table = fb.NORMALISER_TABLE_SIGMA[0] <= sigma <= fb.NORMALISER_TABLE_SIGMA[1]
        for mu in np.linspace(-math.pi / 2 - 4 * sigma, math.pi / 2 + 4 * sigma, 31):
            lo, hi = max(-math.pi / 2, mu - 9 * sigma), min(math.pi / 2, mu + 9 * sigma)
            assert (lo, hi) == fb.lobe_window(mu, sigma)
            cuts = int(lo > mu - 9 * sigma) + int(hi < mu + 9 * sigma)
            branches.add((cuts, sigma < fb.NORMALISER_CLOSED_SIGMA and cuts > 0,
                          sigma >= fb.NORMALISER_WIDE_SIGMA and cuts == 2 and not table, table))
            error = abs(fb.cos2_normaliser(mu, sigma) / dense(mu, sigma) - 1.0)
            # the log form the DS lobes take (the table's log Z as is) is the same Z in every branch
            assert math.exp(fb.log_cos2_normaliser(mu, sigma)) == pytest.approx(fb.cos2_normaliser(mu, sigma),
                                                                                rel=1e-14)
            if table:
                worst_table = max(worst_table, error)
            else:
                worst = max(worst, error)
    rng = np.random.default_rng(5)
    for _ in range(3000):
        sigma = math.exp(rng.uniform(*np.log(fb.NORMALISER_TABLE_SIGMA)))
        mu = rng.uniform(-1.0, 1.0) * (math.pi / 2 + 4 * sigma)
        worst_table = max(worst_table, abs(fb.cos2_normaliser(mu, sigma) / dense(mu, sigma) - 1.0))
    # (cuts, narrow-lobe quadrature, 16-node rule, table); both ends cut needs σ > π/18, where the table (and
    # beyond σ = 8 the 16-node rule) takes over from the closed form less two tails
    assert branches == {(0, False, False, False), (1, False, False, False), (1, True, False, False),
                        (2, False, True, False), (0, False, False, True), (1, False, False, True),
                        (2, False, False, True)}
    assert worst < 3e-8
    assert worst_table < fb.NORMALISER_TABLE_ERROR


def test_faddeeva_function_against_scipy():
    """Re w(x + iy) on the half plane the normaliser's tails use (x = √2σ, y ≥ 0) against ``scipy.special.wofz``."""
    rng = np.random.default_rng(3)
    x, y = rng.uniform(0.0, 30.0, 5000), rng.uniform(0.0, 10.0, 5000)
    ours = np.array([fb._faddeeva_upper(a, b) for a, b in zip(x, y)])
    ref = special.wofz(x + 1j * y)
    assert np.max(np.abs(ours - ref.real) / np.abs(ref)) < 1e-12


def test_spread_params_widens_reflection_keeps_transmission_and_energy():
    """``spread_params``: β_p² grows by spread²·cos²(φ/2) (fully at φ = 0, not at φ = π), and the widened BCSDF still
    returns all the energy (white furnace) since its lobes are renormalised."""
    p = lossless(1 * DEG, 27 * DEG, 38 * DEG)
    wide = np.empty_like(p)
    spread2 = (6 * DEG) ** 2
    fb.spread_params(p, spread2, 0.0, wide)
    assert math.isclose(wide[fb.P_BETA_R], math.hypot(1 * DEG, 6 * DEG), rel_tol=1e-12)
    assert math.isclose(wide[fb.P_BETA_TT], math.hypot(27 * DEG, 6 * DEG), rel_tol=1e-12)
    widths = [fb.P_BETA_R, fb.P_BETA_TT]
    np.testing.assert_array_equal(np.delete(wide, widths), np.delete(p, widths))
    fb.spread_params(p, spread2, math.pi, wide)
    np.testing.assert_allclose(wide, p, rtol=1e-12, atol=1e-15)
    fb.spread_params(p, 0.0, 0.3, wide)
    np.testing.assert_array_equal(wide, p)
    fb.spread_params(p, 0.25, 0.0, wide)  # the renderer's cap, 0.5 rad
    rng = np.random.default_rng(4)
    wi = stratified_sphere(1024, rng)
    for theta_o in (0.0, 60 * DEG):
        wo = np.tile(fb.direction(theta_o, 0.7), (wi.shape[0], 1))
        furnace = (fb.eval_batch(wide, wo, wi) * np.sqrt(1 - wi[:, :1] ** 2) * 4 * np.pi).mean(axis=0)
        assert np.all(np.abs(furnace - 1) < 0.05), (theta_o, furnace)
