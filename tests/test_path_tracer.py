"""Path tracer against analytic answers: furnace, a single fiber under directional and uniform light, 1/√spp
convergence, determinism across thread counts and batching; each analytic case for both geometries (fibers as
Embree curves traced by whole paths, and the tessellated tubes traced by waves), and the two against each other."""

import math

import numba
import numpy as np
import pytest

from data_formats.yarn_spec import load_preset
from knitbake.fibers.fiber_set import FiberSet
from knitbake.fibers.procedural_yarn import generate_fibers
from knitbake.fibers.tessellate import tessellate_fibers
from knitbake.trace.env_light import env_from_image, env_pdf, env_sample, uniform_env
from knitbake.trace.embree_curves import CurveScene
from knitbake.trace.path_tracer import Camera, TracerScene, render, render_samples
from knitrun.shading import equirect
from knitrun.shading import fiber_bcsdf as fb
from knitrun.shading.builtin_sky import sky_image
from tests.chi2 import chi2_pvalue
from tests.helpers import DEG

LOSSLESS = fb.params_from_values([0.3] * 3, [0.6] * 3, [0.1] * 3, 5 * DEG, 10 * DEG, 25 * DEG, -3 * DEG, 1.5 * DEG)
ABSORBING = fb.params_from_values([0.05, 0.1, 0.2], [0.3, 0.5, 0.6], [0.05, 0.05, 0.1], 4 * DEG, 12 * DEG,
                                  30 * DEG)


GEOMETRIES = ["curves", "tubes"]


def traced(fibers, geometry, params, sides=32, **kw):
    """A TracerScene of ``fibers`` (one yarn type) as curves or as tubes of ``sides`` sides."""
    types = np.zeros(fibers.n_fibers, np.int32)
    if geometry == "curves":
        return TracerScene(None, types, params[None], fibers=fibers, **kw)
    return TracerScene(tessellate_fibers(fibers, sides=sides), types, params[None], **kw)


def straight_fibers(radius=0.1, length=4.0):
    pts = np.array([[-length / 2, 0, 0], [length / 2, 0, 0.0]])
    return FiberSet(pts, np.array([0, 2]), np.array([radius]), np.zeros(1, np.int8), np.zeros(1, np.int16))


def straight_fiber(radius=0.1, length=4.0, sides=32):
    return tessellate_fibers(straight_fibers(radius, length), sides=sides)


def top_camera(width=64, height=32, ortho=1.0):
    return Camera(np.array([0, 0, 5.0]), np.zeros(3), np.array([0, 1, 0.0]), width, height, ortho_height=ortho)


def yarn_scene(params=LOSSLESS, geometry="tubes", **lights):
    spec = load_preset("cotton1")
    return traced(generate_fibers(spec, seed=0, flyaways=False), geometry, params, sides=6, **lights)


def yarn_camera(spec_radius=0.03, period=0.45, size=32):
    """Side view of the cotton1 period (yarn along z), orthographic, framing the middle of the yarn."""
    return Camera(np.array([1.0, 0.0, period / 2]), np.array([0.0, 0.0, period / 2]), np.array([0, 0, 1.0]), size,
                  size, ortho_height=2.4 * spec_radius)


@pytest.mark.parametrize("geometry", GEOMETRIES)
def test_furnace_yarn_in_uniform_environment(geometry):
    """Non-absorbing fibers under a uniform environment return its radiance (multiple scattering included)."""
    scene = yarn_scene(geometry=geometry, env=uniform_env([1.0, 1.0, 1.0]))
    img, _ = render(scene, yarn_camera(), spp=64, max_depth=64, seed=1)
    assert abs(img.mean() - 1.0) < 0.025
    assert np.all(np.isfinite(img))


