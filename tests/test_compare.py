"""Image metrics and `knitrun compare`: FLIP/RMSE/relMSE and the yarn-scale metrics behave as metrics, the ensemble
of fiber instances gives its draws' statistics; the report folder is complete, floors and ensemble included; and
(slow) the full model keeps the straight yarn's brightness."""

import json
import math
import shutil
from pathlib import Path

import h5py
import numpy as np
import pytest
from click.testing import CliRunner

from cli.knitrun_cli import main as knitrun
from data_formats.conventions import LUMINANCE
from data_formats.images import read_exr
from data_formats.scene import load_scene
from data_formats.yarn_spec import load_preset
from knitbake.bake import bake
from knitbake.compare.image_metrics import (CONTRAST_BANDS, compare_images, ensemble_floor, ensemble_metrics,
                                            flip_error, radiance_ratio, sub_yarn_contrast, yarn_filter,
                                            yarn_scale_metrics)
from knitbake.trace.reference import trace_reference
from knitrun.render.pipeline import render
from tests.helpers import FRONT, SUN, straight, write_scene

EXAMPLES = Path(__file__).resolve().parent.parent / "examples" / "scenes"


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


def test_yarn_filter_is_a_box_mean_that_keeps_the_mean():
    img = np.zeros((30, 40, 3))
    img[10:20, 10:20] = 1.0
    f = yarn_filter(img, 5)
    assert f[15, 15, 0] == pytest.approx(1.0) and f[10, 15, 0] == pytest.approx(0.6)  # 3 of 5 rows inside
    assert f.sum() == pytest.approx(img.sum())  # the square is far from the edges
    np.testing.assert_array_equal(yarn_filter(img, 0.4), img)  # below one pixel: unchanged


def test_yarn_scale_metrics_forgive_a_shift_below_the_yarn_scale_but_not_a_brightness_error():
    """Two 'yarns' of the same brightness one pixel apart differ completely per pixel, little at the yarn scale; a
    10 % darker yarn in place differs by 10 % at every scale."""
    ref = np.zeros((64, 64, 3), np.float32)
    ref[28:36:2] = 1.0  # thin bright lines: fibers
    shifted = np.roll(ref, 1, axis=0)
    darker = 0.9 * ref
    pixel_l1 = np.abs(shifted - ref).sum() / ref.sum()
    shift, dark = yarn_scale_metrics(shifted, ref, 8), yarn_scale_metrics(darker, ref, 8)
    assert pixel_l1 == pytest.approx(2.0) and shift["rel_l1"] < 0.15 * pixel_l1 and shift["rel_l1_2x"] < shift["rel_l1"]
    assert dark["rel_l1"] == pytest.approx(0.1, rel=1e-6) and dark["mean_ratio"] == pytest.approx(0.9, rel=1e-6)
    assert shift["mean_ratio"] == pytest.approx(1.0)


def test_radiance_ratio_skips_dark_tiles_and_finds_the_worst():
    ref = np.zeros((40, 40, 3))
    ref[:20] = 1.0  # the lower half is background
    test = ref.copy()
    test[:10, 20:] *= 0.5  # two lit tiles at half brightness
    r = radiance_ratio(test, ref, tile=10)
    assert r["tiles"] == 8 and r["worst_tile"] == [0, 2] and r["worst_tile_ratio"] == pytest.approx(0.5)
    assert r["mean_ratio"] == pytest.approx(1 - 0.5 * 200 / 800)


