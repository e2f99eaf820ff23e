"""The procedural fiber generator against the model it implements (Wu and Yuksel 2019 §2.2/§3.1, Huang et al. 2025 eqs.
12–13)."""

import dataclasses
import math

import numba
import numpy as np
import pytest
from scipy import integrate, stats

from data_formats.yarn_spec import load_preset, preset_names
from knitbake.fibers.fiber_set import KIND_HAIR, KIND_LOOP, KIND_REGULAR
from knitbake.fibers.procedural_yarn import density, generate_fibers, sample_radii


def with_geometry(spec, **changes):
    return dataclasses.replace(spec, geometry=dataclasses.replace(spec.geometry, **changes))


def radial_cdf(eps, beta):
    """CDF of the fiber-centre radius when centres are drawn with density p(R) per unit area: ∝ ∫ p(r) r dr."""
    grid = np.linspace(0.0, 1.0, 4001)
    cum = integrate.cumulative_trapezoid(density(grid, eps, beta) * grid, grid, initial=0.0)
    cum /= cum[-1]
    return lambda r: np.interp(r, grid, cum)


def ply_local_radius(spec, fibers, z_index=0):
    """Normalised radius of each regular fiber's centre at the z_index-th sample, from its points alone."""
    g = spec.geometry
    reg = fibers.select(fibers.kind == KIND_REGULAR)
    pts = reg.points.reshape(reg.n_fibers, -1, 3)[:, z_index]
    z = pts[0, 2]
    psi = 2 * np.pi * reg.ply / g.plies + (-1 if g.ply_clockwise else 1) * 2 * np.pi * z / g.ply_pitch
    n = np.stack([np.cos(psi), np.sin(psi)], -1)
    b = np.stack([-np.sin(psi), np.cos(psi)], -1)
    rel = pts[:, :2] - g.ply_distance * n
    a_n = (rel * n).sum(-1) / g.ply_semi_axes[1]
    a_b = (rel * b).sum(-1) / g.ply_semi_axes[0]
    return np.hypot(a_n, a_b)


@pytest.mark.parametrize("name", ["cotton1", "rayon1", "silk2"])
def test_radial_distribution_matches_p_of_r(name):
    """Kolmogorov–Smirnov test of the fiber-centre radii (recovered from the geometry, migration off) against p(R)."""
    spec = with_geometry(load_preset(name), fibers_per_ply=400, migration_rho_min=1.0)
    g = spec.geometry
    radii = np.concatenate([ply_local_radius(spec, generate_fibers(spec, seed=s, flyaways=False)) for s in range(3)])
    cdf = radial_cdf(g.density_eps, g.density_beta)
    assert stats.kstest(radii, cdf).pvalue > 0.01
    # the same test has the power to reject a wrong density (no floor ε, β + 1)
    assert stats.kstest(radii, radial_cdf(0.0, g.density_beta + 1.0)).pvalue < 0.01


def test_rejection_sampler_large_sample():
    rng = np.random.Generator(np.random.PCG64(7))
    r = sample_radii(rng, 50000, 0.1, 0.6)
    assert stats.kstest(r, radial_cdf(0.1, 0.6)).pvalue > 0.01
    assert stats.kstest(r, radial_cdf(0.1, 1.2)).pvalue < 1e-6


def unwrap_turns(angles):
    return np.unwrap(angles) / (2 * np.pi)


