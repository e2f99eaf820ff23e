"""Environment-light table I_M: the direct quadrature against independent estimates and closed-form limits, the
parameterisation's symmetries, the baked table's lookup accuracy, determinism, finiteness, and the pack round trip."""

import math

import numpy as np
import pytest
from numba import njit
from scipy import integrate, special

from data_formats import asset_pack as ap
from data_formats.conventions import cell_centres
from data_formats.yarn_spec import load_preset
from knitbake.bake import QUALITY
from knitbake.stages import im_table as im
from knitrun.shading import fiber_bcsdf as fb
from knitrun.shading.im_lookup import (R_NEGLIGIBLE, i0e, im_kernel, im_lookup, im_slice_kernel, im_slices,
                                       im_table_from, sg)
from tests.helpers import BCSDF, DEG, ROUGH, TEST_SHAPE, YARN, provenance

MEDIUM = fb.params_from_values([0.3, 0.25, 0.2], [0.5, 0.45, 0.4], [0.1, 0.15, 0.2], 8 * DEG, 12 * DEG, 25 * DEG,
                               -3 * DEG, 1.5 * DEG)
def albedo(p):
    return p[fb.P_A_R:fb.P_A_R + 3] + p[fb.P_A_TT:fb.P_A_TT + 3] + p[fb.P_A_D:fb.P_A_D + 3]


def brute_force(p, theta_o, theta_j, dphi, lam, phi_o=0.7, n=300):
    """∫ G f cos θ_i dω_i by the midpoint rule on an n × 2n (θ_i, φ_i) grid, with the view at azimuth φ_o ≠ 0."""
    th = ((np.arange(n) + 0.5) / n - 0.5) * np.pi
    ph = (np.arange(2 * n) + 0.5) / n * np.pi
    t, f = np.meshgrid(th, ph, indexing="ij")
    wi = fb.direction(t.ravel(), f.ravel())
    wo = np.broadcast_to(fb.direction(theta_o, phi_o), wi.shape).copy()
    weight = sg(wi, fb.direction(theta_j, phi_o + dphi), lam) * np.cos(t.ravel()) ** 2 * (np.pi / n) ** 2
    return weight @ fb.eval_batch(p, wo, wi)


def sg_monte_carlo(p, theta_o, theta_j, dphi, lam, n, rng):
    """I_M by sampling the normalised SG exactly: (2π/λ)(1 − e^{−2λ}) E[f cos θ_i]; returns (mean, stderr)."""
    u1, u2 = rng.random(n), rng.random(n)
    cos_g = 1.0 + np.log(u1 + (1.0 - u1) * math.exp(-2.0 * lam)) / lam
    sin_g = np.sqrt(np.maximum(0.0, 1.0 - cos_g ** 2))
    wj = fb.direction(theta_j, dphi)
    a = np.cross(wj, [0.0, 0.0, 1.0] if abs(wj[2]) < 0.9 else [1.0, 0.0, 0.0])
    a /= np.linalg.norm(a)
    b = np.cross(wj, a)
    psi = 2 * np.pi * u2
    wi = cos_g[:, None] * wj + sin_g[:, None] * (np.cos(psi)[:, None] * a + np.sin(psi)[:, None] * b)
    wo = np.broadcast_to(fb.direction(theta_o, 0.0), wi.shape).copy()
    g = fb.eval_batch(p, wo, wi) * np.sqrt(np.maximum(0.0, 1.0 - wi[:, :1] ** 2))
    scale = 2 * np.pi / lam * (1.0 - math.exp(-2.0 * lam))
    return scale * g.mean(axis=0), scale * g.std(axis=0) / math.sqrt(n)


@pytest.fixture(scope="module")
def rough_table():
    return im.bake_im_table(ROUGH, TEST_SHAPE, nodes=4)


# --- the direct quadrature --------------------------------------------------------------------------------------

