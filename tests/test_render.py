"""The strip renderer end to end (knitrun.render.pipeline and `knitrun render`): determinism, finite images at the
extremes (camera inside a yarn, grazing views, zero-length segments, an empty view), SRBF counts 1/16/64, ablations,
pack errors; plus the texture sampler, the flyaway variant hash and the resolve."""

import dataclasses
import json
import math
from types import SimpleNamespace

import numba
import numpy as np
import pytest
from click.testing import CliRunner

from cli.knitrun_cli import main as knitrun
from data_formats.errors import FormatError
from data_formats.images import read_exr, write_exr
from data_formats.scene import load_scene
from data_formats.yarn_curves import make_yarn_curves, write_yarn_curves
from data_formats.yarn_spec import dumps_spec, load_preset
from knitbake.bake import bake
from knitbake.stages import im_table as im
from knitrun.render import pipeline
from knitrun.render.ablations import ABLATIONS, Features
from knitrun.render.pipeline import (PARALLAX_MAX_SIN, SHADOW_BIAS_RADII, Renderer, parallax_shift,
                                     radius_mismatch, render, strip_receivers)
from knitrun.render.strip_shading import (HAIR_DEPTHS, _corrections, _hair_light, behind_share, body_glow,
                                          cylinder_solid_angle, resolve, resolve_behind, shade_regular, variant_of)
from knitrun.render.shading_inputs import Corrections, Lights, Lobes, Look, Points, no_lights, no_lobes, no_rows
from knitrun.render.texture_sampling import mip_stack, sample_mip
from knitrun.render.yarn_look import no_detail, no_full_table, no_view_table, ones_factor, shading_look
from knitrun.shading import fiber_bcsdf as fb
from knitrun.shading.builtin_sky import sky_image
from knitrun.shading.dual_scattering import D_B, D_F
from knitrun.shading.equirect import texel_directions
from knitrun.shading.im_lookup import im_slices, im_table_from, no_im_table
from knitrun.shading.srbf_fit import fit_srbf
from tests.helpers import BACKLIT, FRONT, ROUGH, SKY, SUN, TEST_SHAPE, TINY, straight, write_scene


def _render(path, pack, **kw):
    return render(load_scene(path), {"cotton1": str(pack)}, **kw)


def test_straight_yarn_is_drawn_lit_and_deterministic(tmp_path, pack):
    path = write_scene(tmp_path, [straight()], camera=FRONT, lights=SUN)
    a = _render(path, pack)
    b = _render(path, pack)
    assert np.array_equal(a.image, b.image)
    img = a.image
    assert img.shape == (48, 64, 3) and np.all(np.isfinite(img)) and img.min() >= 0
    # the yarn crosses the middle rows; the corners show the background exactly
    assert np.allclose(img[0, 0], [0.1, 0.2, 0.3]) and np.allclose(img[-1, -1], [0.1, 0.2, 0.3])
    middle = img[22:26, 10:54]
    assert np.abs(middle - [0.1, 0.2, 0.3]).sum(axis=2).mean() > 0.05
    assert set(a.timings) >= {"load", "raster", "shadow", "shade", "resolve"}
    assert a.facts["shading_points"] > 0 and a.facts["flyaway_points"] > 0  # flyaways are on by default
    assert _render(path, pack, features=Features(flyaways=False)).facts["flyaway_points"] == 0


def test_identical_for_one_and_two_threads(tmp_path, pack):
    path = write_scene(tmp_path, [straight(), straight(z=0.1) + [0, 0.05, 0]], camera=FRONT, lights=SUN)
    before = numba.get_num_threads()
    try:
        numba.set_num_threads(1)
        one = _render(path, pack).image
        numba.set_num_threads(2)
        two = _render(path, pack).image
    finally:
        numba.set_num_threads(before)
    assert np.array_equal(one, two)


def test_a_yarn_in_front_shadows_the_one_behind(tmp_path, pack):
    """A yarn crossing 0.2 above another, lit at 37° from the normal along the lower yarn: its shadow falls on the
    lower yarn 0.15 beside the crossing (image columns 15–21 of the front camera), where the lower yarn is darker
    than drawn alone; away from the shadow, and wherever the upper yarn does not cover it, it is unchanged."""
    slanted = SUN.replace("[0.3, 0.6, 1.0]", "[0.6, 0.0, 0.8]")
    lower = straight(z=0.0)
    upper = straight(z=0.2)[:, [1, 0, 2]]  # crosses the lower yarn at right angles, between it and the light
    images = [_render(write_scene(tmp_path, yarns, camera=FRONT, lights=slanted, name=name), pack,
                      features=ABLATIONS["plain_ds"]).image
              for yarns, name in (([lower], "lone"), ([lower, upper], "both"), ([upper], "upper"))]
    lone, both, alone_upper = images
    assert np.all(np.isfinite(both))
    background = lone[0, 0]
    drawn = np.abs(lone - background).sum(axis=-1) > 1e-3
    uncovered = drawn & (np.abs(alone_upper - background).sum(axis=-1) < 1e-6)
    shadow = np.zeros_like(uncovered)
    shadow[:, 15:22] = True
    assert (uncovered & shadow).sum() > 10
    assert both[uncovered & shadow].mean() < 0.85 * lone[uncovered & shadow].mean()
    far = uncovered.copy()
    far[:, 10:42] = False
    assert far.sum() > 10
    np.testing.assert_allclose(both[far], lone[far], rtol=1e-6)


@pytest.mark.parametrize("case", ["inside", "grazing", "along", "zero_length", "empty_view", "one_point"])
def test_extremes_give_finite_images(tmp_path, pack, case):
    curves = [straight()]
    camera = FRONT
    if case == "inside":  # the camera sits on the yarn axis, looking across it
        camera = FRONT.replace("[0.0, 0.0, 1.0]", "[0.0, 0.0, 0.0]").replace("look_at = [0.0, 0.0, 0.0]",
                                                                             "look_at = [0.0, 1.0, 0.0]")
        camera = camera.replace("fov_deg", "up = [0.0, 0.0, 1.0]\nfov_deg")
    elif case == "grazing":  # light along the yarn, camera almost along it
        camera = FRONT.replace("[0.0, 0.0, 1.0]", "[2.0, 0.0, 0.01]")
    elif case == "along":  # the camera looks exactly along the yarn: every strip is edge-on
        camera = FRONT.replace("[0.0, 0.0, 1.0]", "[2.0, 0.0, 0.0]")
    elif case == "zero_length":
        c = straight()
        curves = [np.concatenate([c[:3], c[2:3], c[2:3], c[3:]]), np.repeat(c[:1], 3, axis=0)]
    elif case == "empty_view":
        camera = FRONT.replace("look_at = [0.0, 0.0, 0.0]", "look_at = [0.0, 0.0, 2.0]")
    elif case == "one_point":  # nothing to draw: a curve file needs a curve, this one is a single point twice
        curves = [np.repeat(straight()[:1], 2, axis=0)]
    lights = SUN.replace("[0.3, 0.6, 1.0]", "[1.0, 0.0, 0.0]") if case == "grazing" else SUN
    path = write_scene(tmp_path, curves, camera=camera, lights=lights + "\n" + SKY)
    img = _render(path, pack).image
    assert np.all(np.isfinite(img)) and img.min() >= 0
    if case in ("empty_view", "one_point", "along"):
        assert np.allclose(img, [0.1, 0.2, 0.3])


def _kernel_frames(n, seed):
    """What ``shade_regular`` needs of n points besides the lights: random unit tangents and view directions, a flat
    tangent texture along the yarn, full coverage, and every correction switched off."""
    rng = np.random.default_rng(seed)
    tangent = rng.normal(size=(n, 3))
    tangent /= np.linalg.norm(tangent, axis=1, keepdims=True)
    view = rng.normal(size=(n, 3))
    view /= np.linalg.norm(view, axis=1, keepdims=True)
    off = Corrections(no_full_table(), ones_factor(), ones_factor(), no_full_table(), ones_factor(), ones_factor(),
                      no_view_table(), no_full_table(), no_view_table())
    return (tangent, view, mip_stack([[np.tile([1.0, 0.0, 0.0], (2, 4, 1))]]), mip_stack([[np.ones((2, 4))]]), off)


def _no_environment(n):
    """``shade_regular``'s environment arguments (lobes, multiple-scattering cells, I_M slices) for a scene without
    one, at n points."""
    return no_lobes(n), no_lights(n), im_slices(no_im_table(), np.zeros(0))


def test_light_between_a_blocking_yarns_fibers_reaches_the_point_directly():
    """A directional light's direct fraction at yarn level is V + (1 − V) τ_Y (``past_blockers``): with no fiber
    counted toward the light (n_occluded = n_cross = 0, so only the direct fraction differs), a point fully in
    another yarn's shadow (V = 0) with gap transmittance τ_Y = 0.25 shades as an unblocked point lit at V = 0.25; a
    lit point (V = 1) does not move; a partly shadowed point (V = 0.4) takes 0.4 + 0.6·0.25 = 0.55. With two
    blocking yarns counted (``Lights.beyond`` V₂, the fraction at most one yarn blocks), a point behind two
    (V = V₂ = 0) passes τ_Y² = 0.0625, one behind one (V₂ = 1) τ_Y as before, and half and half (V₂ = 0.5)
    0.5·0.25 + 0.5·0.0625."""
    n = 16
    tangent, view, flat, full, off = _kernel_frames(n, seed=11)
    ds = np.stack([np.full((4, 3), x) for x in (0.7, 0.2, 0.3, 0.1, 0.3)])
    points = Points(view, tangent, np.zeros(n), np.zeros(n), np.full(n, 1e-3), np.zeros(n, np.int64), np.zeros((n, 3)),
                    np.ones(n))
    sun = np.array([[0.3, 0.6, 1.0]]) / np.linalg.norm([0.3, 0.6, 1.0])

    def shaded(visibility, gap, beyond=None):
        look = Look(ROUGH, ds, 1.0, 1.0, 1.0, 0.0, 0.0, 0.0, gap, D_F, D_B)
        rgb, alpha = np.zeros((n, 3)), np.zeros(n)
        lights = Lights(sun, np.full((1, 3), 2.0), np.full((1, n), visibility),
                        np.zeros((1, 0)) if beyond is None else np.full((1, n), beyond))  # (1, 0): not counted
        shade_regular(np.arange(n), points, look, off, flat, full, no_detail(), lights, *_no_environment(n), no_rows(),
                      rgb, alpha)
        return rgb

    assert np.any(shaded(0.25, 0.0) > 0.0)
    np.testing.assert_allclose(shaded(0.0, 0.25), shaded(0.25, 0.0), rtol=1e-12)
    np.testing.assert_allclose(shaded(1.0, 0.25), shaded(1.0, 0.0), rtol=1e-12)
    np.testing.assert_allclose(shaded(0.4, 0.25), shaded(0.55, 0.0), rtol=1e-12)
    assert np.all(shaded(0.0, 0.25) >= shaded(0.0, 0.0))
    np.testing.assert_allclose(shaded(0.0, 0.25, beyond=0.0), shaded(0.0625, 0.0), rtol=1e-12)
    np.testing.assert_allclose(shaded(0.0, 0.25, beyond=0.5), shaded(0.5 * 0.25 + 0.5 * 0.0625, 0.0), rtol=1e-12)
    np.testing.assert_allclose(shaded(1.0, 0.25, beyond=1.0), shaded(1.0, 0.0), rtol=1e-12)
    np.testing.assert_array_equal(shaded(0.4, 0.25, beyond=1.0), shaded(0.4, 0.25))  # counted at 1 = not counted


