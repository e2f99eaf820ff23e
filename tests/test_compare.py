"""Image metrics and `knitrun compare`: FLIP/RMSE/relMSE behave as metrics; the report folder is complete."""

import json

import numpy as np
import pytest
from click.testing import CliRunner

from cli.knitrun_cli import main as knitrun
from knitbake.compare.image_metrics import compare_images, flip_error
from tests.helpers import FRONT, SUN, straight, write_scene


def test_metrics_are_zero_for_identical_images_and_grow_with_the_difference():
    rng = np.random.default_rng(0)
    ref = rng.random((32, 48, 3)).astype(np.float32)
    same = compare_images(ref, ref)
    assert same["flip"] == 0 and same["rmse"] == 0 and same["rel_mse"] == 0
    small, large = compare_images(ref * 0.9, ref), compare_images(ref * 0.5, ref)
    assert 0 < small["flip"] < large["flip"] and 0 < small["rmse"] < large["rmse"]
    assert small["rel_mse"] < large["rel_mse"]
    mean, error_map = flip_error(ref * 0.5, ref)
    assert error_map.shape == (32, 48) and np.isclose(error_map.mean(), mean, rtol=1e-4)
    assert flip_error(ref * 0.5, ref, magma=True)[1].shape == (32, 48, 3)


def test_metrics_refuse_mismatched_or_non_finite_images():
    a = np.zeros((4, 4, 3), np.float32)
    with pytest.raises(ValueError, match="same"):
        compare_images(a, np.zeros((4, 5, 3)))
    b = a.copy()
    b[0, 0, 0] = np.nan
    with pytest.raises(ValueError, match="finite"):
        compare_images(b, a)


def test_cli_compare_writes_a_complete_report(tmp_path, pack):
    scene = write_scene(tmp_path, [straight()], camera=FRONT, lights=SUN)
    out = tmp_path / "report"
    result = CliRunner().invoke(knitrun, ["compare", str(scene), "--spp", "1", "--pack", f"cotton1={pack}",
                                          "-o", str(out), "--json"])
    assert result.exit_code == 0, result.output
    summary = json.loads(result.stdout)
    assert set(summary["ablations"]) >= {"plain_ds", "xi", "xi_shadowing", "full"}
    for row in summary["ablations"].values():
        assert 0 <= row["flip"] <= 1 and row["rmse"] >= 0 and row["speedup"] > 0
    for name in ("reference.exr", "reference.png", "report.md", "report.json", "side_by_side.png",
                 "strip_full.png", "flip_full.png", "diff_full.png"):
        assert (out / name).is_file(), name
    assert "FLIP" in (out / "report.md").read_text()
    again = CliRunner().invoke(knitrun, ["compare", str(scene), "--reference", str(out / "reference.exr"),
                                         "--pack", f"cotton1={pack}", "-o", str(tmp_path / "r2")])
    assert again.exit_code == 0, again.output
    bad = CliRunner().invoke(knitrun, ["compare", str(scene), "--reference", str(out / "reference.exr"), "--spp", "4",
                                       "-o", str(tmp_path / "r3")])
    assert bad.exit_code != 0 and "exclude" in bad.output
