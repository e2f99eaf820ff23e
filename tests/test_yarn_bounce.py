"""The yarn-level bounce of knitrun.render.yarn_bounce: the strip's solid angle against quadrature, the cylinder's
phase, and the bounce of two parallel yarns against a direct integration along the neighbour; no bounce without a
neighbour, none from a neighbour in the dark, linear in the light; the renderer's ablation."""

import math
from dataclasses import replace

import numpy as np
import pytest

from knitrun.render.ablations import ABLATIONS, Features, combined, regular_fibers
from knitrun.render.strip_raster import vertex_tangents
from knitrun.render.yarn_bounce import (CONTACT_RADII, INV_PI2, BounceLights, BounceYarns, lambert_cylinder,
                                        segment_solid_angle, vertex_bounce)
from tests.helpers import FRONT, SUN, straight, write_scene
from tests.test_render import _render


def _quadrature_solid_angle(x, a, b, width, nearest, n=20001):
    """∫ width · h / d³ ds along a → b (the strip's projected width over the squared distance, times sin β = h/d),
    h clamped below at ``nearest`` as the kernel does, by the trapezoid rule."""
    u = (b - a) / np.linalg.norm(b - a)
    s_a = (a - x) @ u
    h = max(np.linalg.norm((a - x) - s_a * u), nearest)
    s = np.linspace(s_a, s_a + np.linalg.norm(b - a), n)
    return np.trapezoid(width * h / (h * h + s * s) ** 1.5, s)


def test_segment_solid_angle_matches_quadrature():
    rng = np.random.default_rng(3)
    for _ in range(20):
        x, a, b = rng.normal(size=(3, 3))
        got = segment_solid_angle(x, a, b, 0.06, 0.05)
        assert got == pytest.approx(_quadrature_solid_angle(x, a, b, 0.06, 0.05), rel=1e-6)
    # an infinite line at distance h subtends 2·width/h; a point on the axis counts at the contact distance
    far = 1e6
    assert segment_solid_angle(np.zeros(3), np.array([0.5, 0, -far]), np.array([0.5, 0, far]), 0.1, 0.0) == \
        pytest.approx(2 * 0.1 / 0.5, rel=1e-9)
    on_axis = segment_solid_angle(np.zeros(3), np.array([0, 0, -far]), np.array([0, 0, far]), 0.1, 0.2)
    assert on_axis == pytest.approx(2 * 0.1 / 0.2, rel=1e-9)
    assert segment_solid_angle(np.zeros(3), np.ones(3), np.ones(3), 0.1, 0.1) == 0.0


def test_lambert_cylinder_is_a_normalised_phase():
    """g averages 1 over the circle (the tube's mean radiance is ρ E cos θ/π²), peaks at π²/4 toward the light, is 0
    opposite and π/4 at right angles; outside [0, π] it clamps."""
    alpha = np.linspace(0.0, math.pi, 100001)
    g = np.array([lambert_cylinder(a) for a in alpha])
    assert np.trapezoid(g, alpha) / math.pi == pytest.approx(1.0, rel=1e-9)
    assert lambert_cylinder(0.0) == pytest.approx(math.pi ** 2 / 4)
    assert lambert_cylinder(math.pi) == pytest.approx(0.0, abs=1e-15)
    assert lambert_cylinder(0.5 * math.pi) == pytest.approx(math.pi / 4)
    assert np.all(g >= -1e-15) and lambert_cylinder(-1.0) == lambert_cylinder(0.0)


def _yarns(curves, radius, reflect, transmit, camera):
    points = np.concatenate(curves)
    offsets = np.cumsum([0] + [len(c) for c in curves])
    rest = np.concatenate([np.concatenate([[0.0], np.cumsum(np.linalg.norm(np.diff(c, axis=0), axis=1))])
                           for c in curves])
    view = camera - points
    view /= np.linalg.norm(view, axis=1, keepdims=True)
    n = len(points)
    return BounceYarns(points, vertex_tangents(points, offsets), np.repeat(np.arange(len(curves)), np.diff(offsets)),
                       offsets, rest, np.full(len(curves), radius), np.tile(reflect, (n, 1)),
                       np.tile(transmit, (n, 1)), view)


def _line(x, z):
    return np.stack([np.full_like(z, x), np.zeros_like(z), z], axis=1)


def test_two_parallel_yarns_match_a_direct_integration():
    """Two parallel yarns along z, 3 radii apart along x, lit and seen from +y: the bounce at the middle of one equals
    the module docstring's sum done by hand along the other (the same strips, angles and phases in NumPy), and f
    the covered fraction of its one neighbour."""
    r, reach = 0.03, 8.0 * 0.03
    z = np.linspace(-1.0, 1.0, 801)
    camera = np.array([0.0, 100.0, 0.0])
    reflect, transmit = np.array([0.3, 0.2, 0.1]), np.array([0.45, 0.3, 0.15])
    yarns = _yarns([_line(0.0, z), _line(3 * r, z)], r, reflect, transmit, camera)
    light = np.array([[0.0, 1.0, 0.0]])
    e = np.array([[2.0, 2.0, 2.0]])
    bounce, covered = vertex_bounce(yarns, BounceLights(light, e, np.ones((1, len(yarns.points)))))
    i = 400  # the middle of the first yarn
    x = yarns.points[i]
    omega, total = 0.0, np.zeros(3)
    for j in range(801, 1601):  # the second yarn's segments within reach
        a, b = yarns.points[j], yarns.points[j + 1]
        mid = 0.5 * (a + b)
        if np.linalg.norm(x - mid) > reach:
            continue
        w = segment_solid_angle(x, a, b, 2 * r, CONTACT_RADII * r)
        omega += w
        d = (x - mid) / np.linalg.norm(x - mid)
        t = np.array([0.0, 0.0, 1.0])

        def across(u, v):
            up, vp = u - (u @ t) * t, v - (v @ t) * t
            return np.linalg.norm(up), math.acos(np.clip(up @ vp / np.linalg.norm(up) / np.linalg.norm(vp), -1, 1))

        cos_l, alpha_l = across(light[0], d)
        sent = e[0] * cos_l * (reflect * lambert_cylinder(alpha_l) + transmit * lambert_cylinder(math.pi - alpha_l))
        cos_r, alpha_r = across(-d, yarns.toward_camera[i])
        total += w * sent * cos_r * (reflect * lambert_cylinder(alpha_r) + transmit * lambert_cylinder(math.pi - alpha_r))
    f = -math.expm1(-omega / (4 * math.pi))
    expected = total * 4 * math.pi * f / omega * INV_PI2 ** 2 / (1 - (reflect + transmit) * f)
    assert covered[i] == pytest.approx(f, rel=1e-12)
    np.testing.assert_allclose(bounce[i], expected, rtol=1e-9)
    assert np.all(bounce[i] > 0) and 0.05 < f < 0.5