@pytest.mark.parametrize("geometry", GEOMETRIES)
def test_single_fiber_uniform_environment_returns_albedo(geometry):
    """A convex fiber under a uniform environment: every pixel on it is albedo × L exactly (one scattering)."""
    scene = traced(straight_fibers(), geometry, ABSORBING, env=uniform_env([2.0, 2.0, 2.0]), background=np.zeros(3))
    img, _ = render(scene, top_camera(), spp=256, seed=2)
    on_fiber = img[13:19]  # rows entirely inside the fiber (|y| < 0.094 for radius 0.1)
    albedo = np.array([0.4, 0.65, 0.9])
    np.testing.assert_allclose(on_fiber.mean(axis=(0, 1)), 2.0 * albedo, rtol=0.02)


@pytest.mark.parametrize("geometry", GEOMETRIES)
@pytest.mark.parametrize("light_deg", [20.0, 60.0, 85.0])
def test_single_fiber_directional_light_against_direct_integration(light_deg, geometry):
    """Image integral of a fiber lit by a directional light = f(ω_i, ω_o) cos θ_i E × projected area."""
    radius = 0.1
    light = np.array([math.sin(light_deg * DEG) * 0.6, math.sin(light_deg * DEG) * 0.8, math.cos(light_deg * DEG)])
    light_local = np.array([light[0], light[1], light[2]])  # fiber frame: x tangent; (y, z) normal plane
    irradiance = np.array([1.0, 2.0, 3.0])
    scene = traced(straight_fibers(radius), geometry, ABSORBING, light_dirs=light[None],
                   light_irradiance=irradiance[None])
    cam = top_camera(width=64, height=32, ortho=1.0)
    img, _ = render(scene, cam, spp=64, seed=3)
    pixel_area = (1.0 / 32) ** 2
    visible_length = 2.0  # the camera sees x in [−1, 1]
    measured = img.sum(axis=(0, 1)) * pixel_area
    f = fb.eval_batch(ABSORBING, np.array([[0.0, 0.0, 1.0]]), light_local[None])[0]
    cos_i = math.sqrt(1 - light_local[0] ** 2)
    expected = f * cos_i * irradiance * 2 * radius * visible_length
    np.testing.assert_allclose(measured, expected, rtol=0.01)


def test_error_falls_like_inverse_sqrt_spp():
    env_img = np.ones((16, 32, 3)) * 0.2
    env_img[2:5, 10:14] = 40.0  # a small bright "sun": noisy NEE and BCSDF sampling
    scene = yarn_scene(ABSORBING, env=env_from_image(env_img))
    cam = yarn_camera(size=24)
    reference, _ = render(scene, cam, spp=1024, seed=100)
    spps = [4, 16, 64, 256]
    errors = []
    for spp in spps:
        rmse = [np.sqrt(((render(scene, cam, spp=spp, seed=s)[0] - reference) ** 2).mean()) for s in (1, 2)]
        errors.append(np.mean(rmse))
    slope = np.polyfit(np.log(spps), np.log(errors), 1)[0]
    assert -0.62 < slope < -0.38, (errors, slope)


def test_deterministic_across_threads_and_batching():
    scene = yarn_scene(ABSORBING, env=uniform_env([1.0, 0.5, 0.2]), light_dirs=np.array([[1.0, 0.3, 0.2]]),
                       light_irradiance=np.array([[2.0, 2.0, 2.0]]))
    cam = yarn_camera(size=16)
    before = numba.get_num_threads()
    try:
        numba.set_num_threads(1)
        scene.ray_scene.threads = 1
        a, _ = render(scene, cam, spp=8, seed=5, samples_per_pass=8)
        numba.set_num_threads(before)
        scene.ray_scene.threads = 2
        b, _ = render(scene, cam, spp=8, seed=5, samples_per_pass=3)
    finally:
        numba.set_num_threads(before)
    assert np.array_equal(a, b)
    c, _ = render(scene, cam, spp=8, seed=6)
    assert not np.array_equal(a, c)


