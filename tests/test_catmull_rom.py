"""Centripetal Catmull-Rom subdivision: control points kept, circle and line reproduction, C1 joints, rest arc
length, closing segments, degenerate curves, identity at per_span = 1, and input validation."""

import numpy as np
import pytest

from knitrun.catmull_rom import subdivide


def polyline_rest(points):
    return np.concatenate([[0.0], np.cumsum(np.linalg.norm(np.diff(points, axis=0), axis=1))])


def circle(n, radius=1.0):
    th = 2 * np.pi * np.arange(n) / n
    return np.stack([radius * np.cos(th), radius * np.sin(th), np.zeros(n)], axis=1)


def wiggle(n=9):
    rng = np.random.default_rng(3)
    return np.cumsum(rng.normal(size=(n, 3)) * [1.0, 0.5, 2.0], axis=0)


def test_control_points_are_kept_exactly():
    a, b = wiggle(7), circle(5)
    pts = np.concatenate([a, b])
    rest = np.concatenate([polyline_rest(a), polyline_rest(b) + 10])
    p2, o2, r2, _ = subdivide(pts, [0, 7, 12], [False, True], rest, 5)
    assert o2.tolist() == [0, 31, 56]
    assert np.array_equal(p2[0:31:5], a) and np.array_equal(p2[31:56:5], b)
    assert np.array_equal(r2[0:31:5], rest[:7]) and np.array_equal(r2[31:56:5], rest[7:])


def test_closed_circle_stays_on_the_circle():
    pts = circle(8, radius=2.0)
    p2, o2, _, _ = subdivide(pts, [0, 8], [True], polyline_rest(np.vstack([pts, pts[:1]]))[:-1], 8)
    assert o2.tolist() == [0, 64]
    spline_err = np.abs(np.linalg.norm(p2, axis=1) - 2.0).max()
    chord_err = 2.0 * (1 - np.cos(np.pi / 8))  # the polyline's deviation at its chord midpoints
    assert spline_err < 0.01 * 2.0 and spline_err < chord_err / 5


def test_straight_line_stays_straight_and_evenly_spaced():
    d = np.array([0.3, -1.2, 0.7])
    pts = np.array([0.5, 1.0, -2.0]) + np.arange(5)[:, None] * d
    p2, _, r2, _ = subdivide(pts, [0, 5], [False], polyline_rest(pts), 6)
    assert len(p2) == 25
    steps = np.diff(p2, axis=0)
    assert np.allclose(steps, d / 6, atol=1e-12)
    assert np.allclose(np.diff(r2), np.linalg.norm(d) / 6)


def test_tangents_are_continuous_at_control_points():
    pts = wiggle(6)
    n = 400
    knots = np.sqrt(np.linalg.norm(np.diff(np.vstack([pts, pts[:1]]), axis=0), axis=1))  # t2 − t1 per span
    for closed in (False, True):
        p2, _, _, _ = subdivide(pts, [0, 6], [closed], polyline_rest(pts), n)
        for i in range(1, 6 if closed else 5):
            k = i * n  # control point i
            hl, hr = knots[i - 1] / n, knots[i] / n  # dC/dt by one-sided second-order differences
            left = (3 * p2[k] - 4 * p2[k - 1] + p2[k - 2]) / (2 * hl)
            right = (-3 * p2[k] + 4 * p2[(k + 1) % len(p2)] - p2[(k + 2) % len(p2)]) / (2 * hr)
            assert np.linalg.norm(left - right) < 1e-3 * np.linalg.norm(left)
            chord_left, chord_right = (pts[i] - pts[i - 1]) / knots[i - 1], (pts[(i + 1) % 6] - pts[i]) / knots[i]
            assert np.linalg.norm(chord_left - chord_right) > 0.1 * np.linalg.norm(left)  # the polyline has a kink


def test_rest_arclength_is_monotone_and_linear_per_span():
    pts = wiggle(8)
    rest = polyline_rest(pts) * 1.3
    p2, _, r2, _ = subdivide(pts, [0, 8], [False], rest, 7)
    assert np.all(np.diff(r2) > 0)
    assert np.array_equal(r2[::7], rest)
    assert np.allclose(r2[7:14], rest[1] + np.arange(7) / 7 * (rest[2] - rest[1]))