def test_i0e_matches_scipy_and_the_power_series():
    """The Chebyshev form against scipy (whose values it was interpolated from, at other points) and against the
    power series e^{−x} Σ (x²/4)^k/(k!)², summed in Python, which shares nothing with it."""
    x = np.concatenate([np.linspace(0, 40, 401), np.geomspace(40, 1e6, 100),
                        np.random.default_rng(2).uniform(0, 30, 300)])
    ours = np.array([i0e(v) for v in x])
    assert np.max(np.abs(ours / special.i0e(x) - 1)) < 1e-13
    for v in x[x <= 20]:
        term = total = 1.0
        k = 0
        while term > 1e-18 * total:
            k += 1
            term *= 0.25 * v * v / (k * k)
            total += term
        assert i0e(v) == pytest.approx(total * math.exp(-v), rel=1e-13)


@pytest.mark.parametrize("args", [(0.3, -0.2, 2.5, 0.5), (-1.2, 1.0, 3.0, 20.0), (1.5, 0.1, -2.0, 1.0),
                                  (-0.4, 1.5, 0.2, 3.0)])
def test_direct_matches_brute_force_grid(args):
    """Rotation invariance (the grid puts the view at φ_o = 0.7) and the 1-D/2-D reduction of every lobe."""
    np.testing.assert_allclose(im.im_direct(MEDIUM, *args), brute_force(MEDIUM, *args), rtol=1e-4)


@pytest.mark.parametrize("lam", [300.0, 1e4])
def test_direct_matches_sg_importance_sampling(lam):
    rng = np.random.default_rng(3)
    for theta_o, theta_j, dphi in [(0.2, -0.1, 2.8), (-0.9, 0.7, 0.4), (1.3, -1.45, -2.0)]:
        mc, se = sg_monte_carlo(MEDIUM, theta_o, theta_j, dphi, lam, 50_000, rng)
        direct = im.im_direct(MEDIUM, theta_o, theta_j, dphi, lam)
        assert np.all(np.abs(direct - mc) <= 4 * se + 1e-9 * mc), (theta_o, theta_j, dphi, direct, mc, se)


def test_large_lambda_limit():
    """λ → ∞: I_M → (2π/λ) f(ω_j, ω_o) cos θ_j, with a relative correction O(1/(λ σ²))."""
    rng = np.random.default_rng(4)
    theta_o, theta_j, dphi = rng.uniform(-1.3, 1.3, 20), rng.uniform(-1.2, 1.2, 20), rng.uniform(-np.pi, np.pi, 20)
    f = fb.eval_batch(ROUGH, fb.direction(theta_o, 0.0), fb.direction(theta_j, dphi))
    for lam, rtol in [(1e4, 2e-3), (1e6, 2e-5)]:
        limit = 2 * np.pi / lam * f * np.cos(theta_j)[:, None]
        np.testing.assert_allclose(im.im_direct(ROUGH, theta_o, theta_j, dphi, lam), limit, rtol=rtol)


def test_small_lambda_limit_and_bounds():
    """λ → 0: I_M → the albedo (∫ f cos θ_i dω_i); for any λ, e^{−2λ} ≤ G ≤ 1 bounds I_M by the albedo."""
    rng = np.random.default_rng(5)
    args = rng.uniform(-np.pi / 2, np.pi / 2, 30), rng.uniform(-np.pi / 2, np.pi / 2, 30), rng.uniform(-4, 4, 30)
    np.testing.assert_allclose(im.im_direct(ROUGH, *args, 1e-6), np.tile(albedo(ROUGH), (30, 1)), rtol=1e-5)
    for lam in (0.5, 2.0, 10.0):
        value = im.im_direct(MEDIUM, *args, lam)
        assert np.all(value <= albedo(MEDIUM) * (1 + 1e-9))
        assert np.all(value >= albedo(MEDIUM) * math.exp(-2 * lam) * (1 - 1e-9))


