"""The yarn-level bounce of knitrun.render.yarn_bounce: the strip's solid angle against quadrature, the cylinder's
phase and its table against the formula, a tube in a uniform field, the pack's phase in a colour, and the bounce of
two parallel yarns against a direct integration along the neighbour; no bounce without a neighbour, none from a
neighbour in the dark, linear in the light; the renderer's ablations (the bounce, and on the hairs)."""

import math
from dataclasses import replace
from types import SimpleNamespace

import numpy as np
import pytest

from data_formats.conventions import cell_centres
from knitrun.render.ablations import ABLATIONS, Features, combined, regular_fibers
from knitrun.render.strip_raster import vertex_tangents
from knitrun.render.yarn_bounce import (CONTACT_RADII, INV_PI2, PHASE_PHI, PHASE_THETA, BounceLights, BounceYarns,
                                        lambert_pair, lambert_phase, phase_at, phase_grid,
                                        segment_solid_angle, tube_optics, vertex_bounce)
from knitrun.render.yarn_look import tube_phase
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
    """The curves as ``BounceYarns`` of one yarn entry whose tube scatters ``reflect`` R_Y back and ``transmit`` S_Y
    forward, with the Lambertian cylinder's phase (``lambert_phase``)."""
    points = np.concatenate(curves)
    offsets = np.cumsum([0] + [len(c) for c in curves])
    rest = np.concatenate([np.concatenate([[0.0], np.cumsum(np.linalg.norm(np.diff(c, axis=0), axis=1))])
                           for c in curves])
    view = camera - points
    view /= np.linalg.norm(view, axis=1, keepdims=True)
    n = len(points)
    return BounceYarns(points, vertex_tangents(points, offsets), np.repeat(np.arange(len(curves)), np.diff(offsets)),
                       offsets, rest, np.full(len(curves), radius), np.tile(reflect + transmit, (n, 1)), view,
                       lambert_phase(reflect, transmit)[None], np.zeros(len(curves), np.int64))


def _lambert(reflect, transmit, theta_i, phi):
    """The Lambertian cylinder's phase written out: cos θ_i (R g(|φ|) + S g(π − |φ|)) / π²."""
    alpha = abs(math.remainder(phi, 2 * math.pi))
    return math.cos(theta_i) * (reflect * _g(alpha) + transmit * _g(math.pi - alpha)) * INV_PI2


def _trilinear(table, theta_i, theta_o, phi):
    """The grid rule of ASSET_PACK.md §4.3 on the shared phase grid, in NumPy (θ clamp, φ repeat)."""
    def cell(x, lo, hi, n, repeat):
        t = (x - lo) / (hi - lo) * n - 0.5
        if repeat:
            t = t % n
            i0 = int(math.floor(t))
            return i0, (i0 + 1) % n, t - i0
        t = min(max(t, 0.0), n - 1.0)
        i0 = int(math.floor(t))
        return i0, min(i0 + 1, n - 1), t - i0

    a0, a1, fa = cell(theta_i, -math.pi / 2, math.pi / 2, table.shape[0], False)
    b0, b1, fb = cell(theta_o, -math.pi / 2, math.pi / 2, table.shape[1], False)
    c0, c1, fc = cell(phi, -math.pi, math.pi, table.shape[2], True)
    out = np.zeros(3)
    for i, wi in ((a0, 1 - fa), (a1, fa)):
        for j, wj in ((b0, 1 - fb), (b1, fb)):
            for k, wk in ((c0, 1 - fc), (c1, fc)):
                out += wi * wj * wk * table[i, j, k]
    return out


def _angles(t, wo, wi):
    """(θ_i, θ_o, φ) of ``fiber_frame``, written out: asin against t, φ from ω_i's projection to ω_o's about t."""
    po, pi = wo - (wo @ t) * t, wi - (wi @ t) * t
    phi = math.atan2(np.cross(pi, po) @ t, pi @ po)
    return math.asin(np.clip(wi @ t, -1, 1)), math.asin(np.clip(wo @ t, -1, 1)), phi


def _line(x, z):
    return np.stack([np.full_like(z, x), np.zeros_like(z), z], axis=1)


