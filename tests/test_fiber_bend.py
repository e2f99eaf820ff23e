"""The fiber bend (``strip_shading.fiber_bend`` of ``pipeline.segment_bend``'s curvature and stretch): the along-yarn
scale λ (1 − κ·o) of the regular fibers' tangent on analytic curves (an arc seen from its axis, a stretched straight
yarn, a bend tighter than the radius, a closing segment), and the same scale measured on the reference's own fibers
swept along an arc (``sweep_fibers``)."""

import dataclasses

import numpy as np
import pytest

from data_formats.yarn_curves import make_yarn_curves
from data_formats.yarn_spec import load_preset
from knitbake.fibers.fiber_set import KIND_REGULAR
from knitbake.fibers.fiber_sweep import sweep_fibers
from knitrun.render.pipeline import _Polylines, segment_bend
from knitrun.render.strip_shading import MIN_ALONG, _strip_frame, fiber_bend
from knitrun.render.strip_raster import vertex_tangents

RADIUS = 0.05  # cm


def _arc(bend_radius, n=401, angle=np.pi / 2):
    """A circular arc in the xy-plane about the origin, counter-clockwise from (bend_radius, 0, 0)."""
    a = np.linspace(0.0, angle, n)
    return np.stack([bend_radius * np.cos(a), bend_radius * np.sin(a), np.zeros(n)], axis=1)


def _lines(points, rest=None):
    rest = np.concatenate([[0.0], np.cumsum(np.linalg.norm(np.diff(points, axis=0), axis=1))]) if rest is None \
        else rest
    return _Polylines(points, np.array([0, len(points)]), rest, np.zeros(1, np.int64), np.zeros_like(points))


def _points_on(lines, segment, v, view_dir):
    """Shading points at the middle of ``segment`` (indices), at strip coordinate v, seen from ``view_dir``."""
    t = vertex_tangents(lines.points, lines.offsets)
    tangent = t[segment] + t[segment + 1]
    tangent /= np.linalg.norm(tangent, axis=1, keepdims=True)
    n = len(segment)
    return {"segment": segment, "tangent": tangent, "view_dir": np.tile(view_dir, (n, 1)),
            "v": np.asarray(v, np.float64)}


def _along(points, lines):
    """The fiber bend of each point, as ``shade_regular`` takes it: its strip frame from ``_strip_frame``."""
    curvature, stretch = segment_bend(points, lines)
    out = []
    for q in range(len(stretch)):
        n, b = np.empty(3), np.empty(3)
        assert _strip_frame(points["tangent"][q], points["view_dir"][q], n, b)
        out.append(fiber_bend(curvature, stretch, q, RADIUS, points["v"][q], n, b))
    return np.array(out)


def test_an_arc_seen_from_its_axis_tilts_the_outside_fibers_toward_the_yarn_and_the_inside_ones_away():
    bend = 0.5  # cm: r/R = 0.1
    lines = _lines(_arc(bend))
    segment = np.array([100, 200, 300, 100, 200])
    # seen from +z: n = +z, b = n × t points toward the centre (t counter-clockwise), so v = −1 is the outside
    points = _points_on(lines, segment, [-1.0, -1.0, 1.0, 0.0, -0.5], np.array([0.0, 0.0, 1.0]))
    along = _along(points, lines)
    expected = [1.1, 1.1, 0.9, 1.0, 1.05]  # 1 − κ·o, o = r (v b + √(1 − v²) n), κ = −(1/R) radial
    np.testing.assert_allclose(along, expected, atol=2e-4)


def test_a_stretched_straight_yarn_tilts_its_fibers_toward_its_tangent_by_the_stretch():
    points = np.stack([np.linspace(0.0, 1.0, 11), np.zeros(11), np.zeros(11)], axis=1)
    lines = _lines(points, rest=np.linspace(0.0, 1.0 / 1.3, 11))
    pts = _points_on(lines, np.arange(10), np.linspace(-1.0, 1.0, 10), np.array([0.0, 0.3, 1.0]) / np.sqrt(1.09))
    np.testing.assert_allclose(_along(pts, lines), 1.3, rtol=1e-12)


def test_a_bend_tighter_than_the_radius_folds_no_fiber_and_a_closing_segment_is_left_alone():
    lines = _lines(_arc(0.8 * RADIUS))
    pts = _points_on(lines, np.array([200]), [1.0], np.array([0.0, 0.0, 1.0]))  # the inside: 1 − 1.25 < 0
    assert _along(pts, lines)[0] == MIN_ALONG
    last = len(lines.points) - 1  # a closed curve's closing segment starts at the last point
    pts = {"segment": np.array([last]), "tangent": np.array([[0.0, 1.0, 0.0]]), "view_dir": np.array([[0.0, 0, 1]]),
           "v": np.array([1.0])}
    assert _along(pts, lines)[0] == 1.0


@pytest.mark.parametrize("stretch", [1.0, 1.2])
def test_the_reference_fibers_swept_along_an_arc_tilt_by_the_bend_and_the_stretch(stretch):
    """Each regular fiber segment of the reference's fibers swept along an arc (radius 2.5 r, rest length that of
    its polygon over ``stretch``) against the same fiber swept along a straight line of the same rest length: its
    advance along the arc's tangent over its advance along the line is λ (1 − κ·o), o its midpoint's offset from
    the arc's axis, as ``fiber_bend`` scales the texture tangent."""
    spec = load_preset("cotton1")
    spec = dataclasses.replace(spec, geometry=dataclasses.replace(spec.geometry, fibers_per_ply=8))
    bend = 2.5 * RADIUS
    arc = _arc(bend, n=721, angle=2.0)
    rest = np.concatenate([[0.0], np.cumsum(np.linalg.norm(np.diff(arc, axis=0), axis=1))]) / stretch
    line = np.stack([rest, np.zeros_like(rest), np.zeros_like(rest)], axis=1)
    swept = [sweep_fibers(make_yarn_curves(p, np.array([0, len(p)]), rest_arclength=rest, curve_type="PL"), 0,
                          {0: spec}, {0: RADIUS}, seed=4, flyaways=False) for p in (arc, line)]
    bent, straight = swept
    assert np.array_equal(bent.offsets, straight.offsets)
    starts = np.concatenate([np.arange(a, b - 1) for a, b, k in zip(bent.offsets[:-1], bent.offsets[1:], bent.kind)
                             if k == KIND_REGULAR])
    step_bent = bent.points[starts + 1] - bent.points[starts]
    step_straight = straight.points[starts + 1, 0] - straight.points[starts, 0]  # the rest arc length it advances
    mid = 0.5 * (bent.points[starts + 1] + bent.points[starts])
    radial = mid * [1.0, 1.0, 0.0]
    radial /= np.linalg.norm(radial, axis=1, keepdims=True)
    tangent = np.cross([0.0, 0.0, 1.0], radial)
    offset_out = (mid * radial).sum(axis=1) - bend  # o·(outward radial) = −o·κ R
    measured = (step_bent * tangent).sum(axis=1) / step_straight
    predicted = stretch * (1.0 + offset_out / bend)
    inside = np.abs(mid[:, 2]) < 2.0 * RADIUS  # all of them: a sanity check that the fibers lie around the arc
    assert inside.all()
    np.testing.assert_allclose(measured, predicted, rtol=0, atol=0.01)
    assert np.ptp(predicted) > 0.5  # the bend moves the scale by ±40 % across the yarn: the check has teeth