def test_ensemble_mean_ratio_and_spread_are_those_of_the_draws_means():
    """Draws that are the same image scaled by 0.9, 1.0 and 1.1: their means spread by 0.1 (sd over the mean), the
    ensemble's mean is the unscaled image's, and a test image 1.2× it has mean ratio 1.2; their leave-one-out rel L1
    is what the scaling gives (draw k against the mean of the other two)."""
    base = np.random.default_rng(1).uniform(0.1, 1.0, (40, 60, 3)).astype(np.float32)
    draws = [base * f for f in (0.9, 1.0, 1.1)]
    floor = ensemble_floor(draws, 4.0)
    assert floor["instances"] == 3 and floor["mean_sd"] == pytest.approx(0.1, rel=1e-5)
    assert floor["mean_se"] == pytest.approx(0.1 / math.sqrt(3), rel=1e-5)
    # draw 0.9 against (1.0 + 1.1)/2 = 1.05: |0.9 − 1.05|/1.05; draw 1.0 against 1.0: 0; draw 1.1 against 0.95
    assert floor["rel_l1_each"] == pytest.approx([0.15 / 1.05, 0.0, 0.15 / 0.95], rel=1e-5, abs=1e-7)
    row = ensemble_metrics(base * 1.2, draws, 4.0)
    assert row["mean_ratio"] == pytest.approx(1.2, rel=1e-5)
    assert row["rel_l1"] == pytest.approx(np.mean([0.15 / 1.05, 0.2, 0.25 / 0.95]), rel=1e-5)
    assert row["to_floor"] == pytest.approx(row["rel_l1"] / floor["rel_l1"])
    with pytest.raises(ValueError, match="at least 3"):
        ensemble_floor(draws[:2], 4.0)


def test_ensemble_the_draws_expectation_beats_one_draw():
    """Draws = one image plus independent fine-grained noise (a fiber instance's own deviations, finer than the yarn
    scale but not wholly averaged away by it): the noiseless image, what every draw scatters about, is closer to the
    others than any draw is (ratio to the ensemble floor < 1), and a 10 % brighter one is farther."""
    rng = np.random.default_rng(2)
    base = np.full((64, 64, 3), 0.5, np.float32)
    draws = [base + rng.normal(0.0, 0.2, base.shape).astype(np.float32) for _ in range(6)]
    assert ensemble_metrics(base, draws, 3.0)["to_floor"] < 0.6
    assert ensemble_metrics(1.1 * base, draws, 3.0)["to_floor"] > ensemble_metrics(base, draws, 3.0)["to_floor"]


def _striped(rng, shape=(96, 96), period=6.0):
    """An image of yarn-like stripes across x (a ply-scale pattern of ``period`` px) with a slow ramp, RGB."""
    x = np.arange(shape[1])[None, :] + rng.uniform(0, period)
    lum = 0.5 + 0.3 * np.sin(2 * np.pi * x / period) + 0.1 * np.arange(shape[0])[:, None] / shape[0]
    return np.repeat(np.broadcast_to(lum, shape)[..., None], 3, axis=2).astype(np.float64)


def test_sub_yarn_contrast_is_one_for_the_reference_and_scales_with_the_contrast_not_the_brightness():
    """C(test)/C(ref) per band: 1 for the reference itself and for it 3× brighter; 2 for its variation about the
    mean doubled (the band is linear and keeps the mean); below 1 for it blurred; None for a band that rounds to
    nothing at a tiny diameter."""
    ref = _striped(np.random.default_rng(0))
    d = 18.0
    same, bright = sub_yarn_contrast(ref, ref, d), sub_yarn_contrast(3.0 * ref, ref, d)
    hard = sub_yarn_contrast(ref.mean() + 2.0 * (ref - ref.mean()), ref, d)
    soft = sub_yarn_contrast(yarn_filter(ref, 5), ref, d)
    for band in CONTRAST_BANDS:
        assert same[band] == pytest.approx(1.0) and bright[band] == pytest.approx(1.0)
        assert hard[band] == pytest.approx(2.0) and same[f"{band}_noise"] == 0.0
    assert soft["ply"] < 0.5
    assert sub_yarn_contrast(ref, ref, 2.0)["ply"] is None  # d/6 and d/2 both round to 1 px


