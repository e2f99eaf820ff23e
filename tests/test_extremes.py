"""Stability at the extremes through the whole pipeline (DESIGN.md §5): extreme deformations simulated, rendered
and compared; extreme fibers (roughness → 0, absorption 0 and total) baked and rendered under grazing light and an
environment. Every output is finite; nothing raises. (Per-module extremes — the BCSDF at θ = ±π/2, DS, I_M at
λ = 0.5 and 10⁴, the knot solver's degenerate faces — are tested in their own modules.)"""

import dataclasses

import numpy as np
import pytest

from data_formats.asset_pack import validate
from data_formats.scene import load_scene
from data_formats.yarn_curves import write_yarn_curves
from data_formats.yarn_spec import dumps_spec, load_preset
from knitbake.bake import bake
from knitbake.compare.image_metrics import compare_images
from knitrun.render.ablations import ABLATIONS
from knitrun.render.pipeline import render
from knitrun.sim.deformations import deformation_frames
from knitrun.sim.knit_chart import chart_to_mesh, pattern_chart
from knitrun.sim.simulate import simulate
from tests.helpers import FRONT, SKY, SUN, TINY, straight, write_scene

PATCH_CAMERA = """[camera]
position = [0.6, 0.5, 6.0]
look_at = [0.6, 0.5, 0.0]
fov_deg = 40.0
width = 64
height = 48"""


@pytest.mark.parametrize("deform", ["stretch-x=20", "stretch-y=0.05", "shear=3", "stretch-x=0.05"])
def test_extreme_deformation_simulates_renders_and_compares(tmp_path, pack, deform):
    mesh = chart_to_mesh(pattern_chart("stockinette", 4, 4))
    curves, _ = simulate(mesh, deformation_frames(mesh.vertices, [deform], 2))
    assert np.all(np.isfinite(curves.points))
    path = write_scene(tmp_path, [straight()], camera=PATCH_CAMERA, lights=SUN + "\n" + SKY)
    write_yarn_curves(tmp_path / "s.h5", dataclasses.replace(curves, yarn_types=["cotton1"]))  # the patch instead
    path.write_text(path.read_text() + "frame = 1\n")
    scene = load_scene(path)
    images = [render(scene, {"cotton1": str(pack)}, features=ABLATIONS[name]).image for name in ("plain_ds", "full")]
    for img in images:
        assert np.all(np.isfinite(img)) and img.min() >= 0
    metrics = compare_images(images[1], images[0])
    assert all(np.isfinite(v) for k, v in metrics.items() if k != "flip_mode")


def _spec(kind):
    spec = load_preset("cotton1")
    optics = spec.optics
    if kind == "smooth":  # roughness → 0 at the spec's lower bound
        optics = dataclasses.replace(optics, beta_r_deg=1e-3, beta_tt_deg=1e-3, gamma_tt_deg=1e-3)
    elif kind == "black":  # total absorption
        optics = dataclasses.replace(optics, r_color=(0.0, 0.0, 0.0), tt_color=(0.0, 0.0, 0.0), d_color=(0.0, 0.0, 0.0))
    elif kind == "white":  # no absorption: every lobe colour at the energy bound r + tt + d = 1
        optics = dataclasses.replace(optics, r_color=(0.3, 0.3, 0.3), tt_color=(0.6, 0.6, 0.6), d_color=(0.1, 0.1, 0.1))
    geometry = dataclasses.replace(spec.geometry, fibers_per_ply=15)
    return dataclasses.replace(spec, optics=optics, geometry=geometry)


@pytest.mark.parametrize("kind", ["smooth", "black", "white"])
def test_extreme_fibers_bake_valid_packs_and_render_finite_images(tmp_path, kind):
    spec = _spec(kind)
    pack_path = tmp_path / f"{kind}.h5"
    bake(spec, pack_path, overrides=TINY, seed=2, use_cache=False)
    assert validate(pack_path) == []
    (tmp_path / "yarn.toml").write_text(dumps_spec(spec))
    grazing = SUN.replace("[0.3, 0.6, 1.0]", "[1.0, 0.0, 1e-4]")  # light almost along the yarn (θ_i → π/2)
    path = write_scene(tmp_path, [straight()], camera=FRONT.replace("[0.0, 0.0, 1.0]", "[0.9, 0.0, 0.05]"),
                       lights=grazing + "\n" + SKY)
    path.write_text(path.read_text().replace('yarn = "cotton1"', 'yarn = "yarn.toml"'))
    img = render(load_scene(path), {"cotton1": str(pack_path)}).image
    assert np.all(np.isfinite(img)) and img.min() >= 0
    if kind == "black":  # no light leaves a black fiber: only the background remains
        assert np.all(img <= np.array([0.1, 0.2, 0.3], np.float32) + 1e-6)