@pytest.mark.parametrize("lam", [0.5, 30.0, 1e4])
def test_diffuse_lobe_along_the_fiber_axis_closed_form(lam):
    """D only, ω_j = t (θ_j = π/2): I_M = (2 A_D/π) ∫ exp(λ(sin θ − 1)) cos²θ dθ, for every view."""
    p = fb.params_from_values([0.0] * 3, [0.0] * 3, [0.2, 0.4, 0.6], 5 * DEG, 5 * DEG, 5 * DEG)
    edge = math.pi / 2 - min(1.0, 12 / math.sqrt(lam))
    def integrand(t):
        return math.exp(lam * (math.sin(t) - 1)) * math.cos(t) ** 2

    expected = 2 / math.pi * sum(integrate.quad(integrand, a, b, epsabs=0, epsrel=1e-12, limit=200)[0]
                                 for a, b in [(-math.pi / 2, edge), (edge, math.pi / 2)])
    for theta_o in (-1.0, 0.3, math.pi / 2):
        np.testing.assert_allclose(im.im_direct(p, theta_o, math.pi / 2, 0.4, lam), p[6:9] * expected, rtol=1e-6)


def test_symmetries_and_what_the_papers_axes_lose():
    rng = np.random.default_rng(6)
    theta_o, theta_j, dphi, lam = (rng.uniform(-1.5, 1.5, 40), rng.uniform(-1.5, 1.5, 40), rng.uniform(-3, 3, 40),
                                   10 ** rng.uniform(-0.3, 4, 40))
    base = im.im_direct(MEDIUM, theta_o, theta_j, dphi, lam)
    np.testing.assert_allclose(im.im_direct(MEDIUM, theta_o, theta_j, -dphi, lam), base, rtol=1e-9)  # f even in φ
    np.testing.assert_allclose(im.im_direct(MEDIUM, theta_o, theta_j, dphi + 2 * np.pi, lam), base, rtol=1e-9)
    # (cos θ_j, cos θ_o, cos(θ_j − θ_o), 1/λ) are equal for these pairs, I_M is not: shifted lobes tell the sign of θ,
    # and TT depends on the azimuth
    flipped = im.im_direct(MEDIUM, -0.6, 0.3, 0.5, 20.0) / im.im_direct(MEDIUM, 0.6, -0.3, 0.5, 20.0)
    assert np.all(np.abs(flipped - 1) > 0.05), flipped
    turned = im.im_direct(MEDIUM, 0.6, -0.3, 2.8, 20.0) / im.im_direct(MEDIUM, 0.6, -0.3, 0.5, 20.0)
    assert np.all(np.abs(turned - 1) > 0.5), turned


def test_near_zero_roughness_is_finite_and_meets_its_limit():
    """β = γ = 1e-3°: the lobes are delta functions on the scale of any SG with λ ≤ 10⁴, so I_M → the SG at the lobe
    directions: A_R e^{λ(cos(μ_R − θ_j) − 1)} I0e(λ cos μ_R cos θ_j) + A_TT G(ω_TT; ω_j, λ), μ_p = 2α_p − θ_o and
    ω_TT = (μ_TT, φ_o + π)."""
    p = fb.params_from_values([0.3, 0.2, 0.1], [0.6, 0.5, 0.4], [0.0] * 3, 1e-3 * DEG, 1e-3 * DEG, 1e-3 * DEG,
                              -3 * DEG, 1.5 * DEG)
    rng = np.random.default_rng(7)
    theta_o, theta_j, dphi = rng.uniform(-1.4, 1.4, 30), rng.uniform(-1.4, 1.4, 30), rng.uniform(-np.pi, np.pi, 30)
    for lam in (0.5, 20.0, 1e4):
        mu_r, mu_tt = 2 * p[fb.P_ALPHA_R] - theta_o, 2 * p[fb.P_ALPHA_TT] - theta_o
        r = np.exp(lam * (np.cos(mu_r - theta_j) - 1)) * special.i0e(lam * np.cos(mu_r) * np.cos(theta_j))
        tt = sg(fb.direction(mu_tt, np.pi), fb.direction(theta_j, dphi), lam)
        expected = r[:, None] * p[fb.P_A_R:fb.P_A_R + 3] + tt[:, None] * p[fb.P_A_TT:fb.P_A_TT + 3]
        got = im.im_direct(p, theta_o, theta_j, dphi, lam)
        assert np.all(np.abs(got - expected) <= 1e-4 * expected + 1e-12), lam
    poles = np.array([-np.pi / 2, -np.pi / 2 + 1e-9, 0.0, np.pi / 2 - 1e-9, np.pi / 2])
    t_o, t_j, lam = np.meshgrid(poles, poles, [0.5, 1e4], indexing="ij")
    assert np.all(np.isfinite(im.im_direct(p, t_o, t_j, 0.3, lam)))
    table, err, axes = im.bake_im_table(p, (5, 9, 4, 6), nodes=4)
    assert np.all(np.isfinite(table)) and np.all(table >= 0) and np.all(np.isfinite(err))
    assert np.all(np.isfinite(im_lookup(table, axes, p, t_o, t_j, 0.3, lam)))


