"""The bake end to end on a tiny configuration: a valid, finite, error-barred pack; determinism across thread
counts; stage caching; what a scene needs; the CLI contract of `knitbake bake` and `knitbake export`."""

import dataclasses
import json

import numba
import numpy as np
import pytest
from click.testing import CliRunner

from cli.knitbake_cli import main as knitbake
from data_formats.asset_pack import describe, read_pack, validate
from data_formats.errors import FormatError
from data_formats.yarn_spec import load_preset
from knitbake.bake import STAGE_ORDER, bake, bake_plan, scene_needs, stage_key, stages_for
from tests.helpers import TINY

def small_yarn():
    spec = load_preset("silk1")
    return dataclasses.replace(spec, geometry=dataclasses.replace(spec.geometry, fibers_per_ply=12))


@pytest.fixture(scope="module")
def tiny_pack(tmp_path_factory):
    out = tmp_path_factory.mktemp("bake") / "p.h5"
    summary = bake(small_yarn(), out, overrides=TINY, seed=3, use_cache=False)
    return out, summary


def test_pack_is_valid_finite_and_error_barred(tiny_pack):
    out, summary = tiny_pack
    assert validate(out) == []
    pack = read_pack(out)
    assert set(summary) == set(STAGE_ORDER)
    for name, table in pack.tables.items():
        assert np.all(np.isfinite(table)), name
        assert np.isfinite(pack.info[name].error_estimate), name
    prov = pack.provenance
    assert set(prov["timings"]) == set(STAGE_ORDER) and prov["seed"] == 3
    assert prov["sample_counts"]["correction"]["batches"] == 2
    assert "correction/xi_residual" in pack.tables and "shadowing/psi_residual" in pack.tables
    im = pack.info["environment/I_M_TT_D"]  # the lookup's measured error travels with the table
    assert all(0 < im.attrs[k] < np.inf for k in ("lookup_rel_error", "lookup_error_per_decade"))  # a 3-sample grid
    notes = describe(out)["tables"]["environment/I_M_TT_D"]["notes"]
    assert notes["lookup_rel_error"] == im.attrs["lookup_rel_error"]


def test_same_seed_same_pack_whatever_the_thread_count(tiny_pack, tmp_path):
    out, _ = tiny_pack
    before = numba.get_num_threads()
    try:
        numba.set_num_threads(1)
        bake(small_yarn(), tmp_path / "one.h5", overrides=TINY, seed=3, use_cache=False)
    finally:
        numba.set_num_threads(before)
    a, b = read_pack(out), read_pack(tmp_path / "one.h5")
    assert set(a.tables) == set(b.tables)
    for name, table in b.tables.items():
        assert np.array_equal(table, a.tables[name]), name


def test_stages_are_cached_and_reused(tmp_path, monkeypatch):
    monkeypatch.setenv("KNIT_CACHE_DIR", str(tmp_path / "cache"))
    first = bake(small_yarn(), tmp_path / "a.h5", overrides=TINY, only=["shadowing", "dual_scattering"])
    second = bake(small_yarn(), tmp_path / "b.h5", overrides=TINY, only=["shadowing", "dual_scattering"])
    assert not any(r["cached"] for r in first.values()) and all(r["cached"] for r in second.values())
    a, b = read_pack(tmp_path / "a.h5"), read_pack(tmp_path / "b.h5")
    assert all(np.array_equal(a.tables[n], b.tables[n]) for n in a.tables)
    third = bake(small_yarn(), tmp_path / "c.h5", overrides=TINY, only=["shadowing"], seed=4)
    assert not third["shadowing"]["cached"]  # another seed is another input


