"""Dual scattering: the precomputed tables against brute-force quadrature of the BCSDF, energy, extremes, Zinke
eqs. 14–17, the runtime DS estimate (normalisation, limits, finiteness) and the θ-table lookup rule."""

import math

import numpy as np
import pytest

from data_formats import asset_pack as ap
from data_formats.conventions import cell_centres
from knitbake.stages.ds_precompute import ERROR_KIND, precompute_dual_scattering
from knitrun.shading import dual_scattering as ds
from knitrun.shading import fiber_bcsdf as fb
from knitrun.shading.fiber_frame import wrap_angle
from knitrun.shading.table_lookup import lookup_axis, lookup_theta
from tests.helpers import DEG

COLOURS = ([0.05, 0.1, 0.2], [0.3, 0.5, 0.7], [0.0, 0.1, 0.05])  # absorbing; D = 0 in the red channel
LOSSLESS = ([0.3] * 3, [0.6] * 3, [0.1] * 3)
ROUGHNESS = [(3 * DEG, 10 * DEG, 25 * DEG), (10 * DEG, 27 * DEG, 38 * DEG), (30 * DEG, 45 * DEG, 90 * DEG)]
N_THETA = 18  # cell centres −85°, −75°, …, 85°


def params(colours, beta_r, beta_tt, gamma_tt, alpha_r=-3 * DEG, alpha_tt=1.5 * DEG):
    return fb.params_from_values(*colours, beta_r, beta_tt, gamma_tt, alpha_r, alpha_tt)


def brute_force(p, theta, n_theta=1200, n_phi=24):
    """ā, ᾱ, β̄ of both halves at light angle θ by product quadrature over ω' of f(ω', ω_θ) cos θ' (dω' = cos θ' dθ'
    dφ) on ``fb.eval_batch``: midpoint rule in θ', Gauss–Legendre in φ on each quarter (N_TT has a kink at φ = 0);
    independent of the separable (closed-form azimuth, per-lobe) evaluation of the precompute."""
    t = -0.5 * math.pi + (np.arange(n_theta) + 0.5) * math.pi / n_theta
    x, w = np.polynomial.legendre.leggauss(n_phi)
    out = {}
    for half, lo in {"f": 0.5 * math.pi, "b": -0.5 * math.pi}.items():
        ph = np.concatenate([lo + 0.25 * math.pi * (1 + x), lo + 0.25 * math.pi * (3 + x)])
        tt, pp = np.meshgrid(t, ph, indexing="ij")
        wi = fb.direction(tt.ravel(), -pp.ravel())  # φ_o = 0, so φ = φ_o − φ_i = pp
        wo = np.tile(fb.direction(theta, 0.0), (wi.shape[0], 1))
        dw = (np.cos(tt) ** 2 * (math.pi / n_theta) * 0.25 * math.pi * np.concatenate([w, w])[None, :]).ravel()
        weight = fb.eval_batch(p, wo, wi) * dw[:, None]
        th = 0.5 * (theta + tt.ravel())[:, None]
        a = weight.sum(axis=0)
        m = (weight * th).sum(axis=0) / a
        out["a_" + half], out["alpha_" + half] = a, m
        out["beta_" + half] = np.sqrt((weight * (th - m) ** 2).sum(axis=0) / a)
    return out


@pytest.mark.parametrize("rough", ROUGHNESS)
def test_precompute_matches_brute_force_quadrature(rough):
    p = params(COLOURS, *rough)
    tables = precompute_dual_scattering(p, n_theta=N_THETA)
    centres = cell_centres(-0.5 * math.pi, 0.5 * math.pi, N_THETA)
    for k in (0, 6, 9, 14, 17):  # −85°, −25°, 5°, 55°, 85°
        ref = brute_force(p, centres[k])
        for name, value in ref.items():
            table, err = tables[f"dual_scattering/{name}"]
            # stated (quadrature) error + the brute-force rule's own (< 3e-10 here: refining it 2× moves it less);
            # the precompute integrates exactly normalised lobes, the brute force the evaluated f, whose lobes carry
            # their energy to the normaliser table's bound (``fiber_bcsdf.NORMALISER_TABLE_ERROR``)
            bound = err[k].max() + 1e-9 + fb.NORMALISER_TABLE_ERROR * np.abs(value)
            np.testing.assert_array_less(np.abs(table[k] - value), bound, err_msg=f"{name} θ#{k}")