# --- the R lobe, integrated at lookup time --------------------------------------------------------------------

@pytest.mark.parametrize("beta_r_deg", [1e-3, 1.0, 5.238, 25.0])
def test_r_lobe_rule_matches_direct_quadrature(beta_r_deg):
    """The lookup's R-lobe rules (``r_lobe_integral``, reached through ``im_lookup`` with an all-zero TT+D
    table) against ``im_direct`` of the R lobe alone: within 0.25% wherever I_M^R exceeds 0.1% of its largest value in
    the λ decade, for β_R from near zero to very rough, λ from 0.5 to 10⁴, points on the lobe's ridge and at the
    poles; exactly finite at θ = ±π/2."""
    p = fb.params_from_values([0.3, 0.2, 0.1], [0.0] * 3, [0.0] * 3, beta_r_deg * DEG, 10 * DEG, 20 * DEG, -2 * DEG)
    axes = im.im_axes((2, 2, 2, 2))
    rng = np.random.default_rng(11)
    n = 3000
    theta_o, lam = rng.uniform(-np.pi / 2, np.pi / 2, n), 10 ** rng.uniform(math.log10(0.5), 4, n)
    lam[:300], lam[300:600] = 0.5, 1e4
    width = np.sqrt((2 * beta_r_deg * DEG) ** 2 + 1 / lam)
    theta_j = np.clip(2 * p[fb.P_ALPHA_R] - theta_o + rng.normal(0, 2, n) * width, -np.pi / 2, np.pi / 2)
    theta_j[:1000] = rng.uniform(-np.pi / 2, np.pi / 2, 1000)
    pole = np.pi / 2 * np.sign(rng.normal(size=300)) * (1 - rng.uniform(0, 1e-3, 300))
    theta_o[1000:1300], theta_j[1300:1600] = pole, pole
    got = im_lookup(np.zeros((2, 2, 2, 2, 3)), axes, p, theta_o, theta_j, 0.0, lam)
    ref = im.im_direct(p, theta_o, theta_j, 0.0, lam)
    decade = np.clip(np.floor(np.log10(lam) + 0.3), 0, 4)
    for d in range(5):
        m = decade == d
        counted = ref[m] > 1e-3 * ref[m].max(axis=0)
        assert np.max(np.abs(got[m] / np.where(counted, ref[m], 1.0) - 1)[counted]) < 2.5e-3, d
    skipped = np.all(got == 0.0, axis=1)  # the rule's bound said the lobe and the SRBF do not meet: it must hold
    assert np.all(ref[skipped] <= R_NEGLIGIBLE * p[fb.P_A_R:fb.P_A_R + 3])
    assert beta_r_deg > 20 or skipped.sum() > 100
    ends = np.array([-np.pi / 2, np.pi / 2])
    t_o, t_j, lams = np.meshgrid(ends, ends, [0.5, 1e4], indexing="ij")
    edge = im_lookup(np.zeros((2, 2, 2, 2, 3)), axes, p, t_o, t_j, 0.0, lams)
    assert np.all(np.isfinite(edge)) and np.all(edge >= 0)