def test_only_what_the_yarn_and_scene_need():
    spec = small_yarn()
    bare = dataclasses.replace(spec, flyaways=dataclasses.replace(spec.flyaways, hair_density=0.0, loop_density=0.0))
    assert "flyaway" not in stages_for(bare) and "flyaway" in stages_for(spec)
    assert "environment" not in stages_for(spec, needs={"environment": False})
    with pytest.raises(ValueError, match="unknown table group"):
        stages_for(spec, only=["xi"])
    # the closure runs after, and only with, its four input stages; the colour closure after it, and only with it
    assert stages_for(spec)[-2:] == ["closure", "colour_closure"]
    assert not {"closure", "colour_closure"} & set(stages_for(spec, only=["correction", "shadowing"]))
    assert {"closure", "colour_closure"} <= set(stages_for(spec, only=["dual_scattering", "correction", "shadowing",
                                                                       "textures"]))
    # it closes the split ξ of multiple scattering: without the split (knitbake bake --whole-xi) there is none
    assert "colour_closure" in bake_plan(spec, overrides=TINY)[1]
    assert "colour_closure" not in bake_plan(spec, overrides={**TINY, "closure": {"split": False}})[1]


def test_the_closures_cache_key_follows_its_input_stages():
    spec = small_yarn()
    key = lambda settings: stage_key("closure", spec, settings["closure"], 0)  # noqa: E731
    base = bake_plan(spec, overrides=TINY)[0]
    assert key(base) == key(bake_plan(spec, overrides=TINY)[0])
    for stage, change in (("textures", {"samples": 2}), ("shadowing", {"spp": 2}), ("correction", {"spp": 2})):
        moved = bake_plan(spec, overrides={**TINY, stage: {**TINY[stage], **change}})[0]
        assert key(moved) != key(base), stage
    assert key(bake_plan(spec, overrides={**TINY, "environment": {"shape": (3, 3, 4, 4)}})[0]) == key(base)
    # the colour closure's key follows the closure's settings too (it starts from the closure's ξ)
    colour = lambda settings: stage_key("colour_closure", spec, settings["colour_closure"], 0)  # noqa: E731
    assert colour(bake_plan(spec, overrides={**TINY, "closure": {"iterations": 2}})[0]) != colour(base)


def test_scene_sets_texture_size_and_environment():
    from data_formats.scene import load_scene

    scene = load_scene("examples/scenes/straight_yarn_directional.toml")
    needs = scene_needs(scene, load_preset("cotton1"))
    assert needs["environment"] is False
    # 2 × 0.0297 cm across, 0.3 cm over 256 px → about 51 px → 64 texels
    assert needs["texture_height"] == 64 and needs["texture_width"] >= needs["texture_height"]
    sky = scene_needs(load_scene("examples/scenes/straight_yarn_sky.toml"), load_preset("cotton1"))
    assert sky["environment"] is True


def test_cli_bake_inspect_export(tmp_path, monkeypatch):
    import knitbake.bake as bake_module

    monkeypatch.setenv("KNIT_CACHE_DIR", str(tmp_path / "cache"))
    tiny = {q: {k: {**v, **TINY[k]} for k, v in stages.items()} for q, stages in bake_module.QUALITY.items()}
    monkeypatch.setattr(bake_module, "QUALITY", tiny)
    out = tmp_path / "c.h5"
    runner = CliRunner()
    result = runner.invoke(knitbake, ["bake", "silk1", "-o", str(out), "--only", "shadowing,textures", "--json"])
    assert result.exit_code == 0, result.output
    summary = json.loads(result.stdout)
    assert set(summary["stages"]) == {"shadowing", "textures"}
    inspect = runner.invoke(knitbake, ["inspect", str(out)])
    assert "shadowing/psi_residual" in inspect.stdout and "error" in inspect.stdout
    export = runner.invoke(knitbake, ["export", str(out), str(tmp_path / "exp"), "--csv"])
    assert export.exit_code == 0
    manifest = json.loads((tmp_path / "exp" / "manifest.json").read_text())
    assert any(f["dataset"] == "textures/normal/mip0" for f in manifest["files"])
    assert (tmp_path / "exp" / "normal_mip0.png").exists() and (tmp_path / "exp" / "shadowing_psi_GM.csv").exists()
    bad = runner.invoke(knitbake, ["bake", "silk1", "-o", str(tmp_path / "x.h5"), "--only", "nope"])
    assert bad.exit_code == 1 and "unknown table group" in bad.stderr and not (tmp_path / "x.h5").exists()
    assert runner.invoke(knitbake, ["bake", "silk1", "-o", str(tmp_path / "x.txt")]).exit_code == 1
    seen = []  # --whole-xi asks the closure for the one ξ alone (every preset closes it apart as well)
    real = bake_module.bake
    monkeypatch.setattr(bake_module, "bake", lambda *a, **k: seen.append(k["overrides"]) or real(*a, **k))
    for flags in ([], ["--whole-xi"]):
        assert runner.invoke(knitbake, ["bake", "silk1", "-o", str(tmp_path / "s.h5"), "--only", "shadowing",
                                        *flags]).exit_code == 0
    assert seen == [None, {"closure": {"split": False}}]
    assert all(stages["closure"]["split"] for stages in bake_module.QUALITY.values())