def test_environment_sampling_pdf_is_consistent():
    rng = np.random.default_rng(0)
    img = rng.random((8, 16, 3)) ** 4 * 10
    env = env_from_image(img)
    out = np.empty(3)
    for _ in range(200):
        pdf = env_sample(env.radiance, env.row_cdf, env.col_cdf, env.pixel_prob, *rng.random(4), out)
        assert pdf == pytest.approx(env_pdf(env.radiance, env.pixel_prob, out), rel=1e-9)
    # the pdf integrates to 1 over the sphere
    n = 400
    theta = (np.arange(n) + 0.5) * np.pi / n
    phi = (np.arange(2 * n) + 0.5) * np.pi / n - np.pi
    d = np.empty(3)
    total = 0.0
    for t in theta:
        for p in phi[::8]:
            equirect.direction(t, p, d)
            total += env_pdf(env.radiance, env.pixel_prob, d) * math.sin(t)
    total *= (np.pi / n) * (np.pi / n * 8)
    assert total == pytest.approx(1.0, rel=0.01)


def _env_directions(env, n, rng):
    """``n`` directions drawn by ``env_sample``, as (N, 3) in the χ² helper's frame (polar axis +y: (y, z, x))."""
    out = np.empty((n, 3))
    for k, u in enumerate(rng.random((n, 4))):
        env_sample(env.radiance, env.row_cdf, env.col_cdf, env.pixel_prob, *u, out[k])
    return out[:, [1, 2, 0]]


def _env_pdf(env):
    """``env_pdf`` of directions given in the χ² helper's frame."""
    return lambda d: np.array([env_pdf(env.radiance, env.pixel_prob, np.ascontiguousarray(x[[2, 0, 1]])) for x in d])


def test_chi2_environment_sampling_matches_its_pdf():
    """χ² (tests/chi2.py) of ``env_sample`` against ``env_pdf`` on the built-in sky (a sun texel 10⁴× the sky, a
    gradient, the ground), one bin per texel; and the test's power: samples drawn from another image's distribution
    are rejected."""
    env = env_from_image(sky_image(16, 32))
    bins = {"n_theta": 16, "n_phi": 32, "sub": 4}
    rng = np.random.default_rng(5)
    assert chi2_pvalue(_env_directions(env, 100_000, rng), _env_pdf(env), **bins) > 0.01
    flipped = env_from_image(sky_image(16, 32)[::-1])  # sky below, sun under the horizon
    assert chi2_pvalue(_env_directions(flipped, 100_000, rng), _env_pdf(env), **bins) < 1e-6


def test_bad_render_settings():
    scene = TracerScene(straight_fiber(), np.zeros(1, np.int32), LOSSLESS[None])
    with pytest.raises(ValueError, match="spp"):
        render(scene, top_camera(), spp=0)
    with pytest.raises(ValueError, match="direction"):
        TracerScene(straight_fiber(), np.zeros(1, np.int32), LOSSLESS[None], light_dirs=np.zeros((1, 3)),
                    light_irradiance=np.ones((1, 3)))
    with pytest.raises(ValueError, match="one geometry"):
        TracerScene(straight_fiber(), np.zeros(1, np.int32), LOSSLESS[None], fibers=straight_fibers())
    with pytest.raises(ValueError, match="one geometry"):
        TracerScene(None, np.zeros(1, np.int32), LOSSLESS[None])
    with pytest.raises(RuntimeError, match="commit"):  # a scene built in two steps is not traced half-built
        CurveScene(straight_fibers(), commit=False).handle


def test_yarn_only_mode_drops_scattering_off_other_yarns():
    """With yarn_only_radius, a neighbour outside the cylinder adds no light: the image equals the image of the yarn
    alone (same seeds); without the mode the neighbour's bounce light shows."""
    def fiber(x):
        return FiberSet(np.array([[x, 0, -2.0], [x, 0, 2.0]]), np.array([0, 2]), np.array([0.1]),
                        np.zeros(1, np.int8), np.zeros(1, np.int16))

    two = FiberSet(np.r_[fiber(0.0).points, fiber(0.5).points], np.array([0, 2, 4]), np.array([0.1, 0.1]),
                   np.zeros(2, np.int8), np.zeros(2, np.int16))
    light = dict(light_dirs=np.array([[0.0, 1.0, 0.0]]), light_irradiance=np.array([[1.0, 1.0, 1.0]]))
    cam = Camera(np.array([0.0, 3.0, 0.0]), np.zeros(3), np.array([0, 0, 1.0]), 24, 24, ortho_height=0.4)
    alone = TracerScene(tessellate_fibers(fiber(0.0), sides=12), np.zeros(1, np.int32), LOSSLESS[None], **light)
    pair = TracerScene(tessellate_fibers(two, sides=12), np.zeros(2, np.int32), LOSSLESS[None], **light)
    a, _ = render(alone, cam, spp=16, seed=9, yarn_only_radius=0.2)
    b, _ = render(pair, cam, spp=16, seed=9, yarn_only_radius=0.2)
    c, _ = render(pair, cam, spp=16, seed=9)
    assert np.array_equal(a, b)
    assert c.sum() > a.sum() * 1.01


