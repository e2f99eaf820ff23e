"""The bake's closure stage (``knitbake/stages/closure.py``): the strip renderer with the view-closed ξ reproduces the
path-traced radiance Ψ_* of the bake's yarn at every (θ_i, θ_o, φ) bin centre, where the paper's ξ does not; the
renderer reads the closed ξ by default where the pack has it, the diagonal-closed ξ of a schema-2.3 pack, and the
paper's ξ when asked or where neither is there (``Features.closed_xi``)."""

import dataclasses
import shutil

import h5py
import numpy as np
import pytest

from data_formats.asset_pack.schema import CLOSURE_STAGE_VERSION
from data_formats.yarn_spec import load_preset
from knitbake.bake import bake
from knitbake.stages import closure, colour_closure
from knitrun.render import ablations
from knitrun.render.ablations import Features
from knitrun.render.pipeline import Renderer
from tests.helpers import TINY

SPEC = load_preset("cotton1")
ROWS = TINY["correction"]["rows"]  # the closure's rows: max(rows, n_v) of the correction stage
SPLIT = {**TINY, "closure": {**TINY["closure"], "split": True}}  # with ξ closed apart (the presets' default)
WHOLE = {**TINY, "closure": {**TINY["closure"], "split": False}}  # the one ξ alone (knitbake bake --whole-xi)


@pytest.fixture(scope="module")
def closed_pack(tmp_path_factory):
    """A tiny cotton1 pack of the closure and its inputs, baked into a stage cache of its own (``KNIT_CACHE_DIR``
    set for the bake; the test of the cache bakes again into it)."""
    folder = tmp_path_factory.mktemp("closure")
    with pytest.MonkeyPatch.context() as mp:
        mp.setenv("KNIT_CACHE_DIR", str(folder / "cache"))
        summary = bake(SPEC, folder / "cotton1.h5", overrides=SPLIT, only=list(closure.CLOSURE_INPUTS))
    assert list(summary)[-2:] == ["closure", "colour_closure"] and not summary["closure"]["cached"]
    return folder / "cotton1.h5"


def test_the_closure_is_cached_like_every_stage(closed_pack, monkeypatch):
    monkeypatch.setenv("KNIT_CACHE_DIR", str(closed_pack.parent / "cache"))
    again = bake(SPEC, closed_pack.parent / "again.h5", overrides=SPLIT, only=list(closure.CLOSURE_INPUTS))
    assert all(row["cached"] for row in again.values())
    with h5py.File(closed_pack) as a, h5py.File(closed_pack.parent / "again.h5") as b:
        assert np.array_equal(a["correction/xi_view"][()], b["correction/xi_view"][()])


def test_a_pack_closed_by_an_older_closure_is_drawn_with_a_warning(closed_pack, tmp_path):
    """Every closure table carries the stage version that baked it; the renderer warns, naming the pack, when the
    closed ξ it reads has an older one or none (a pack closed before version 4), and not otherwise."""
    with h5py.File(closed_pack) as f:
        assert all(f[f"correction/{n}"].attrs["closure_version"] == CLOSURE_STAGE_VERSION
                   for n in ("xi_view", "xi_closed", "radiance_view", "xi_view_ss", "xi_closed_ms"))
    old = tmp_path / "old.h5"
    shutil.copy(closed_pack, old)
    with h5py.File(old, "r+") as f:
        del f["correction/xi_view"].attrs["closure_version"], f["correction/xi_view_ss"].attrs["closure_version"]
    (tmp_path / "new").mkdir()
    (tmp_path / "old").mkdir()
    bare = Features(flyaways=False)  # the pack has no flyaway textures
    assert Renderer(closure._scene(tmp_path / "new", SPEC, closed_pack), features=bare).warnings == []
    for features in (bare, Features(flyaways=False, split_xi=False)):  # xi_view_ss and _ms; xi_view
        warned = Renderer(closure._scene(tmp_path / "old", SPEC, old), features=features).warnings
        assert len(warned) == 1 and str(old) in warned[0] and "closure stage version < 4" in warned[0]
    # the diagonal's tables (xi_closed_ss, _ms; xi_closed) carry this version
    for features in (Features(flyaways=False, view_xi=False), Features(flyaways=False, view_xi=False, split_xi=False)):
        assert Renderer(closure._scene(tmp_path / "old", SPEC, old), features=features).warnings == []