@pytest.mark.parametrize("name", ["cotton1", "cotton2", "polyester1", "rayon1", "silk1"])
def test_twist_pitches_match_spec(name):
    """Ply and fiber pitches measured from the points of a 12-period yarn equal α_yarn and α_fiber within 1%."""
    spec = load_preset(name)
    g = spec.geometry
    periods = 12
    fibers = generate_fibers(spec, length=periods * g.ply_pitch, seed=2, flyaways=False, segments_per_period=96)
    reg = fibers.select(fibers.kind == KIND_REGULAR)
    pts = reg.points.reshape(reg.n_fibers, -1, 3)
    length = pts[0, -1, 2] - pts[0, 0, 2]
    fiber_turns = []
    for j in range(g.plies):
        ply_pts = pts[reg.ply == j]
        centre = ply_pts[:, :, :2].mean(axis=0)  # measured ply centre line
        ply_turns = unwrap_turns(np.arctan2(centre[:, 1], centre[:, 0]))
        ply_pitch = length / abs(ply_turns[-1] - ply_turns[0])
        assert ply_pitch == pytest.approx(g.ply_pitch, rel=0.01)
        assert (ply_turns[-1] < ply_turns[0]) == g.ply_clockwise
        # ply centre line: the measured angle (least-squares line in z) at the measured mean distance
        zs = ply_pts[0, :, 2]
        psi = np.polyval(np.polyfit(zs, 2 * np.pi * ply_turns, 1), zs)
        n = np.stack([np.cos(psi), np.sin(psi)], -1)
        centre = np.linalg.norm(centre, axis=-1).mean() * n
        rel = ply_pts[:, :, :2] - centre
        a = (rel * n).sum(-1)
        b = rel[..., 1] * n[:, 0] - rel[..., 0] * n[:, 1]
        turns = unwrap_turns(np.arctan2(b, a))  # (fibers, z)
        fiber_turns.append(turns[:, -1] - turns[:, 0])
    fiber_turns = np.concatenate(fiber_turns)
    assert np.all((fiber_turns < 0) == g.fiber_clockwise)
    mean_pitch = length / np.mean(np.abs(fiber_turns))
    assert mean_pitch == pytest.approx(g.fiber_pitch, rel=0.01)


@pytest.mark.parametrize("name", ["cotton1", "rayon4"])
def test_flyaway_counts_match_densities(name):
    """Hair and loop counts per unit length per ply match ρ_hair, ρ_loop within 4 Poisson standard deviations."""
    spec = load_preset(name)
    length = 40 * spec.geometry.ply_pitch
    fibers = generate_fibers(spec, length=length, seed=11, segments_per_period=8)
    for kind, rho in ((KIND_HAIR, spec.flyaways.hair_density), (KIND_LOOP, spec.flyaways.loop_density)):
        expected = rho * length * spec.geometry.plies
        count = int(np.sum(fibers.kind == kind))
        assert abs(count - expected) < 4 * math.sqrt(expected), (kind, count, expected)
        per_ply = np.bincount(fibers.ply[fibers.kind == kind], minlength=spec.geometry.plies)
        assert np.all(np.abs(per_ply - expected / spec.geometry.plies) < 4 * math.sqrt(expected / spec.geometry.plies))


def test_flyaways_start_near_their_ply_and_stick_out():
    spec = load_preset("cotton1")
    fibers = generate_fibers(spec, length=10 * spec.geometry.ply_pitch, seed=5, segments_per_period=8)
    hairs = fibers.select(fibers.kind == KIND_HAIR)
    tips = np.array([np.linalg.norm(hairs.fiber(i)[-1, :2]) for i in range(hairs.n_fibers)])
    assert np.median(tips) > 0.8 * spec.radius  # hairs end around or outside the regular fibers
    loops = fibers.select(fibers.kind == KIND_LOOP)
    peaks = np.array([np.linalg.norm(loops.fiber(i)[:, :2], axis=1).max() for i in range(loops.n_fibers)])
    ends = np.array([np.linalg.norm(loops.fiber(i)[0, :2]) for i in range(loops.n_fibers)])
    assert np.all(peaks >= ends - 1e-12)
    assert np.all(np.isfinite(fibers.points))


@pytest.mark.parametrize("name", preset_names())
def test_period_tiles_seamlessly(name):
    """End of every regular fiber over one period == start of its successor, shifted by one period."""
    spec = load_preset(name)
    fibers = generate_fibers(spec, seed=3)
    reg = fibers.select(fibers.kind == KIND_REGULAR)
    pts = reg.points.reshape(reg.n_fibers, -1, 3)
    ends = pts[:, -1].copy()
    ends[:, 2] -= spec.geometry.ply_pitch
    starts = pts[fibers.info["successor"], 0]
    assert np.sort(fibers.info["successor"]).tolist() == list(range(reg.n_fibers))  # a permutation
    assert np.abs(ends - starts).max() < 1e-6 * spec.radius