def test_the_lambert_table_is_the_lambertian_cylinder_and_scatters_its_albedo_in_a_uniform_field():
    """``lambert_phase`` read by ``phase_at`` is the formula to 1 % of its peak at random angles (the table's grid,
    33 × 33 × 36 cells, against the written-out phase); and a tube in a uniform field of radiance 1 sends R_Y + S_Y
    toward every view: ∫ Φ(ω_i → ω_o) dω_i over the sphere (the phase of a yarn is radiance per unit irradiance, so
    this is its albedo, as the hull albedo ρ_Y less the gap light τ_Y is), to 1 %."""
    reflect, transmit = np.array([0.3, 0.2, 0.1]), np.array([0.45, 0.3, 0.05])
    table = lambert_phase(reflect, transmit)
    assert table.shape == (PHASE_THETA, PHASE_THETA, PHASE_PHI, 3)
    rng = np.random.default_rng(5)
    got, peak = np.empty(3), math.pi ** 2 / 4 * INV_PI2 * reflect
    for theta_i, theta_o, phi in zip(rng.uniform(-1.5, 1.5, 200), rng.uniform(-1.5, 1.5, 200),
                                     rng.uniform(-math.pi, math.pi, 200)):
        phase_at(table, theta_i, theta_o, phi, got)
        np.testing.assert_allclose(got, _lambert(reflect, transmit, theta_i, phi), atol=0.01 * peak.max())
    # ∫ over the sphere of ω_i: dω = cos θ_i dθ_i dφ, midpoint rule on a fine grid
    theta, phi = cell_centres(-math.pi / 2, math.pi / 2, 90), cell_centres(-math.pi, math.pi, 180)
    weight = np.cos(theta) * (math.pi / 90) * (2 * math.pi / 180)
    for theta_o in (0.0, 0.7, -1.2):
        total = np.zeros(3)
        for i, ti in enumerate(theta):
            for pj in phi:
                phase_at(table, ti, theta_o, pj, got)
                total += weight[i] * got
        np.testing.assert_allclose(total, reflect + transmit, rtol=1e-2)


def test_the_packs_phase_is_its_yarn_averaged_over_v_in_the_colour():
    """``yarn_look.tube_phase``: the pack's ``radiance_view`` averaged over v on the shared grid (a table constant
    along θ_o and φ and linear in θ_i inside the outer centres comes back as it was), each channel scaled by what
    the tube scatters in the colour, (ρ_Y − τ_Y) over the white yarn's; a channel that scatters no more than its gap
    light sends nothing."""
    theta = cell_centres(-math.pi / 2, math.pi / 2, 9)
    per_theta = 0.05 + 0.01 * theta  # linear in θ_i
    view = np.broadcast_to(per_theta[None, :, None, None, None], (4, 9, 9, 5, 3)).copy()
    view[0] *= 0.5  # rows of v that differ: the mean is taken over them
    view[1] *= 1.5
    white, gap = np.array([0.78, 0.74, 0.64]), 0.16
    same = tube_phase(view, white, white, gap)
    assert same.shape == (PHASE_THETA, PHASE_THETA, PHASE_PHI, 3)
    inside = np.abs(cell_centres(-math.pi / 2, math.pi / 2, PHASE_THETA)) <= theta[-1]
    expected = 0.05 + 0.01 * cell_centres(-math.pi / 2, math.pi / 2, PHASE_THETA)
    np.testing.assert_allclose(same[inside, 3, 7, 1], expected[inside], rtol=1e-12)
    red = tube_phase(view, white, np.array([0.575, 0.228, 0.10]), gap)
    np.testing.assert_allclose(red / np.where(same > 0, same, 1), np.broadcast_to(
        [(0.575 - gap) / (0.78 - gap), (0.228 - gap) / (0.74 - gap), 0.0], same.shape), rtol=1e-12)
    # a smooth table on a draft pack's grid, resampled to the shared one, reads back its samples at their centres
    # (φ repeats across its ends)
    phi = cell_centres(-math.pi, math.pi, 5)
    coarse = (1.0 + 0.3 * np.sin(theta)[:, None, None, None] + 0.2 * np.cos(theta)[None, :, None, None]
              + 0.1 * np.cos(phi)[None, None, :, None]) * np.array([1.0, 0.5, 0.25])
    fine = phase_grid(coarse)
    got = np.empty(3)
    for i, j, k in ((4, 4, 0), (2, 6, 3), (1, 7, 4)):
        phase_at(fine, theta[i], theta[j], phi[k], got)
        np.testing.assert_allclose(got, coarse[i, j, k], rtol=5e-3)