def test_without_the_split_the_closure_bakes_the_one_xi_alone_and_the_same(closed_pack, monkeypatch):
    """With the split off (``knitbake bake --whole-xi``) the closure (its inputs from the cache) writes no ``*_ss``,
    ``*_ms`` tables, and its one closed ξ is the split bake's, bit for bit."""
    monkeypatch.setenv("KNIT_CACHE_DIR", str(closed_pack.parent / "cache"))
    summary = bake(SPEC, closed_pack.parent / "one.h5", overrides=WHOLE, only=list(closure.CLOSURE_INPUTS))
    assert not summary["closure"]["cached"] and all(row["cached"] for s, row in summary.items() if s != "closure")
    assert "colour_closure" not in summary  # it closes the split ξ_ms
    with h5py.File(closed_pack) as a, h5py.File(closed_pack.parent / "one.h5") as b:
        assert not any(name.endswith(("_ss", "_ms")) for name in b["correction"])
        for name in ("xi_view", "xi_closed", "radiance_view"):
            assert np.array_equal(a[f"correction/{name}"][()], b[f"correction/{name}"][()]), name


def _miss(pack, xi_view, folder):
    """RMS of S/Ψ_* − 1 over the closure's measured bins, the renderer drawing with ``xi_view`` as the pack's ξ."""
    copy = folder / f"xi_{abs(hash(xi_view.tobytes()))}.h5"
    shutil.copy(pack, copy)
    with h5py.File(copy, "r+") as f:
        f["correction/xi_view"][...] = xi_view.astype(np.float32)
        target, err = f["correction/radiance_view"][()], f["correction/radiance_view_stderr"][()]
    measured = np.all((target > closure.SIGNAL * target.max()) & (err <= closure.MAX_RELATIVE_ERROR * target),
                      axis=-1)
    rendered = closure.render_bins(copy, SPEC, target.shape[:4], ROWS)
    assert measured.sum() >= 4, "too few measured bins for the test to mean anything"
    return float(np.sqrt(np.mean((rendered[measured] / target[measured] - 1.0) ** 2)))


def test_the_residual_the_pack_reports_is_the_residual_of_its_own_xi(closed_pack):
    """``closure_residual_rms`` and ``_max`` are those of the table the pack holds, drawn again. (On this tiny pack no
    bin drops below the signal in the last render, so the reset of closure version 3, which made the standard pack's
    stored ξ draw 0.54 RMS where it reported 0.23, does not show here: the synthetic test above catches that.)"""
    with h5py.File(closed_pack) as f:
        target, err = f["correction/radiance_view"][()], f["correction/radiance_view_stderr"][()]
        attrs = dict(f["correction/xi_view"].attrs)
    rendered = closure.render_bins(closed_pack, SPEC, target.shape[:4], ROWS)
    used = np.all((target > closure.SIGNAL * target.max()) & (err <= closure.MAX_RELATIVE_ERROR * target), axis=-1,
                  keepdims=True) & (rendered > closure.SIGNAL * rendered.max())
    miss = np.abs(rendered[used] / target[used] - 1.0)
    assert miss.size >= 4, "too few closed bins for the test to mean anything"
    assert np.sqrt(np.mean(miss ** 2)) == pytest.approx(attrs["closure_residual_rms"], rel=1e-3, abs=1e-6)
    assert miss.max() == pytest.approx(attrs["closure_residual_max"], rel=1e-3, abs=1e-6)