def test_closed_curve_closing_segment():
    pts = circle(6, radius=1.5)
    rest = np.arange(6) * 1.5  # chord of a hexagon = its radius
    p2, o2, r2, cl = subdivide(pts, [0, 6], [True], rest, 4)
    assert len(p2) == 24 and cl.shape == (1,)
    assert np.isclose(cl[0], 1.5 / 4)
    assert np.allclose(r2[-4:], rest[-1] + np.arange(4) * 1.5 / 4)  # the closing span's sub-points
    assert np.linalg.norm(p2[-1] - pts[0]) < 1.5 / 4 * 1.1  # the last sub-point sits just before the first
    _, _, _, cl = subdivide(pts, [0, 6], [True], rest, 4, closing_length=3.0)
    assert np.isclose(cl[0], 0.75)
    _, _, _, cl = subdivide(pts, [0, 6], [False], rest, 4)
    assert cl[0] == 0.0


def test_degenerate_curves_stay_finite():
    pts = np.array([[0.0, 0, 0], [0, 0, 0], [1, 0, 0], [1, 0, 0], [1, 0, 0], [2, 1, 0],  # zero-length spans
                    [5.0, 5, 5],  # 1 point
                    [0.0, 0, 1], [0, 0, 2],  # 2 points
                    [3.0, 3, 3], [3, 3, 3],  # 2 coincident points, closed
                    [7.0, 7, 7]])  # 1 point, closed
    offsets = [0, 6, 7, 7, 9, 11, 12]  # curve 2 is empty
    closed = [False, False, False, False, True, True]
    rest = np.arange(len(pts), dtype=float)
    for closed_first in (False, True):
        closed[0] = closed_first
        p2, o2, r2, cl = subdivide(pts, offsets, closed, rest, 5)
        assert np.isfinite(p2).all() and np.isfinite(r2).all() and np.isfinite(cl).all()
        sizes = np.diff(o2).tolist()
        assert sizes == [30 if closed_first else 26, 1, 0, 6, 10, 5]
    assert np.array_equal(p2[30:31], pts[6:7])
    assert np.allclose(p2[31:37], [[0, 0, 1 + k / 5] for k in range(6)])  # a 2-point curve is its segment
    assert np.array_equal(p2[37:47], np.repeat(pts[9:11], 5, axis=0))
    assert np.array_equal(p2[47:], np.repeat(pts[11:], 5, axis=0))
    zero_span = p2[:5]  # the span between the two coincident points at the start is constant
    assert np.array_equal(zero_span, np.zeros((5, 3)))
    p2, o2, _, _ = subdivide(np.zeros((0, 3)), [0, 0], [True], np.zeros(0), 4)
    assert p2.shape == (0, 3) and o2.tolist() == [0, 0]


def test_per_span_one_is_a_copy_of_the_input():
    pts = wiggle(5)
    rest = polyline_rest(pts)
    offsets = np.array([0, 2, 5])
    p2, o2, r2, cl = subdivide(pts, offsets, [False, True], rest, 1)
    assert np.array_equal(p2, pts) and np.array_equal(o2, offsets) and np.array_equal(r2, rest)
    assert p2 is not pts and r2 is not rest and o2 is not offsets
    assert cl[0] == 0.0 and np.isclose(cl[1], np.linalg.norm(pts[4] - pts[2]))


def test_bad_input_raises():
    pts = wiggle(4)
    rest = polyline_rest(pts)
    for per_span in (0, -2, 1.5):
        with pytest.raises(ValueError, match="per_span"):
            subdivide(pts, [0, 4], [False], rest, per_span)
    bad = pts.copy()
    bad[2, 1] = np.inf
    with pytest.raises(ValueError, match="curve 1: point 1"):
        subdivide(bad, [0, 1, 4], [False, False], rest, 3)
    bad_rest = rest.copy()
    bad_rest[3] = np.nan
    with pytest.raises(ValueError, match="curve 0: point 3"):
        subdivide(pts, [0, 4], [False], bad_rest, 3)
    with pytest.raises(ValueError, match="offsets"):
        subdivide(pts, [0, 3], [False], rest, 3)
