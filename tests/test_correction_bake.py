"""Correction and shadowing bakes: the rank-1 factorization, DS against the path tracer on a fiber slab, and the
shadowing table's physics (lit side visible, back side shadowed)."""

import math

import numpy as np
import pytest

from data_formats.conventions import cell_centres
from data_formats.yarn_spec import load_preset
from knitbake.fibers.fiber_set import FiberSet
from knitbake.fibers.tessellate import tessellate_fibers
from knitbake.stages import correction as cb
from knitbake.stages.ds_precompute import precompute_dual_scattering
from knitbake.trace.path_tracer import Camera, TracerScene, render
from knitrun.shading import fiber_bcsdf as fb
from tests.helpers import DEG



def test_factor_rank1_recovers_a_product_and_reports_residual():
    rng = np.random.default_rng(0)
    a = rng.uniform(0.5, 2, (3, 4, 3))
    c = rng.uniform(0.5, 2, (3, 5, 3))
    x = a[:, :, None, :] * c[:, None, :, :]
    fa, fc, by_v, total = cb.factor_rank1(x)
    np.testing.assert_allclose(fa[:, :, None] * fc[:, None], x, rtol=1e-10)
    np.testing.assert_allclose(fc.mean(axis=1), 1.0, rtol=1e-12)
    assert total < 1e-10 and np.all(by_v < 1e-10)
    noisy = x * rng.uniform(0.8, 1.2, x.shape)
    assert cb.factor_rank1(noisy)[3] > 0.02


def test_weighted_factorization_ignores_an_outlier_of_zero_weight():
    rng = np.random.default_rng(1)
    a = rng.uniform(0.5, 2, (2, 6, 3))
    c = rng.uniform(0.5, 2, (2, 8, 3))
    x = a[:, :, None, :] * c[:, None, :, :]
    spiked = x.copy()
    spiked[:, 0, 0] *= 20.0  # one cell whose DS denominator was tiny: a huge, meaningless ratio
    weight = np.ones_like(x)
    weight[:, 0, 0] = 0.0
    fa, fc, _, _ = cb.factor_rank1(spiked, weight)
    product = fa[:, :, None] * fc[:, None]
    np.testing.assert_allclose(product[:, 1:], x[:, 1:], rtol=1e-6)  # every other cell exact
    plain = cb.factor_rank1(spiked)
    assert np.abs(plain[0][:, :, None] * plain[1][:, None] - x)[:, 1:].max() > 0.1  # the unweighted fit is pulled


def slab(layers=3, per_layer=24, radius=0.01, spacing=0.025, length=2.0):
    """Parallel straight fibers along z in ``layers`` planes x = −k·spacing, packed along y."""
    pts, offs = [], [0]
    for k in range(layers):
        for j in range(per_layer):
            y = (j - per_layer / 2 + 0.5 * (k % 2)) * spacing
            pts += [[-k * spacing, y, -length / 2], [-k * spacing, y, length / 2]]
            offs.append(len(pts))
    n = len(offs) - 1
    return FiberSet(np.array(pts, float), np.array(offs), np.full(n, radius), np.zeros(n, np.int8),
                    np.zeros(n, np.int16))


@pytest.mark.parametrize("light_deg", [20.0, 50.0])
def test_dual_scattering_on_a_fiber_slab_against_the_path_tracer(light_deg):
    """A 3-layer slab of parallel fibers (the layered geometry DS assumes) lit from the front: the DS estimate of
    the front view agrees with multiple-scattering path tracing within 25 %."""
    params = fb.params_from_values([0.1] * 3, [0.6] * 3, [0.2] * 3, 6 * DEG, 12 * DEG, 30 * DEG)
    ds = {k: v[0] for k, v in precompute_dual_scattering(params, n_theta=32).items()}
    light = np.array([math.cos(light_deg * DEG), math.sin(light_deg * DEG) * 0.6, math.sin(light_deg * DEG) * 0.8])
    mesh = tessellate_fibers(slab(), sides=8)
    geometry = TracerScene(mesh, np.zeros(mesh.tube_radius.size, np.int32), params[None])
    lit = TracerScene(mesh, geometry.fiber_type, geometry.params, light_dirs=light[None],
                      light_irradiance=np.ones((1, 3)), ray_scene=geometry.ray_scene)
    cam = Camera(np.array([2.0, 0.0, 0.0]), np.zeros(3), np.array([0, 0, 1.0]), 32, 32, ortho_height=0.3)
    traced, _ = render(lit, cam, 32, seed=1, max_depth=32)
    ds_img = cb._ds_image(geometry, cam, light, 32, 1, ds, params)
    ratio = traced.sum(axis=(0, 1)) / ds_img.sum(axis=(0, 1))
    print(f"slab, light {light_deg} deg: path traced / DS = {ratio.round(3).tolist()}")
    assert np.all(np.abs(ratio - 1) < 0.25), ratio