def test_environment_shading_matches_quadrature_for_1_16_64_lobes():
    """Eq. 17 in the shading kernel (I_M table lookups summed over J lobes, ξ = Ψ = 1, unshadowed, no
    multiple-scattering lights) against direct
    quadrature of the same fitted lobes, Σ_j W_j I_M^direct; and the 64-lobe result against brute-force
    integration of the sky itself."""
    table = im.bake_im_table(ROUGH, TEST_SHAPE, nodes=4)[0]
    axes = im.im_axes(TEST_SHAPE)
    i_m = im_table_from(table, axes)
    n = 12
    tangent, view, flat, full, off = _kernel_frames(n, seed=5)
    sky = sky_image(64, 128)
    dirs = texel_directions(64, 128).reshape(-1, 3)
    texel_sr = (np.pi / 64) * (2 * np.pi / 128) * np.cos(np.arcsin(np.clip(dirs[:, 1], -1, 1)))
    results = {}
    for j in (1, 16, 64):
        fit = fit_srbf(sky, n_lobes=j, seed=0)
        rgb, alpha = np.zeros((n, 3)), np.zeros(n)
        points = Points(view, tangent, np.zeros(n), np.zeros(n), np.full(n, 1e-3), np.zeros(n, np.int64),
                        np.zeros((n, 3)), np.ones(n))
        look = Look(ROUGH, np.ones((5, 4, 3)), 1.0, 1.0, 1.0, 0.0, 0.0, 0.0, 0.0, D_F, D_B)
        shade_regular(np.arange(n), points, look, off, flat, full, no_detail(), no_lights(n),
                      Lobes(fit.directions, fit.sharpness, fit.weights, np.ones((j, n)), np.zeros(4)), no_lights(n),
                      im_slices(i_m, fit.sharpness), no_rows(), rgb, alpha)
        theta_o = np.arcsin(np.sum(view * tangent, axis=1))
        direct = np.zeros((n, 3))
        for wj, lam, w in zip(fit.directions, fit.sharpness, fit.weights):
            theta_j = np.arcsin(np.clip(tangent @ wj, -1, 1))
            dphi = -np.array([_phi(t, v, wj) for t, v in zip(tangent, view)])
            direct += w * im.im_direct(ROUGH, theta_o, theta_j, dphi, lam)
        assert np.all(alpha == 1.0)
        assert np.allclose(rgb, direct, rtol=0.03, atol=0.01 * direct.max()), j
        results[j] = rgb
    truth = np.zeros((n, 3))
    for k in range(n):
        wo = np.broadcast_to(_local(tangent[k], view[k], view[k]), (len(dirs), 3)).copy()
        wi = np.array([_local(tangent[k], view[k], d) for d in dirs])
        f = fb.eval_batch(ROUGH, wo, wi) * np.sqrt(np.maximum(0, 1 - wi[:, :1] ** 2))
        truth[k] = (sky.reshape(-1, 3) * f * texel_sr[:, None]).sum(axis=0)
    err = {j: np.abs(r - truth).sum() / truth.sum() for j, r in results.items()}
    print(err)
    assert err[16] < 0.1 and err[64] < 0.1 and err[64] <= err[1]


def _phi(t, wo, wi):
    o, i = wo - (wo @ t) * t, wi - (wi @ t) * t
    return math.atan2(np.cross(i, o) @ t, i @ o)


def _local(t, wo, w):
    """w in the BCSDF's local frame (x along t, y toward wo's normal-plane part)."""
    y = wo - (wo @ t) * t
    y /= np.linalg.norm(y)
    return np.array([w @ t, w @ y, w @ np.cross(t, y)])


def test_ablations_change_the_image(tmp_path, pack):
    """Each rung of the ladder changes the image: under the sun and the sky (inter-reflection acts on the sky's
    lobes) with a second yarn in front of the first, whose shadow the inter-reflection softens."""
    path = write_scene(tmp_path, [straight(), straight(z=0.1) + [0, 0.05, 0]], camera=FRONT, lights=SKY + "\n" + SUN)
    ladder = ["plain_ds", "xi", "xi_shadowing", "interreflection", "closed", "full"]
    others = ("no_tables", "factored", "no_detail", "papers_xi")  # the tiny pack stores both forms and both ξ
    # only the models compared here: each switch of the flyaway layer is a shading kernel of its own to compile
    # (~35 s each on 2 cores), and the hair switches have their own tests under the light they act in
    images = {name: _render(path, pack, features=ABLATIONS[name]).image for name in (*ladder, *others)}
    for a, b in zip(ladder, ladder[1:]):
        assert not np.array_equal(images[a], images[b]), (a, b)
    for other in others:
        assert not np.array_equal(images["full"], images[other]), other


def test_the_split_by_the_surface_seen_first_draws_opaque_black_hairs(tmp_path, pack):
    """``Features(hair_light=False)`` draws the hairs opaque and black (the counterpart of the reference traced with
    ``seen="regular"``): per pixel never brighter than the full image (the hairs add no light and pass none of the
    body's), darker where hairs are drawn, the background where they are not; without the flyaway layer it changes
    nothing (the GL backend refuses it: ``tests/test_gl_render.py``)."""
    sun = write_scene(tmp_path, [straight()], camera=FRONT, lights=SKY + "\n" + SUN, name="sun")
    full = _render(sun, pack).image
    split = _render(sun, pack, features=Features(hair_light=False)).image
    assert np.all(split <= full + 1e-6 * np.abs(full).max())
    darker = (full - split).sum(axis=2) > 1e-4
    assert darker.sum() > 50  # the hairs over and beside the body
    assert np.array_equal(_render(sun, pack, features=Features(flyaways=False, hair_light=False)).image,
                          _render(sun, pack, features=Features(flyaways=False)).image)


def test_other_yarns_hair_layers_dim_the_directional_lights(tmp_path, pack):
    """``Features.hair_canopy`` (the default; ``no_hair_canopy`` leaves it out): a lone yarn keeps its image bit for
    bit (its own layer is the lone yarn's); a yarn in the hair layer of another between it and the sun is darker,
    nowhere brighter; the switch changes nothing without flyaways."""
    without = Features(hair_canopy=False)
    lone = write_scene(tmp_path, [straight()], camera=FRONT, lights=SUN, name="lone")
    assert np.array_equal(_render(lone, pack).image, _render(lone, pack, features=without).image)
    # the sun (0.3, 0.6, 1.0): the upper yarn 2.6 radii along it from the lower one, their bodies clear of each other
    # and the lower one inside the upper one's hair layer
    r = 0.03
    step = 2.6 * r * np.array([0.3, 0.6, 1.0]) / np.linalg.norm([0.3, 0.6, 1.0])
    pair = write_scene(tmp_path, [straight(), straight() + step], camera=FRONT, lights=SUN, name="pair")
    full = _render(pair, pack, features=without).image
    dimmed = _render(pair, pack).image
    assert np.all(dimmed <= full + 1e-6 * np.abs(full).max())
    assert (full - dimmed).sum(axis=2).max() > 1e-3
    bare = dict(flyaways=False)
    assert np.array_equal(_render(pair, pack, features=Features(**bare)).image,
                          _render(pair, pack, features=Features(hair_canopy=False, **bare)).image)


def test_the_single_scattering_split_is_darker_and_blind_to_what_crosses_yarns(tmp_path, pack):
    """``Features(multiple_scattering=False)`` keeps single scattering alone: never brighter than the full image
    under the sun and the sky, clearly darker over the yarns, not black; and, its DS density factors being 0, blind
    to the fiber counts of light crossing another yarn, which only the forward-scattered (multiple) light passes:
    under the sun, without the hairs (whose own single scattering crosses their yarn), any counts draw the same
    image. What it does see is the light passing between a blocker's fibers (the gap transmittance τ_Y, with
    ``interreflection``): with it the yarn in the other's shadow is brighter, nowhere darker."""
    pair = [straight(), straight(z=0.1) + [0, 0.05, 0]]
    both = write_scene(tmp_path, pair, camera=FRONT, lights=SKY + "\n" + SUN, name="both")
    full = _render(both, pack).image - [0.1, 0.2, 0.3]
    single = _render(both, pack, features=Features(multiple_scattering=False)).image - [0.1, 0.2, 0.3]
    covered = np.abs(full).sum(axis=2) > 1e-3
    assert covered.sum() > 100
    assert np.all(single <= full + 1e-6 * np.abs(full).max())
    assert 0.05 * full[covered].mean() < single[covered].mean() < 0.9 * full[covered].mean()
    sun = write_scene(tmp_path, pair, camera=FRONT, lights=SUN, name="sun")
    split = dict(multiple_scattering=False, flyaways=False)
    renderer = Renderer(load_scene(sun), {"cotton1": str(pack)}, Features(**split))
    a = renderer.render().image
    for look in renderer.looks:  # counts far from the pack's: single scattering does not see them
        look.n_cross, look.n_cross_rest = 0.0, 50.0
    renderer.kernel_looks = [shading_look(look) for look in renderer.looks]
    assert np.array_equal(a, renderer.render().image)
    b = _render(sun, pack, features=Features(interreflection=False, **split)).image  # τ_Y = 0, the geometric count
    assert np.all(a >= b - 1e-6) and np.abs(a - b).max() > 1e-4
    # ... which the full light transport is not: there the count moves the yarn in the other's shadow
    c = _render(sun, pack, features=Features(flyaways=False)).image
    d = _render(sun, pack, features=Features(interreflection=False, flyaways=False)).image
    assert np.abs(c - d).max() > 1e-4


def test_the_single_scattering_split_leaves_out_light_another_fiber_scattered_first(tmp_path, pack):
    """The yarn-level terms whose light a body's fibers or another yarn scattered before the fiber seen are multiple
    scattering, so ``Features(multiple_scattering=False)`` draws none of them: under the sun the body's glow on its
    hairs (the split's image is the same with ``hair_glow`` off, which the full image is not), and under the sky the
    lobes' inter-reflection between two yarns (the same with ρ_Y taken out of the lobes, which the full image is
    not). Until stop 63 both counted as single scattering."""
    pair = [straight(), straight(z=0.1) + [0, 0.05, 0]]
    single = dict(multiple_scattering=False)
    sun = write_scene(tmp_path, pair, camera=FRONT, lights=SUN, name="sun")
    assert np.array_equal(_render(sun, pack, features=Features(**single)).image,
                          _render(sun, pack, features=Features(hair_glow=False, **single)).image)
    glow = _render(sun, pack).image - _render(sun, pack, features=Features(hair_glow=False)).image
    assert glow.max() > 1e-4
    sky = write_scene(tmp_path, pair, camera=FRONT, lights=SKY, name="sky")
    renderer = Renderer(load_scene(sky), {"cotton1": str(pack)}, Features(flyaways=False, **single))
    a = renderer.render().image
    for look in renderer.looks:  # no hull albedo: nothing to inter-reflect the lobes with
        look.yarn_albedo = None
    assert np.array_equal(a, renderer.render().image)
    full = Renderer(load_scene(sky), {"cotton1": str(pack)}, Features(flyaways=False))
    b = full.render().image
    for look in full.looks:
        look.yarn_albedo = None
    assert np.abs(b - full.render().image).max() > 1e-4


def _parallax_points(xyz, rest, segment, arclength, v, tangent, view, radius=0.03):
    """``parallax_shift`` of points on one polyline (vertices ``xyz``, rest arc length ``rest``)."""
    lines = SimpleNamespace(points=np.asarray(xyz, float), rest=np.asarray(rest, float),
                            offsets=np.array([0, len(xyz)], np.int64))
    n = len(arclength)
    points = {"segment": np.asarray(segment, np.int32), "arclength": np.asarray(arclength, np.float32),
              "v": np.asarray(v, np.float32), "tangent": np.asarray(tangent, np.float32),
              "view_dir": np.tile(np.asarray(view, float), (n, 1)), "yarn": np.zeros(n, np.int32),
              "curve": np.zeros(n, np.int32)}
    return parallax_shift(points, lines, [SimpleNamespace(radius=radius)])


