"""The bake's closure stage (``knitbake/stages/closure.py``): the strip renderer with the closed ξ reproduces the
correction stage's path-traced radiance Ψ_* on the bake's own configurations, where the paper's ξ does not; the
renderer reads the closed ξ by default where the pack has it, and the paper's ξ when asked or where it does not
(``Features.closed_xi``)."""

import shutil

import h5py
import numpy as np
import pytest

from data_formats.yarn_spec import load_preset
from knitbake.bake import bake
from knitbake.stages import closure
from knitrun.render.ablations import Features
from knitrun.render.pipeline import Renderer
from tests.helpers import TINY

SPEC = load_preset("cotton1")
ROWS = TINY["correction"]["rows"]  # the closure's rows: max(rows, n_v) of the correction stage


@pytest.fixture(scope="module")
def closed_pack(tmp_path_factory):
    """A tiny cotton1 pack of the closure and its inputs, baked into a stage cache of its own (``KNIT_CACHE_DIR``
    set for the bake; the test of the cache bakes again into it)."""
    folder = tmp_path_factory.mktemp("closure")
    with pytest.MonkeyPatch.context() as mp:
        mp.setenv("KNIT_CACHE_DIR", str(folder / "cache"))
        summary = bake(SPEC, folder / "cotton1.h5", overrides=TINY, only=list(closure.CLOSURE_INPUTS))
    assert list(summary)[-1] == "closure" and not summary["closure"]["cached"]
    return folder / "cotton1.h5"


def test_the_closure_is_cached_like_every_stage(closed_pack, monkeypatch):
    monkeypatch.setenv("KNIT_CACHE_DIR", str(closed_pack.parent / "cache"))
    again = bake(SPEC, closed_pack.parent / "again.h5", overrides=TINY, only=list(closure.CLOSURE_INPUTS))
    assert all(row["cached"] for row in again.values())
    with h5py.File(closed_pack) as a, h5py.File(closed_pack.parent / "again.h5") as b:
        assert np.array_equal(a["correction/xi_closed"][()], b["correction/xi_closed"][()])


def _miss(pack, xi, folder):
    """RMS of S/Ψ_* − 1 over the closure's measured bins, the renderer drawing with ``xi`` as the pack's ξ."""
    copy = folder / f"xi_{abs(hash(xi.tobytes()))}.h5"
    shutil.copy(pack, copy)
    with h5py.File(copy, "r+") as f:
        f["correction/xi"][...] = xi.astype(np.float32)
        target, err = f["correction/radiance"][()], f["correction/radiance_stderr"][()]
    measured = np.all((target > closure.SIGNAL * target.max()) & (err <= closure.MAX_RELATIVE_ERROR * target),
                      axis=-1)
    rendered = closure.render_bins(copy, SPEC, target.shape[:3], ROWS)
    assert measured.sum() >= 4, "too few measured bins for the test to mean anything"
    return float(np.sqrt(np.mean((rendered[measured] / target[measured] - 1.0) ** 2)))


def test_the_closed_xi_reproduces_the_traced_radiance_where_the_papers_does_not(closed_pack, tmp_path):
    with h5py.File(closed_pack) as f:
        paper, closed = f["correction/xi"][()], f["correction/xi_closed"][()]
        attrs = dict(f["correction/xi_closed"].attrs)
        assert np.all(np.isfinite(f["correction/xi_closed_stderr"][()]))
    before, after = _miss(closed_pack, paper, tmp_path), _miss(closed_pack, closed, tmp_path)
    assert after < 0.5 * before, (before, after)
    assert 0.0 <= attrs["closure_residual_rms"] <= attrs["closure_residual_max"]
    assert np.all(closed >= paper / closure.CLAMP - 1e-6) and np.all(closed <= paper * closure.CLAMP + 1e-6)


def test_the_renderer_reads_the_closed_xi_where_the_pack_has_it(closed_pack, tmp_path):
    scene = closure._scene(tmp_path, SPEC, closed_pack)
    with h5py.File(closed_pack) as f:
        paper, closed = f["correction/xi"][()], f["correction/xi_closed"][()]
    assert np.array_equal(Renderer(scene).looks[0].xi_full, closed)
    assert Renderer(scene).setup_facts["xi"] == {SPEC.name: "closed on the renderer"}
    # the pack was baked with --only (no flyaway stage): drawn without the flyaway layer, and said
    assert any("drawn without its flyaway layer" in w for w in Renderer(scene).warnings)
    assert np.array_equal(Renderer(scene, features=Features(closed_xi=False)).looks[0].xi_full, paper)
    factored = Renderer(scene, features=Features(full_tables=False)).looks[0]  # the closed ξ has no factors
    assert factored.xi_full.shape[0] == 0 and "factors" in factored.xi_from
    old = tmp_path / "schema22.h5"  # a pack from before the closure
    shutil.copy(closed_pack, old)
    with h5py.File(old, "r+") as f:
        del f["correction/xi_closed"], f["correction/xi_closed_stderr"]
    scene = closure._scene(tmp_path, SPEC, old)
    renderer = Renderer(scene)
    assert np.array_equal(renderer.looks[0].xi_full, paper)
    assert renderer.setup_facts["xi"] == {SPEC.name: "the paper's (the pack has no correction/xi_closed)"}