def test_the_closure_stores_the_xi_its_last_render_drew(monkeypatch):
    """A bin the fixed point moved that falls below the signal in the last render keeps its moved ξ (the table
    stored is the one the residual was measured on), with its error from Ψ_*; a bin never measured keeps the paper's.
    Synthetic renderer: S = ξ · base, base the traced radiance halved, but bin (0, 0, 0, 0) dark in the last render."""
    from knitbake.stages.stage_result import StageResult

    paper_tab = np.full((2, 2, 1, 3), 1.5)
    target = np.full((2, 2, 2, 1, 3), 0.2)
    target[1, 1, 1, 0] = 0.0  # never measured
    monkeypatch.setattr(closure, "trace_view_radiance", lambda *a, **k: (target, 0.01 * target))
    drawn, calls = [], []

    def write_pack_to(path, xi, split=None):
        drawn.append(xi.copy())

    def render_bins(pack, spec, shape, rows, progress=None, split=False, single=False):
        calls.append(1)
        out = drawn[-1] * 0.5 * target
        if len(calls) == 3:  # the last render (iterations = 2)
            out[0, 0, 0, 0] = 0.0
        return out

    monkeypatch.setattr(closure, "render_bins", render_bins)
    inputs = {"correction": StageResult({"correction/xi": paper_tab, "correction/radiance": target[:, [1, 0], [0, 1]]},
                                        {"correction/xi": 0.1 * paper_tab,
                                         "correction/radiance": 0.01 * target[:, [1, 0], [0, 1]]})}
    tables, errors, counts, left = closure.close_correction(SPEC, inputs, write_pack_to, ROWS, 2, 1, 1, 0,
                                                            split=False)
    stored = tables["correction/xi_view"]
    assert np.array_equal(stored, drawn[-1])
    assert np.allclose(stored[0, 0, 0, 0], 2.0) and np.allclose(stored[1, 1, 1, 0], 1.5)  # S = Ψ_* at ξ = 2
    assert np.allclose(errors["correction/xi_view"][0, 0, 0, 0], 0.01 * 2.0)
    assert np.allclose(errors["correction/xi_view"][1, 1, 1, 0], 0.1 * 1.5)
    assert counts["bins_closed"] == 7 and left["correction/xi_view"]["closure_residual_rms"] == pytest.approx(0.0)


def test_the_closed_xi_reproduces_the_traced_radiance_where_the_papers_does_not(closed_pack, tmp_path):
    with h5py.File(closed_pack) as f:
        paper, closed = closure.papers_xi_at_views(f["correction/xi"][()]), f["correction/xi_view"][()]
        attrs = dict(f["correction/xi_view"].attrs)
        assert np.all(np.isfinite(f["correction/xi_view_stderr"][()]))
        assert np.all(np.isfinite(f["correction/radiance_view_stderr"][()]))
        assert np.array_equal(f["correction/xi_closed"][()], closure.diagonal_of(closed))
        assert np.array_equal(closure.diagonal_of(f["correction/radiance_view"][()]), f["correction/radiance"][()])
    before, after = _miss(closed_pack, paper, tmp_path), _miss(closed_pack, closed, tmp_path)
    assert after < 0.5 * before, (before, after)
    assert 0.0 <= attrs["closure_residual_rms"] <= attrs["closure_residual_max"]
    assert np.all(closed >= paper / closure.CLAMP - 1e-6) and np.all(closed <= paper * closure.CLAMP + 1e-6)


def test_the_closure_draws_its_lone_yarn_unshadowed_by_its_own_strip(closed_pack, monkeypatch):
    """The closure's renderer draws the full model without flyaways (with the one ξ, which it closes first; one
    blocker counted: a lone straight yarn has no second layer toward a light). The lone yarn's bins are the same
    looked up on the tube's surface as on the strip plane; without the tilt of its own strip (``pipeline.receiver_bias``
    = the bias alone, ½ radius) the far side of the tube, up to r/cos θ behind the strip, is shadowed by it in every
    θ bin of a grid of four (±22.5°, ±67.5°; with the bias of 1.5 r of stops before 75 only in the outer two)."""
    import knitrun.render.pipeline as pipeline

    asked = []

    class Recording(pipeline.Renderer):
        def __init__(self, scene, packs=None, features=Features(), *args, **kwargs):
            asked.append(features)
            super().__init__(scene, packs, features, *args, **kwargs)

    with h5py.File(closed_pack) as f:
        shape = f["correction/xi_view"].shape[:4]
    with monkeypatch.context() as m:
        m.setattr(pipeline, "Renderer", Recording)
        assert np.all(np.isfinite(closure.render_bins(closed_pack, SPEC, shape, ROWS)))
    assert asked == [Features(flyaways=False, split_xi=False, two_blockers=False)]

    def bins(own_strip=True, **features):
        with monkeypatch.context() as m:
            m.setattr(ablations, "Features", lambda **kw: Features(**{**kw, **features}))
            if not own_strip:
                m.setattr(pipeline, "receiver_bias", lambda receivers, direction: receivers.bias)
            return closure.render_bins(closed_pack, SPEC, (shape[0], 4, 4, shape[3]), ROWS)

    surface = bins()
    np.testing.assert_allclose(bins(surface_shadows=False), surface, rtol=1e-9, atol=1e-12)
    tilted = bins(own_strip=False)
    for k in range(4):  # each θ bin shadowed by its own strip somewhere
        lit = surface[:, k] > 1e-3 * surface.max()
        assert np.abs(tilted[:, k][lit] / surface[:, k][lit] - 1.0).max() > 0.3