def test_the_axial_parallax_reads_the_centre_line_whose_surface_is_seen():
    """A straight yarn tilted by ψ toward the camera: the point at v is read r √(1 − v²) tan ψ further along (in rest
    length: half as far on a yarn stretched 2×), its tangent unchanged; across the view (ψ = 0) and at the strip's
    edges (|v| = 1) nothing moves; past the clamp the shift stops growing. On a ring seen edge-on the tangent turns
    with the arc: the circle's tangent at the shifted arc length (where the shift lands: the next test)."""
    r = 0.03
    for psi in (0.0, 0.4, 1.3):  # 1.3: beyond the clamp (sin ψ = 0.96)
        axis = np.array([math.cos(psi), 0.0, math.sin(psi)])
        xyz = np.linspace(0.0, 1.0, 101)[:, None] * axis
        rest = 0.5 * np.linspace(0.0, 1.0, 101)  # stretched 2×: rest length is half the current
        v = np.array([0.0, 0.6, -1.0])
        got = _parallax_points(xyz, rest, [40, 40, 40], [0.2015] * 3, v, np.tile(axis, (3, 1)), [0, 0, 1], r)
        tan_o = min(math.tan(psi), PARALLAX_MAX_SIN / math.sqrt(1 - PARALLAX_MAX_SIN ** 2))
        np.testing.assert_allclose(got["arclength"], 0.2015 + 0.5 * r * np.sqrt(1 - v ** 2) * tan_o, atol=1e-6)
        np.testing.assert_allclose(got["tangent"], np.tile(axis, (3, 1)), atol=1e-6)
        assert np.all(got["segment"] == np.floor(got["arclength"] / 0.005).astype(int))
    rho, n = 0.2, 721  # a ring in the x–z plane, seen from +z, arc length = ρ·angle
    angle = np.linspace(0.0, 2 * np.pi, n)
    xyz = np.stack([rho * np.cos(angle), np.zeros(n), rho * np.sin(angle)], axis=1)
    rest = rho * angle
    at = np.array([0.3, 0.9, 1.4, 2.0, 4.0])  # angles of the points, v = 0
    seg = np.floor(at / (angle[1] - angle[0])).astype(int)
    tangent = np.stack([-np.sin(at), np.zeros_like(at), np.cos(at)], axis=1)
    got = _parallax_points(xyz, rest, seg, rho * at, np.zeros_like(at), tangent, [0, 0, 1], r)
    moved = got["arclength"] / rho
    assert np.all(np.abs(moved - at) > 0.02 * r / rho)
    expect = np.stack([-np.sin(moved), np.zeros_like(at), np.cos(moved)], axis=1)
    np.testing.assert_allclose(got["tangent"], expect, atol=2e-4)
    # a closed curve's closing segment (from its last vertex back to its first) keeps its attributes
    closing = _parallax_points(xyz, rest, [n - 1], [rest[-1] + 1e-4], [0.0], [[0.0, 0.0, 1.0]], [0, 0, 1], r)
    assert closing["segment"][0] == n - 1 and closing["arclength"][0] == np.float32(rest[-1] + 1e-4)
    np.testing.assert_array_equal(closing["tangent"], [[0.0, 0.0, 1.0]])


def test_the_axial_parallax_meets_the_tube_where_the_ray_does_on_a_ring(monkeypatch):
    """A ring of radius ρ = 0.2 (a torus of tube radius r = 0.03) in the x–z plane, seen edge-on from +z, v = 0: the
    ray through the strip point at angle a meets the outer wall (ρ + r) on the half toward the camera and the inner
    wall (ρ − r) on the far half, at the angle a' whose x is ρ cos a; the parallax's shift is ρ (a' − a). Its Newton
    steps land within 1 % of it on both walls (measured ≤ 0.7 %), where the straight tube's shift alone (one step)
    errs by 15–29 %."""
    rho, r, n = 0.2, 0.03, 721
    angle = np.linspace(0.0, 2 * np.pi, n)
    xyz = np.stack([rho * np.cos(angle), np.zeros(n), rho * np.sin(angle)], axis=1)
    at = np.array([0.6, 0.9, 1.4, 1.8, 2.5, 3.9, 4.3, 5.0, 5.5])
    seg = np.floor(at / (angle[1] - angle[0])).astype(int)
    tangent = np.stack([-np.sin(at), np.zeros_like(at), np.cos(at)], axis=1)
    x = rho * np.cos(at)
    z = np.where(np.sin(at) > 0, np.sqrt((rho + r) ** 2 - x ** 2), -np.sqrt((rho - r) ** 2 - x ** 2))
    exact = np.mod(np.arctan2(z, x), 2 * np.pi) - at

    def shift():
        got = _parallax_points(xyz, rho * angle, seg, rho * at, np.zeros_like(at), tangent, [0, 0, 1], r)
        return got["arclength"] / rho - at

    assert np.all(np.abs(shift() - exact) < 0.01 * np.abs(exact))
    monkeypatch.setattr(pipeline, "PARALLAX_PASSES", 1)
    assert np.all(np.abs(shift() - exact) > 0.14 * np.abs(exact))


def test_the_axial_parallax_leaves_a_yarn_across_the_view_and_moves_a_tilted_bent_one(tmp_path, pack):
    """Seen orthographically a straight yarn in the image plane has θ_o = 0 everywhere: nothing moves (a pinhole
    camera sees its ends obliquely, which moves them). A yarn that rises toward the camera is drawn otherwise."""
    ortho = FRONT.replace("fov_deg = 30.0", "ortho_height = 0.5")
    across = write_scene(tmp_path, [straight()], camera=ortho, lights=SUN, name="across")
    off = Features(parallax=False)
    np.testing.assert_allclose(_render(across, pack).image, _render(across, pack, features=off).image, atol=1e-5)
    t = np.linspace(0.0, np.pi, 25)
    arc = np.stack([0.25 * np.cos(t), 0.05 * np.sin(t), 0.2 * np.sin(t)], axis=1)  # rises toward the camera
    bent = write_scene(tmp_path, [arc], camera=FRONT, lights=SUN, name="bent")
    assert np.abs(_render(bent, pack).image - _render(bent, pack, features=off).image).max() > 1e-3


def test_receivers_carry_their_offset_from_the_yarn_axis():
    """``strip_receivers``: a strip point lies v r along b = normalize(ω_o × t) from the axis, the tube surface
    r √(1 − v²) further toward the camera; both biased by ``SHADOW_BIAS_RADII`` r; a point looking along its yarn (ω_o × t = 0) has
    no lateral part."""
    points = {"weight": np.ones(3), "position": np.array([[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0]]),
              "view_dir": np.array([[0.0, 0.0, 1.0], [0.0, 0.6, 0.8], [1.0, 0.0, 0.0]]),
              "v": np.array([0.5, 0.6, -1.0], np.float32), "yarn": np.array([0, 1, 0], np.int32),
              "tangent": np.array([[1.0, 0.0, 0.0], [2.0, 0.0, 0.0], [1.0, 0.0, 0.0]])}
    looks = [SimpleNamespace(radius=0.03), SimpleNamespace(radius=0.05)]
    strip, surface = strip_receivers(points, looks, False), strip_receivers(points, looks, True)
    lateral = np.array([[0.0, 0.015, 0.0], [0.0, 0.05 * 0.6 * 0.8, -0.05 * 0.6 * 0.6], [0.0, 0.0, 0.0]])
    height = np.array([0.03 * np.sqrt(0.75), 0.05 * 0.8, 0.0])[:, None] * points["view_dir"]
    np.testing.assert_allclose(strip.offset, lateral, atol=1e-9)
    np.testing.assert_allclose(surface.offset, lateral + height, atol=1e-9)
    np.testing.assert_allclose(strip.position, points["position"], atol=0)
    np.testing.assert_allclose(surface.position, points["position"] + height, atol=1e-9)
    np.testing.assert_allclose(surface.bias, SHADOW_BIAS_RADII * np.array([0.03, 0.05, 0.03]))
    np.testing.assert_allclose(strip.bias, surface.bias)


def test_surface_shadows_light_the_front_of_a_yarn_whose_axis_plane_a_touching_neighbour_shadows(tmp_path, pack):
    """Two touching yarns side by side in the image plane, the light grazing across them from B's side (16° above
    the plane): the ray toward the light from A's axis passes 0.56 r from B's axis (shadowed), the ray from the
    front of A's tube 1.52 r (lit). Looked up on the tube's surface (``Features.surface_shadows``), A's middle is
    lit as the reference's fibers there are; B, with nothing between it and the light, does not change."""
    r = 0.03
    a, b = straight(), straight() + np.array([0.0, 2 * r, 0.0])
    camera = FRONT.replace("fov_deg = 30.0", "ortho_height = 0.3")
    grazing = SUN.replace("direction = [0.3, 0.6, 1.0]", "direction = [0.0, 1.0, 0.29]")
    path = write_scene(tmp_path, [a, b], camera=camera, lights=grazing, render="layers = 1",
                       name="touching")
    path.write_text(path.read_text().replace("background = [0.1, 0.2, 0.3]", "background = [0.0, 0.0, 0.0]"))
    axis_plane = _render(path, pack, features=Features(flyaways=False, surface_shadows=False, yarn_bounce=False)
                         ).image.sum(axis=-1)
    surface = _render(path, pack, features=Features(flyaways=False, yarn_bounce=False)).image.sum(axis=-1)
    px = 0.3 / 48  # ortho_height / height: rows of A's middle third and of B's, away from the shared edge
    row_a = slice(24 - int(r / 3 / px), 24 + int(r / 3 / px) + 1)
    row_b = slice(24 - int((2 * r + r / 3) / px), 24 - int((2 * r - r / 3) / px) + 1)
    cols = slice(16, 48)
    assert surface[row_a, cols].mean() > 1.5 * axis_plane[row_a, cols].mean()
    np.testing.assert_allclose(surface[row_b, cols], axis_plane[row_b, cols], rtol=1e-6, atol=1e-9)


def test_a_lone_yarn_lit_along_its_length_is_not_shadowed_by_its_own_strip(tmp_path, pack):
    """A lone yarn with nothing to shadow it, lit from behind, the light 56° from its normal plane toward its axis:
    the tube surface the camera sees is the side away from the light, and past 48° it fell behind its own strip
    (the strip faces the light and tilts in depth). Looked up on the tube's surface, the image is the axis plane's
    (``pipeline.receiver_bias``)."""
    along = SUN.replace("direction = [0.3, 0.6, 1.0]", "direction = [1.0, 0.3, -0.6]")
    path = write_scene(tmp_path, [straight()], camera=FRONT, lights=along, name="along")
    axis_plane = _render(path, pack, features=Features(surface_shadows=False)).image
    surface = _render(path, pack).image
    assert axis_plane.max() > 0.0
    np.testing.assert_allclose(surface, axis_plane, rtol=1e-6, atol=1e-9)


def test_a_lone_yarns_hairs_are_not_shadowed_by_its_own_strip(tmp_path, pack, monkeypatch):
    """A lone yarn lit from behind and from one side: its hairs on the far side lie behind its own strip in the
    light's map, up to their strip's half-width (2.24 radii in the test pack) from the axis, beyond the bias. The kernels shadow a hair by its own yarn themselves (``strip_shading._hair_light``), so the map must
    not: the image is the one with every yarn-level lookup lit (measured before stop 62, when a hair's lookup had no
    margin from its own strip: one pixel 0.52 % of the peak darker, the mean 0.003 %)."""
    side = SUN.replace("direction = [0.3, 0.6, 1.0]", "direction = [0.2, 0.8, -0.5]")
    path = write_scene(tmp_path, [straight()], camera=FRONT, lights=side, name="side")
    mapped = _render(path, pack)

    def lit_everywhere(lines, radius, direction, size, angular, receivers, depth_maps, two_layers=False):
        return [(np.ones(len(r.position)),) * 2 if two_layers else np.ones(len(r.position)) for r in receivers]

    monkeypatch.setattr(pipeline, "_visibility", lit_everywhere)
    lit = _render(path, pack)
    assert mapped.facts["flyaway_points_covered"] > 0 and lit.image.max() > 0.0
    np.testing.assert_allclose(mapped.image, lit.image, rtol=1e-6, atol=1e-9)


