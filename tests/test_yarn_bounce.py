"""The yarn-level bounce of knitrun.render.yarn_bounce: the strip's solid angle against quadrature, the cylinder's
phase, and the bounce of two parallel yarns against a direct integration along the neighbour; no bounce without a
neighbour, none from a neighbour in the dark, linear in the light; the renderer's ablation."""

import math
from dataclasses import replace
from types import SimpleNamespace

import numpy as np
import pytest

from knitrun.render.ablations import ABLATIONS, Features, combined, regular_fibers
from knitrun.render.strip_raster import vertex_tangents
from knitrun.render.yarn_bounce import (CONTACT_RADII, INV_PI2, BounceLights, BounceYarns, lambert_pair,
                                        segment_solid_angle, tube_optics, vertex_bounce)
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


def _g(alpha):
    """The Lambertian cylinder's phase over its mean, written out here: (π/4)(sin α + (π − α) cos α)."""
    return 0.25 * math.pi * (math.sin(alpha) + (math.pi - alpha) * math.cos(alpha))


def test_lambert_pair_is_a_normalised_phase_at_alpha_and_its_supplement():
    """g averages 1 over the circle (the tube's mean radiance is ρ E cos θ/π²), peaks at π²/4 toward the light, is 0
    opposite and π/4 at right angles; the kernel's pair is (g(α), g(π − α)) from cos α."""
    alpha = np.linspace(0.0, math.pi, 100001)
    pairs = np.array([lambert_pair(math.cos(a)) for a in alpha])  # the kernel takes cos α
    g = pairs[:, 0]
    assert np.trapezoid(g, alpha) / math.pi == pytest.approx(1.0, rel=1e-9)
    assert lambert_pair(1.0)[0] == pytest.approx(math.pi ** 2 / 4) and lambert_pair(-1.0)[1] == pytest.approx(
        math.pi ** 2 / 4)
    assert lambert_pair(-1.0)[0] == pytest.approx(0.0, abs=1e-15)
    assert lambert_pair(0.0)[0] == pytest.approx(math.pi / 4)
    assert np.all(pairs >= -1e-15)
    exact = np.arccos(np.cos(alpha))  # the angle the cosine carries (cos loses α's last digits near 0 and π)
    # to 1e-12 of the peak π²/4: near α = π, g ~ α³ is a difference of two near-equal terms, where √(1 − cos²α)
    # and sin α part in their last digits
    np.testing.assert_allclose(g, [_g(a) for a in exact], rtol=1e-12, atol=1e-12)
    np.testing.assert_allclose(pairs[:, 1], [_g(math.pi - a) for a in exact], rtol=1e-12, atol=1e-12)
    assert lambert_pair(1.0 + 1e-12) == lambert_pair(1.0)  # a cosine rounded past ±1 is clamped


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
        sent = e[0] * cos_l * (reflect * _g(alpha_l) + transmit * _g(math.pi - alpha_l))
        cos_r, alpha_r = across(-d, yarns.toward_camera[i])
        total += w * sent * cos_r * (reflect * _g(alpha_r) + transmit * _g(math.pi - alpha_r))
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


def test_a_long_neighbouring_segment_counts_by_its_midpoint_wherever_its_ends_lie():
    """The grid finds a sender by its midpoint, the point the reach is measured to: a neighbour drawn as one long
    segment whose ends lie several grid cells away (the cell is the reach) still covers the vertex it passes, by the
    strip's solid angle. (Until stop 51 segments were binned by their first point, and such a neighbour was missed.)"""
    r = 0.03
    reach = 8.0 * r
    receiver = _line(0.0, np.linspace(-0.1, 0.1, 3))  # along z through the origin
    long_leg = np.array([[-3 * reach, 0.1, 0.0], [3 * reach, 0.1, 0.0]])  # midpoint 0.1 from the receiver's middle
    camera = np.array([0.0, 100.0, 0.0])
    reflect, transmit = np.array([0.3, 0.3, 0.3]), np.array([0.4, 0.4, 0.4])
    yarns = _yarns([receiver, long_leg], r, reflect, transmit, camera)
    light, e = np.array([[0.0, 1.0, 0.0]]), np.array([[1.0, 1.0, 1.0]])
    bounce, covered = vertex_bounce(yarns, BounceLights(light, e, np.ones((1, 5))))
    omega = segment_solid_angle(yarns.points[1], long_leg[0], long_leg[1], 2 * r, CONTACT_RADII * r)
    assert covered[1] == pytest.approx(-math.expm1(-omega / (4 * math.pi)), rel=1e-12) and covered[1] > 0.01
    assert np.all(bounce[1] > 0.0)


def test_the_bounce_brightens_crossing_yarns_and_is_on_by_default(tmp_path, pack):
    """Two crossing yarns under the sun: the default (``Features.yarn_bounce``) is at least as bright everywhere as
    ``no_bounce`` and brighter near the crossing (finite); a lone yarn gets no bounce; the facts report the covered
    fraction."""
    crossing = [straight(z=0.0), straight(z=0.07)[:, [1, 0, 2]]]
    scene = write_scene(tmp_path, crossing, camera=FRONT, lights=SUN, name="crossing")
    without = _render(scene, pack, features=ABLATIONS["no_bounce"])
    with_bounce = _render(scene, pack)
    assert "yarn_bounce" not in without.facts and with_bounce.facts["yarn_bounce"]["covered_sphere"] > 0.0
    assert np.all(np.isfinite(with_bounce.image))
    assert np.all(with_bounce.image >= without.image - 1e-6) and with_bounce.image.mean() > without.image.mean()
    lone = write_scene(tmp_path, [straight()], camera=FRONT, lights=SUN, name="lone")
    np.testing.assert_array_equal(_render(lone, pack).image,
                                  _render(lone, pack, features=Features(yarn_bounce=False)).image)