def test_sub_yarn_contrast_takes_the_path_tracers_noise_off_the_references():
    """A reference and its Monte Carlo floor = one image plus independent per-pixel noise (its variance at the ply
    scale about a quarter of the band's; the examples' references: up to a sixth): the noiseless image scores 1 at
    the ply scale only with the noise taken off (without it the noisy reference looks 'harder' and the image flatter,
    < 0.9), and a floor traced at the same spp (``test_traced``) scores 1 too."""
    rng = np.random.default_rng(1)
    clean = _striped(rng)
    noisy = [clean + rng.normal(0.0, 0.45, clean.shape) for _ in range(3)]
    ref, mc, other = noisy
    corrected = sub_yarn_contrast(clean, ref, 18.0, mc)
    assert corrected["ply"] == pytest.approx(1.0, abs=0.04) and 0.2 < corrected["ply_noise"] < 0.5
    assert sub_yarn_contrast(clean, ref, 18.0)["ply"] < 0.9
    assert sub_yarn_contrast(other, ref, 18.0, mc, test_traced=True)["ply"] == pytest.approx(1.0, abs=0.06)


def test_cli_compare_writes_a_complete_report(tmp_path, pack):
    scene = write_scene(tmp_path, [straight()], camera=FRONT, lights=SUN)
    out = tmp_path / "report"
    result = CliRunner().invoke(knitrun, ["compare", str(scene), "--spp", "1", "--pack", f"cotton1={pack}",
                                          "-o", str(out), "--json"])
    assert result.exit_code == 0, result.output
    summary = json.loads(result.stdout)
    assert set(summary["ablations"]) >= {"plain_ds", "xi", "xi_shadowing", "full"}
    # the FRONT camera: 30° vertical field of view, 48 rows, 1 cm from the yarn
    pixel = 2 * math.tan(math.radians(15)) / 48
    assert summary["yarn_px"] == pytest.approx(2 * load_preset("cotton1").radius / pixel)
    for row in summary["ablations"].values():
        assert 0 <= row["flip"] <= 1 and row["rmse"] >= 0 and row["speedup"] > 0
        assert set(row["contrast"]) >= set(CONTRAST_BANDS) and row["contrast"]["ply_noise"] > 0  # the MC floor's
        assert row["yarn"]["rel_l1"] >= 0 and row["yarn"]["mean_ratio"] > 0
        assert row["to_instance_floor"]["rel_l1"] == pytest.approx(
            row["yarn"]["rel_l1"] / summary["floors"]["instance"]["yarn"]["rel_l1"])
    floors = summary["floors"]
    assert floors["instance"]["image"]["fiber_seed"] == 1 and floors["monte_carlo"]["image"]["fiber_seed"] == 0
    assert floors["instance"]["image"]["seed"] == floors["monte_carlo"]["image"]["seed"] == 1
    for name in ("reference.exr", "reference.png", "report.md", "report.json", "side_by_side.png",
                 "strip_full.png", "flip_full.png", "diff_full.png", "floor_instance.exr", "floor_monte_carlo.png"):
        assert (out / name).is_file(), name
    report = (out / "report.md").read_text()
    assert "## Verdict" in report and "instance floor" in report and "FLIP" in report
    assert "ply-scale contrast" in report and "with the Monte Carlo floor" in report
    assert summary["ablations"]["full"]["xi"] == {
        "cotton1": "closed on the renderer at every view, apart on single and multiple scattering, multiple "
                   "scattering's closed in the yarn's colour"}
    assert summary["ablations"]["whole_xi"]["xi"] == {"cotton1": "closed on the renderer at every view"}
    assert summary["ablations"]["papers_xi"]["xi"] == {"cotton1": "the paper's"}
    assert "Rows drawn without the tables they ask for" not in report
    old = tmp_path / "schema22.h5"  # a pack from before the closure: every row shaded with the paper's ξ, and said
    shutil.copy(pack, old)
    with h5py.File(old, "r+") as f:
        for name in ("xi_closed", "xi_view", "radiance_view", "xi_closed_ss", "xi_closed_ms", "xi_view_ss",
                     "xi_view_ms", "radiance_view_ss"):
            del f[f"correction/{name}"], f[f"correction/{name}_stderr"]
    # with a third draw the report adds the ensemble (here the Monte Carlo floor stands in for a further fiber
    # instance: the plumbing is what is tested; ``test_ensemble_*`` test the statistics)
    again = CliRunner().invoke(knitrun, ["compare", str(scene), "--reference", str(out / "reference.exr"),
                                         "--instance-floor", str(out / "floor_instance.exr"),
                                         "--instance", str(out / "floor_monte_carlo.exr"),
                                         "--pack", f"cotton1={old}", "-o", str(tmp_path / "r2"), "--json"])
    assert again.exit_code == 0, again.output
    given = json.loads(again.stdout)
    assert set(given["floors"]) == {"instance"}
    assert given["ablations"]["full"]["xi"] == {"cotton1": "the paper's (the pack has no correction/xi_closed)"}
    assert "ξ of the full model: cotton1: the paper's (the pack has no" in (tmp_path / "r2" / "report.md").read_text()
    lacking = [line for line in (tmp_path / "r2" / "report.md").read_text().splitlines()
               if line.startswith("Rows drawn without the tables they ask for: ")]
    assert len(lacking) == 1 and ("full with one ξ closed on single and multiple scattering together: cotton1: ξ the "
                                  "paper's (the pack has no correction/xi_closed)") in lacking[0]
    draws = [read_exr(out / f) for f in ("reference.exr", "floor_instance.exr", "floor_monte_carlo.exr")]
    assert given["ensemble"]["instances"] == 3 and given["ensemble"]["files"] == [str(out / "floor_monte_carlo.exr")]
    strip = read_exr(tmp_path / "r2" / "strip_full.exr")
    assert given["ablations"]["full"]["ensemble"]["mean_ratio"] == pytest.approx(
        (strip @ LUMINANCE).mean() / np.mean([(d @ LUMINANCE).mean() for d in draws]), rel=1e-5)
    assert "## Against 3 fiber instances" in (tmp_path / "r2" / "report.md").read_text()
    lone = CliRunner().invoke(knitrun, ["compare", str(scene), "--instance", str(out / "floor_monte_carlo.exr"),
                                        "-o", str(tmp_path / "r4")])
    assert lone.exit_code != 0 and "at least 3 fiber instances" in lone.output
    for key in ("rel_l1", "rel_l1_2x", "flip", "mean_ratio"):  # the same floor, read instead of traced
        assert given["floors"]["instance"]["yarn"][key] == pytest.approx(floors["instance"]["yarn"][key])
    bad = CliRunner().invoke(knitrun, ["compare", str(scene), "--reference", str(out / "reference.exr"), "--spp", "4",
                                       "-o", str(tmp_path / "r3")])
    assert bad.exit_code != 0 and "exclude" in bad.output



@pytest.mark.slow
def test_the_full_model_keeps_the_straight_yarns_brightness(tmp_path):
    """Brightness is the first thing a user sees: on the example straight yarn under the directional light, the full
    model's mean radiance stays within ±10 % of the path-traced reference's (cotton1 at standard quality, the
    reference at the scene's spp; about a minute with the bake's stages in the cache, ~20 min without)."""
    scene = load_scene(EXAMPLES / "straight_yarn_directional.toml")
    pack = tmp_path / "cotton1.h5"
    bake(load_preset("cotton1"), pack, quality="standard")
    reference, _ = trace_reference(scene, scene.render.spp, scene.render.seed, scene.render.max_depth)
    image = render(scene, {"cotton1": str(pack)}).image
    ratio = radiance_ratio(image, reference, tile=64)["mean_ratio"]
    assert 0.9 <= ratio <= 1.1, f"full model at {ratio:.3f} of the reference's mean radiance"