def test_pack_errors_are_one_line(tmp_path, pack):
    path = write_scene(tmp_path, [straight()], camera=FRONT, lights=SUN)
    with pytest.raises(ValueError, match=r"yarns\[0\] \(cotton1\) has no asset pack"):
        render(load_scene(path))
    with pytest.raises(ValueError, match="does not exist"):
        render(load_scene(path), {"cotton1": str(tmp_path / "nope.h5")})
    other = tmp_path / "silk.h5"
    bake(load_preset("silk1"), other, overrides=TINY, seed=1, use_cache=False, only=["dual_scattering"])
    with pytest.raises(ValueError, match="silk1"):
        render(load_scene(path), {"cotton1": str(other)})


def test_cli_render_writes_png_exr_and_json(tmp_path, pack):
    path = write_scene(tmp_path, [straight()], camera=FRONT, lights=SUN)
    out, exr = tmp_path / "out.png", tmp_path / "out.exr"
    result = CliRunner().invoke(knitrun, ["render", str(path), "-o", str(out), "--exr", str(exr),
                                          "--pack", f"cotton1={pack}", "--json"])
    assert result.exit_code == 0, result.output
    summary = json.loads(result.stdout)
    assert out.is_file() and read_exr(exr).shape == (48, 64, 3)
    assert set(summary["ms_per_pass"]) >= {"raster", "shade"} and summary["ms_total"] > 0
    bad = CliRunner().invoke(knitrun, ["render", str(path), "-o", str(out)])
    assert bad.exit_code != 0 and "has no asset pack" in bad.output and "Traceback" not in bad.output


def test_cli_render_takes_a_combination_of_ablations_and_names_an_unknown_one(tmp_path, pack):
    """``--ablation a+b`` draws what ``ablations.combined`` gives (the image of the library call); an unknown part is
    a usage error that names it."""
    path = write_scene(tmp_path, [straight(z=0.0), straight(z=-0.1) + [0.0, -0.04, 0.0]], camera=FRONT, lights=SUN)
    exr = tmp_path / "out.exr"
    result = CliRunner().invoke(knitrun, ["render", str(path), "-o", str(tmp_path / "out.png"), "--exr", str(exr),
                                          "--pack", f"cotton1={pack}", "--ablation", "axis_shadows+no_parallax"])
    assert result.exit_code == 0, result.output
    expect = _render(path, pack, features=Features(surface_shadows=False, parallax=False)).image
    np.testing.assert_array_equal(read_exr(exr), expect)
    bad = CliRunner().invoke(knitrun, ["render", str(path), "-o", str(tmp_path / "b.png"), "--pack",
                                       f"cotton1={pack}", "--ablation", "full+bounce"])
    assert bad.exit_code == 2 and "unknown ablation 'bounce'" in bad.output and "Traceback" not in bad.output


# --- building blocks ---------------------------------------------------------------------------------------------

def test_texture_sampling_hits_texel_centres_and_wraps_u():
    rng = np.random.default_rng(0)
    level0 = rng.random((4, 8, 2)).astype(np.float32)
    level1 = level0.reshape(2, 2, 4, 2, 2).mean(axis=(1, 3))
    stack = mip_stack([[level0, level1]])
    out = np.empty(2)
    for i in range(4):
        for j in range(8):
            u, v = (j + 0.5) / 8, -1 + (i + 0.5) * 2 / 4
            sample_mip(stack, 0, 0.0, u + 3.0, v, out)
            assert np.allclose(out, level0[i, j], atol=1e-6)
    # halfway between the last and the first column: the mean of the two (u repeats)
    sample_mip(stack, 0, 0.0, 1.0, -1 + 0.25, out)
    assert np.allclose(out, (level0[0, 0] + level0[0, 7]) / 2, atol=1e-6)
    # level 0.5 blends the two levels; levels beyond the chain clamp to the last
    sample_mip(stack, 0, 0.5, 0.3125, -0.75, out)
    a, b = np.empty(2), np.empty(2)
    sample_mip(stack, 0, 0.0, 0.3125, -0.75, a)
    sample_mip(stack, 0, 1.0, 0.3125, -0.75, b)
    assert np.allclose(out, (a + b) / 2)
    sample_mip(stack, 0, 9.0, 0.3125, -0.75, out)
    assert np.allclose(out, b)


def _splitmix_variant(curve, period_index):
    """The flyaway variant hash of ``strip_shading.variant_of`` in plain Python integers (splitmix64's finaliser of
    curve·φ64 + the period index's low 48 bits, mod 3): the fixed definition the kernel must keep."""
    mask = (1 << 64) - 1
    x = (curve * 0x9E3779B97F4A7C15 + (period_index & 0xFFFFFFFFFFFF)) & mask
    x = ((x ^ (x >> 30)) * 0xBF58476D1CE4E5B9) & mask
    x = ((x ^ (x >> 27)) * 0x94D049BB133111EB) & mask
    return (x ^ (x >> 31)) % 3


def test_flyaway_variant_hash_is_the_fixed_hash_and_uses_all_three():
    """The kernel's hash equals its definition (so a yarn keeps its flyaway pattern across versions, frames and
    thread counts), negative periods (curves that start before s = 0) included, and spreads over all three."""
    pairs = [(c, p) for c in range(5) for p in range(-50, 200)] + [(123_456, 7), (2**40, 2**47 - 1)]
    picks = np.array([variant_of(c, p) for c, p in pairs])
    np.testing.assert_array_equal(picks, [_splitmix_variant(c, p) for c, p in pairs])
    counts = np.bincount(picks, minlength=3)
    assert counts.min() > 0.25 * picks.size  # each variant about a third


def _through_yarn(v, w_b, w_n, reach, a_f, n_cross, gap=0.0, behind=False):
    """The fraction of light reaching a hair beside a yarn (unit radius; ``behind``: behind its body) from direction
    (w_b, w_n) in the yarn's cross-section, by ray–circle intersection at each of the kernel's depths (spread over
    −d…d, d = √(reach² − v²); ``behind``: over −d…−√(1 − v²)): the gap transmittance plus the rest times a_f to the
    power n_cross times the chord inside the circle over its diameter."""
    d = np.array([w_b, w_n]) / math.hypot(w_b, w_n)
    depth = math.sqrt(max(reach * reach - v * v, 0.0))
    lo, hi = -depth, -math.sqrt(1.0 - v * v) if behind else depth
    out = np.zeros(3)
    for k in range(HAIR_DEPTHS):
        p = np.array([v, lo + (hi - lo) * (k + 0.5) / HAIR_DEPTHS])
        disc = (p @ d) ** 2 - (p @ p - 1.0)  # |p + s d| = 1: s = −p·d ± √disc
        crossed = disc > 0 and -(p @ d) - math.sqrt(disc) > 0
        out += gap + (1.0 - gap) * a_f ** (n_cross * math.sqrt(disc)) if crossed else 1.0
    return out / HAIR_DEPTHS


def test_an_infinite_cylinders_solid_angle_against_directions_drawn_on_the_sphere():
    """``cylinder_solid_angle``: the fraction of 400,000 uniform directions from a point ρ radii from the axis of a
    unit cylinder along z whose ray meets it (ray–circle test in the xy plane), times 4π; 2π at the surface."""
    rng = np.random.default_rng(5)
    d = rng.normal(size=(400_000, 3))
    d /= np.linalg.norm(d, axis=1, keepdims=True)
    for rho in (1.0, 1.3, 2.0, 5.0):
        dxy = d[:, :2]
        along = -rho * dxy[:, 0]  # toward the axis from (ρ, 0): the projection on the xy plane meets the circle?
        miss = rho * rho - along ** 2 / np.maximum(np.sum(dxy ** 2, axis=1), 1e-300)
        hit = (along > 0) & (miss <= 1.0)
        expected = 4 * np.pi * hit.mean()
        assert cylinder_solid_angle(rho) == pytest.approx(expected, abs=4 * np.pi * 3 * np.sqrt(0.25 / len(d)))
    assert cylinder_solid_angle(1.0) == pytest.approx(2 * np.pi) and cylinder_solid_angle(0.9) == pytest.approx(
        2 * np.pi)


def test_the_bodys_glow_on_a_hair_is_the_tube_phase_over_the_tubes_solid_angle():
    """``body_glow`` against the module docstring's sum written out here, at the same depths; zero for a light along
    the yarn; linear in R_Y and S_Y; a hair on the lit side gets more of it than one on the far side of a yarn that
    reflects more than it passes on."""
    t, n, b = np.array([1.0, 0, 0]), np.array([0, 0, 1.0]), np.array([0, 1.0, 0])  # b = n × t
    tube = np.array([[0.3, 0.25, 0.2], [0.2, 0.15, 0.1]])
    albedo = np.array([0.9, 0.8, 0.7])
    reach, out = 2.2, np.empty(3)

    def glow(v, w, tube=tube):
        body_glow(tube, albedo, reach, v, 0.0, n, b, np.asarray(w, float) / np.linalg.norm(w), out)
        return out.copy()

    def g(a):
        return 0.25 * np.pi * (np.sin(a) + (np.pi - a) * np.cos(a))

    w = np.array([0.0, 0.6, 0.8])  # in the normal plane: cos θ_L = 1
    expected = np.zeros(3)
    depth = np.sqrt(reach ** 2 - 1.4 ** 2)
    for k in range(HAIR_DEPTHS):
        z = depth * ((2 * k + 1) / HAIR_DEPTHS - 1)
        rho = np.hypot(1.4, z)
        alpha = np.arccos(np.clip((1.4 * 0.6 + z * 0.8) / rho, -1, 1))
        expected += ((tube[0] * g(alpha) + tube[1] * g(np.pi - alpha)) / np.pi ** 2 * 4 * np.arcsin(1 / rho)
                     / (4 * np.pi) * albedo / HAIR_DEPTHS)
    np.testing.assert_allclose(glow(1.4, w), expected, rtol=1e-12)
    np.testing.assert_allclose(glow(1.4, [1.0, 0, 0]), 0.0)  # the light along the yarn lights no side of it
    np.testing.assert_allclose(glow(1.4, w, 2 * tube), 2 * expected, rtol=1e-12)
    assert np.all(glow(1.4, w) > glow(-1.4, w))  # R_Y > S_Y: the lit side (+b) glows more
    assert np.all(glow(1.4, w) > 0.0) and np.all(np.isfinite(glow(1.0001, w)))


