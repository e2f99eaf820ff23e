"""Compile-ahead (``knitrun.render.compile_ahead``): ``Renderer.compile_shading`` of the helper's scene compiles
every signature of the later passes' kernels that a frame of the caller's scene then calls (else the helper's work
would be wasted and the cold frame would compile them again); the helper process runs, the frame waits for it and
draws the same image; a helper that fails costs time, not the image, and the frame says so."""

import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from numba.core import types

from data_formats.scene import load_scene
from knitrun.render import compile_ahead, pipeline
from knitrun.render.ablations import ABLATIONS
from knitrun.render.interreflection import _interreflect
from knitrun.render.strip_raster import _peel_floor, _raster, _raster_depth
from knitrun.render.strip_shading import (_resolve, flyaway_coverage, past_blockers, resolve_behind, shade_flyaway,
                                          shade_regular)
from tests.helpers import FRONT, SKY, SUN, straight, write_scene

KERNELS = (shade_regular, shade_flyaway, _resolve, resolve_behind, flyaway_coverage)


def _scene(folder, lights, layers=2):
    """Two yarns, one in front of the other, so both layers and the flyaway layer have points. (Cases: a directional
    light with both layers and the flyaway layer; the sky with one layer and no flyaways: the layer count and the
    flyaway switch decide which kernels a frame calls.)"""
    return load_scene(write_scene(folder, [straight(), straight(z=-0.05)[:, [1, 0, 2]]], camera=FRONT, lights=lights,
                                  render=f"layers = {layers}"))


@pytest.mark.parametrize("lights, ablation, layers", [(SUN, "full", 2), (SKY, "closed", 1)],
                         ids=["sun-flyaways-2-layers", "sky-1-layer"])
def test_compile_shading_compiles_every_signature_the_frame_calls(tmp_path, pack, lights, ablation, layers):
    scene, packs = _scene(tmp_path, lights, layers), {"cotton1": str(pack)}
    pipeline.Renderer(compile_ahead.helper_scene(scene), packs, ABLATIONS[ablation]).compile_shading()
    before = {k.__name__: set(k.signatures) for k in KERNELS}
    result = pipeline.Renderer(scene, packs, ABLATIONS[ablation]).render()
    assert {k.__name__: set(k.signatures) for k in KERNELS} == before
    assert result.facts["shading_points"] > 0 and result.image.std() > 0  # the frame did call them


def test_every_scene_and_ablation_shades_with_one_signature_of_each_kernel(tmp_path, pack):
    """The shading kernels take a kind of light the scene lacks, and an ablation's off switch, as inputs of no rows,
    not None (``strip_shading``, "One signature"): after a frame under the sun and the sky with every feature, frames
    under the sun alone, under the sky alone and with the ablations that drop the bounce, the hairs' glow, the hairs
    behind the body or the tables compile no new signature of ``shade_regular`` or ``shade_flyaway``."""
    packs, both = {"cotton1": str(pack)}, SUN + "\n" + SKY
    pipeline.Renderer(_scene(tmp_path, both), packs).render()
    shading = (shade_regular, shade_flyaway)
    before = {k.__name__: set(k.signatures) for k in shading}
    for lights, ablation in ((SUN, "full"), (SKY, "full"), (both, "no_bounce"), (both, "no_hair_glow"),
                             (SUN, "no_hairs_behind"), (both, "plain_ds"), (SUN, "factored")):
        result = pipeline.Renderer(_scene(tmp_path, lights), packs, ABLATIONS[ablation]).render()
        assert result.image.std() > 0
        assert {k.__name__: set(k.signatures) for k in shading} == before, (lights, ablation)


def test_the_kernel_cache_index_is_where_kernels_cached_looks(tmp_path, pack):
    """``kernels_cached`` reads a private attribute of Numba's cache; if a Numba upgrade moves it, this fails (the
    function itself would then always answer True: no helper, the safe side)."""
    pipeline.render(_scene(tmp_path, SUN), {"cotton1": str(pack)})
    assert Path(shade_regular._cache._cache_file._index_path).is_file()
    assert compile_ahead.kernels_cached()


def test_the_helper_runs_and_the_frame_is_the_same(tmp_path, pack, monkeypatch):
    scene = _scene(tmp_path, SUN)
    alone = pipeline.Renderer(scene, {"cotton1": str(pack)}).render()
    monkeypatch.setattr(compile_ahead, "kernels_cached", lambda: False)  # as on an empty cache
    renderer = pipeline.Renderer(scene, {"cotton1": str(pack)}, compile_ahead=True)
    helper = renderer._compile_helper
    assert helper is not None
    result = renderer.render()
    assert helper.returncode == 0 and renderer._compile_helper is None
    assert np.array_equal(result.image, alone.image) and result.facts["warnings"] == alone.facts["warnings"]
    assert pipeline.Renderer(scene, {"cotton1": str(pack)}, compile_ahead=False)._compile_helper is None


def test_a_failed_helper_costs_time_not_the_image(tmp_path, pack, monkeypatch):
    scene = _scene(tmp_path, SUN)
    alone = pipeline.Renderer(scene, {"cotton1": str(pack)}).render()
    monkeypatch.setattr(pipeline, "start_compile_ahead", lambda *args: subprocess.Popen(
        [sys.executable, "-c", "raise SystemExit(3)"]))
    result = pipeline.Renderer(scene, {"cotton1": str(pack)}, compile_ahead=True).render()
    assert np.array_equal(result.image, alone.image)
    assert [w for w in result.facts["warnings"] if "compile-ahead helper failed (exit 3)" in w]


def test_a_frame_compiles_each_of_its_raster_and_visibility_kernels_once(tmp_path, pack):
    """Fewer specialisations (issue 15, item 4): each kernel a frame calls is compiled for one set of argument
    types. Numba specialises on read-only and literal arguments, so a broadcast view or a module constant passed in
    one place and a plain array in another compiled the kernel twice: ``_depth_test`` (a literal 0 and a read-only
    constant from ``_raster_depth``, a variable and an array from ``_raster``), ``_peel_floor`` and ``_interreflect``
    (read-only broadcast views) and ``past_blockers`` (called on arrays by the yarn-level bounce), ~2.6 s of a cold
    frame. ``_depth_test`` is reached only from ``_raster`` and ``_raster_depth``, whose signatures are read here (a
    warm cache loads those, not their callees'): their bound arguments must have the same types."""
    # a shadow map and its peeled second layer (``_raster_depth``), both layers and the flyaway layer (``_raster``)
    for lights in (SUN, SKY):
        pipeline.Renderer(_scene(tmp_path, lights), {"cotton1": str(pack)}).render()
    bound_types = {tuple(str(t) for t in signature[-5:-3]) for signature in _raster.signatures}
    bound_types |= {tuple(str(t) for t in signature[-4:-2]) for signature in _raster_depth.signatures}
    assert len(bound_types) == 1, bound_types
    assert len(_peel_floor.signatures) == 1, _peel_floor.signatures
    assert len(_interreflect.signatures) == 1, _interreflect.signatures
    assert not any(isinstance(t, types.Array) for signature in past_blockers.signatures for t in signature)
