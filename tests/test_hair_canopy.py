"""The hair canopy (``knitrun.render.hair_canopy``): shells from a coverage profile, beams through other yarns' hair
layers against the chord integrals they stand for, and what the renderer does with it."""

import math
from types import SimpleNamespace

import numba
import numpy as np
import pytest

from knitrun.render.hair_canopy import HAIR_SHELLS, canopy_grid, canopy_transmittance, hair_shells
from knitrun.render.yarn_bounce import REACH_RADII

R = 0.03  # yarn radius, scene units
H = 2.3  # the flyaway strip's half-width, yarn radii


def chord(rho, v):
    return 2.0 * math.sqrt(max(rho * rho - v * v, 0.0))


def depth_at(edges, sigma, v):
    """Optical depth of a straight beam at offset v (yarn radii) from an infinite yarn's axis, across it."""
    return sum(s * (chord(b, v) - chord(a, v)) for a, b, s in zip(edges[:-1], edges[1:], sigma))


def profile(rows=64, density=lambda rho: 0.4 / rho ** 2):
    """Coverage per texture row (v from −1 to 1 in flyaway half-widths) of a hair layer of the given density per
    yarn radius, integrated along each row's chord (fine quadrature), outside the body."""
    v = np.abs((np.arange(rows) + 0.5) / rows * 2.0 - 1.0) * H
    alpha = np.zeros(rows)
    for i, vi in enumerate(v):
        if vi < 1.0:
            continue
        z = np.linspace(0.0, math.sqrt(H * H - vi * vi), 2001)
        rho = np.hypot(vi, z)
        alpha[i] = 1.0 - math.exp(-2.0 * np.trapezoid(density(rho), z))
    return alpha


def lines_of(*polylines):
    points = np.concatenate(polylines)
    offsets = np.concatenate([[0], np.cumsum([len(p) for p in polylines])]).astype(np.int64)
    rest = np.concatenate([np.concatenate([[0.0], np.cumsum(np.linalg.norm(np.diff(p, axis=0), axis=1))])
                           for p in polylines])
    return SimpleNamespace(points=points, offsets=offsets, rest=rest)


def yarn_along_x(y=0.0, z=0.0, half=1.0, n=21):
    return np.stack([np.linspace(-half, half, n), np.full(n, y), np.full(n, z)], axis=1)


def test_shells_give_back_the_coverage_of_each_band():
    """Peeled from the outside in, the shells make a beam across the yarn at each band's middle meet the band's mean
    coverage, 1 − exp(−τ(v_mid)) = ᾱ_band, and recover a smooth density within the band averaging; no coverage, no
    density, and none where the strip is no wider than the body."""
    alpha = profile()
    edges, sigma = hair_shells(alpha, H)
    assert len(edges) == HAIR_SHELLS + 1 and edges[0] == 1.0 and edges[-1] == pytest.approx(H)
    v = np.abs((np.arange(64) + 0.5) / 64 * 2.0 - 1.0) * H
    for j in range(HAIR_SHELLS):
        band = (v >= edges[j]) & (v < edges[j + 1])
        mid = 0.5 * (edges[j] + edges[j + 1])
        assert 1.0 - math.exp(-depth_at(edges, sigma, mid)) == pytest.approx(alpha[band].mean(), rel=1e-9, abs=1e-12)
        assert sigma[j] == pytest.approx(0.4 / mid ** 2, rel=0.15)
    assert np.all(hair_shells(np.zeros(64), H)[1] == 0.0)
    assert np.all(hair_shells(alpha, 1.0)[1] == 0.0)  # a strip no wider than the body: no layer outside it


def test_a_beam_across_another_yarn_meets_its_hairs():
    """A receiver below a yarn lit from above, at offset v from its axis: the beam crosses the layer's chord and
    passes exp(−τ(v)), at the middle of a band 1 − ᾱ of that band; through the body itself the layer on both sides
    counts, the body is the shadow map's. The same yarn below the receiver (away from the light), a receiver
    beside the layer and a yarn without flyaways let everything through; a non-finite receiver reads 1."""
    shells = hair_shells(profile(), H)
    edges, sigma = shells
    lines = lines_of(yarn_along_x(z=0.0), yarn_along_x(y=5.0, z=-1.0))  # the second yarn far off
    up = np.array([0.0, 0.0, 1.0])
    grid = canopy_grid(lines, np.full(2, R), [shells, shells], up)
    offsets = np.array([0.0, 0.5, 1.2, 1.8, 2.2, 2.4])
    receivers = np.stack([np.zeros(6), offsets * R, np.full(6, -0.2)], axis=1)
    through = canopy_transmittance(grid, receivers, np.ones(6, np.int64), np.zeros(6))
    expected = [math.exp(-depth_at(edges, sigma, v)) for v in offsets]
    assert through == pytest.approx(expected, rel=1e-9)
    assert through[-1] == 1.0 and through[2] < 0.95
    below = canopy_transmittance(grid, receivers * [1, 1, -1], np.ones(6, np.int64), np.zeros(6))
    assert np.all(below == 1.0)
    bare = canopy_grid(lines, np.full(2, R), [None, None], up)
    assert bare is None and np.all(canopy_transmittance(bare, receivers, np.ones(6), np.zeros(6)) == 1.0)
    assert canopy_transmittance(grid, np.array([[np.nan, 0.0, -0.2]]), [1], [0.0])[0] == 1.0


