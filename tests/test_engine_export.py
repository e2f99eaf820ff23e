"""Engine-ready export (``data_formats.engine_export``, ASSET_PACK.md §14): the .bin files and manifest alone give
back the pack's tables, exactly as float32 and within float16 rounding; RGB tables are RGBA with A = 0; the
manifest passes the shipped JSON Schema; a damaged export is named in one line; bad input writes nothing."""

import json

import h5py
import numpy as np
import pytest
from click.testing import CliRunner

from cli.knitbake_cli import main as knitbake
from data_formats import FormatError
from data_formats.asset_pack import read_pack
from data_formats.engine_export import export_engine, read_export, schema, validate_export
from tests.helpers import write_full


@pytest.fixture(scope="module")
def pack(tmp_path_factory):
    path = tmp_path_factory.mktemp("pack") / "full.h5"
    write_full(path)
    return path


def test_float32_export_reads_back_exactly_from_the_bin_files_alone(pack, tmp_path):
    manifest = export_engine(pack, tmp_path / "exp")
    tables = read_pack(pack).tables
    back = read_export(tmp_path / "exp")
    assert set(back) == set(tables)
    for name, arr in tables.items():
        assert back[name].dtype == np.float32 and np.array_equal(back[name], arr), name
    rgb = [t for t in manifest["tables"] if t["padded_from"] == 3]
    assert rgb and all(t["shape"][-1] == 4 and t["source_shape"][-1] == 3 for t in rgb)
    raw = np.fromfile(tmp_path / "exp" / rgb[0]["file"], "<f4").reshape(rgb[0]["shape"])
    assert np.all(raw[..., 3] == 0)
    on_disk = json.loads((tmp_path / "exp" / "manifest.json").read_text())
    import jsonschema

    jsonschema.validate(on_disk, schema())
    assert validate_export(tmp_path / "exp") == []


def test_float16_export_is_within_half_precision_rounding(pack, tmp_path):
    export_engine(pack, tmp_path / "exp", dtype="float16")
    back = read_export(tmp_path / "exp")
    for name, arr in read_pack(pack).tables.items():
        a = np.asarray(arr, np.float64)
        assert back[name].dtype == np.float16
        # round to nearest: half an ulp, 2^-11 relative for normal numbers, 2^-25 absolute below them
        assert np.all(np.abs(back[name] - a) <= np.maximum(np.abs(a) * 2.0**-11, 2.0**-25)), name


def test_float16_refuses_values_it_cannot_hold_and_writes_nothing(pack, tmp_path):
    big = tmp_path / "big.h5"
    big.write_bytes(pack.read_bytes())
    with h5py.File(big, "a") as f:
        f["correction/xi"][...] = 1e5
    with pytest.raises(FormatError, match=r"correction/xi holds 100000, beyond float16's 65504"):
        export_engine(big, tmp_path / "exp", dtype="float16")
    assert not (tmp_path / "exp").exists()
    result = CliRunner().invoke(knitbake, ["export", str(tmp_path / "missing.h5"), str(tmp_path / "exp")])
    assert result.exit_code == 1 and not (tmp_path / "exp").exists()


@pytest.mark.parametrize("damage, message", [
    (lambda d, m: (d / m["tables"][0]["file"]).unlink(), "missing"),
    (lambda d, m: (d / m["tables"][0]["file"]).write_bytes(b"\0" * 4), "4 bytes"),
    (lambda d, m: np.full(m["tables"][0]["shape"], np.inf, "<f4").tofile(d / m["tables"][0]["file"]), "non-finite"),
    (lambda d, m: (d / "manifest.json").write_text(json.dumps({**m, "tables": [{**m["tables"][0],
                                                                                "dtype": "float64"}]})),
     "dtype: 'float64' is not one of"),
    (lambda d, m: (d / "manifest.json").write_text("{not json"), "not JSON"),
])
def test_a_damaged_export_is_named_in_one_line(pack, tmp_path, damage, message):
    manifest = export_engine(pack, tmp_path / "exp")
    damage(tmp_path / "exp", manifest)
    problems = validate_export(tmp_path / "exp")
    assert problems and message in problems[0] and all("\n" not in p for p in problems), problems
    with pytest.raises(FormatError, match="exp"):
        read_export(tmp_path / "exp")
    result = CliRunner().invoke(knitbake, ["validate", str(tmp_path / "exp" / "manifest.json")])
    recognised = message != "not JSON"  # text that is not JSON is no manifest: "not a file the toolchain reads"
    assert result.exit_code == 1 and (message if recognised else "not a file the toolchain reads") in result.output


def test_the_cli_exports_bin_by_default_and_csv_on_request(pack, tmp_path):
    runner = CliRunner()
    result = runner.invoke(knitbake, ["export", str(pack), str(tmp_path / "bin"), "--dtype", "float16"])
    assert result.exit_code == 0 and "as float16 .bin" in result.output, result.output
    assert (tmp_path / "bin" / "manifest.json").is_file() and not list((tmp_path / "bin").glob("*.csv"))
    assert "engine-export" in runner.invoke(knitbake, ["inspect", str(tmp_path / "bin" / "manifest.json")]).output
    result = runner.invoke(knitbake, ["export", str(pack), str(tmp_path / "csv"), "--csv"])
    assert result.exit_code == 0 and list((tmp_path / "csv").glob("*.csv"))
    assert not list((tmp_path / "csv").glob("*.bin"))