def test_shadowing_sees_the_lit_side_and_not_the_back():
    spec = load_preset("cotton1")
    tables, errors = cb.bake_shadowing(spec, n_v=4, n_theta=2, n_phi=4, rows=8, spp=1, batches=2, seed=0)
    psi = tables["shadowing/psi_GM"][:, :, None, 0] * tables["shadowing/psi_GN"][:, None, :, 0]
    phis = cell_centres(-math.pi, math.pi, 4)
    front = np.abs(phis) < math.pi / 2  # light from the camera's side
    assert psi[:, :, front].mean() > 2 * psi[:, :, ~front].mean()
    assert np.all((psi >= 0) & (psi <= 1.5)) and all(np.all(np.isfinite(e)) for e in errors.values())


@pytest.mark.parametrize("theta_deg", [0.0, 11.25, -33.75, 56.25, -78.75, 87.0])
def test_the_strip_camera_starts_its_rays_outside_the_yarn(theta_deg):
    """An orthographic ray starts on the image plane: an oblique view must not put that plane through the yarn, or
    its rays begin inside the fibers and the bake sees the yarn cut open (every correction bin with |θ_d| ≳ 28°
    did, for cotton1)."""
    from knitbake.fibers.procedural_yarn import generate_fibers
    from knitbake.trace.path_tracer import camera_rays
    from knitrun.render.camera import tan_half_fov

    spec = load_preset("cotton1")
    fibers = generate_fibers(spec, flyaways=False)
    extent = np.hypot(fibers.points[:, 0], fibers.points[:, 1]).max() + fibers.radius.max()
    cam = cb.strip_camera(spec, math.radians(theta_deg), 16)
    fwd, right, up = cam.basis()
    org, dirs = np.empty((cam.width * cam.height, 3)), np.empty((cam.width * cam.height, 3))
    camera_rays(np.asarray(cam.position, float), fwd, right, up, cam.width, cam.height, tan_half_fov(cam),
                float(cam.ortho_height), 0, 0, 1, org, dirs)
    assert np.hypot(org[:, 0], org[:, 1]).min() > extent
    # the rays still cross the axis plane over the framed period (the width is rounded up to whole pixels)
    t = -org[:, 0] / dirs[:, 0]
    z = org[:, 2] + t * dirs[:, 2]
    pixel = 2 * spec.radius / cam.height / math.cos(math.radians(theta_deg))
    assert -pixel < z.min() < pixel and -pixel < z.max() - spec.geometry.ply_pitch < pixel


def test_the_bake_traces_paths_as_long_as_the_references():
    """Every trace the bake closes on (the correction stage, the closure, the yarn hull) follows paths as long as the
    references' (the scene format's default ``render.max_depth``): at 16 events, the bake's until stop 66, a
    knitted course of cotton1 kept 5 % less multiple scattering than its reference (BENCHMARKS.md, "Issue 13: the
    bake's paths as long as the reference's")."""
    import inspect

    from data_formats.scene import RENDER_FIELDS
    from knitbake.stages import closure, yarn_hull
    from knitbake.trace.path_tracer import MAX_DEPTH
    from knitbake.trace.reference import trace_reference

    assert MAX_DEPTH == RENDER_FIELDS["max_depth"][0] == 32
    for traces in (cb.bake_correction, closure.trace_view_radiance, yarn_hull.hull_radiance, trace_reference, render):
        assert inspect.signature(traces).parameters["max_depth"].default == MAX_DEPTH, traces.__name__