# --- the baked table --------------------------------------------------------------------------------------------

def test_lookup_matches_direct_quadrature(rough_table):
    """Random points, plus λ = 0.5, λ = 10⁴ and θ_o, θ_j within 1.6e-3 rad of ±π/2. The acceptance criterion: relative
    error < 2% wherever I_M exceeds 1% of its maximum over the test set; and at every λ decade the error is < 1% of
    that decade's largest value (this covers large λ, where I_M ∝ 1/λ is below 1% of the overall maximum)."""
    table, err, axes = rough_table
    rng = np.random.default_rng(5)
    n = 2000
    theta_o, theta_j = rng.uniform(-np.pi / 2, np.pi / 2, n), rng.uniform(-np.pi / 2, np.pi / 2, n)
    dphi, lam = rng.uniform(-np.pi, np.pi, n), 10 ** rng.uniform(math.log10(0.5), 4, n)
    lam[:150], lam[150:300] = 0.5, 1e4
    pole = np.pi / 2 * np.sign(rng.normal(size=100)) * (1 - rng.uniform(0, 1e-3, 100))
    theta_o[300:400], theta_j[400:500] = pole, pole[::-1]
    ref = im.im_direct(ROUGH, theta_o, theta_j, dphi, lam)
    got = im_lookup(table, axes, ROUGH, theta_o, theta_j, dphi, lam)
    counted = ref > 0.01 * ref.max(axis=0)
    assert counted[:150].any() and counted[300:500].any()
    assert np.max(np.abs(got / ref - 1)[counted]) < 0.02
    decade = np.clip(np.floor(np.log10(lam) + 0.3), 0, 4)
    for d in range(5):
        m = decade == d
        assert np.max(np.abs(got[m] - ref[m]) / ref[m].max(axis=0)) < 0.01, d


@njit(cache=True)
def _both_kernels(table, slices, params, theta_o, theta_j, dphi, lam, lobe):
    """im_kernel on the table and im_slice_kernel on its slices, per point (lobe[k]: the point's lobe)."""
    full, sliced = np.empty((theta_o.shape[0], 3)), np.empty((theta_o.shape[0], 3))
    for k in range(theta_o.shape[0]):
        c = fb.view_context(params, theta_o[k])
        im_kernel(table, params, c, theta_o[k], theta_j[k], dphi[k], lam[k], full[k])
        im_slice_kernel(slices, lobe[k], params, c, theta_o[k], theta_j[k], dphi[k], lam[k], sliced[k])
    return full, sliced


@pytest.mark.parametrize("order", [(0, 1, 2, 3), (3, 1, 0, 2)])
def test_slices_at_the_lobes_lambda_give_the_tables_lookup(rough_table, order):
    """The renderer interpolates the table along log λ once per lobe (``im_slices``) and then over the other three
    axes: the same value as the 16-corner lookup to rounding, for λ inside, at and beyond the axis' ends, whatever
    the axes' order in the table."""
    table, _, axes = rough_table
    im = im_table_from(np.transpose(table, order + (4,)), [axes[a] for a in order])
    lambdas = np.array([0.3, 0.5, 2.7, 64.0, 6600.0, 1e4, 3e4])
    rng = np.random.default_rng(3)
    n = 3000
    lobe = rng.integers(0, len(lambdas), n)
    theta_o, theta_j = rng.uniform(-np.pi / 2, np.pi / 2, n), rng.uniform(-np.pi / 2, np.pi / 2, n)
    full, sliced = _both_kernels(im, im_slices(im, lambdas), ROUGH, theta_o, theta_j, rng.uniform(-7, 7, n),
                                 lambdas[lobe], lobe)
    assert np.all(full > 0) and np.allclose(sliced, full, rtol=1e-12, atol=0)
    with pytest.raises(ValueError, match="λ"):
        im_slices(im, [1.0, 0.0])