def test_without_light_between_yarns_a_path_ends_at_another_yarn():
    """``own_yarn`` (the reference's ``inter_yarn=False``): two parallel fibers, two yarns, lit and seen from above.
    Ending the paths that scatter off the other yarn only removes light: per pixel never brighter than the full
    image with the same seeds, darker in all, and the same image bit for bit when both fibers are one yarn (no path
    changes yarn); the tubes' tracer refuses it."""
    def fiber(x):
        return FiberSet(np.array([[x, -2.0, 0.0], [x, 2.0, 0.0]]), np.array([0, 2]), np.array([0.1]),
                        np.zeros(1, np.int8), np.zeros(1, np.int16))

    two = FiberSet(np.r_[fiber(0.0).points, fiber(0.25).points], np.array([0, 2, 4]), np.array([0.1, 0.1]),
                   np.zeros(2, np.int8), np.zeros(2, np.int16))
    light = dict(light_dirs=np.array([[0.3, 0.0, 1.0]]), light_irradiance=np.array([[1.0, 1.0, 1.0]]))
    scene = traced(two, "curves", LOSSLESS, **light)
    cam = top_camera(32, 32, ortho=0.8)
    full, _ = render(scene, cam, spp=16, seed=4)
    sigma = np.array([0.0, 4.0, 0.0, 4.0])  # rest arc length of the fiber points along their yarn

    def own(yarns, sigma=sigma, reach=10.0):
        return render_samples(scene, cam, 0, 16, seed=4, own_yarn=(np.array(yarns), sigma, reach))[0] / 16

    apart, together = own([0, 1]), own([0, 0])
    assert np.all(apart <= full + 1e-12) and apart.sum() < 0.98 * full.sum()
    assert np.array_equal(together, full)
    # one yarn that loops back: its other leg is more than the reach of arc length away, so it counts as another
    assert np.array_equal(own([0, 0], sigma=np.array([0.0, 4.0, 20.0, 24.0])), apart)
    with pytest.raises(ValueError, match="curves"):
        render_samples(traced(two, "tubes", LOSSLESS, **light), cam, 0, 1, own_yarn=(np.array([0, 1]), sigma, 1.0))


def test_a_reference_without_light_between_yarns(tmp_path):
    """``trace_reference(inter_yarn=False)`` on two crossing yarns of a scene: each fiber carries its curve's yarn,
    the image is nowhere brighter than the full reference with the same seeds and darker in all, the facts say so."""
    from data_formats.scene import load_scene
    from knitbake.trace.reference import build_reference, trace_reference
    from tests.helpers import FRONT, SUN, straight, write_scene

    crossing = [straight(z=0.0), straight(z=0.07)[:, [1, 0, 2]]]
    scene = load_scene(write_scene(tmp_path, crossing, camera=FRONT, lights=SUN))
    built = build_reference(scene, own_yarn=True)
    yarn, sigma, reach = built.own_yarn
    assert build_reference(scene).own_yarn is None
    assert sorted(np.unique(yarn)) == [0, 1] and len(yarn) == built.facts["fibers"]
    assert len(sigma) == built.facts["segments"] + built.facts["fibers"]  # a σ per fiber point
    assert 0.0 <= sigma.min() and sigma.max() <= 0.6 + 1e-9 and reach > 0.0  # the 0.6 long straight yarns
    full, facts = trace_reference(scene, 4, seed=2)
    alone, alone_facts = trace_reference(scene, 4, seed=2, inter_yarn=False)
    assert "inter_yarn" not in facts and alone_facts["inter_yarn"] is False
    assert np.all(alone <= full + 1e-6) and alone.sum() < full.sum()