def test_a_hair_over_the_body_takes_the_glow_at_the_depths_in_front_of_and_behind_it():
    """Over the body (|v| ≤ 1) the hairs the camera sees lie in front of it, and a share ``behind`` behind it (seen
    through its gaps): ``body_glow`` averages the same sum over the depths √(1 − v²)…√(reach² − v²) with weight
    1 − behind and −√(reach² − v²)…−√(1 − v²) with weight behind (none inside the body). Lit from behind (ω along
    −n) a hair in front sees the body's dark side, so it takes S_Y's glow and hardly R_Y's (under 1 %: the depths lie
    a few degrees off the light's axis), and a hair behind the body sees its lit side: R_Y's glow and hardly S_Y's;
    where the reach ends inside the body, nothing."""
    n, b = np.array([0, 0, 1.0]), np.array([0, 1.0, 0])
    albedo, reach, v, out = np.array([0.9, 0.8, 0.7]), 2.2, 0.5, np.empty(3)

    def glow(tube, w, behind=0.0, reach=reach):
        body_glow(np.asarray(tube, float), albedo, reach, v, behind, n, b, np.asarray(w, float) / np.linalg.norm(w),
                  out)
        return out.copy()

    def g(a):
        return 0.25 * np.pi * (np.sin(a) + (np.pi - a) * np.cos(a))

    def over(tube, w, lo, hi):
        total = np.zeros(3)
        for k in range(HAIR_DEPTHS):
            z = lo + (hi - lo) * (k + 0.5) / HAIR_DEPTHS
            rho = np.hypot(v, z)
            alpha = np.arccos(np.clip((v * w[1] + z * w[2]) / rho, -1, 1))
            total += ((tube[0] * g(alpha) + tube[1] * g(np.pi - alpha)) / np.pi ** 2 * 4 * np.arcsin(1 / rho)
                      / (4 * np.pi) * albedo / HAIR_DEPTHS)
        return total

    tube = np.array([[0.3, 0.25, 0.2], [0.2, 0.15, 0.1]])
    w = np.array([0.0, 0.6, 0.8])
    front, depth = np.sqrt(1 - v ** 2), np.sqrt(reach ** 2 - v ** 2)
    in_front, at_back = over(tube, w, front, depth), over(tube, w, -depth, -front)
    np.testing.assert_allclose(glow(tube, w), in_front, rtol=1e-12)
    np.testing.assert_allclose(glow(tube, w, behind=1.0), at_back, rtol=1e-12)
    np.testing.assert_allclose(glow(tube, w, behind=0.3), 0.7 * in_front + 0.3 * at_back, rtol=1e-12)
    from_behind = [0.0, 0.0, -1.0]
    forward, back = glow([[0.0] * 3, [0.3] * 3], from_behind), glow([[0.3] * 3, [0.0] * 3], from_behind)
    assert np.all(forward > 0) and np.all(back < 1e-2 * forward)
    forward, back = (glow([[0.0] * 3, [0.3] * 3], from_behind, behind=1.0),
                     glow([[0.3] * 3, [0.0] * 3], from_behind, behind=1.0))
    assert np.all(back > 0) and np.all(forward < 1e-2 * back)
    np.testing.assert_allclose(glow(tube, w, behind=0.5, reach=0.8), 0.0)  # the reach ends inside the body


def test_the_share_of_the_hairs_behind_the_body_is_what_its_gaps_let_the_camera_see():
    """``behind_share``: hairs as dense behind the body as in front, the camera sees all in front and the fraction
    1 − c behind (c the body's coverage): drawn here as two equal random sets, the behind ones kept with probability
    1 − c, the share of the kept ones that lie behind. None behind an opaque body, half behind an empty one; inputs
    outside [0, 1] clamp."""
    rng = np.random.default_rng(3)
    for c in (0.0, 0.3, 0.8, 1.0):
        seen_behind = (rng.random(200_000) >= c).sum()
        drawn = seen_behind / (200_000 + seen_behind)
        assert behind_share(c) == pytest.approx(drawn, abs=3e-3)
    assert behind_share(1.0) == 0.0 and behind_share(0.0) == 0.5
    assert behind_share(1.7) == 0.0 and behind_share(-0.4) == 0.5


def test_the_bodys_glow_lights_the_hairs_under_directional_lights_only(tmp_path, pack):
    """``Features.hair_glow`` (the default): under the sun the hairs beside the yarn and in front of it are brighter
    than without it and nothing is darker; under the sky alone (no directional light) the image is the one without
    it, bit for bit."""
    path = write_scene(tmp_path, [straight()], camera=FRONT, lights=SUN, name="sun")
    glowing, plain = _render(path, pack).image, _render(path, pack, features=Features(hair_glow=False)).image
    assert np.all(np.isfinite(glowing)) and np.all(glowing >= plain - 1e-7)
    assert glowing.sum() - plain.sum() > 4e-4 * plain.sum()
    sky = write_scene(tmp_path, [straight()], camera=FRONT, lights=SKY, name="sky")
    np.testing.assert_array_equal(_render(sky, pack).image,
                                  _render(sky, pack, features=Features(hair_glow=False)).image)


def test_hairs_seen_through_the_body_are_lit_past_it(tmp_path, pack):
    """``Features.hairs_behind`` (the default): lit from behind the yarn (the camera at +z, the light toward −z) a
    share of the hairs seen over the body lie behind it in the open, where those taken to lie in front of it get the
    body's Ψ^Fiber_G, nearly 0 there: the image is brighter over the body and nowhere darker; the rows beside the body
    are the same, bit for bit. Lit from the camera the same hairs lie in the body's shadow, lit through it (whether
    that is more or less than the body's Ψ^Fiber_G depends on the yarn: this tiny pack's sparse yarn passes on more
    than its surface fibers get, the standard cotton1 pack's less; ``_hair_light``'s test holds the values): the
    image moves over the body alone."""
    path = write_scene(tmp_path, [straight()], camera=FRONT, lights=BACKLIT, name="backlit")
    radius = load_scene(path).yarns[0].radius
    behind, front = _render(path, pack).image, _render(path, pack, features=Features(hairs_behind=False)).image
    pixel = 2.0 * math.tan(math.radians(15.0)) / 48  # cm per pixel at the yarn (FRONT: fov 30°, 48 rows, 1 cm)
    y = 24 * pixel - (np.arange(48) + 0.5) * pixel
    beside, over = np.abs(y) > radius + 2 * pixel, np.abs(y) < radius - 2 * pixel
    assert beside.sum() >= 8 and over.sum() >= 2
    assert np.all(np.isfinite(behind)) and np.all(behind >= front - 1e-7)
    assert behind[over].sum() > 1.02 * front[over].sum()
    np.testing.assert_array_equal(behind[beside], front[beside])
    lit = write_scene(tmp_path, [straight()], camera=FRONT, lights=BACKLIT.replace("0.3, -1.0", "0.0, 1.0"),
                      name="frontlit")
    shadowed, front = _render(lit, pack).image, _render(lit, pack, features=Features(hairs_behind=False)).image
    assert np.all(np.isfinite(shadowed)) and np.abs(shadowed[over] - front[over]).max() > 1e-3
    np.testing.assert_array_equal(shadowed[beside], front[beside])


def test_a_term_that_asks_for_one_xi_gets_what_asking_for_both_gives():
    """``_corrections(single=…, multiple=…)``: the sky's lobes ask for single scattering's ξ, its cells for multiple
    scattering's; each gets the value a call asking for both gives, and the other output is not written. Without
    single scattering's own table its ξ is the one ξ, looked up even when only it is asked for."""
    rng = np.random.default_rng(5)
    ms, ss = rng.uniform(0.5, 2.0, (4, 3, 3, 4, 3)), rng.uniform(0.5, 2.0, (4, 3, 3, 4, 3))
    t, n, b = np.array([1.0, 0, 0]), np.array([0, 0, 1.0]), np.array([0, 1.0, 0])
    w = np.array([0.3, 0.5, 0.8]) / np.linalg.norm([0.3, 0.5, 0.8])
    out = {name: np.full(3, -1.0) for name in ("xi", "xi_s", "psi", "scratch")}

    def ask(tables, **which):
        for value in out.values():
            value[:] = -1.0
        _corrections(tables, 0.3, t, n, b, 0.2, w, out["xi"], out["xi_s"], out["psi"], out["scratch"], **which)
        return out["xi"].copy(), out["xi_s"].copy()

    apart = Corrections(no_full_table(), ones_factor(), ones_factor(), no_full_table(), ones_factor(), ones_factor(),
                        ms, no_full_table(), ss)
    xi, xi_s = ask(apart)
    assert np.all(xi > 0) and np.all(xi_s > 0) and not np.allclose(xi, xi_s)
    single, multiple = ask(apart, multiple=False), ask(apart, single=False)
    np.testing.assert_array_equal(single[1], xi_s)
    np.testing.assert_array_equal(single[0], -1.0)
    np.testing.assert_array_equal(multiple[0], xi)
    np.testing.assert_array_equal(multiple[1], -1.0)
    whole = apart._replace(xi_single_view=no_view_table())
    one, _ = ask(whole)
    np.testing.assert_array_equal(ask(whole, multiple=False)[1], one)


def test_a_hair_beside_its_yarn_is_in_the_yarns_shadow_only_where_the_light_crosses_it():
    """``_hair_light`` beyond the body: 1 with the light on the hair's side or along the yarn, its own yarn's
    transmittance where the ray toward the light crosses the tube (ray–circle intersection at the same depths), and
    over the body Ψ^Fiber_G, whatever the geometry."""
    a_f = np.array([0.2, 0.5, 0.8])
    ds = np.zeros((5, 9, 3))
    ds[0] = a_f  # row R_A_F: ā_f(θ) the same at every θ
    t, n, b = np.array([1.0, 0, 0]), np.array([0, 0, 1.0]), np.array([0, 1.0, 0])  # b = n × t
    psi = np.full((4, 1, 3), 0.25)
    tables = Corrections(np.zeros((0, 1, 1, 3)), np.ones((4, 1, 3)), np.ones((4, 1, 3)), np.zeros((0, 1, 1, 3)),
                         psi, np.ones((4, 1, 3)), np.zeros((0, 1, 1, 1, 3)), np.zeros((0, 1, 1, 3)),
                         np.zeros((0, 1, 1, 1, 3)))
    out, scratch = np.empty(3), np.empty(3)
    reach, n_cross = 2.5, 6.0

    def light(v, w, on_body=False, count=n_cross, gap=0.0, behind=0.0):
        _hair_light(on_body, behind, tables, ds, count, gap, reach, v, t, n, b,
                    np.asarray(w, float) / np.linalg.norm(w), out, scratch)
        return out.copy()

    up = [0.0, 1.0, 0.3]  # from above (+b), a little in front
    np.testing.assert_allclose(light(1.5, up), 1.0)  # the hair above: nothing between it and the light
    below = light(-1.5, up)
    np.testing.assert_allclose(below, _through_yarn(-1.5, 1.0, 0.3, reach, a_f, n_cross), rtol=1e-12)
    assert np.all(below < 1.0) and below[0] < below[1] < below[2]  # redder through a red-passing yarn
    assert np.all(light(-1.2, up) <= below)  # nearer the axis: longer chords
    np.testing.assert_allclose(light(-1.5, [1.0, 0, 0]), 1.0)  # along the yarn
    np.testing.assert_allclose(light(-1.5, up, count=0.0), 1.0)  # a yarn that lets everything through
    back = [0.4, 0.5, -1.0]  # from behind and above: the hair below and in front is shadowed at some depths
    np.testing.assert_allclose(light(-1.3, back), _through_yarn(-1.3, 0.5, -1.0, reach, a_f, n_cross), rtol=1e-12)
    np.testing.assert_allclose(light(0.5, up, on_body=True), 0.25)  # over the body: Ψ^Fiber_G
    # a yarn with gaps between its fibers: τ_Y of the crossing light passes unscattered, the rest as before
    gappy = light(-1.5, up, gap=0.3)
    np.testing.assert_allclose(gappy, _through_yarn(-1.5, 1.0, 0.3, reach, a_f, n_cross, gap=0.3), rtol=1e-12)
    assert np.all(gappy > below) and np.all(gappy >= 0.3)
    np.testing.assert_allclose(light(1.5, up, gap=0.3), 1.0)  # nothing to cross: unchanged
    np.testing.assert_allclose(light(0.5, up, on_body=True, gap=0.3), 0.25)  # the body's Ψ^Fiber_G: unchanged
    # over the body a share ``behind`` lies behind it: past its own yarn over the depths behind the body
    from_behind, from_front = [0.0, 0.1, -1.0], [0.0, 0.1, 1.0]
    np.testing.assert_allclose(light(0.5, from_behind, on_body=True, behind=1.0), 1.0)  # in the open
    shadowed = light(0.5, from_front, on_body=True, behind=1.0)  # in the body's shadow
    np.testing.assert_allclose(shadowed, _through_yarn(0.5, 0.1, 1.0, reach, a_f, n_cross, behind=True), rtol=1e-12)
    assert np.all(shadowed < 0.5)
    np.testing.assert_allclose(light(0.5, from_front, on_body=True, behind=0.4), 0.6 * 0.25 + 0.4 * shadowed,
                               rtol=1e-12)
    np.testing.assert_allclose(light(0.5, [1.0, 0, 0], on_body=True, behind=0.4), 0.6 * 0.25 + 0.4)  # along t