@pytest.mark.parametrize("rough", ROUGHNESS)
def test_energy_forward_plus_backward_is_the_albedo(rough):
    for colours in (LOSSLESS, COLOURS):
        tables = precompute_dual_scattering(params(colours, *rough), n_theta=32)
        total = tables["dual_scattering/a_f"][0] + tables["dual_scattering/a_b"][0]
        np.testing.assert_allclose(total, np.broadcast_to(np.sum(colours, axis=0), total.shape), rtol=1e-12)


EXTREMES = {
    "smooth": params(LOSSLESS, 1e-3 * DEG, 1e-3 * DEG, 1e-3 * DEG),
    "smooth_no_shift": params(LOSSLESS, 1e-3 * DEG, 1e-3 * DEG, 5 * DEG, 0.0, 0.0),
    "near_total_absorption": params(([1e-9] * 3, [1e-9] * 3, [1e-9] * 3), 5 * DEG, 10 * DEG, 20 * DEG),
    "total_absorption": params(([0.0] * 3,) * 3, 5 * DEG, 10 * DEG, 20 * DEG),
    "forward_only": params(([0.0] * 3, [1.0] * 3, [0.0] * 3), 2 * DEG, 2 * DEG, 2 * DEG),  # ā_f → 1
    "rough": params(LOSSLESS, 90 * DEG, 90 * DEG, 180 * DEG),
}


@pytest.mark.parametrize("name", sorted(EXTREMES))
def test_extremes_are_finite_and_in_range(name):
    p = EXTREMES[name]
    for n_theta in (1, 2000):  # 2000: centres within 0.045° of ±π/2
        tables = precompute_dual_scattering(p, n_theta=n_theta, quality=16)
        for key, (table, err) in tables.items():
            spec, _ = ap.resolve_table(key)
            assert table.shape == err.shape == (n_theta, 3)
            assert np.all(np.isfinite(table)) and np.all(np.isfinite(err)) and np.all(err >= 0), key
            if spec.value_range[0] is not None:
                assert table.min() >= spec.value_range[0], key
    if name == "forward_only":
        assert tables["dual_scattering/a_f"][0].min() > 1 - 1e-12  # the 1 − ā_f² guard is active


def test_tables_are_accepted_by_the_asset_pack_writer(tmp_path):
    p = params(COLOURS, *ROUGHNESS[0])
    tables = precompute_dual_scattering(p, n_theta=16)
    bcsdf = {"r_color": COLOURS[0], "tt_color": COLOURS[1], "d_color": COLOURS[2], "beta_r": 3 * DEG,
             "beta_tt": 10 * DEG, "gamma_tt": 25 * DEG, "alpha_r": -3 * DEG, "alpha_tt": 1.5 * DEG}
    provenance = {"yarn_spec_toml": 'name = "t"\n', "bake_settings": {"n_theta": 16}, "seed": 0,
                  "code_version": "test", "created": "2026-01-31T12:00:00+00:00", "timings": {"ds": 0.1},
                  "sample_counts": {}}
    path = tmp_path / "ds.h5"
    ap.write_pack(path, {"name": "t", "units": "cm", "radius": 0.04, "period": 0.15, "plies": 2}, provenance, bcsdf,
                  {k: v[0] for k, v in tables.items()}, {k: v[1] for k, v in tables.items()},
                  {k: {"error_kind": ERROR_KIND} for k in tables})
    pack = ap.read_pack(path, tables=list(ds.RUNTIME_NAMES))
    np.testing.assert_allclose(fb.params_from_pack(pack.fiber_bcsdf), p, rtol=1e-6)
    np.testing.assert_allclose(pack.tables["dual_scattering/A_b"], tables["dual_scattering/A_b"][0], rtol=1e-6)


def test_backscatter_terms_follow_zinke_eqs_14_to_17():
    af, ab, alf, alb, bf, bb, db = 0.6, 0.15, -0.04, 0.07, 0.12, 0.2, 0.7
    big_a, delta, sigma = ds.backscatter_terms(af, ab, alf, alb, bf, bb, db)
    q = 1 - af ** 2
    assert big_a == pytest.approx(ab * af ** 2 / q + ab ** 3 * af ** 2 / q ** 3, rel=1e-14)
    expected = alb * (1 - 2 * ab ** 2 / q ** 2) + alf * (2 * q ** 2 + 4 * af ** 2 * ab ** 2) / q ** 3
    assert delta == pytest.approx(expected, rel=1e-14)
    assert sigma == pytest.approx((1 + db * af ** 2) * (ab * math.sqrt(2 * bf ** 2 + bb ** 2) + ab ** 3 * math.sqrt(
        2 * bf ** 2 + 3 * bb ** 2)) / (ab + ab ** 3 * (2 * bf + 3 * bb)), rel=1e-14)
    # guards: ā_f = 1 (1 − ā_f² floored) and ā_b = 0 (eq. 17's limit)
    big_a, delta, sigma = ds.backscatter_terms([1.0, 0.5], [0.0, 0.0], -0.05, 0.05, 0.1, 0.2, db)
    assert np.all(np.isfinite(big_a)) and np.all(np.isfinite(delta)) and np.all(np.isfinite(sigma))
    np.testing.assert_allclose(sigma, (1 + db * np.array([1.0, 0.25])) * math.sqrt(2 * 0.01 + 0.04))