def test_cotton1_standard_quality_meets_the_lookup_target():
    """The issue's target on the default yarn: I_M as the renderer evaluates it (the standard quality's table plus
    the R-lobe rule) against direct quadrature, max relative error < 2% wherever I_M > 1% of its maximum, and < 1% of
    each λ decade's maximum, at random points including λ = 0.5, λ = 10⁴, the R ridge and θ within 1e-3 of ±π/2.
    (The measured errors of cotton1 and of the narrower-lobed presets per quality: BENCHMARKS.md, The bake.)"""
    params = fb.params_from_optics(load_preset("cotton1").optics)
    table, _, axes = im.bake_im_table(params, QUALITY["standard"]["environment"]["shape"], nodes=4)
    accuracy = im.lookup_accuracy(table, axes, params)
    assert accuracy["lookup_rel_error"] < 0.02, accuracy
    assert accuracy["lookup_error_per_decade"] < 0.01, accuracy


def test_samples_are_the_direct_values_within_their_error(rough_table):
    table, err, axes = rough_table
    samples = [cell_centres(*a["range"], n) for a, n in zip(axes, TEST_SHAPE)]
    rng = np.random.default_rng(8)
    idx = tuple(rng.integers(0, n, 300) for n in TEST_SHAPE)
    without_r = ROUGH.copy()
    without_r[fb.P_A_R:fb.P_A_R + 3] = 0.0  # the table holds the TT and D lobes
    direct = im.im_direct(without_r, *(s[i] for s, i in zip(samples[:3], idx[:3])), 10 ** samples[3][idx[3]])
    assert np.all(np.abs(table[idx] - direct) <= err[idx] + 1e-12)
    assert np.all(np.abs(table[idx] - direct) <= 1e-3 * direct)
    np.testing.assert_allclose(samples[0][[0, -1]], [-np.pi / 2, np.pi / 2])  # end samples on the domain ends
    np.testing.assert_allclose(10 ** samples[3][[0, -1]], im.LAMBDA_RANGE)


def test_bake_is_deterministic_and_round_trips_through_a_pack(tmp_path):
    shape = (4, 6, 5, 7)
    p = fb.params_from_pack(BCSDF)
    calls = []
    table, err, axes = im.bake_im_table(p, shape, progress=lambda done, total: calls.append((done, total)))
    assert calls == [(i, shape[0]) for i in range(1, shape[0] + 1)]
    again = im.bake_im_table(p, shape)
    assert np.array_equal(table, again[0]) and np.array_equal(err, again[1]) and axes == again[2]
    assert np.all(np.isfinite(table)) and np.all(table > 0) and np.all(err >= 0) and err.max() < 1e-3 * table.max()
    path = tmp_path / "im.h5"
    ap.write_pack(path, YARN, provenance(), BCSDF, {"environment/I_M_TT_D": table}, {"environment/I_M_TT_D": err},
                  {"environment/I_M_TT_D": {"axes": axes, "error_kind": im.ERROR_KIND}})
    assert ap.validate(path) == []
    pack = ap.read_pack(path, tables=["environment/I_M_TT_D"])
    info = pack.info["environment/I_M_TT_D"]
    assert [a.name for a in info.axes][:4] == [a["name"] for a in axes]
    query = (np.array([0.2, -1.5]), np.array([1.2, -0.3]), np.array([-2.0, 0.1]), np.array([3.0, 900.0]))
    np.testing.assert_array_equal(im_lookup(pack.tables["environment/I_M_TT_D"], info.axes, p, *query),
                                  im_lookup(table.astype(np.float32), axes, p, *query))


def test_lookup_refuses_an_unknown_parameterisation():
    axes = [{"name": n, "range": [0.0, 1.0], "wrap": "clamp"} for n in
            ("cos_theta_j", "cos_theta_o", "cos_theta_j_minus_theta_o", "inv_lambda")]
    with pytest.raises(ValueError, match="cos_theta_j"):
        im_lookup(np.zeros((2, 2, 2, 2, 3)), axes, ROUGH, 0.1, 0.2, 0.3, 4.0)