def test_resolve_weights_coverage_over_the_background():
    start = np.array([0, 2, 2])
    weight = np.array([0.5, 0.5])
    rgb = np.array([[1.0, 0, 0], [0, 1.0, 0]])
    alpha = np.array([1.0, 0.5])
    under = np.array([[0, 0, 1.0], [0.2, 0.2, 0.2]])
    out = np.empty((2, 3))
    resolve(start, weight, rgb, alpha, np.zeros((2, 3)), under, out)
    assert np.allclose(out[0], [0.5, 0.25, 0.25])  # 0.5 red + 0.25 green + (1 − 0.75) blue
    assert np.allclose(out[1], [0.2, 0.2, 0.2])
    assert math.isclose(out.sum(), 0.5 + 0.25 + 0.25 + 0.6)
    # points that pass on τ of what lies behind them: blue keeps 1 − (0.5·(1 − 0.5) + 0.25·(1 − 0.2)) = 0.55
    transmit = np.array([[0.5, 0.5, 0.5], [1.0, 0.0, 0.2]])
    resolve(start, weight, rgb, alpha, transmit, under, out)
    assert np.allclose(out[0], [0.5, 0.25, 0.55])
    # τ = 1 everywhere: the layer only adds light
    resolve(start, weight, rgb, alpha, np.ones((2, 3)), under, out)
    assert np.allclose(out[0], [0.5, 0.25, 1.0]) and np.allclose(out[1], under[1])
    # in place (the renderer composites its layers so): the same as into a separate image
    resolve(start, weight, rgb, alpha, transmit, under, out)
    layered = under.copy()
    resolve(start, weight, rgb, alpha, transmit, layered, layered)
    assert np.array_equal(layered, out)


def test_resolve_composites_its_layers_the_farthest_first():
    """``start`` of L layers (the flyaway layers, nearest first): each layer over the ones behind it. One pixel, a red
    layer in front of a green one, both of coverage 0.8 passing on τ = 0.25 of what lies behind: red over (green over
    blue); the other order would give green over (red over blue)."""
    start = np.array([[0, 1], [1, 2]])  # layer 0 (nearest): point 0; layer 1: point 1
    weight, alpha = np.ones(2), np.full(2, 0.8)
    rgb = np.array([[1.0, 0, 0], [0, 1.0, 0]])
    transmit = np.full((2, 3), 0.25)
    under, out = np.array([[0, 0, 1.0]]), np.empty((1, 3))
    resolve(start, weight, rgb, alpha, transmit, under, out)

    def over(colour, behind):
        return 0.8 * colour + (1.0 - 0.8 * 0.75) * behind

    np.testing.assert_allclose(out[0], over(rgb[0], over(rgb[1], under[0])), rtol=1e-12)
    assert np.abs(out[0] - over(rgb[1], over(rgb[0], under[0]))).max() > 0.1


def test_the_second_layer_shows_through_the_front_only_where_the_front_is_transparent():
    """``resolve_behind`` then ``resolve``, per pixel (MSAA 2): the front at alpha 0.5 over the whole pixel with the
    back layer opaque behind it gives half of each; a front covering one sample opaquely, with the back layer behind
    that sample only, hides it (the other sample shows the background); no front, the background."""
    bg = np.array([0.1, 0.1, 0.1])
    front = {"start": np.array([0, 1, 2, 2]), "weight": np.array([1.0, 0.5])}
    back = {"start": np.array([0, 1, 2, 2]), "weight": np.array([1.0, 0.5])}
    red, green = np.array([[1.0, 0, 0], [1.0, 0, 0]]), np.array([[0, 1.0, 0], [0, 1.0, 0]])
    shaded = [(red, np.array([0.5, 1.0])), (green, np.array([1.0, 1.0]))]
    image = np.empty((3, 3))
    resolve_behind(front["start"], front["weight"], shaded[0][1], back["start"], back["weight"], *shaded[1], bg, image)
    resolve(front["start"], front["weight"], red, shaded[0][1], np.zeros((2, 3)), image, image)
    assert np.allclose(image[0], [0.5, 0.5, 0.0])
    assert np.allclose(image[1], [0.55, 0.05, 0.05])  # half red, half background; the green behind is hidden
    assert np.allclose(image[2], bg)


def test_a_yarn_shows_through_the_gaps_of_the_one_in_front(tmp_path, pack):
    """Two layers (the default): where a yarn crosses in front of another, the pixels of the front yarn's partial
    coverage take the back yarn's light instead of the background's; elsewhere the image is the one-layer image
    bit for bit."""
    lower, upper = straight(z=0.0), straight(z=0.2)[:, [1, 0, 2]]
    path = write_scene(tmp_path, [lower, upper], camera=FRONT, lights=SUN, name="cross")
    scene = load_scene(path)
    one = render(dataclasses.replace(scene, render=dataclasses.replace(scene.render, layers=1)),
                 {"cotton1": str(pack)}).image
    two = render(scene, {"cotton1": str(pack)}).image
    alone = [render(load_scene(write_scene(tmp_path, [y], camera=FRONT, lights=SUN, name=f"y{k}")),
                    {"cotton1": str(pack)}).image for k, y in enumerate((lower, upper))]
    background = one[0, 0]
    drawn = [np.abs(a - background).sum(axis=-1) > 1e-4 for a in alone]
    both = drawn[0] & drawn[1]
    assert both.sum() > 20 and np.all(np.isfinite(two))
    assert np.array_equal(one[~both], two[~both])
    moved = np.abs(two - one).sum(axis=-1) > 1e-4
    assert moved[both].mean() > 0.2 and not moved[~both].any()
    # what changed is the background swapped for the yarn behind: the change points from the background's colour
    # toward that yarn's (drawn alone) at nearly every moved pixel
    toward = ((two - one) * (alone[0] - background)).sum(axis=-1)
    assert (toward[both & moved] > 0).mean() > 0.95


def test_yarn_colour_acts_per_channel(tmp_path, pack):
    """The entry colour multiplies the lobe colours channel by channel and every table lookup and DS term is per
    channel: a colour of 1 in red leaves the red channel exactly as the white yarn's, the dimmed channels are darker
    (single scattering scales by the colour, multiple scattering by about its powers) but not black. Without the
    yarn-level inter-reflection, whose one hull albedo per yarn is the luminance of ρ_Y·colour
    (``knitrun.render.interreflection``), so that it couples the channels."""
    white = write_scene(tmp_path, [straight()], camera=FRONT, lights=SKY + "\n" + SUN, name="white")
    tinted = write_scene(tmp_path, [straight()], camera=FRONT, lights=SKY + "\n" + SUN, name="tinted")
    for path in (white, tinted):
        text = path.read_text().replace("background = [0.1, 0.2, 0.3]", "background = [0.0, 0.0, 0.0]")
        if path == tinted:
            text = text.replace('yarn = "cotton1"', 'yarn = "cotton1"\ncolor = [1.0, 0.5, 0.25]')
        path.write_text(text)
    no_bounce = Features(interreflection=False)
    a, b = _render(white, pack, features=no_bounce).image, _render(tinted, pack, features=no_bounce).image
    lit = a[..., 1] > 1e-3
    assert lit.sum() > 100
    np.testing.assert_allclose(b[..., 0], a[..., 0], rtol=1e-5, atol=1e-7)
    for ch, colour in ((1, 0.5), (2, 0.25)):
        assert np.all(b[..., ch][lit] <= a[..., ch][lit] * (1 + 1e-5))
        assert np.all(b[..., ch][lit] >= 0) and b[..., ch][lit].mean() > 0.25 * colour * a[..., ch][lit].mean()


def test_texture_phase_follows_the_view_azimuth_in_the_yarn_frame():
    """A yarn along +x with yarn-frame normal N = +y: seen along N (γ = 0) the texture is read at s; seen from +z
    (γ = +90°) a counter-clockwise-plied yarn is read a quarter period earlier, a clockwise one a quarter later."""

    from knitrun.render.pipeline import view_phase_arclength

    lines = SimpleNamespace(rest=np.array([0.0, 1.0]), normal=np.array([[0.0, 1.0, 0.0], [0.0, 1.0, 0.0]]))
    views = np.array([[0.0, 1.0, 0.0], [0.0, 0.0, 1.0], [0.0, -1.0, 0.0]])
    points = {"segment": np.zeros(3, np.int32), "arclength": np.full(3, 0.5, np.float32),
              "tangent": np.tile([1.0, 0.0, 0.0], (3, 1)), "view_dir": views, "yarn": np.zeros(3, np.int64)}
    for sign in (1.0, -1.0):
        look = SimpleNamespace(twist_sign=sign, period=0.2)
        s = view_phase_arclength(points, lines, [look])
        np.testing.assert_allclose(s, [0.5, 0.5 - sign * 0.05, 0.5 - sign * 0.1], atol=1e-12)


def test_a_stitch_mesh_entry_is_simulated_at_rest_and_drawn(tmp_path, pack):
    from data_formats.stitch_mesh import write_stitch_mesh
    from knitrun.sim.knit_chart import chart_to_mesh, pattern_chart

    write_stitch_mesh(tmp_path / "m.h5", chart_to_mesh(pattern_chart("stockinette", 3, 3)))
    camera = FRONT.replace("[0.0, 0.0, 1.0]", "[0.3, 0.25, 2.0]").replace("look_at = [0.0, 0.0, 0.0]",
                                                                          "look_at = [0.3, 0.25, 0.0]")
    path = write_scene(tmp_path, [straight()], camera=camera, lights=SUN)
    path.write_text(path.read_text().replace('curves = "s.h5"', 'stitch_mesh = "m.h5"'))
    result = _render(path, pack)
    assert result.facts["curves"] >= 1 and result.facts["shading_points"] > 100
    assert np.all(np.isfinite(result.image))


def test_the_flyaway_layer_skips_exactly_the_points_its_hairs_do_not_cover(tmp_path, pack, monkeypatch):
    """The coverage pass (``flyaway_coverage``) gives every flyaway point the alpha that shading it gives; the points
    it finds uncovered (the close-up camera magnifies the hair texture: many) are neither shadow-tested nor shaded,
    and every covered one is."""
    from knitrun.render import pipeline

    seen = {}
    coverage_kernel, shade_kernel = pipeline.flyaway_coverage, pipeline.shade_flyaway

    def coverage(idx, points, look, flyaway, alpha):
        coverage_kernel(idx, points, look, flyaway, alpha)
        seen["coverage"], seen["points"] = alpha, points

    def shade(idx, points, *args):
        seen["shaded"] = idx.copy()
        shade_kernel(idx, points, *args)
        everything = np.arange(len(points.v))  # shading every point gives the alpha the coverage pass found
        alpha = np.zeros(len(everything))
        shade_kernel(everything, points, *args[:-3], np.zeros((len(everything), 3)), alpha,
                     np.zeros((len(everything), 3)))
        seen["alpha"] = alpha

    monkeypatch.setattr(pipeline, "flyaway_coverage", coverage)
    monkeypatch.setattr(pipeline, "shade_flyaway", shade)
    path = write_scene(tmp_path, [straight()], camera=FRONT, lights=SUN + "\n" + SKY)
    result = _render(path, pack)
    assert np.array_equal(seen["coverage"], seen["alpha"])
    covered = np.flatnonzero(seen["coverage"] > 0.0)
    assert np.array_equal(seen["shaded"], covered)
    assert 0 < len(covered) < 0.9 * len(seen["coverage"]) and result.facts["flyaway_points_covered"] == len(covered)