def test_a_reference_without_its_flyaways_keeps_the_same_regular_fibers(tmp_path):
    """``trace_reference(flyaways=False)``: the loop and hair fibers of the same draw dropped, the regular ones kept
    point for point; the image differs from the full one (the flyaways' light) and the facts say so; the diagnostic
    does not combine with ``own_yarn`` (one-line error)."""
    from data_formats.scene import load_scene
    from knitbake.fibers.fiber_set import KIND_REGULAR
    from knitbake.trace import reference
    from tests.helpers import FRONT, SUN, straight, write_scene

    scene = load_scene(write_scene(tmp_path, [straight()], camera=FRONT, lights=SUN))
    drawn = []
    sweep = reference.sweep_fibers

    def recorded(*args, **kwargs):
        drawn.append(sweep(*args, **kwargs))
        return drawn[-1]

    reference.sweep_fibers = recorded
    try:
        full, bare = reference.build_reference(scene, seed=3), reference.build_reference(scene, seed=3, flyaways=False)
    finally:
        reference.sweep_fibers = sweep
    regular = drawn[0].kind == KIND_REGULAR
    assert 0 < regular.sum() < len(regular)  # cotton1 has flyaways to drop
    assert bare.facts["fibers"] == regular.sum() and full.facts["fibers"] == len(regular)
    kept = drawn[1].select(regular)
    assert np.array_equal(kept.points, drawn[0].select(regular).points)
    with pytest.raises(ValueError, match="do not combine"):
        reference.build_reference(scene, own_yarn=True, flyaways=False)
    image, facts = reference.trace_reference(scene, 2, seed=3, flyaways=False)
    assert facts["flyaways"] is False and facts["fibers"] == regular.sum()
    assert not np.allclose(image, reference.trace_reference(scene, 2, seed=3)[0])


def test_light_by_the_surface_seen_first_splits_the_image():
    """``first_seen``: two parallel fibers of two types, lit and seen from above, the second beside the first and
    lower, so each blocks and lights the other. The images of complementary masks hold the same paths and random
    numbers: they sum to the full image, each is nowhere brighter than it and each holds light; a mask of the wrong
    length and the tubes' tracer are refused with one line."""
    two = FiberSet(np.array([[0.0, -2.0, 0.0], [0.0, 2.0, 0.0], [0.12, -2.0, -0.15], [0.12, 2.0, -0.15]]),
                   np.array([0, 2, 4]), np.array([0.1, 0.1]), np.zeros(2, np.int8), np.zeros(2, np.int16))
    light = dict(light_dirs=np.array([[0.3, 0.0, 1.0]]), light_irradiance=np.array([[1.0, 1.0, 1.0]]))
    scene = TracerScene(None, np.array([0, 1], np.int32), np.stack([LOSSLESS, LOSSLESS]), fibers=two, **light)
    cam = top_camera(32, 32, ortho=0.8)

    def seen(mask):
        return render_samples(scene, cam, 0, 8, seed=5, first_seen=mask)[0]

    full, first, second = seen(None), seen([True, False]), seen([False, True])
    assert np.allclose(first + second, full, rtol=1e-12, atol=1e-12)
    for part in (first, second):
        assert np.all(part <= full + 1e-12) and 0.05 * full.sum() < part.sum() < 0.95 * full.sum()
    assert np.array_equal(seen([True, True]), full)
    with pytest.raises(ValueError, match="2 fiber types"):
        seen([True])
    tubes = TracerScene(tessellate_fibers(two, sides=8), np.array([0, 1], np.int32), np.stack([LOSSLESS, LOSSLESS]),
                        **light)
    with pytest.raises(ValueError, match="curves"):
        render_samples(tubes, cam, 0, 1, first_seen=[True, False])


