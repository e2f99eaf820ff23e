"""The command-line contract: examples in --help, JSON output, one-line errors and exit codes, no partial files."""

import json
from pathlib import Path

import numpy as np
import pytest
from click.testing import CliRunner

from cli.knitbake_cli import main as knitbake
from cli.knitrun_cli import main as knitrun
from data_formats.stitch_mesh import write_obj_stitch_mesh
from data_formats.yarn_spec import load_preset, loads_spec, preset_names
from tests.helpers import sample, write_full


def run(prog, *args):
    return CliRunner().invoke(prog, [str(a) for a in args], catch_exceptions=False)


def assert_one_line_error(result, *fragments):
    assert result.exit_code == 1, result.output
    lines = result.stderr.strip().splitlines()
    assert len(lines) == 1 and "error:" in lines[0] and "Traceback" not in result.stderr, result.stderr
    for fragment in fragments:
        assert fragment in lines[0]


@pytest.mark.parametrize("args", [[], ["yarn"], ["yarn", "list"], ["yarn", "show"], ["inspect"], ["validate"],
                                  ["fibers"]])
def test_knitbake_help_has_an_example(args):
    result = run(knitbake, *args, "--help")
    assert result.exit_code == 0 and "Example" in result.output


def test_knitrun_help_has_an_example():
    for args in ([], ["convert"]):
        result = run(knitrun, *args, "--help")
        assert result.exit_code == 0 and "Example" in result.output


def test_yarn_list_and_json():
    result = run(knitbake, "yarn", "list")
    assert result.exit_code == 0 and all(name in result.output for name in preset_names())
    rows = json.loads(run(knitbake, "yarn", "list", "--json").stdout)
    assert [r["name"] for r in rows] == preset_names()


def test_yarn_show_preset_file_and_toml(tmp_path):
    shown = run(knitbake, "yarn", "show", "rayon1")
    assert shown.exit_code == 0 and "fiber_pitch" in shown.output and "provenance" in shown.output
    toml_text = run(knitbake, "yarn", "show", "rayon1", "--toml").output
    assert loads_spec(toml_text) == load_preset("rayon1")
    path = tmp_path / "mine.toml"
    path.write_text(toml_text.replace('name = "rayon1"', 'name = "mine"'))
    assert json.loads(run(knitbake, "yarn", "show", path, "--json").stdout)["name"] == "mine"


def test_yarn_show_unknown_and_bad_spec(tmp_path):
    assert_one_line_error(run(knitbake, "yarn", "show", "nope"), "nope", "cotton1")
    bad = tmp_path / "bad.toml"
    bad.write_text(run(knitbake, "yarn", "show", "cotton1", "--toml").output.replace("density_eps = 0.0",
                                                                                     "density_eps = 0.9"))
    assert_one_line_error(run(knitbake, "yarn", "show", bad), "density_eps", "0.9", "[0, 0.5]")


