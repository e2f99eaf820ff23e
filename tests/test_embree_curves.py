"""Fibers as Embree 4 round linear curves (``knitbake.trace.embree_curves``): hits against the analytic tube, the
segment and fiber a hit names, a tapering radius, round ends, occlusion, bad input, and determinism over threads."""

import math

import numba
import numpy as np
import pytest

from knitbake.fibers.fiber_set import FiberSet
from knitbake.trace.embree_curves import CurveScene, any_hits, closest_hits


def _fibers(polylines, radii):
    points = np.concatenate(polylines)
    offsets = np.concatenate([[0], np.cumsum([len(p) for p in polylines])]).astype(np.int64)
    n = len(polylines)
    return FiberSet(points, offsets, np.asarray(radii, float), np.zeros(n, np.int8), np.zeros(n, np.int16))


def test_rays_hit_a_straight_fiber_where_the_cylinder_is():
    """A fiber along x of radius r: a ray down −z at lateral offset y hits at z = √(r² − y²), normal (0, y, z)/r;
    rays beyond r miss; the segment index follows the ray's x."""
    r = 0.1
    line = np.stack([np.linspace(-1, 1, 5), np.zeros(5), np.zeros(5)], axis=1)
    scene = CurveScene(_fibers([line], [r]))
    rng = np.random.default_rng(0)
    x, y = rng.uniform(-0.9, 0.9, 2000), rng.uniform(-1.5 * r, 1.5 * r, 2000)
    origins = np.stack([x, y, np.full_like(x, 5.0)], axis=1)
    t, seg, normal, u = closest_hits(scene, origins, [[0.0, 0.0, -1.0]] * 2000)
    inside = np.abs(y) < 0.999 * r
    outside = np.abs(y) > 1.001 * r
    assert np.all(seg[inside] >= 0) and np.all(seg[outside] == -1) and np.all(np.isinf(t[outside]))
    z = np.sqrt(r * r - y[inside] ** 2)
    np.testing.assert_allclose(t[inside], 5.0 - z, atol=2e-6 * 5)
    expected = np.stack([np.zeros(inside.sum()), y[inside], z], axis=1) / r
    assert np.max(np.abs(normal[inside] - expected)) < 2e-3
    np.testing.assert_array_equal(seg[inside], np.minimum(((x[inside] + 1) / 0.5).astype(int), 3))
    assert np.all((u[inside] >= 0) & (u[inside] <= 1))


def test_segments_name_their_fibers_and_ends_are_round():
    a = np.array([[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [2.0, 0.0, 0.0]])
    b = np.array([[0.0, 1.0, 0.0], [1.0, 1.0, 0.0]])
    scene = CurveScene(_fibers([a, b], [0.05, 0.2]))
    assert scene.n_segments == 3 and list(scene.segment_fiber) == [0, 0, 1] and list(scene.segment_start) == [0, 1, 3]
    t, seg, _, _ = closest_hits(scene, [[1.5, 0, 5], [0.5, 1, 5], [1.1, 1.0, 5]], [[0, 0, -1]] * 3)
    assert list(seg) == [1, 2, 2]
    np.testing.assert_allclose(t[:2], [5 - 0.05, 5 - 0.2], atol=1e-5)
    cap = math.sqrt(0.2 ** 2 - 0.1 ** 2)  # beyond the last point the fiber ends in a sphere of its radius
    np.testing.assert_allclose(t[2], 5 - cap, atol=1e-5)


def test_occlusion_counts_only_the_interval():
    line = np.array([[-1.0, 0, 0], [1.0, 0, 0]])
    scene = CurveScene(_fibers([line], [0.1]))
    blocked = any_hits(scene, [[0, 0, 5]] * 3, [[0, 0, -1]] * 3, [10.0, 4.95, 4.85])  # the surface is at t = 4.9
    assert list(blocked) == [True, True, False]


def test_bad_fibers_are_refused_in_one_line():
    line = np.array([[0.0, 0, 0], [1.0, 0, 0]])
    with pytest.raises(ValueError, match="radii"):
        CurveScene(_fibers([line], [0.0]))
    with pytest.raises(ValueError, match="fewer than 2 points"):
        CurveScene(_fibers([line[:1]], [0.1]))
    with pytest.raises(ValueError, match="finite"):
        CurveScene(_fibers([line * np.nan], [0.1]))


def test_hits_are_the_same_for_one_and_two_threads():
    rng = np.random.default_rng(3)
    polylines = [np.cumsum(rng.normal(0, 0.05, (20, 3)), axis=0) + rng.uniform(-1, 1, 3) for _ in range(200)]
    scene = CurveScene(_fibers(polylines, rng.uniform(0.005, 0.02, 200)))
    origins = rng.uniform(-2, 2, (5000, 3))
    directions = rng.normal(size=(5000, 3))
    before = numba.get_num_threads()
    try:
        numba.set_num_threads(1)
        one = closest_hits(scene, origins, directions)
        numba.set_num_threads(2)
        two = closest_hits(scene, origins, directions)
    finally:
        numba.set_num_threads(before)
    for a, b in zip(one, two):
        assert np.array_equal(a, b)
    assert (one[1] >= 0).sum() > 50