# --- runtime -----------------------------------------------------------------------------------------------------

def constant_tables(n=8, a_f=1.0, beta_f=0.1, a_back=0.2, delta_b=-0.05, sigma_b=0.15):
    values = {"a_f": a_f, "beta_f": beta_f, "A_b": a_back, "Delta_b": delta_b, "sigma_b": sigma_b}
    return {f"dual_scattering/{k}": np.full((n, 3), v, dtype=np.float64) for k, v in values.items()}


def sphere_integral(tables, p, theta_o, n_front, d_b, n_t=200, n_p=48):
    """∫ (L_o/E) dω_i over the sphere of light directions by a midpoint grid (φ cells aligned with ±π/2)."""
    t = -0.5 * math.pi + (np.arange(n_t) + 0.5) * math.pi / n_t
    ph = -math.pi + (np.arange(n_p) + 0.5) * 2 * math.pi / n_p
    tt, pp = np.meshgrid(t, ph, indexing="ij")
    val = ds.evaluate_ds(tables, tt, theta_o, pp, n_front, d_b=d_b, params=p)
    return (val * np.cos(tt)[..., None]).sum(axis=(0, 1)) * (math.pi / n_t) * (2 * math.pi / n_p)


def test_runtime_lobes_carry_their_energy():
    """∫ F cos θ_i dω_i: direct = albedo + d_b Ā_b; scattered (constant tables) = T_f (albedo + d_b Ā_b), to the
    normaliser table's bound (``fiber_bcsdf.NORMALISER_TABLE_ERROR``: every lobe is normalised to it)."""
    p = params(COLOURS, *ROUGHNESS[1])
    tables = constant_tables()
    albedo = np.sum(COLOURS, axis=0)
    for theta_o in (0.0, 0.6, -1.2):
        direct = sphere_integral(tables, p, theta_o, 0.0, 0.7)
        np.testing.assert_allclose(direct, albedo + 0.7 * 0.2, rtol=1e-5)  # midpoint error ≈1.3e-6 (N_b's edges)
        scattered = sphere_integral(tables, p, theta_o, 3.0, 0.7)
        np.testing.assert_allclose(scattered, ds.D_F * (albedo + 0.7 * 0.2), rtol=1e-8 + fb.NORMALISER_TABLE_ERROR)


def test_global_azimuthal_functions_are_the_convolutions():
    u = -0.5 * math.pi + (np.arange(4000) + 0.5) * math.pi / 4000
    gamma = 20 * DEG
    s = gamma * math.sqrt(3) / math.pi
    n_tt = np.vectorize(lambda x: fb.logistic_trimmed(wrap_angle(x - math.pi), s))
    n_b = np.vectorize(ds.n_back)
    for phi in (0.0, 0.4, 1.5, 2.9, -2.2, math.pi):
        assert ds.n_tt_global(phi, gamma) == pytest.approx(n_tt(phi - u).mean(), rel=1e-5, abs=1e-12)
        assert ds.n_back_global(phi) == pytest.approx(n_b(phi - u).mean(), abs=1e-3)
    assert ds.tt_front_fraction(gamma) == pytest.approx(np.mean(n_tt(u + math.pi)) * math.pi, rel=1e-6)


def test_no_fibers_in_front_and_no_backscatter_is_single_scattering():
    p = params(COLOURS, *ROUGHNESS[0])
    tables = precompute_dual_scattering(p, n_theta=16)
    rng = np.random.default_rng(3)
    ti, to, ph = rng.uniform(-1.5, 1.5, 50), rng.uniform(-1.5, 1.5, 50), rng.uniform(-math.pi, math.pi, 50)
    got = ds.evaluate_ds(tables, ti, to, ph, 0.0, d_b=0.0, params=p)
    f = fb.eval_batch(p, fb.direction(to, 0.0), fb.direction(ti, -ph))
    np.testing.assert_allclose(got, f * np.cos(ti)[:, None], rtol=1e-12)