def test_no_neighbour_no_dark_neighbour_no_bounce_and_linear_in_the_light():
    """A lone straight yarn has no bounce (its own curve near the vertex is the baked tables' part); a neighbour in
    the dark sends nothing; doubling the irradiance doubles the bounce; the far ends of a U-turn see each other's
    legs (the same curve, more than the reach of arc length apart)."""
    r = 0.03
    z = np.linspace(-1.0, 1.0, 201)
    camera = np.array([0.0, 100.0, 0.0])
    reflect, transmit = np.array([0.3, 0.3, 0.3]), np.array([0.4, 0.4, 0.4])
    light, e = np.array([[0.0, 1.0, 0.0]]), np.array([[1.0, 1.0, 1.0]])
    lone = _yarns([_line(0.0, z)], r, reflect, transmit, camera)
    bounce, covered = vertex_bounce(lone, BounceLights(light, e, np.ones((1, 201))))
    assert np.all(bounce == 0.0) and np.all(covered == 0.0)
    pair = _yarns([_line(0.0, z), _line(3 * r, z)], r, reflect, transmit, camera)
    dark = np.ones((1, 402))
    dark[0, 201:] = 0.0  # the second yarn in the dark
    bounce, covered = vertex_bounce(pair, BounceLights(light, e, dark))
    assert np.all(bounce[:201] == 0.0) and np.all(covered[:201] > 0.0) and np.all(bounce[201:] > 0.0)
    once, _ = vertex_bounce(pair, BounceLights(light, e, np.ones((1, 402))))
    twice, _ = vertex_bounce(pair, BounceLights(light, 2 * e, np.ones((1, 402))))
    np.testing.assert_allclose(twice, 2 * once, rtol=1e-12)
    hairpin = np.concatenate([_line(0.0, z), _line(3 * r, z[::-1])])  # down one leg, back up the other
    bounce, covered = vertex_bounce(_yarns([hairpin], r, reflect, transmit, camera),
                                    BounceLights(light, e, np.ones((1, 402))))
    assert covered[100] > 0.0 and np.all(bounce[100] > 0.0)


def test_the_bounce_ablation_brightens_crossing_yarns_and_is_off_by_default(tmp_path, pack):
    """Two crossing yarns under the sun: with ``Features.yarn_bounce`` the image is at least as bright everywhere and
    brighter near the crossing (finite); the default draws no bounce, as does a lone yarn with it; the facts report
    the covered fraction."""
    crossing = [straight(z=0.0), straight(z=0.07)[:, [1, 0, 2]]]
    scene = write_scene(tmp_path, crossing, camera=FRONT, lights=SUN, name="crossing")
    default = _render(scene, pack)
    with_bounce = _render(scene, pack, features=ABLATIONS["yarn_bounce"])
    assert "yarn_bounce" not in default.facts and with_bounce.facts["yarn_bounce"]["covered_sphere"] > 0.0
    assert np.all(np.isfinite(with_bounce.image))
    assert np.all(with_bounce.image >= default.image - 1e-6) and with_bounce.image.mean() > default.image.mean()
    lone = write_scene(tmp_path, [straight()], camera=FRONT, lights=SUN, name="lone")
    np.testing.assert_array_equal(_render(lone, pack, features=Features(yarn_bounce=True)).image,
                                  _render(lone, pack).image)


def test_ablations_combine_as_their_changes_to_the_full_model():
    """"a+b" is the full model with what a and b each change (the probes' ``--models``); an unknown name is refused
    in one line."""
    assert combined("yarn_bounce+split_xi") == Features(yarn_bounce=True, split_xi=True)
    assert combined("full") == ABLATIONS["full"] and combined("no_tables") == ABLATIONS["no_tables"]
    assert combined("no_tables+yarn_bounce") == Features(xi=False, fiber_shadowing=False, fiber_detail=False,
                                                         yarn_bounce=True)
    assert combined("papers_xi+view_xi") == Features(closed_xi=False, view_xi=True)
    with pytest.raises(ValueError, match="unknown ablation 'bounce'"):
        combined("full+bounce")
    # the flyaway-free probes take the same names
    assert regular_fibers("view_xi+two_blockers") == Features(view_xi=True, two_blockers=True, flyaways=False)
    assert regular_fibers("plain_ds") == replace(ABLATIONS["plain_ds"], flyaways=False)
    with pytest.raises(ValueError, match="unknown ablation 'paper_xi'"):
        regular_fibers("paper_xi")