def test_the_bounce_spreads_only_the_light_a_tube_scatters():
    """``tube_optics``: R_Y = ρ_Y − T_Y back, S_Y = T_Y − τ_Y forward; a yarn whose fibers scatter nothing (all it
    passes on crosses between them: ρ_Y = T_Y = τ_Y) sends no bounce either way; what it spreads is its albedo less
    the gap light; noise that puts T_Y below τ_Y spreads nothing, not a negative amount."""
    albedo, transmit = np.array([[0.785, 0.741, 0.641], [0.16, 0.16, 0.16]]), np.array([[0.46, 0.44, 0.40],
                                                                                       [0.16, 0.16, 0.16]])
    gap = np.array([0.16, 0.16])[:, None]
    reflect, forward = tube_optics(albedo, transmit, gap)
    np.testing.assert_allclose(reflect + forward, [[0.625, 0.581, 0.481], [0.0, 0.0, 0.0]], atol=1e-12)
    np.testing.assert_allclose(forward[0], [0.30, 0.28, 0.24], atol=1e-12)
    assert np.all(tube_optics(albedo, transmit, 0.5)[1][1] == 0.0)


def test_the_bounce_is_computed_about_one_and_a_half_radii_apart_and_interpolated_between():
    """``pipeline.bounce_vertices`` keeps every curve's first and last point and points about
    ``BOUNCE_SPACING_RADII`` radii apart (none of an empty curve); ``frame_bounce`` at those points, interpolated by
    rest arc length, is the bounce computed at every point to 2 % of its peak: two wavy yarns 3 r apart, sampled
    every 0.3 r, under a slanted light."""
    from knitrun.render.camera import Camera
    from knitrun.render.pipeline import BOUNCE_SPACING_RADII, _Polylines, bounce_vertices, frame_bounce

    r, step = 0.03, 0.009
    x = np.arange(0.0, 0.6, step)
    wave = [np.stack([x, dy + 0.3 * r * np.sin(x / (4 * r)), 0.5 * r * np.cos(x / (3 * r))], axis=1)
            for dy in (0.0, 3 * r)]
    curves = [wave[0], np.zeros((0, 3)), wave[1]]
    counts = [len(c) for c in curves]
    points = np.concatenate(curves)
    rest = np.concatenate([np.arange(n) * step for n in counts])
    lines = _Polylines(points, np.cumsum([0] + counts), rest, np.zeros(3, np.int64), np.tile([0.0, 0.0, 1.0],
                                                                                            (len(points), 1)))
    look = SimpleNamespace(radius=r, hull_albedo=np.array([0.78, 0.74, 0.64]),
                           hull_transmittance=np.array([0.46, 0.44, 0.40]), gap=0.16)
    at = bounce_vertices(lines, [look])
    first, last = lines.offsets[[0, 2]], lines.offsets[[1, 3]] - 1
    assert set(first) | set(last) <= set(at) and np.all(np.diff(at) > 0)
    spacing = np.linalg.norm(np.diff(points[at[:10]], axis=0), axis=1).mean()
    assert 0.6 * BOUNCE_SPACING_RADII * r <= spacing <= 1.2 * BOUNCE_SPACING_RADII * r
    camera = Camera(np.array([0.3, 0.05, 2.0]), np.array([0.3, 0.05, 0.0]), np.array([0.0, 1.0, 0.0]), 64, 48)
    light, e = np.array([[0.3, 0.5, 0.8]]) / np.linalg.norm([0.3, 0.5, 0.8]), np.array([[1.0, 1.0, 1.0]])
    everywhere = np.arange(len(points))
    full, _ = frame_bounce(lines, [look], camera, light, e, everywhere, np.ones((1, len(points))),
                           np.ones((1, len(points))))
    thinned, _ = frame_bounce(lines, [look], camera, light, e, at, np.ones((1, len(at))), np.ones((1, len(at))))
    assert full.max() > 0.0 and np.all(np.isfinite(thinned))
    assert np.abs(thinned - full).max() < 0.02 * full.max()


def test_ablations_combine_as_their_changes_to_the_full_model():
    """"a+b" is the full model with what a and b each change (the probes' ``--models``); an unknown name is refused
    in one line."""
    assert combined("no_bounce+whole_xi") == Features(yarn_bounce=False, split_xi=False)
    assert combined("full") == ABLATIONS["full"] and combined("no_tables") == ABLATIONS["no_tables"]
    assert combined("no_tables+no_bounce") == Features(xi=False, fiber_shadowing=False, fiber_detail=False,
                                                       yarn_bounce=False)
    assert combined("papers_xi+no_parallax") == Features(closed_xi=False, parallax=False)
    with pytest.raises(ValueError, match="unknown ablation 'bounce'"):
        combined("full+bounce")
    # the flyaway-free probes take the same names
    assert regular_fibers("diagonal_xi+two_blockers") == Features(view_xi=False, two_blockers=True, flyaways=False)
    assert regular_fibers("plain_ds") == replace(ABLATIONS["plain_ds"], flyaways=False)
    with pytest.raises(ValueError, match="unknown ablation 'paper_xi'"):
        regular_fibers("paper_xi")