def test_a_settings_file_replaces_the_presets_settings(tmp_path, monkeypatch):
    """`knitbake bake --settings FILE`: its per-stage settings replace the preset's (the pack's provenance holds
    them), merged with --whole-xi; a misspelt stage or setting or a value of another kind is refused in one line
    that names it, before anything is baked."""
    import tomli_w

    monkeypatch.setenv("KNIT_CACHE_DIR", str(tmp_path / "cache"))
    settings = tmp_path / "settings.toml"
    settings.write_text(tomli_w.dumps({**TINY, "shadowing": {**TINY["shadowing"], "n_theta": 3}}))
    out = tmp_path / "p.h5"
    runner = CliRunner()
    result = runner.invoke(knitbake, ["bake", "silk1", "-o", str(out), "--only", "shadowing", "--settings",
                                      str(settings), "--whole-xi"])
    assert result.exit_code == 0, result.output
    assert f"(draft with {settings}," in result.stdout
    baked = read_pack(out).provenance["bake_settings"]["settings"]
    assert baked["shadowing"] == {**TINY["shadowing"], "n_theta": 3}
    assert baked["closure"]["split"] is False and baked["closure"]["iterations"] == TINY["closure"]["iterations"]
    assert read_pack(out).tables["shadowing/psi_GM"].shape[1] == 3  # (N_v, N_theta, channel)
    for text, named in (("[corection]\nn_v = 4\n", "[corection]: unknown stage"),
                        ("[shadowing]\nn_thetas = 4\n", "shadowing.n_thetas: unknown setting"),
                        ("[shadowing]\nn_theta = 0\n", "shadowing.n_theta = 0: expected an integer ≥ 1"),
                        ("[shadowing]\nn_theta = '9'\n", "expected an integer"),
                        ("[closure]\nsplit = 1\n", "closure.split = 1: expected true or false"),
                        ("[correction.ds]\nn_phi = 3\n", "correction.ds.n_phi: unknown setting"),
                        ("[environment]\nshape = [3, 3]\n", "expected 4 integers"),
                        ("[shadowing\n", "cannot read bake settings")):
        settings.write_text(text)
        bad = runner.invoke(knitbake, ["bake", "silk1", "-o", str(tmp_path / "x.h5"), "--settings", str(settings)])
        assert bad.exit_code == 1 and named in bad.stderr and len(bad.stderr.strip().splitlines()) == 1, bad.stderr
        assert not (tmp_path / "x.h5").exists()
    with pytest.raises(FormatError, match="textures.sample: unknown setting"):
        bake_plan(small_yarn(), overrides={"textures": {"sample": 2}})


@pytest.mark.slow
@pytest.mark.parametrize("quality", ["draft", "standard", "final"])
def test_every_quality_bakes_a_valid_pack(quality, tmp_path):
    """The real presets (no overrides): `knitbake validate` passes and no table holds NaN/Inf (minutes each)."""
    out = tmp_path / f"{quality}.h5"
    summary = bake(load_preset("cotton1"), out, quality=quality, use_cache=False)
    assert set(summary) == set(STAGE_ORDER)
    assert validate(out) == []
    pack = read_pack(out)
    assert all(np.all(np.isfinite(t)) for t in pack.tables.values())