def test_the_hairs_of_two_yarns_both_show_in_the_gap_between_them(tmp_path, pack):
    """``render.hair_layers``: between two parallel yarns (A nearer the camera) both flyaway strips cover the gap.
    With one layer the gap shows A's hairs alone, even where A's strip holds no hair and B's does; with two, B's
    hairs composited under A's: A alone + t_A (B alone − background), t_A A's transmittance (from A drawn over two
    backgrounds). Each yarn is drawn "alone" with the other moved out of view, so that it keeps its curve index (the
    flyaway variant hashes it), and without the neighbours' light on the hairs (``Features.hair_bounce``), which
    lights A's hairs by B where both are drawn."""
    camera = """[camera]
position = [0.0, 0.0, 1.0]
look_at = [0.0, 0.0, 0.0]
ortho_height = 0.32
width = 48
height = 64"""
    light = """[[lights]]
type = "directional"
direction = [0.0, 0.0, 1.0]
irradiance = [2.0, 2.0, 2.0]"""  # from the camera: neither yarn shadows the gap
    radius = load_scene(write_scene(tmp_path, [straight()], camera=camera, lights=light, name="probe")).yarns[0].radius
    a, b = straight(z=0.1) + [0.0, 1.5 * radius, 0.0], straight() - [0.0, 1.5 * radius, 0.0]
    away = np.array([5.0, 0.0, 0.0])

    def draw(curves, layers=1, background=(0.1, 0.2, 0.3)):
        scene = load_scene(write_scene(tmp_path, curves, camera=camera, lights=light, name="pair"))
        scene = dataclasses.replace(scene, background=background,
                                    render=dataclasses.replace(scene.render, hair_layers=layers))
        return render(scene, {"cotton1": str(pack)}, Features(hair_bounce=False)).image.astype(np.float64)

    one, two = draw([a, b]), draw([a, b], 2)
    a_alone, a_light, b_alone = draw([a, b + away]), draw([a, b + away], 1, (0.6, 0.7, 0.8)), draw([a + away, b])
    transmit_a = (a_light - a_alone) / 0.5
    y = 0.16 - (np.arange(64) + 0.5) * 0.32 / 64  # pixel centres (cm)
    half_px = 0.16 / 64
    gap = (np.abs(y) < 0.5 * radius - 1.5 * half_px)  # rows whose pixels lie off both bodies by a quarter pixel
    assert gap.sum() >= 3
    assert np.array_equal(one[gap], a_alone[gap])
    np.testing.assert_allclose(two[gap], (a_alone + transmit_a * (b_alone - (0.1, 0.2, 0.3)))[gap], atol=1e-5)
    b_hairs = np.abs(b_alone[gap] - (0.1, 0.2, 0.3)).sum(axis=-1)
    assert b_hairs.max() > 0.02 and np.abs(two[gap] - one[gap]).sum(axis=-1).max() > 0.5 * b_hairs.max()
    assert transmit_a[gap].min() < 0.95  # A's hairs are there too


def test_the_hair_cover_is_the_share_of_each_pixel_the_hairs_take(tmp_path, pack):
    """``Renderer.hair_cover`` (``benchmarks/probe_hair_coverage.py``'s strip side), two parallel yarns under the sun
    and the sky: the hairs drawn opaque and black (``Features.hair_light`` False) leave (1 − cover) of the image
    without them, in every pixel (the regular strips' shading does not depend on the hairs once the canopy is
    off); the cover lies in [0, 1], grows with ``render.hair_layers`` (the farther yarn's hairs in the gap) and is 0
    without flyaways."""
    radius = 0.03
    curves = [straight(z=0.1) + [0.0, 1.5 * radius, 0.0], straight() - [0.0, 1.5 * radius, 0.0]]
    scene = load_scene(write_scene(tmp_path, curves, camera=FRONT, lights=SUN + "\n" + SKY, name="cover"))
    packs = {"cotton1": str(pack)}

    def at(layers, features=Features(hair_canopy=False)):
        return Renderer(dataclasses.replace(scene, render=dataclasses.replace(scene.render, hair_layers=layers)),
                        packs, features)

    one, two = at(1).hair_cover(), at(2).hair_cover()
    assert one.shape == (scene.camera.height, scene.camera.width)
    assert one.min() >= 0.0 and two.max() <= 1.0 and np.all(two >= one - 1e-12)
    assert (two - one).max() > 0.05 and two.mean() > 0.02
    split = at(2, Features(hair_canopy=False, hair_light=False)).render().image.astype(np.float64)
    bare = at(2, Features(hair_canopy=False, flyaways=False)).render().image.astype(np.float64)
    np.testing.assert_allclose(split, (1.0 - two)[..., None] * bare, rtol=1e-5, atol=1e-6)
    assert not np.any(at(2, Features(flyaways=False)).hair_cover())


def test_a_hair_takes_each_kind_of_light_alone_as_beside_the_other(tmp_path, pack, monkeypatch):
    """``shade_flyaway`` with the directional lights alone (lobes of no rows) plus the lobes alone (directional lights
    of no rows, and so no glow) is the hair radiance of both together; alpha and transmittance do not depend on the
    lights."""
    from knitrun.render import pipeline

    seen = {}
    shade_kernel = pipeline.shade_flyaway

    def shade(idx, points, look, corrections, flyaway, coverage, lights, glow, lobes, im, rgb, alpha, transmit):
        shade_kernel(idx, points, look, corrections, flyaway, coverage, lights, glow, lobes, im, rgb, alpha, transmit)
        n = len(rgb)
        parts = []
        n_points = len(points.v)
        for kinds in ((lights, glow, no_lobes(n_points), im), (no_lights(n_points), no_rows(), lobes, im)):
            out = (np.zeros((n, 3)), np.zeros(n), np.zeros((n, 3)))
            shade_kernel(idx, points, look, corrections, flyaway, coverage, *kinds, *out)
            parts.append(out)
        seen.update(both=(rgb[idx], alpha[idx], transmit[idx]), parts=[[a[idx] for a in out] for out in parts])

    monkeypatch.setattr(pipeline, "shade_flyaway", shade)
    _render(write_scene(tmp_path, [straight()], camera=FRONT, lights=SUN + "\n" + SKY), pack)
    (rgb, alpha, transmit), (sun, sky) = seen["both"], seen["parts"]
    assert rgb.max() > 0 and sun[0].max() > 0 and sky[0].max() > 0
    np.testing.assert_allclose(sun[0] + sky[0], rgb, rtol=1e-12, atol=1e-15)
    for part in (sun, sky):
        assert np.array_equal(part[1], alpha) and np.array_equal(part[2], transmit)


def test_a_yarn_without_flyaways_renders_without_a_flyaway_layer(tmp_path):
    spec = load_preset("cotton1")
    spec = dataclasses.replace(spec, geometry=dataclasses.replace(spec.geometry, fibers_per_ply=15),
                               flyaways=dataclasses.replace(spec.flyaways, hair_density=0.0, loop_density=0.0))
    assert not spec.has_flyaways
    bare = tmp_path / "bare.h5"
    bake(spec, bare, overrides=TINY, seed=1, use_cache=False)  # bakes no flyaway textures
    (tmp_path / "yarn.toml").write_text(dumps_spec(spec))
    path = write_scene(tmp_path, [straight()], camera=FRONT, lights=SUN)
    path.write_text(path.read_text().replace('yarn = "cotton1"', 'yarn = "yarn.toml"'))
    result = render(load_scene(path), {"cotton1": str(bare)})
    assert result.facts["flyaway_points"] == 0 and np.all(np.isfinite(result.image))


def test_curves_drawn_off_the_radius_they_were_built_for_give_a_warning(tmp_path, pack):
    """Curves that carry their build radius and are drawn more than 5 % thicker or thinner are named in a one-line
    warning (overlap or gaps); within 5 %, or without a stored radius, there is none."""
    curves = make_yarn_curves(straight()[None], [0, 9], yarn_types=["cotton1"], units="cm")
    drawn = 0.0297328  # cotton1's radius: the scene entry's default
    assert radius_mismatch(curves, drawn, "yarns[0]") is None  # radius unknown
    for built, expected in ((drawn * 1.04, None), (drawn / 1.5, "overlap"), (drawn * 1.5, "leave gaps")):
        message = radius_mismatch(dataclasses.replace(curves, radius=built), drawn, "yarns[0]")
        assert (message is None) if expected is None else (expected in message and "yarns[0]" in message
                                                           and "\n" not in message)
    path = write_scene(tmp_path, [straight()], camera=FRONT, lights=SUN)
    assert _render(path, pack).facts["warnings"] == []
    write_yarn_curves(tmp_path / "s.h5", dataclasses.replace(curves, radius=drawn / 1.5))
    warnings = _render(path, pack).facts["warnings"]
    assert len(warnings) == 1 and "overlap" in warnings[0]


def test_lobes_of_zero_weight_are_not_drawn_and_the_fit_is_cached(tmp_path, pack, monkeypatch):
    """A black environment with a small sun is one lobe (the compact source of ``srbf_fit``) and 15 of zero weight:
    the renderer draws that one only, and a second render reads the fit from the cache
    (``knitrun.shading.srbf_cache``) and gives the same image."""
    monkeypatch.setenv("KNIT_CACHE_DIR", str(tmp_path / "cache"))
    d = texel_directions(32, 64)
    image = (d @ (np.array([0.3, 0.6, 1.0]) / np.linalg.norm([0.3, 0.6, 1.0])) > math.cos(math.radians(6.0)))[
        ..., None] * np.array([40.0, 38.0, 35.0])
    write_exr(tmp_path / "env.exr", image.astype(np.float32))
    lights = '[[lights]]\ntype = "environment"\nfile = "env.exr"'
    path = write_scene(tmp_path, [straight()], camera=FRONT, lights=lights)
    path.write_text(path.read_text().replace("srbf_count = 4", "srbf_count = 16"))
    first, again = _render(path, pack), _render(path, pack)
    fit = fit_srbf(read_exr(tmp_path / "env.exr").astype(np.float64), n_lobes=16, seed=0)
    assert first.facts["srbf_lobes"] == 16
    assert first.facts["srbf_lobes_drawn"] == int(np.any(fit.weights > 0, axis=1).sum()) == 1
    assert not first.facts["srbf_fit_cached"] and again.facts["srbf_fit_cached"]
    assert np.array_equal(first.image, again.image)


def test_multiple_scattering_cells_keep_energy_and_weigh_their_lobes():
    """``ms_lights.ms_cells``: no light lost or made, a cell's lobe weights sum to 1, a sun goes whole to one cell in
    its own direction, an unused lobe gets no weight, and ``ms_lights`` is the weights applied to the lobes'
    visibilities."""
    from knitrun.render.ms_lights import MS_CELLS, ms_cells, ms_lights

    rng = np.random.default_rng(3)
    d = rng.normal(size=(9, 3))
    d /= np.linalg.norm(d, axis=1, keepdims=True)
    lam, w = rng.uniform(1, 50, 9), rng.uniform(0.1, 1, (9, 3))
    lam[0], w[1] = 2500.0, 0.0  # a sun; an unused lobe
    dirs, irr, weights = ms_cells(d, lam, w)
    energy = w * (2 * np.pi / lam * (1 - np.exp(-2 * lam)))[:, None]
    np.testing.assert_allclose(irr.sum(axis=0), energy.sum(axis=0), rtol=1e-12)
    assert len(dirs) <= MS_CELLS and np.allclose(np.linalg.norm(dirs, axis=1), 1.0) and np.all(irr > 0)
    assert np.allclose(weights.sum(axis=1), 1.0) and np.all(weights[:, 1] == 0)
    assert (weights[:, 0] > 0).sum() == 1
    sun_dirs, sun_irr, sun_weights = ms_cells(d[:1], lam[:1], w[:1])  # a sun alone: one light, where the sun is
    assert sun_dirs.shape == (1, 3) and sun_dirs[0] @ d[0] > 1.0 - 1e-12 and np.allclose(sun_weights, 1.0)
    np.testing.assert_allclose(sun_irr[0], energy[0], rtol=1e-12)
    vis = rng.uniform(0, 1, (9, 5))
    assert np.allclose(ms_lights(d, lam, w, [vis])[2][0], weights @ vis)