def test_the_papers_xi_at_the_views_is_the_papers_on_the_diagonal_and_linear_in_theta_d():
    rng = np.random.default_rng(3)
    xi = rng.uniform(0.5, 2.0, (3, 4, 2, 3))
    at_views = closure.papers_xi_at_views(xi)
    for k in range(4):  # θ_o = −θ_i: θ_d = θ_o, a grid centre
        assert np.allclose(at_views[:, 3 - k, k], xi[:, k])
    # θ_i = θ_o: θ_d = 0, halfway between the two middle centres
    assert np.allclose(at_views[:, 1, 1], 0.5 * (xi[:, 1] + xi[:, 2]))
    # θ_i at the first centre, θ_o at the last: θ_d = 3π/8, the last centre
    assert np.allclose(at_views[:, 0, 3], xi[:, 3])


def test_the_renderer_reads_the_closed_xi_where_the_pack_has_it(closed_pack, tmp_path):
    scene = closure._scene(tmp_path, SPEC, closed_pack)
    with h5py.File(closed_pack) as f:
        paper, closed = f["correction/xi"][()], f["correction/xi_view"][()]
    # the one closed ξ (the pack has it apart too, which the default reads: test_the_renderer_reads_the_split_xi_*)
    whole = ablations.ABLATIONS["whole_xi"]
    view = Renderer(scene, features=whole)  # ξ closed at every view
    assert np.array_equal(view.looks[0].xi_view, closed)
    assert view.setup_facts["xi"] == {SPEC.name: "closed on the renderer at every view"}
    diagonal = Renderer(scene, features=Features(view_xi=False, split_xi=False))  # the view-closed ξ's diagonal
    assert diagonal.looks[0].xi_view.shape[0] == 0
    assert np.array_equal(diagonal.looks[0].xi_full, closure.diagonal_of(closed))
    assert diagonal.setup_facts["xi"] == {SPEC.name: "closed on the renderer"}
    # the pack was baked with --only (no flyaway stage): drawn without the flyaway layer, and said
    assert any("drawn without its flyaway layer" in w for w in Renderer(scene).warnings)
    papers = Renderer(scene, features=Features(closed_xi=False)).looks[0]
    assert np.array_equal(papers.xi_full, paper) and papers.xi_view.shape[0] == 0
    factored = Renderer(scene, features=Features(full_tables=False, view_xi=True)).looks[0]  # no closed factors
    assert factored.xi_full.shape[0] == 0 and factored.xi_view.shape[0] == 0 and "factors" in factored.xi_from
    assert Renderer(scene, features=Features(xi=False, view_xi=True)).looks[0].xi_view.shape[0] == 0
    old = tmp_path / "schema23.h5"  # a pack of schema 2.3: ξ closed on the diagonal
    shutil.copy(closed_pack, old)
    diagonal = paper * 1.25
    with h5py.File(old, "r+") as f:
        for name in ("xi_view_ss", "xi_view_ms", "xi_closed_ss", "xi_closed_ms", "radiance_view_ss"):
            del f[f"correction/{name}"], f[f"correction/{name}_stderr"]
        del f["correction/xi_view"], f["correction/xi_view_stderr"]
        del f["correction/radiance_view"], f["correction/radiance_view_stderr"]
        del f["correction/xi_closed"], f["correction/xi_closed_stderr"]
        for name in ("xi_closed", "xi_closed_stderr"):  # the paper's ξ's attributes: the same axes
            value = diagonal if name == "xi_closed" else f["correction/xi_stderr"][()]
            f[f"correction/{name}"] = value.astype(np.float32)
            f[f"correction/{name}"].attrs.update(f["correction/" + name.replace("_closed", "")].attrs)
    renderer = Renderer(closure._scene(tmp_path, SPEC, old), features=whole)  # asked, not there
    assert np.allclose(renderer.looks[0].xi_full, diagonal) and renderer.looks[0].xi_view.shape[0] == 0
    assert renderer.setup_facts["xi"] == {SPEC.name: "closed on the renderer"}
    default = Renderer(closure._scene(tmp_path, SPEC, old))  # ξ closed apart asked for too, not there either
    assert np.allclose(default.looks[0].xi_full, diagonal) and default.looks[0].xi_single.shape[0] == 0
    assert default.setup_facts["xi"] == {
        SPEC.name: "closed on the renderer (the pack has no ξ closed apart on single and multiple scattering)"}
    with h5py.File(old, "r+") as f:  # a pack from before the closure
        del f["correction/xi_closed"], f["correction/xi_closed_stderr"]
    renderer = Renderer(closure._scene(tmp_path, SPEC, old))
    assert np.array_equal(renderer.looks[0].xi_full, paper)
    assert renderer.setup_facts["xi"] == {SPEC.name: "the paper's (the pack has no correction/xi_closed)"}