def test_zero_density_factors_leave_single_scattering_at_any_count():
    """d_f = d_b = 0 (the renderer's single-scattering split, ``Features.multiple_scattering``): D f cos θ_i for
    every fiber count and direct fraction; with the default factors the same points carry more light."""
    p = params(COLOURS, *ROUGHNESS[1])
    tables = precompute_dual_scattering(p, n_theta=16)
    rng = np.random.default_rng(5)
    ti, to, ph = rng.uniform(-1.5, 1.5, 60), rng.uniform(-1.5, 1.5, 60), rng.uniform(-math.pi, math.pi, 60)
    n, direct = rng.uniform(0.0, 9.0, 60), rng.uniform(0.0, 1.0, 60)
    got = ds.evaluate_ds(tables, ti, to, ph, n, d_f=0.0, d_b=0.0, params=p, direct_fraction=direct)
    f = fb.eval_batch(p, fb.direction(to, 0.0), fb.direction(ti, -ph))
    np.testing.assert_allclose(got, direct[:, None] * f * np.cos(ti)[:, None], rtol=1e-12)
    full = ds.evaluate_ds(tables, ti, to, ph, n, params=p, direct_fraction=direct)
    assert np.all(full >= got) and np.all(full.sum(axis=1) > got.sum(axis=1))


def test_runtime_is_finite_at_the_extremes():
    p = EXTREMES["smooth"]
    cases = [precompute_dual_scattering(q, n_theta=8, quality=16) for q in EXTREMES.values()]
    cases += [constant_tables(a_f=1.0, beta_f=0.0, a_back=0.0, sigma_b=0.0), constant_tables(a_f=0.0)]
    n = np.array([0.0, 0.3, 1.0, 7.0, 1e9, 1e300])
    for tables in cases:
        for theta_i in (-0.5 * math.pi, -1.0, 0.0, 1.4, 0.5 * math.pi):
            for theta_o in (-0.5 * math.pi, 0.2, 0.5 * math.pi):
                out = ds.evaluate_ds(tables, theta_i, theta_o, np.array([0.0, 1.0, math.pi])[:, None], n, params=p)
                assert out.shape == (3, n.size, 3)
                assert np.all(np.isfinite(out)) and np.all(out >= 0)
    comp = ds.ds_components(constant_tables(a_f=1.0), 0.1, 0.2, 3.0, 1e9, params=p)
    assert np.all(comp["T_f"] == ds.D_F) and np.all(np.isfinite(comp["L_over_E"]))
    with pytest.raises(ValueError):
        ds.evaluate_ds(cases[0], 0.0, 0.0, 0.0, -1.0, params=p)


# --- the θ lookup ------------------------------------------------------------------------------------------------

def test_lookup_theta_is_exact_at_centres_linear_between_and_clamps():
    rng = np.random.default_rng(0)
    for n in (1, 2, 7):
        table = rng.uniform(size=(n, 3))
        centres = cell_centres(-0.5 * math.pi, 0.5 * math.pi, n)
        np.testing.assert_allclose(lookup_theta(table, centres), table, rtol=1e-12)
        np.testing.assert_allclose(lookup_theta(table, [-0.5 * math.pi, -2.0]), table[[0, 0]], rtol=1e-12)
        np.testing.assert_allclose(lookup_theta(table, [0.5 * math.pi, 2.0]), table[[-1, -1]], rtol=1e-12)
        if n > 1:
            mid = 0.5 * (centres[:-1] + centres[1:])
            np.testing.assert_allclose(lookup_theta(table, mid), 0.5 * (table[:-1] + table[1:]), rtol=1e-12)
    assert lookup_theta(np.arange(4.0), np.zeros((2, 5))).shape == (2, 5)
    # repeat: halfway between the last and first centres across the seam, and periodic
    table = rng.uniform(size=(6, 3))
    np.testing.assert_allclose(lookup_axis(table, [-math.pi, math.pi], -math.pi, math.pi, "repeat"),
                               np.tile(0.5 * (table[0] + table[-1]), (2, 1)), rtol=1e-12)
    np.testing.assert_allclose(lookup_axis(table, 0.3 + 2 * math.pi, -math.pi, math.pi, "repeat"),
                               lookup_axis(table, 0.3, -math.pi, math.pi, "repeat"), rtol=1e-12)