@pytest.mark.parametrize("suffix,kind", [(".bcc", "bcc"), (".h5", "yarn-curves")])
def test_fibers_inspect_validate(tmp_path, suffix, kind):
    out = tmp_path / f"f{suffix}"
    png = tmp_path / "p.png"
    result = run(knitbake, "fibers", "cotton1", "-o", out, "--preview", png, "--json")
    assert result.exit_code == 0, result.output
    summary = json.loads(result.stdout)
    assert summary["regular"] == 225 and png.stat().st_size > 1000 and summary["preview"]["coverage"] > 0.1
    info = json.loads(run(knitbake, "inspect", out, "--json").stdout)
    assert info["kind"] == kind and info["curves"] == summary["fibers"]
    valid = run(knitbake, "validate", out)
    assert valid.exit_code == 0 and "valid" in valid.output
    # the same file cut short is rejected with reasons
    data = out.read_bytes()
    out.write_bytes(data[: len(data) // 2])
    invalid = run(knitbake, "validate", out)
    assert invalid.exit_code == 1 and "INVALID" in invalid.stderr


def test_fibers_same_seed_same_file(tmp_path):
    a, b = tmp_path / "a.bcc", tmp_path / "b.bcc"
    for path in (a, b):
        assert run(knitbake, "fibers", "silk1", "-o", path, "--seed", 4).exit_code == 0
    assert a.read_bytes() == b.read_bytes()


def test_fibers_bad_input(tmp_path):
    assert_one_line_error(run(knitbake, "fibers", "cotton1", "-o", tmp_path / "x.txt"), "x.txt", ".bcc")
    assert_one_line_error(run(knitbake, "fibers", "cotton1", "-o", tmp_path / "missing" / "x.bcc"), "missing")
    assert not (tmp_path / "missing").exists()
    assert run(knitbake, "fibers", "cotton1", "-o", tmp_path / "x.bcc", "--periods", "-1").exit_code == 2
    assert list(tmp_path.iterdir()) == []


def test_inspect_and_validate_pack(tmp_path):
    pack = tmp_path / "p.h5"
    write_full(pack)
    result = run(knitbake, "inspect", pack)
    assert result.exit_code == 0 and "error" in result.output and "correction/xi_M" in result.output
    info = json.loads(run(knitbake, "inspect", pack, "--json").stdout)
    assert info["kind"] == "asset-pack" and all("error_estimate" in t for t in info["tables"].values())
    assert run(knitbake, "validate", pack).exit_code == 0


def test_inspect_spec_and_unknown_files(tmp_path):
    spec_info = json.loads(run(knitbake, "inspect", "data_formats/presets/silk2.toml", "--json").stdout)
    assert spec_info["kind"] == "yarn-spec" and spec_info["name"] == "silk2"
    junk = tmp_path / "junk.bin"
    junk.write_bytes(b"\x00\x01 not a knit file")
    assert_one_line_error(run(knitbake, "inspect", junk), "junk.bin", "not a file the toolchain reads")
    assert_one_line_error(run(knitbake, "validate", tmp_path / "absent.h5"), "absent.h5", "no such file")


def test_inspect_reports_contact_only_with_a_known_radius(tmp_path):
    """Yarn curves without a radius say how to get the contact statistic; ``--radius`` gives it, on the first and
    the last frame; ``--radius`` on another kind of file is a one-line error."""
    bcc = tmp_path / "a.bcc"
    assert run(knitbake, "fibers", "rayon2", "-o", bcc, "--no-flyaways").exit_code == 0
    assert "pass --radius" in json.loads(run(knitbake, "inspect", bcc, "--json").stdout)["contact"]
    contact = json.loads(run(knitbake, "inspect", bcc, "--radius", "0.0004", "--json").stdout)["contact"]
    assert contact["frames_evaluated"] == [0] and contact["worst"]["radius"] == 0.0004
    assert 0 < contact["worst"]["p5"] <= contact["worst"]["p50"]
    assert_one_line_error(run(knitbake, "inspect", "data_formats/presets/silk2.toml", "--radius", "1"), "--radius")
    assert run(knitbake, "inspect", bcc, "--radius", "0").exit_code == 2


def test_inspect_and_validate_an_obj_stitch_mesh(tmp_path):
    obj = tmp_path / "m.obj"
    write_obj_stitch_mesh(obj, sample())
    info = json.loads(run(knitbake, "inspect", obj, "--json").stdout)
    assert info["kind"] == "stitch-mesh-obj" and info["faces"] == 11 and info["labels"] == str(tmp_path / "m.labels")
    assert run(knitbake, "validate", obj).stdout.strip() == f"{obj}: valid stitch-mesh-obj"
    (tmp_path / "m.labels").write_text("knit\n")  # 1 label for 11 faces
    invalid = run(knitbake, "validate", obj)
    assert invalid.exit_code == 1 and "INVALID stitch-mesh-obj" in invalid.stderr and "1 labels" in invalid.stderr


def test_knitrun_convert_round_trip(tmp_path):
    bcc, h5, back = tmp_path / "a.bcc", tmp_path / "a.h5", tmp_path / "b.bcc"
    assert run(knitbake, "fibers", "rayon2", "-o", bcc, "--no-flyaways").exit_code == 0
    assert run(knitrun, "convert", bcc, h5).exit_code == 0
    assert run(knitrun, "convert", h5, back).exit_code == 0
    assert json.loads(run(knitbake, "inspect", back, "--json").stdout)["points"] == \
        json.loads(run(knitbake, "inspect", bcc, "--json").stdout)["points"]
    assert_one_line_error(run(knitrun, "convert", "data_formats/presets/silk2.toml", tmp_path / "c.bcc"), "yarn-spec")


def test_reference_renders_exr_png_and_json(tmp_path):
    from data_formats.images import read_exr

    scene = tmp_path / "s.toml"
    curves = (Path("examples/scenes/straight_yarn.h5")).resolve()
    scene.write_text(f'''format = "knit-scene"
version = "1.0"
units = "cm"
[[yarns]]
curves = "{curves}"
yarn = "silk1"
[camera]
position = [0.0, 0.0, 1.0]
look_at = [0.0, 0.0, 0.0]
ortho_height = 0.12
width = 48
height = 16
[[lights]]
type = "directional"
direction = [0.3, 1.0, 0.5]
irradiance = [2.0, 2.0, 2.0]
[[lights]]
type = "environment"
builtin = "sky"
''')
    out = tmp_path / "r.exr"
    result = run(knitbake, "reference", scene, "-o", out, "--spp", 2, "--fiber-seed", 3, "--json")
    assert result.exit_code == 0, result.output + result.stderr
    summary = json.loads(result.stdout)
    assert (summary["seed"], summary["fiber_seed"]) == (0, 3)
    assert json.loads(out.with_suffix(".json").read_text()) == summary  # the library wrote what the CLI printed
    image = read_exr(out)
    assert image.shape == (16, 48, 3) and np.all(np.isfinite(image)) and image.max() > 0
    assert (tmp_path / "r.png").stat().st_size > 100 and summary["rays_per_s"] > 0
    assert summary["geometry"] == "curves" and summary["segments"] > 0 and summary["triangles"] == 0
    tubes = json.loads(run(knitbake, "reference", scene, "-o", tmp_path / "t.exr", "--spp", 2, "--fiber-seed", 3,
                           "--geometry", "tubes", "--json").stdout)
    assert tubes["triangles"] > 0 and tubes["segments"] == summary["segments"]
    assert_one_line_error(run(knitbake, "reference", scene, "-o", tmp_path / "r.png"), ".exr")
    assert_one_line_error(run(knitbake, "reference", tmp_path / "none.toml", "-o", out), "none.toml")