def _miss_parts(pack, split, folder):
    """RMS of S/Ψ − 1 of single scattering and of multiple scattering over the bins where each part is measured, the
    renderer drawing with ``split`` = (ξ_ss, ξ_ms) as the pack's split ξ."""
    copy = folder / f"split_{abs(hash(split[0].tobytes() + split[1].tobytes()))}.h5"
    shutil.copy(pack, copy)
    with h5py.File(copy, "r+") as f:
        f["correction/xi_view_ss"][...] = split[0].astype(np.float32)
        f["correction/xi_view_ms"][...] = split[1].astype(np.float32)
        total, total_err = f["correction/radiance_view"][()], f["correction/radiance_view_stderr"][()]
        single, single_err = f["correction/radiance_view_ss"][()], f["correction/radiance_view_ss_stderr"][()]
    shape = total.shape[:4]
    drawn = closure.render_bins(copy, SPEC, shape, ROWS, split=True)
    drawn_single = closure.render_bins(copy, SPEC, shape, ROWS, split=True, single=True)
    out = []
    for want, err, got in ((single, single_err, drawn_single),
                           (total - single, np.hypot(total_err, single_err), drawn - drawn_single)):
        measured = np.all((want > closure.SIGNAL * total.max()) & (err <= closure.MAX_RELATIVE_ERROR * want), axis=-1)
        assert measured.sum() >= 4, "too few measured bins for the test to mean anything"
        out.append(float(np.sqrt(np.mean((got[measured] / want[measured] - 1.0) ** 2))))
    return out


def test_a_part_whose_rows_fail_takes_its_angle_bins_ratio_summed_over_v():
    """``closure.part_ratio``: a measured row moves by its own ratio; a row too noisy alone moves by its angle bin's
    Σ_v want / Σ_v drawn where that sum is measured (every channel, standard errors in quadrature ≤ 25 %); an angle
    bin whose sum is noisy or undrawn leaves its failing rows at 1."""
    want = np.full((4, 1, 1, 3, 3), 0.2)
    err = np.full_like(want, 0.02)
    err[2:, :, :, 1] = 0.2  # angle bin 1: rows 2, 3 fail alone; summed: 0.8 ± 0.28 (35 %) → not pooled either
    err[2:, :, :, 2] = 0.09  # angle bin 2: rows 2, 3 fail alone (45 %); summed: 0.8 ± 0.13 (16 %) → pooled
    drawn = np.full_like(want, 0.1)
    drawn[3, :, :, 2] = 0.3
    rows_ok = np.all(err <= closure.MAX_RELATIVE_ERROR * want, axis=-1, keepdims=True)
    ratio, pooled = closure.part_ratio(want, err, drawn, rows_ok, 1e-3, 1e-3)
    assert ratio.shape == want.shape and pooled.shape == rows_ok.shape
    assert np.allclose(ratio[:, 0, 0, 0], 2.0) and not pooled[:, 0, 0, 0].any()  # every row measured
    assert np.allclose(ratio[:2, 0, 0, 1], 2.0) and np.allclose(ratio[2:, 0, 0, 1], 1.0)
    assert not pooled[:, 0, 0, 1].any()
    assert np.allclose(ratio[:2, 0, 0, 2], 2.0) and np.allclose(ratio[2:, 0, 0, 2], 0.8 / 0.6)
    assert pooled[2:, 0, 0, 2].all() and not pooled[:2, 0, 0, 2].any()
    undrawn = closure.part_ratio(want, err, np.zeros_like(drawn), np.zeros_like(rows_ok), 1e-3, 1e-3)
    assert np.allclose(undrawn[0], 1.0) and not undrawn[1].any()


