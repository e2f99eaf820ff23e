"""Yarn-level inter-reflection: the visibility transform's limits and fixed point, the baked hull albedo ρ_Y against
the white furnace, and what the renderer does with a pack that has no ρ_Y (schema < 2.1)."""

import dataclasses
import shutil

import h5py
import numpy as np
import pytest

from data_formats.yarn_spec import load_preset
from knitbake.stages.yarn_albedo import TABLE, bake_yarn_albedo
from knitrun.render.ablations import Features
from knitrun.render.interreflection import interreflected_visibility
from tests.helpers import FRONT, SKY, straight, write_scene
from tests.test_render import _render


def test_visibility_limits_and_fixed_point():
    v = np.linspace(0.0, 1.0, 11)
    np.testing.assert_allclose(interreflected_visibility(v, 0.0), v)  # nothing sent on: the shadow map's V
    np.testing.assert_allclose(interreflected_visibility(v, 1.0), 1.0)  # lossless yarns: the white furnace
    for rho in (0.3, 0.75, 0.95):
        w = interreflected_visibility(v, rho)
        assert np.all((w >= v - 1e-15) & (w <= 1.0)) and np.all(np.diff(w) > 0)
        # the receiver's incoming radiance V·L + (1 − V)·L_n with L_n = ρ (V L + (1 − V) L_n), L = 1
        neighbour = rho * v / (1 - rho * (1 - v))
        np.testing.assert_allclose(w, v + (1 - v) * neighbour, rtol=1e-12)
        np.testing.assert_allclose(neighbour, rho * w, rtol=1e-12)
    assert np.all(np.isfinite(interreflected_visibility([-1.0, 2.0, 0.0], [2.0, -1.0, 1.0])))


def _lossless(spec):
    optics = dataclasses.replace(spec.optics, d_color=(0.0, 0.0, 0.0),
                                 tt_color=tuple(1.0 - c for c in spec.optics.r_color))
    return dataclasses.replace(spec, optics=optics)


def test_yarn_albedo_is_one_for_lossless_fibers_and_below_the_fiber_albedo_otherwise():
    """White furnace of the bake: with non-absorbing fibers every path leaves the tube, ρ_Y = 1 (within its standard
    error: Russian roulette is unbiased). Cotton's fibers absorb 5–10 % per event and its dense yarn (225 fibers)
    scatters most paths several times, so ρ_Y lies clearly below the fiber albedo, with a finite, positive error."""
    cotton = load_preset("cotton1")
    settings = {"n_views": 3, "rows": 8, "spp": 2, "batches": 2}
    tables, errors = bake_yarn_albedo(_lossless(cotton), seed=3, **settings)
    assert np.all(np.abs(tables[TABLE] - 1.0) < 4 * errors[TABLE] + 0.01), (tables[TABLE], errors[TABLE])
    tables, errors = bake_yarn_albedo(cotton, seed=3, **settings)
    fiber = np.add(cotton.optics.r_color, cotton.optics.tt_color) + cotton.optics.d_color
    assert np.all((tables[TABLE] > 0.3) & (tables[TABLE] < fiber - 0.05)), (tables[TABLE], fiber)
    assert np.all(np.isfinite(errors[TABLE]) & (errors[TABLE] > 0))
    with pytest.raises(ValueError, match="batches = 1"):
        bake_yarn_albedo(cotton, batches=1)


def test_renderer_reports_and_skips_inter_reflection_for_a_pack_without_yarn_albedo(tmp_path, pack):
    """A schema-2.0 pack (no ``/interreflection/albedo``) renders as before the term existed, and says so; with the
    table, blocked sky light comes back and the image is brighter, never darker."""
    old = tmp_path / "old.h5"
    shutil.copy(pack, old)
    with h5py.File(old, "a") as f:
        del f[TABLE], f[TABLE + "_stderr"]
        f.attrs["schema_version"] = "2.0"
    crossing = [straight(z=0.0), straight(z=0.12)[:, [1, 0, 2]]]
    scene = write_scene(tmp_path, crossing, camera=FRONT, lights=SKY, name="crossing")
    without = _render(scene, old)
    assert "absent" in without.facts["interreflection"]["cotton1"]
    switched_off = _render(scene, pack, features=Features(interreflection=False))
    assert switched_off.facts["interreflection"]["cotton1"].startswith("off")
    np.testing.assert_array_equal(without.image, switched_off.image)
    with_term = _render(scene, pack)
    assert 0.0 < with_term.facts["interreflection"]["cotton1"] < 1.0
    assert np.all(with_term.image >= without.image - 1e-6) and with_term.image.mean() > without.image.mean()