def test_multiple_scattering_cells_carry_a_broad_lobes_light_from_where_it_shines():
    """A broad lobe lights a plane facing away from its centre too: the cells' irradiance on the six axis planes,
    Σ_c E_c max(0, ω_c·n), is within 6 % of the lobe's own (a quadrature of ∫ W G(ω) max(0, ω·n) dω) on each plane
    that receives at least a tenth of the brightest's, where one light at the lobe's centre leaves the side planes
    black. Splitting the lobe into two equal halves changes nothing (the lights depend on the sky, not on the fit)."""
    from knitrun.render.ms_lights import ms_cells
    from knitrun.shading.equirect import fibonacci_directions

    centre = np.array([0.3, 1.0, 0.2]) / np.linalg.norm([0.3, 1.0, 0.2])
    lam, w = np.array([0.7]), np.array([[1.0, 0.8, 0.6]])
    samples = fibonacci_directions(200_000)
    radiance = np.exp(lam[0] * (samples @ centre - 1.0))
    planes = np.vstack([np.eye(3), -np.eye(3)])
    exact = (4 * np.pi / len(samples)) * (np.maximum(samples @ planes.T, 0.0) * radiance[:, None]).sum(axis=0)
    dirs, irr, _ = ms_cells(centre[None], lam, w)
    cells = (np.maximum(dirs @ planes.T, 0.0) * irr[:, 1:2]).sum(axis=0) / w[0, 1]
    lit = exact > 0.1 * exact.max()
    assert lit.sum() >= 5
    np.testing.assert_allclose(cells[lit], exact[lit], rtol=0.06)
    halves = ms_cells(np.vstack([centre, centre]), np.repeat(lam, 2), np.vstack([w, w]) / 2)
    np.testing.assert_allclose(halves[0], dirs, atol=1e-12)
    np.testing.assert_allclose(halves[1], irr, rtol=1e-12)


def test_fiber_detail_keeps_each_rows_brightness():
    """``fiber_detail_chain``: over the covered texels of a row the detail averages to 1 (coverage-weighted), it is 1
    where nothing is covered, and it stays within [0, DETAIL_MAX]."""
    from knitrun.render.yarn_look import DETAIL_MAX, fiber_detail_chain

    rng = np.random.default_rng(5)
    ao = [rng.uniform(0.05, 1.0, (8, 32)), rng.uniform(0.05, 1.0, (4, 16))]
    cov = [np.where(rng.uniform(size=(8, 32)) < 0.3, 0.0, rng.uniform(0.2, 1.0, (8, 32))), np.zeros((4, 16))]
    detail = fiber_detail_chain(ao, cov)
    assert [d.shape for d in detail] == [(8, 32), (4, 16)] and all(d.dtype == np.float32 for d in detail)
    rows = (detail[0] * cov[0]).sum(axis=1) / cov[0].sum(axis=1)
    assert np.allclose(rows, 1.0, atol=1e-6)
    assert np.all(detail[0][cov[0] == 0] == 1.0) and np.all(detail[1] == 1.0)
    spiky = fiber_detail_chain([np.array([[1.0, 1e-4, 1e-4, 1e-4, 1e-4, 1e-4]])], [np.ones((1, 6))])[0]
    assert spiky.max() == DETAIL_MAX and spiky.min() >= 0.0


def test_the_environments_detail_is_the_ao_inter_reflected_and_softer():
    """``fiber_detail``: channel 0 is ``fiber_detail_chain`` of the AO, channel 1 that of the AO inter-reflected with
    the albedo (ao / (1 − ρ (1 − ao))), which still averages to 1 along a row but varies less; at ρ = 0 the two are
    equal."""
    from knitrun.render.yarn_look import fiber_detail, fiber_detail_chain

    rng = np.random.default_rng(6)
    ao, cov = [rng.uniform(0.1, 1.0, (8, 32))], [rng.uniform(0.3, 1.0, (8, 32))]
    stack = fiber_detail(ao, cov, 0.75)
    both = stack.data.reshape(8, 32, 2)
    np.testing.assert_allclose(both[..., 0], fiber_detail_chain(ao, cov)[0], rtol=1e-6)
    np.testing.assert_allclose(both[..., 1], fiber_detail_chain([ao[0] / (1 - 0.75 * (1 - ao[0]))], cov)[0], rtol=1e-6)
    np.testing.assert_allclose((both[..., 1] * cov[0]).sum(axis=1) / cov[0].sum(axis=1), 1.0, atol=1e-6)
    assert both[..., 1].std() < 0.6 * both[..., 0].std()
    np.testing.assert_array_equal(fiber_detail(ao, cov, 0.0).data[:, 0], fiber_detail(ao, cov, 0.0).data[:, 1])


def test_the_directional_lights_take_the_first_detail_and_the_environment_the_second():
    """``shade_regular`` with a detail texture of constant channels (a, b): the sun's radiance is a × the
    no-detail image's, the sky's (lobes and cells) b ×, and both lights together a × sun + b × sky."""
    n = 12
    tangent, view, flat, full, off = _kernel_frames(n, seed=7)
    points = Points(view, tangent, np.zeros(n), np.zeros(n), np.full(n, 1e-3), np.zeros(n, np.int64), np.zeros((n, 3)),
                    np.ones(n))
    table = im.bake_im_table(ROUGH, TEST_SHAPE, nodes=4)[0]
    i_m = im_table_from(table, im.im_axes(TEST_SHAPE))
    fit = fit_srbf(sky_image(32, 64), n_lobes=4, seed=0)
    look = Look(ROUGH, np.stack([np.full((4, 3), x) for x in (0.7, 0.2, 0.3, 0.1, 0.3)]), 1.0, 1.0, 1.0, 0.0, 0.0,
                0.0, 0.0, D_F, D_B)
    sun = Lights(np.array([[0.0, 0.6, 0.8]]), np.full((1, 3), 2.0), np.ones((1, n)), np.zeros((1, 0)))
    cells = Lights(np.array([[0.0, 0.0, 1.0], [0.6, 0.8, 0.0]]), np.full((2, 3), 0.5), np.ones((2, n)),
                   np.zeros((2, 0)))

    def shaded(detail, directional, environment):
        rgb, alpha = np.zeros((n, 3)), np.zeros(n)
        sky = (Lobes(fit.directions, fit.sharpness, fit.weights, np.ones((4, n)), np.zeros(4)), cells,
               im_slices(i_m, fit.sharpness)) if environment else _no_environment(n)
        shade_regular(np.arange(n), points, look, off, flat, full, detail, sun if directional else no_lights(n), *sky,
                      no_rows(), rgb, alpha)
        return rgb

    def constant(a, b):
        return mip_stack([[np.dstack([np.full((1, 1), a), np.full((1, 1), b)])]])

    plain_sun, plain_sky = shaded(no_detail(), True, False), shaded(no_detail(), False, True)
    assert plain_sun.max() > 0 and plain_sky.max() > 0
    np.testing.assert_allclose(shaded(constant(2.0, 3.0), True, False), 2.0 * plain_sun, rtol=1e-12)
    np.testing.assert_allclose(shaded(constant(2.0, 3.0), False, True), 3.0 * plain_sky, rtol=1e-12)
    np.testing.assert_allclose(shaded(constant(2.0, 3.0), True, True), 2.0 * plain_sun + 3.0 * plain_sky,
                               rtol=1e-10, atol=1e-14)


def test_a_uniform_ao_texture_leaves_the_image_as_without_detail(tmp_path, pack):
    """Detail is the AO texture's variation only: a pack whose AO is one value renders exactly as without detail."""
    import shutil

    import h5py

    flat_pack = tmp_path / "flat_ao.h5"
    shutil.copy(pack, flat_pack)
    with h5py.File(flat_pack, "r+") as f:
        for name in f["textures/ao"]:
            f[f"textures/ao/{name}"][...] = 0.7
    path = write_scene(tmp_path, [straight(), straight(z=-0.1) + [0, 0.03, 0]], camera=FRONT, lights=SUN)
    with_detail = _render(path, flat_pack).image
    without = _render(path, flat_pack, features=Features(fiber_detail=False)).image
    assert np.array_equal(with_detail, without)
    textured = _render(path, pack).image  # the tiny pack's own AO does move the image
    assert np.abs(textured - _render(path, pack, features=Features(fiber_detail=False)).image).max() > 1e-3


def test_the_view_closed_xi_lookup_is_quadrilinear_on_the_table_grid():
    """``strip_shading._table_v4`` (the lookup of ``correction/xi_view``) against a direct evaluation: the table
    value at a bin centre, the mean of the two neighbours halfway along each axis, clamped in v and θ, wrapped in φ,
    and exact for a function linear in every axis."""
    from data_formats.conventions import THETA_RANGE, cell_centres
    from knitrun.render.strip_shading import _table_v4

    n_v, n_t, n_p = 4, 6, 8
    rng = np.random.default_rng(11)
    tab = rng.uniform(0.5, 2.0, (n_v, n_t, n_t, n_p, 3))
    vs, ts, ps = cell_centres(-1.0, 1.0, n_v), cell_centres(*THETA_RANGE, n_t), cell_centres(-np.pi, np.pi, n_p)
    out = np.empty(3)
    _table_v4(tab, vs[1], ts[2], ts[4], ps[5], out)
    assert np.allclose(out, tab[1, 2, 4, 5])
    _table_v4(tab, vs[1], 0.5 * (ts[2] + ts[3]), ts[4], ps[5], out)  # halfway along θ_i
    assert np.allclose(out, 0.5 * (tab[1, 2, 4, 5] + tab[1, 3, 4, 5]))
    _table_v4(tab, vs[1], ts[2], 0.5 * (ts[0] + ts[1]), ps[5], out)  # halfway along θ_o
    assert np.allclose(out, 0.5 * (tab[1, 2, 0, 5] + tab[1, 2, 1, 5]))
    _table_v4(tab, vs[1], ts[2], ts[4], np.pi - 1e-9, out)  # φ wraps: halfway between the last and the first
    assert np.allclose(out, 0.5 * (tab[1, 2, 4, n_p - 1] + tab[1, 2, 4, 0]))
    _table_v4(tab, 5.0, -4.0, 4.0, ps[2], out)  # v and θ clamp
    assert np.allclose(out, tab[n_v - 1, 0, n_t - 1, 2])
    a, b, c = rng.normal(size=3)  # linear in v, θ_i, θ_o: exact between centres
    linear = (a * vs[:, None, None, None] + b * ts[None, :, None, None] + c * ts[None, None, :, None]
              + np.zeros((1, 1, 1, n_p)))[..., None] * np.ones(3)
    v, ti, to = 0.3 * vs[1] + 0.7 * vs[2], 0.2 * ts[1] + 0.8 * ts[2], 0.6 * ts[3] + 0.4 * ts[4]
    _table_v4(linear, v, ti, to, 0.1, out)
    assert np.allclose(out, a * v + b * ti + c * to)