def test_the_split_xi_reproduces_single_and_multiple_scattering_apart(closed_pack, tmp_path):
    """ξ closed apart (``correction/xi_view_ss``, ``_ms``): the renderer's single scattering and its multiple
    scattering each come closer to the path tracer's, per bin, than with the one closed ξ on both; the split tables are
    finite with finite errors, their diagonals stored, the traced single scattering below the whole."""
    with h5py.File(closed_pack) as f:
        closed = f["correction/xi_view"][()]
        ss, ms = f["correction/xi_view_ss"][()], f["correction/xi_view_ms"][()]
        for name in ("ss", "ms"):
            assert np.array_equal(f[f"correction/xi_closed_{name}"][()],
                                  closure.diagonal_of(f[f"correction/xi_view_{name}"][()]))
            assert np.all(np.isfinite(f[f"correction/xi_view_{name}_stderr"][()]))
            assert 0.0 <= f[f"correction/xi_view_{name}"].attrs["closure_residual_rms"]
        single, total = f["correction/radiance_view_ss"][()], f["correction/radiance_view"][()]
    assert np.all(np.isfinite(ss)) and np.all(np.isfinite(ms))
    assert single.mean() < total.mean()
    one = _miss_parts(closed_pack, (closed, closed), tmp_path)
    apart = _miss_parts(closed_pack, (ss, ms), tmp_path)
    assert apart[0] < 0.7 * one[0] and apart[1] < 0.7 * one[1], (one, apart)


def test_the_renderer_reads_the_split_xi_by_default(closed_pack, tmp_path):
    """``Features.split_xi`` (the default): multiple scattering's ξ where the one ξ was read, single scattering's
    beside it, on the diagonal and at every view; not asked (``whole_xi``), or a pack without them (schema < 2.5),
    the one closed ξ (facts say so); with the paper's ξ, which has no split, that ξ (and facts say nothing of a
    split)."""
    scene = closure._scene(tmp_path, SPEC, closed_pack)
    with h5py.File(closed_pack) as f:
        ss, ms = f["correction/xi_view_ss"][()], f["correction/xi_view_ms"][()]
    split = Renderer(scene, features=Features(split_xi=True, view_xi=False))
    look = split.looks[0]
    assert np.array_equal(look.xi_full, closure.diagonal_of(ms)) and np.array_equal(look.xi_single,
                                                                                   closure.diagonal_of(ss))
    assert split.setup_facts["xi"] == {SPEC.name: "closed on the renderer, apart on single and multiple scattering"}
    view = Renderer(scene, features=Features(split_xi=True, view_xi=True)).looks[0]
    assert np.array_equal(view.xi_view, ms) and np.array_equal(view.xi_single_view, ss)
    default = Renderer(scene).looks[0]
    assert np.array_equal(default.xi_view, ms) and np.array_equal(default.xi_single_view, ss)
    whole = Renderer(scene, features=ablations.ABLATIONS["whole_xi"]).looks[0]
    assert whole.xi_single.shape[0] == 0 and whole.xi_single_view.shape[0] == 0
    papers = Renderer(scene, features=Features(split_xi=True, closed_xi=False))  # the split needs the closed ξ
    assert papers.looks[0].xi_single.shape[0] == 0 and papers.setup_facts["xi"][SPEC.name] == "the paper's"
    old = tmp_path / "schema24.h5"
    shutil.copy(closed_pack, old)
    with h5py.File(old, "r+") as f:
        for name in ("xi_view_ss", "xi_view_ms", "xi_closed_ss", "xi_closed_ms", "radiance_view_ss"):
            del f[f"correction/{name}"], f[f"correction/{name}_stderr"]
    renderer = Renderer(closure._scene(tmp_path, SPEC, old), features=Features(split_xi=True))
    assert renderer.looks[0].xi_single.shape[0] == 0
    assert "the pack has no ξ closed apart" in renderer.setup_facts["xi"][SPEC.name]