def test_runtime_reads_the_tables_by_the_lookup_rule():
    """T_f and σ̄_f² use ā_f(θ_i) and β̄_f(θ_i) interpolated by the asset-pack rule."""
    p = params(COLOURS, *ROUGHNESS[0])
    tables = precompute_dual_scattering(p, n_theta=9)
    rng = np.random.default_rng(1)
    for theta_i in rng.uniform(-1.6, 1.6, 5):
        comp = ds.ds_components(tables, theta_i, 0.1, 0.2, 2.5, params=p)
        a_f = lookup_theta(tables["dual_scattering/a_f"][0], theta_i)
        beta_f = lookup_theta(tables["dual_scattering/beta_f"][0], theta_i)
        np.testing.assert_allclose(comp["T_f"], ds.D_F * a_f ** 2.5, rtol=1e-12)
        np.testing.assert_allclose(comp["sigma_f2"], 2.5 * beta_f ** 2, rtol=1e-12)


def test_without_single_scattering_only_f_leaves_the_direct_term():
    """``single=False`` (the renderer's multiple-scattering lights, whose f is in I_M) drops D·f from F_direct and
    changes nothing else."""
    p = params(COLOURS, *ROUGHNESS[0])
    tables = precompute_dual_scattering(p, n_theta=9)
    theta_i, theta_o, phi, n, direct = 0.3, -0.2, 2.2, 1.5, 0.4
    full = ds.ds_components(tables, theta_i, theta_o, phi, n, params=p, direct_fraction=direct)
    part = ds.ds_components(tables, theta_i, theta_o, phi, n, params=p, direct_fraction=direct, single=False)
    for name in ("T_f", "sigma_f2", "f_back_direct", "f_back_scatter", "F_scatter"):
        np.testing.assert_array_equal(part[name], full[name])
    wo = np.array([[math.sin(theta_o), math.cos(theta_o), 0.0]])
    wi = np.array([[math.sin(theta_i), math.cos(theta_i) * math.cos(phi), -math.cos(theta_i) * math.sin(phi)]])
    f = fb.eval_batch(p, wo, wi)[0]
    np.testing.assert_allclose(full["F_direct"] - part["F_direct"], direct * f, rtol=1e-12)
    assert np.all(f > 0)


def test_forward_fraction_is_the_interpolated_a_f_and_matches_the_brute_force_integral():
    """``forward_fraction`` (the flyaway layer's transmittance) reads ā_f by the lookup rule, in [0, 1]; at a cell
    centre it is the forward half's integral of f cos θ' (``brute_force``) to quadrature accuracy."""
    p = params(COLOURS, *ROUGHNESS[1])
    tables = precompute_dual_scattering(p, n_theta=N_THETA)
    tab = ds.pack_tables(tables)
    out = np.empty(3)
    for theta in np.linspace(-1.6, 1.6, 11):
        ds.forward_fraction(tab, theta, out)
        np.testing.assert_allclose(out, lookup_theta(tables["dual_scattering/a_f"][0], theta), rtol=1e-12)
        assert np.all((out >= 0) & (out <= 1))
    centre = cell_centres(-0.5 * math.pi, 0.5 * math.pi, N_THETA)[11]
    ds.forward_fraction(tab, centre, out)
    np.testing.assert_allclose(out, brute_force(p, centre)["a_f"], rtol=2e-3)


def test_terms_of_zero_weight_read_zero_and_the_total_is_continuous_at_both_ends():
    """``ds_kernel`` skips the terms its direct fraction D weighs by zero (the direct ones at D = 0, the scattered
    ones at D = 1): they read 0, and L_o/E at D = 0 and D = 1 is the limit of D → 0⁺ and D → 1⁻, so skipping them
    is not a change of the estimate."""
    p = params(COLOURS, *ROUGHNESS[0])
    tables = precompute_dual_scattering(p, n_theta=9)
    theta_i, theta_o, n = 0.3, -0.2, 1.5
    for phi in (0.4, 2.6):  # back half (N_b > 0), front half
        at = {d: ds.ds_components(tables, theta_i, theta_o, phi, n, params=p, direct_fraction=d)
              for d in (0.0, 1e-12, 1.0 - 1e-12, 1.0)}
        for name in ("f_back_direct", "F_direct"):
            assert np.all(at[0.0][name] == 0.0), name
        for name in ("f_back_scatter", "F_scatter"):
            assert np.all(at[1.0][name] == 0.0), name
        if phi < math.pi / 2:
            assert np.all(at[1e-12]["f_back_direct"] > 0.0)
        assert np.all(at[1.0 - 1e-12]["f_back_scatter"] > 0.0)
        np.testing.assert_allclose(at[0.0]["L_over_E"], at[1e-12]["L_over_E"], rtol=1e-9)
        np.testing.assert_allclose(at[1.0]["L_over_E"], at[1.0 - 1e-12]["L_over_E"], rtol=1e-9)