def test_two_parallel_yarns_match_a_direct_integration():
    """Two parallel yarns along z, 3 radii apart along x, lit and seen from +y: the bounce at the middle of one equals
    the module docstring's sum done by hand along the other (the same strips, angles and phase table read by the
    grid rule in NumPy), and f the covered fraction of its one neighbour; the neighbours' light arriving there is
    the same sum without the receiver's phase; and with the phase written out instead of read from its table the sum
    is the same to 2 %."""
    r, reach = 0.03, 8.0 * 0.03
    z = np.linspace(-1.0, 1.0, 801)
    camera = np.array([0.0, 100.0, 0.0])
    reflect, transmit = np.array([0.3, 0.2, 0.1]), np.array([0.45, 0.3, 0.15])
    yarns = _yarns([_line(0.0, z), _line(3 * r, z)], r, reflect, transmit, camera)
    table = yarns.phase[0]
    light = np.array([[0.0, 0.6, 0.8]])
    e = np.array([[2.0, 2.0, 2.0]])
    bounce, covered, arriving = vertex_bounce(yarns, BounceLights(light, e, np.ones((1, len(yarns.points)))))
    i = 400  # the middle of the first yarn
    x = yarns.points[i]
    t = np.array([0.0, 0.0, 1.0])
    omega, total, incoming, formula = 0.0, np.zeros(3), np.zeros(3), np.zeros(3)
    for j in range(801, 1601):  # the second yarn's segments within reach
        a, b = yarns.points[j], yarns.points[j + 1]
        mid = 0.5 * (a + b)
        if np.linalg.norm(x - mid) > reach:
            continue
        w = segment_solid_angle(x, a, b, 2 * r, CONTACT_RADII * r)
        omega += w
        d = (x - mid) / np.linalg.norm(x - mid)
        sent_angles, seen_angles = _angles(t, d, light[0]), _angles(t, yarns.toward_camera[i], -d)
        sent = e[0] * _trilinear(table, *sent_angles)
        total += w * sent * _trilinear(table, *seen_angles)
        incoming += w * sent
        formula += w * e[0] * _lambert(reflect, transmit, sent_angles[0], sent_angles[2]) * _lambert(
            reflect, transmit, seen_angles[0], seen_angles[2])
    f = -math.expm1(-omega / (4 * math.pi))
    share = 4 * math.pi * f / omega / (1 - (reflect + transmit) * f)
    assert covered[i] == pytest.approx(f, rel=1e-12)
    np.testing.assert_allclose(bounce[i], total * share, rtol=1e-9)
    np.testing.assert_allclose(arriving[i], incoming * share, rtol=1e-9)
    np.testing.assert_allclose(bounce[i], formula * share, rtol=2e-2)
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
    bounce, covered, _ = vertex_bounce(lone, BounceLights(light, e, np.ones((1, 201))))
    assert np.all(bounce == 0.0) and np.all(covered == 0.0)
    pair = _yarns([_line(0.0, z), _line(3 * r, z)], r, reflect, transmit, camera)
    dark = np.ones((1, 402))
    dark[0, 201:] = 0.0  # the second yarn in the dark
    bounce, covered, _ = vertex_bounce(pair, BounceLights(light, e, dark))
    assert np.all(bounce[:201] == 0.0) and np.all(covered[:201] > 0.0) and np.all(bounce[201:] > 0.0)
    once, _, _ = vertex_bounce(pair, BounceLights(light, e, np.ones((1, 402))))
    twice, _, _ = vertex_bounce(pair, BounceLights(light, 2 * e, np.ones((1, 402))))
    np.testing.assert_allclose(twice, 2 * once, rtol=1e-12)
    hairpin = np.concatenate([_line(0.0, z), _line(3 * r, z[::-1])])  # down one leg, back up the other
    bounce, covered, _ = vertex_bounce(_yarns([hairpin], r, reflect, transmit, camera),
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
    bounce, covered, _ = vertex_bounce(yarns, BounceLights(light, e, np.ones((1, 5))))
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


def test_the_hairs_take_the_neighbours_light_by_default(tmp_path, pack):
    """``Features.hair_bounce`` (the default): on two crossing yarns with their flyaways under the sun the hairs
    return the neighbours' light, so the image is nowhere darker than ``no_hair_bounce``'s and brighter in the
    mean, and the regular fibers alone (no flyaway layer) do not change; a lone yarn's hairs have no neighbour. A
    hair in a uniform field of radiance L, I = 4π L, returns its albedo times L (``strip_shading.hair_bounce``)."""
    from knitrun.render.strip_shading import hair_bounce
    from knitrun.shading.fiber_bcsdf import N_PARAMS, P_A_D, P_A_R, P_A_TT

    crossing = [straight(z=0.0), straight(z=0.07)[:, [1, 0, 2]]]
    scene = write_scene(tmp_path, crossing, camera=FRONT, lights=SUN, name="crossing")
    default, without = _render(scene, pack), _render(scene, pack, features=ABLATIONS["no_hair_bounce"])
    assert np.all(np.isfinite(default.image)) and np.all(default.image >= without.image - 1e-6)
    background = np.array([0.1, 0.2, 0.3])
    assert (default.image - without.image).mean() > 0.005 * np.abs(without.image - background).mean()
    np.testing.assert_array_equal(_render(scene, pack, features=regular_fibers("full")).image,
                                  _render(scene, pack, features=regular_fibers("no_hair_bounce")).image)
    lone = write_scene(tmp_path, [straight()], camera=FRONT, lights=SUN, name="lone")
    np.testing.assert_array_equal(_render(lone, pack).image,
                                  _render(lone, pack, features=ABLATIONS["no_hair_bounce"]).image)
    params = np.zeros(N_PARAMS)
    params[P_A_R:P_A_R + 3], params[P_A_TT:P_A_TT + 3], params[P_A_D:P_A_D + 3] = 0.1, [0.6, 0.5, 0.4], 0.05
    np.testing.assert_allclose(hair_bounce(np.full((2, 3), 4 * math.pi * 0.7), params),
                               np.tile(0.7 * np.array([0.75, 0.65, 0.55]), (2, 1)), rtol=1e-12)


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
                           hull_transmittance=np.array([0.46, 0.44, 0.40]), gap=0.16, tube_phase=None)
    at = bounce_vertices(lines, [look])
    first, last = lines.offsets[[0, 2]], lines.offsets[[1, 3]] - 1
    assert set(first) | set(last) <= set(at) and np.all(np.diff(at) > 0)
    spacing = np.linalg.norm(np.diff(points[at[:10]], axis=0), axis=1).mean()
    assert 0.6 * BOUNCE_SPACING_RADII * r <= spacing <= 1.2 * BOUNCE_SPACING_RADII * r
    camera = Camera(np.array([0.3, 0.05, 2.0]), np.array([0.3, 0.05, 0.0]), np.array([0.0, 1.0, 0.0]), 64, 48)
    light, e = np.array([[0.3, 0.5, 0.8]]) / np.linalg.norm([0.3, 0.5, 0.8]), np.array([[1.0, 1.0, 1.0]])
    everywhere = np.arange(len(points))
    full, _, _ = frame_bounce(lines, [look], camera, light, e, everywhere, np.ones((1, len(points))),
                           np.ones((1, len(points))))
    thinned, _, _ = frame_bounce(lines, [look], camera, light, e, at, np.ones((1, len(at))), np.ones((1, len(at))))
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
    assert regular_fibers("diagonal_xi+one_blocker") == Features(view_xi=False, two_blockers=False, flyaways=False)
    assert regular_fibers("plain_ds") == replace(ABLATIONS["plain_ds"], flyaways=False)
    with pytest.raises(ValueError, match="unknown ablation 'paper_xi'"):
        regular_fibers("paper_xi")