# --- the colour closure (knitbake/stages/colour_closure.py) --------------------------------------------------------

def _colour_inputs(closed_pack, monkeypatch):
    """The colour closure's input stages of the fixture's bake, from its stage cache, and their pack writer."""
    from knitbake import bake as bake_module

    monkeypatch.setenv("KNIT_CACHE_DIR", str(closed_pack.parent / "cache"))
    settings = bake_module.bake_plan(SPEC, overrides=SPLIT)[0]
    inputs = {}
    for stage in colour_closure.COLOUR_CLOSURE_INPUTS:
        inputs[stage], row = bake_module.run_stage(SPEC, stage, settings[stage], 0)
        assert row["cached"], stage
    writer = bake_module._input_pack_writer(SPEC, 0, {s: inputs[s] for s in closure.CLOSURE_INPUTS})
    return inputs, writer, settings["colour_closure"]


def test_the_colour_closure_closes_multiple_scattering_where_the_white_xi_does_not(closed_pack, monkeypatch):
    """In a grey k < 1 the strips with the white yarn's ξ_ms miss the path tracer's multiple scattering (Zinke's
    estimate falls faster with the albedo than two scattering events do); closed in that grey they reach it."""
    inputs, writer, settings = _colour_inputs(closed_pack, monkeypatch)
    args = (SPEC, inputs, writer, settings["rows"])
    _, _, _, white = colour_closure.close_by_colour(*args, 0, settings["spp"], settings["batches"], 0)
    table, error, counts, closed = colour_closure.close_by_colour(*args, 2, settings["spp"], settings["batches"], 0)
    assert white["closure_residual_rms"] > 0.3
    assert closed["closure_residual_rms"] < 0.5 * white["closure_residual_rms"]
    assert counts["bins_closed_k0.125"] > 0 and np.all(np.isfinite(table)) and np.all(np.isfinite(error))
    # each grey measured how far its start (the white's, then the lighter greys' ratio carried on) was from the
    # bins it closed
    assert len(closed["start_rms_log"]) == colour_closure.N_COLOURS and min(closed["start_rms_log"]) > 0


def test_a_darker_grey_starts_from_the_lighter_greys_ratio_carried_on():
    """``colour_closure.continuation``: with the white alone known, the white's ξ_ms and error; with ξ(1/2) = 2 ξ(1),
    ξ(1/4) starts at 4 ξ(1) (the ratio carried on in log k) and ξ(1/8) from ξ(1/2) = 2 and ξ(1/4) = 3 at 4.5; a
    start past ``CLAMP`` times the white's is clamped; the inputs' relative errors are weighed by their powers."""
    white = np.array([1.0, 2.0, 0.0])
    white_relative = np.array([0.01, 0.01, 0.01])
    xi, relative = colour_closure.continuation(0.5, {}, {}, white, white_relative)
    np.testing.assert_array_equal(xi, white)
    np.testing.assert_array_equal(relative, white_relative)
    half = {0.5: 2.0 * white}
    xi, relative = colour_closure.continuation(0.25, half, {0.5: 0.05 * half[0.5]}, white, white_relative)
    np.testing.assert_allclose(xi, 4.0 * white)
    np.testing.assert_allclose(relative[:2], np.hypot(2 * 0.05, 0.01))  # ξ(1/2)² / ξ(1)
    closed = {0.5: 2.0 * white, 0.25: 3.0 * white}
    xi, relative = colour_closure.continuation(0.125, closed, {g: 0.0 * v for g, v in closed.items()}, white,
                                               white_relative)
    np.testing.assert_allclose(xi, 4.5 * white)
    np.testing.assert_allclose(relative, 0.0)
    closed = {0.5: 4.0 * white, 0.25: 7.0 * white}
    xi, relative = colour_closure.continuation(0.125, closed, {g: 0.1 * v for g, v in closed.items()}, white,
                                               white_relative)
    np.testing.assert_allclose(xi, colour_closure.CLAMP * white)
    assert np.all(np.isfinite(relative))