def test_a_reference_split_by_the_surface_seen_first(tmp_path):
    """``trace_reference(seen=...)`` on a yarn with flyaways: the flyaways trace as a type of their own with the same
    optics, the regular and the flyaway parts sum to the full reference with the same seeds (each holds the background
    where camera rays miss), the flyaways' part holds light, and the facts say which part; an unknown ``seen`` is refused with one line."""
    from data_formats.errors import FormatError
    from data_formats.scene import load_scene
    from knitbake.trace.reference import build_reference, trace_reference
    from tests.helpers import FRONT, SUN, straight, write_scene

    scene = load_scene(write_scene(tmp_path, [straight()], camera=FRONT, lights=SUN))
    built = build_reference(scene, seed=3, seen="regular")
    assert built.first_seen.tolist() == [True, False]
    assert np.array_equal(built.tracer.params[0], built.tracer.params[1])
    assert sorted(np.unique(built.tracer.fiber_type)) == [0, 1]
    full, facts = trace_reference(scene, 2, seed=3)
    regular, regular_facts = trace_reference(scene, 2, seed=3, seen="regular")
    hairs, hair_facts = trace_reference(scene, 2, seed=3, seen="flyaways")
    assert "seen" not in facts and regular_facts["seen"] == "regular" and hair_facts["seen"] == "flyaways"
    # every part holds the background where camera rays miss: the parts sum to the full image plus a fraction m of
    # the background (0.1, 0.2, 0.3) per pixel, the share of its samples that missed
    missed = (regular + hairs - full) / np.array([0.1, 0.2, 0.3])
    assert np.allclose(missed, missed[..., :1], atol=1e-5) and missed.min() > -1e-5 and missed.max() < 1 + 1e-5
    assert missed.max() > 0.5 and missed.min() < 1e-5  # the yarn and the background are both in view
    hair_light, regular_light = full - regular, full - hairs  # the light leaving each kind of fiber
    assert 0.02 < hair_light.sum() / (hair_light + regular_light).sum() < 0.6 and regular_light.min() > -1e-6
    with pytest.raises(FormatError, match="seen 'hair'"):
        build_reference(scene, seen="hair")


def test_curves_are_deterministic_across_threads_and_batching():
    scene = yarn_scene(ABSORBING, geometry="curves", env=uniform_env([1.0, 0.5, 0.2]),
                       light_dirs=np.array([[1.0, 0.3, 0.2]]), light_irradiance=np.array([[2.0, 2.0, 2.0]]))
    cam = yarn_camera(size=16)
    before = numba.get_num_threads()
    try:
        numba.set_num_threads(1)
        a, stats = render(scene, cam, spp=8, seed=5, samples_per_pass=8)
        numba.set_num_threads(before)
        b, _ = render(scene, cam, spp=8, seed=5, samples_per_pass=3)
    finally:
        numba.set_num_threads(before)
    assert np.array_equal(a, b) and stats.rays > 8 * 16 * 16
    assert not np.array_equal(a, render(scene, cam, spp=8, seed=6)[0])


def test_curves_and_tubes_give_the_same_yarn():
    """The cotton1 period under a sky with a sun, seen from the side, traced as curves and as tubes (the tubes are
    hexagons of the perimeter-fit radius, the curves exact): mean radiance within 2 %, and pixel-wise within the
    noise of 64 spp at the yarn's scale (4 × 4 blocks)."""
    env_img = np.ones((16, 32, 3)) * 0.3
    env_img[3:5, 10:13] = 30.0
    kw = dict(env=env_from_image(env_img), light_dirs=np.array([[1.0, 0.2, 0.3]]),
              light_irradiance=np.array([[1.0, 1.0, 1.0]]))
    cam = yarn_camera(size=32)
    curves, _ = render(yarn_scene(ABSORBING, geometry="curves", **kw), cam, spp=64, seed=11)
    tubes, _ = render(yarn_scene(ABSORBING, geometry="tubes", **kw), cam, spp=64, seed=11)
    assert abs(curves.mean() / tubes.mean() - 1.0) < 0.02
    block = lambda im: im.reshape(8, 4, 8, 4, 3).mean(axis=(1, 3))  # noqa: E731
    assert np.abs(block(curves) - block(tubes)).mean() / block(tubes).mean() < 0.1