def test_any_window_shows_the_same_periodic_yarn():
    spec = load_preset("cotton1")
    p = spec.geometry.ply_pitch
    long = generate_fibers(spec, length=3 * p, seed=4, segments_per_period=40, flyaways=False)
    second = generate_fibers(spec, length=p, z_start=p, seed=4, segments_per_period=40, flyaways=False)
    a = long.points.reshape(long.n_fibers, -1, 3)[:, 40:81]
    b = second.points.reshape(second.n_fibers, -1, 3)
    np.testing.assert_allclose(a, b[long.info["successor"]], atol=1e-12 * spec.radius)


def test_a_flyaway_seed_draws_other_flyaways_on_the_same_regular_fibers():
    """``flyaway_seed`` (the texture stage's draws): the regular fibers are those of the seed, bit for bit; the
    flyaways are another draw, the same for the same flyaway seed; None keeps the flyaways of the seed's own stream
    (what the reference path tracer draws)."""
    spec = load_preset("cotton1")
    base = generate_fibers(spec, length=2 * spec.geometry.ply_pitch, seed=5)
    draws = [generate_fibers(spec, length=2 * spec.geometry.ply_pitch, seed=5, flyaway_seed=j) for j in (0, 1, 1)]
    regular = base.select(base.kind == KIND_REGULAR)
    for fibers in draws:
        np.testing.assert_array_equal(fibers.select(fibers.kind == KIND_REGULAR).points, regular.points)
    flyaway = [f.select(f.kind != KIND_REGULAR).points for f in [base] + draws]
    assert flyaway[0].shape != flyaway[1].shape or not np.array_equal(flyaway[0], flyaway[1])
    assert flyaway[1].shape != flyaway[2].shape or not np.array_equal(flyaway[1], flyaway[2])
    np.testing.assert_array_equal(flyaway[2], flyaway[3])
    again = generate_fibers(spec, length=2 * spec.geometry.ply_pitch, seed=5, flyaway_seed=None)
    np.testing.assert_array_equal(again.points, base.points)


def test_regular_fibers_stay_inside_the_yarn_radius():
    spec = load_preset("rayon1")
    fibers = generate_fibers(spec, length=4 * spec.geometry.ply_pitch, seed=1, flyaways=False)
    r = np.linalg.norm(fibers.points[:, :2], axis=1)
    assert r.max() + spec.geometry.fiber_radius <= spec.radius * (1 + 1e-9)


def test_same_seed_same_fibers_any_thread_count():
    spec = load_preset("rayon1")
    before = numba.get_num_threads()
    try:
        numba.set_num_threads(1)
        a = generate_fibers(spec, length=2 * spec.geometry.ply_pitch, seed=9)
        numba.set_num_threads(max(2, before))
        b = generate_fibers(spec, length=2 * spec.geometry.ply_pitch, seed=9)
    finally:
        numba.set_num_threads(before)
    c = generate_fibers(spec, length=2 * spec.geometry.ply_pitch, seed=10)
    assert np.array_equal(a.points, b.points) and np.array_equal(a.kind, b.kind)
    assert not np.array_equal(a.points[: c.points.shape[0] // 2], c.points[: c.points.shape[0] // 2])


def test_extreme_specs_give_finite_fibers():
    spec = load_preset("cotton1")
    cases = [
        dict(plies=1, ply_distance=0.0, fibers_per_ply=1),
        dict(migration_frequency=0.0),
        dict(migration_frequency=50.0, migration_rho_min=0.0),
        dict(fiber_pitch=1e-3),
        dict(fiber_pitch=1e3, ply_pitch=1e3),
        dict(density_beta=100.0, density_eps=0.5),
    ]
    for change in cases:
        f = generate_fibers(with_geometry(spec, **change), seed=0)
        assert np.all(np.isfinite(f.points)), change
        assert f.n_fibers >= 1


@pytest.mark.parametrize("length", [0.0, -1.0, float("nan"), float("inf")])
def test_bad_length_is_refused(length):
    with pytest.raises(ValueError, match="length"):
        generate_fibers(load_preset("cotton1"), length=length)