def test_the_colour_table_is_stored_beside_the_closures_white_xi_ms(closed_pack):
    with h5py.File(closed_pack) as f:
        table, white = f[colour_closure.TABLE][()], f["correction/xi_view_ms"][()]
        assert f[colour_closure.TABLE].attrs["closure_version"] == CLOSURE_STAGE_VERSION
    assert table.shape == (colour_closure.N_COLOURS,) + white.shape
    assert np.all(np.isfinite(table)) and np.all(table >= 0)
    assert not np.allclose(table[0], white)  # the darkest grey was closed on its own
    np.testing.assert_allclose(colour_closure.colour_scales(), [0.125, 0.25, 0.5])


def test_the_strips_single_scattering_is_linear_in_the_colour(closed_pack):
    """The colour closure draws the strips' single scattering once, in white, and scales it by k (module docstring):
    the BCSDF is linear in the lobe albedos."""
    shape = (ROWS, 2, 2, 2)
    white = closure.render_bins(closed_pack, SPEC, shape, ROWS, split=True, single=True)
    grey = closure.render_bins(closed_pack, SPEC, shape, ROWS, split=True, single=True, colour_scale=0.25)
    assert white.max() > 0
    np.testing.assert_allclose(grey, 0.25 * white, rtol=1e-5, atol=1e-7 * white.max())


def test_each_channel_reads_the_colour_table_at_its_own_colour():
    from knitrun.render.yarn_look import ms_xi_in_colour

    # the samples at k = 1/8, 1/4, 1/2 hold 1, 2, 3 and the white table (k = 1) 4
    table = np.broadcast_to(np.arange(1.0, 4.0)[:, None, None, None, None, None], (3, 2, 3, 3, 2, 3)).copy()
    white, span = np.full((2, 3, 3, 2, 3), 4.0), (-3.5, -0.5)
    # on the samples, their values; between two, linear in 1/k (k = 2^-1.5: 1/k = 2√2 between 4 and 2; 0.75: 4/3
    # between 2 and 1); beyond the ends, the ends (0 reads the darkest)
    for colour, want in (((1.0, 0.25, 0.125), (4, 2, 1)), ((2 ** -1.5, 0.05, 3.0), (2 + (4 - 2 * 2 ** 0.5) / 2, 1, 4)),
                         ((0.0, 0.75, 0.5), (1, 3 + 2 / 3, 3))):
        got = ms_xi_in_colour(table, span, white, np.array(colour))
        np.testing.assert_allclose(got[0, 0, 0, 0], want, err_msg=str(colour))


def test_the_renderer_draws_multiple_scattering_with_the_xi_of_its_colour(closed_pack, tmp_path):
    from knitrun.render.yarn_look import ms_xi_in_colour

    scene = closure._scene(tmp_path, SPEC, closed_pack)
    red = dataclasses.replace(scene, yarns=(dataclasses.replace(scene.yarns[0], color=(0.9, 0.25, 0.2)),))
    with h5py.File(closed_pack) as f:
        table, white = f[colour_closure.TABLE][()], f["correction/xi_view_ms"][()]
    bare = Features(flyaways=False)
    look = Renderer(red, features=bare).looks[0]
    np.testing.assert_allclose(look.xi_view, ms_xi_in_colour(table, (-3.5, -0.5), white, np.array([0.9, 0.25, 0.2])))
    assert "colour" in look.xi_from
    np.testing.assert_allclose(Renderer(red, features=Features(flyaways=False, colour_xi=False)).looks[0].xi_view,
                               white)
    np.testing.assert_allclose(Renderer(scene, features=bare).looks[0].xi_view, white)  # white: the closure's own