def test_a_beam_along_a_yarn_runs_through_one_shell():
    """Lit along its axis, a receiver inside another yarn's shell k (at a constant distance from the axis) has its
    beam in that shell for the stretch of the yarn ahead of it: τ = σ_k ℓ / r."""
    shells = hair_shells(profile(), H)
    edges, sigma = shells
    k = 3
    rho = 0.5 * (edges[k] + edges[k + 1])
    lines = lines_of(yarn_along_x(half=0.3, n=13), yarn_along_x(y=5.0))
    grid = canopy_grid(lines, np.full(2, R), [shells, shells], np.array([1.0, 0.0, 0.0]))
    through = canopy_transmittance(grid, np.array([[0.1, rho * R, 0.0]]), [1], [0.0])
    assert through[0] == pytest.approx(math.exp(-sigma[k] / R * 0.2), rel=1e-9)


def test_the_receivers_own_layer_is_left_out_but_not_its_yarn_coming_back():
    """A yarn's own hairs within ``REACH_RADII`` radii of rest arc length are the lone yarn's (module docstring): a
    point on a hairpin's lower leg, lit across it, is dimmed by the upper leg (far along the yarn) and not by its own
    leg, though both layers lie around it."""
    shells = hair_shells(profile(), H)
    leg = yarn_along_x(half=1.0, n=41)
    upper = leg[::-1] + [0.0, 0.0, 5.0 * R]  # its layer (out to 2.3 r) clear of the receiver
    hairpin = np.concatenate([leg, upper])
    lines = lines_of(hairpin)
    grid = canopy_grid(lines, [R], [shells], np.array([0.0, 0.0, 1.0]))
    at = 20  # the lower leg's middle (x = 0), rest arc length 1.0
    point = lines.points[at] + [0.0, 0.0, R]
    looped = canopy_transmittance(grid, point[None], [0], [lines.rest[at]])[0]
    edges, sigma = shells
    assert looped == pytest.approx(math.exp(-depth_at(edges, sigma, 0.0)), rel=1e-6)
    straight = canopy_grid(lines_of(leg), [R], [shells], np.array([0.0, 0.0, 1.0]))
    assert canopy_transmittance(straight, point[None], [0], [1.0])[0] == 1.0
    assert REACH_RADII * R < 1.0  # the upper leg lies beyond the window


def test_the_same_for_any_thread_count():
    shells = hair_shells(profile(), H)
    rng = np.random.default_rng(3)
    lines = lines_of(*[yarn_along_x(y=y, z=z) for y, z in rng.uniform(-0.1, 0.1, (6, 2))])
    grid = canopy_grid(lines, np.full(6, R), [shells] * 6, np.array([0.2, 1.0, 0.3]))
    receivers = rng.uniform(-0.12, 0.12, (500, 3))
    curve, arc = rng.integers(0, 6, 500), rng.uniform(0.0, 2.0, 500)
    before = numba.get_num_threads()
    try:
        numba.set_num_threads(1)
        one = canopy_transmittance(grid, receivers, curve, arc)
        numba.set_num_threads(before)
        many = canopy_transmittance(grid, receivers, curve, arc)
    finally:
        numba.set_num_threads(before)
    assert np.array_equal(one, many) and one.min() < 0.9 and np.all(one > 0.0)


def test_each_cell_lists_its_segments_nearest_the_light_first_and_the_grid_changes_no_beam(monkeypatch):
    """The receivers stop at a cell's first segment wholly behind them, so each cell must hold its segments by
    decreasing top (toward the light, hair reach included); and the grid only prunes: with every segment in one cell
    the beams meet the same hairs."""
    import knitrun.render.hair_canopy as hc

    shells = hair_shells(profile(), H)
    rng = np.random.default_rng(11)
    tilt = [yarn_along_x(y=y, z=z) @ np.array([[math.cos(a), math.sin(a), 0.0], [-math.sin(a), math.cos(a), 0.0],
                                                [0.0, 0.0, 1.0]])
            for (y, z), a in zip(rng.uniform(-0.1, 0.1, (8, 2)), rng.uniform(0.0, math.pi, 8))]
    lines = lines_of(*tilt)
    direction = np.array([0.3, -0.4, 1.0])
    grid = canopy_grid(lines, np.full(8, R), [shells] * 8, direction)
    assert grid.size.prod() > 100
    top = np.maximum(grid.toward[grid.first], grid.toward[grid.first + 1]) + grid.reach[grid.seg_curve]
    for c in range(len(grid.start) - 1):
        held = top[grid.members[grid.start[c]:grid.start[c + 1]]]
        assert np.all(np.diff(held) <= 0.0), c
    receivers = rng.uniform(-0.12, 0.12, (400, 3))
    curve, arc = rng.integers(0, 8, 400), rng.uniform(0.0, 2.0, 400)
    fine = canopy_transmittance(grid, receivers, curve, arc)
    monkeypatch.setattr(hc, "MAX_CELLS", 1)
    coarse_grid = canopy_grid(lines, np.full(8, R), [shells] * 8, direction)
    assert coarse_grid.size.prod() <= 9
    coarse = canopy_transmittance(coarse_grid, receivers, curve, arc)
    assert fine.min() < 0.9 and np.allclose(fine, coarse, rtol=0.0, atol=1e-12)
