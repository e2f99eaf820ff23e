"""The contact statistic (``knitrun.sim.contact``) on scenes with a known answer: parallel yarns at a set distance, a
lone yarn, a hairpin whose legs are one curve, smooth curve types, and its invariances."""

import math

import numpy as np
import pytest

from data_formats.errors import FormatError
from data_formats.yarn_curves import make_yarn_curves
from knitrun.sim.contact import CAP, contact_ratios, contact_statistic

R = 0.05


def line(y, z=0.0, n=41, length=4.0):
    x = np.linspace(0.0, length, n)
    return np.column_stack([x, np.full(n, y), np.full(n, z)])


def curves(*polylines, curve_type="PL", closed=None):
    offsets = np.concatenate([[0], np.cumsum([len(p) for p in polylines])])
    return make_yarn_curves(np.concatenate(polylines), offsets, closed=closed, curve_type=curve_type)


@pytest.mark.parametrize("gap", [2 * R, R, 0.5 * R, 3 * R])
def test_parallel_yarns_measure_their_distance_over_a_diameter(gap):
    ratios = contact_ratios(curves(line(0.0), line(gap, z=0.0)), R)
    np.testing.assert_allclose(ratios, gap / (2 * R), rtol=1e-9, atol=1e-12)


def test_a_lone_yarn_has_no_other_part_and_counts_as_the_cap():
    np.testing.assert_array_equal(contact_ratios(curves(line(0.0)), R), CAP)


def test_a_hairpin_is_its_own_other_part_beyond_the_exclusion_window():
    """One curve: a leg, a half circle of radius R (legs 2R apart: touching), the leg back. Far from the bend each
    leg's nearest other part is the other leg, 1.0; near the bend, the same curve within 8r is excluded."""
    leg = line(0.0, n=81)[::-1]
    a = np.linspace(-0.5 * math.pi, 0.5 * math.pi, 31)[1:-1]
    bend = np.column_stack([-R * np.cos(a), R + R * np.sin(a), np.zeros_like(a)])
    pin = np.concatenate([leg, bend, line(2 * R, n=81)])
    ratios = contact_ratios(curves(pin), R)
    s = np.arange(len(ratios)) * 0.25 * R
    far = np.abs(s - s.mean()) > 12 * R  # ≥ 8r from the bend along the curve, on either leg
    np.testing.assert_allclose(ratios[far], 1.0, atol=1e-3)
    assert ratios.min() >= 1.0 - 1e-3  # the bend's own arc never counts as interpenetration


def test_smooth_curve_types_are_evaluated_before_sampling():
    """A Catmull-Rom curve through collinear points is the same straight yarn as the polyline."""
    a, b = line(0.0, n=9), line(R, n=9)
    np.testing.assert_allclose(contact_ratios(curves(a, b, curve_type="C0"), R), 0.5, rtol=1e-9)


def test_invariant_under_curve_order_and_direction():
    rng = np.random.default_rng(3)
    wavy = [line(0.0) + rng.normal(0, 0.3 * R, (41, 3)), line(1.6 * R) + rng.normal(0, 0.3 * R, (41, 3))]
    a = contact_statistic(curves(*wavy), R)
    b = contact_statistic(curves(wavy[1][::-1], wavy[0]), R)
    for key in ("p5", "p50", "p95", "min"):
        assert a[key] == pytest.approx(b[key], abs=0.02)  # resampling starts at the other end: within a step


def test_closed_loops_exclude_their_own_arc_either_way_round():
    """A closed circle of circumference < 16r has no other part; two concentric circles 1.5r apart measure 0.75."""
    t = np.linspace(0, 2 * math.pi, 64, endpoint=False)
    small = np.column_stack([2 * R * np.cos(t), 2 * R * np.sin(t), np.zeros_like(t)])  # circumference 12.6r
    np.testing.assert_array_equal(contact_ratios(curves(small, closed=[True]), R), CAP)
    big = np.column_stack([20 * R * np.cos(t), 20 * R * np.sin(t), np.zeros_like(t)])
    ring = np.column_stack([20 * R * np.cos(t), 20 * R * np.sin(t), np.full_like(t, 1.5 * R)])
    ratios = contact_ratios(curves(big, ring, closed=[True, True]), R)
    np.testing.assert_allclose(ratios, 0.75, atol=1e-3)


def test_asking_few_neighbours_first_gives_the_answer_of_one_query_of_the_whole_window(monkeypatch):
    """``contact_ratios`` asks ``K_FIRST`` neighbours first and the whole exclusion window's only where those all lie
    on the sample's own excluded stretch. On a tight coil (its own turns within the window crowd the nearest
    samples), a loose yarn 3.5r from it and a touching pair, that is the answer of one query of the window's size."""
    import knitrun.sim.contact as contact

    s = np.linspace(0.0, 12 * math.pi, 600)
    coil = np.column_stack([1.2 * R * np.cos(s), 1.2 * R * np.sin(s), 0.4 * R * s])  # turns 2.5r apart along z
    yarns = curves(coil, line(3.5 * R, n=81), line(-2.0 * R, z=3.0 * R, n=81), line(-4.0 * R, z=3.0 * R, n=81))
    two_pass = contact_ratios(yarns, R)
    monkeypatch.setattr(contact, "K_FIRST", 10_000)  # one query of the window's size for every sample
    one_pass = contact_ratios(yarns, R)
    np.testing.assert_array_equal(two_pass, one_pass)
    assert (two_pass < CAP).mean() > 0.5 and two_pass.min() < 1.0


@pytest.mark.parametrize("radius", [0.0, -1.0, float("nan"), float("inf")])
def test_bad_radius_is_a_one_line_error(radius):
    with pytest.raises(FormatError, match="radius"):
        contact_ratios(curves(line(0.0)), radius)


def test_summary_is_json_ready_and_names_the_frame():
    stats = contact_statistic(curves(line(0.0), line(R)), R)
    assert stats["p50"] == 0.5 and stats["min"] == 0.5 and stats["fraction_below_0.8"] == 1.0
    assert stats["frame"] == 0 and stats["samples"] == 2 * 321  # 4.0 long at steps of r/4 = 0.0125, both ends
    with pytest.raises(FormatError, match="frame 3"):
        contact_statistic(curves(line(0.0)), R, frame=3)
