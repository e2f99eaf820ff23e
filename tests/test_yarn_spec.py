"""Yarn spec: presets (content, regeneration from the reference tables), TOML round trips, one-line validation
messages, atomic writes, preset resolution, the inspect hooks, and the agreement of YARN_SPEC.md with the code."""

import importlib.util
import json
import math
import os
import re
from pathlib import Path

import pytest

from data_formats import yarn_spec as ys
from data_formats.errors import FormatError

ROOT = Path(__file__).resolve().parents[1]
REFERENCE = ROOT.parent / "shared" / "reference"
DOC = ROOT / "data_formats" / "YARN_SPEC.md"
PRESETS = ys.preset_names()


def test_there_are_presets():
    assert len(PRESETS) >= 1
    assert "cotton1" in PRESETS


# --- presets -------------------------------------------------------------------------------------------------------

@pytest.mark.parametrize("name", PRESETS)
def test_preset_loads_with_provenance_and_plausible_packing(name):
    spec = ys.load_preset(name)
    assert spec.name == name
    assert spec.units == "cm"
    for key in ("geometry", "flyaways", "optics", "fiber_radius"):
        assert isinstance(spec.provenance.get(key), str) and spec.provenance[key].strip(), key
    g = spec.geometry
    a, b = g.ply_semi_axes
    packing = g.fibers_per_ply * math.pi * g.fiber_radius ** 2 / (math.pi * a * b)
    assert 0.05 <= packing <= 0.6, f"{name}: fiber packing fraction {packing:.3f} outside [0.05, 0.6]"


def _make_presets_module():
    path = ROOT / "scripts" / "make_presets.py"
    spec = importlib.util.spec_from_file_location("_make_presets_under_test", path)
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


@pytest.mark.skipif(not REFERENCE.is_dir(), reason=f"reference tables not found at {REFERENCE}")
def test_committed_presets_equal_regenerated():
    mp = _make_presets_module()
    yarns = mp.read_csv(REFERENCE / "yarn_params_zhao2016.csv")
    flyaways = mp.read_csv(REFERENCE / "flyaway_params_zhao2016.csv")
    optics = mp.read_csv(REFERENCE / "fiber_bcsdf_khungurn2015.csv")
    assert sorted(yarns) == PRESETS, "presets/ and the reference yarn table list different yarns"
    for name, y in yarns.items():
        expected = ys.spec_to_dict(mp.preset(name, y, flyaways[name], optics))
        committed = ys.spec_to_dict(ys.load_preset(name))
        assert committed == expected, f"presets/{name}.toml is stale: run scripts/make_presets.py"


# --- round trips ---------------------------------------------------------------------------------------------------

@pytest.mark.parametrize("name", PRESETS)
def test_toml_round_trip(name, tmp_path):
    spec = ys.load_preset(name)
    assert ys.loads_spec(ys.dumps_spec(spec)) == spec
    path = tmp_path / f"{name}.toml"
    ys.save_spec(path, spec)
    assert ys.load_spec(path) == spec
    assert sorted(p.name for p in tmp_path.iterdir()) == [path.name]  # no temporary left behind


def test_round_trip_fills_defaults():
    spec = ys.loads_spec(_render(_base()))
    assert spec.flyaways.hair_curvature_alpha == 1.0
    assert spec.optics.d_color == (0.0, 0.0, 0.0)
    assert spec.geometry.migration_rho_max == 1.0
    assert not spec.has_flyaways
    assert ys.loads_spec(ys.dumps_spec(spec)) == spec


# --- validation messages -------------------------------------------------------------------------------------------

def _base():
    """A small valid spec as TOML literals: {section or "": {key: literal}}."""
    return {
        "": {"format": '"knit-yarn-spec"', "version": '"1.0"', "name": '"test"', "units": '"cm"'},
        "provenance": {"geometry": '"made up"'},
        "geometry": {"plies": "3", "fibers_per_ply": "40", "ply_pitch": "0.4", "fiber_pitch": "0.3",
                     "ply_distance": "0.02", "ply_semi_axes": "[0.02, 0.01]", "fiber_radius": "0.0008",
                     "density_eps": "0.1", "density_beta": "0.5", "migration_rho_min": "0.8",
                     "migration_frequency": "1.0"},
        "flyaways": {},
        "optics": {"r_color": "[0.5, 0.5, 0.5]", "tt_color": "[0.5, 0.5, 0.5]", "beta_r_deg": "5.0",
                   "beta_tt_deg": "10.0", "gamma_tt_deg": "25.0"},
    }


def _render(tables):
    lines = [f"{k} = {v}" for k, v in tables[""].items()]
    for section, body in tables.items():
        if section:
            lines.append(f"[{section}]")
            lines += [f"{k} = {v}" for k, v in body.items()]
    return "\n".join(lines) + "\n"


def _set(section, key, literal):
    def mutate(t):
        t[section][key] = literal
    return mutate


def _del(section, key):
    def mutate(t):
        del t[section][key]
    return mutate


def _both(*mutations):
    def mutate(t):
        for m in mutations:
            m(t)
    return mutate


BAD = [
    ("missing-required", _del("geometry", "plies"), ["[geometry] plies", "missing", "required", "[1, 16]"]),
    ("missing-required-optics", _del("optics", "gamma_tt_deg"), ["[optics] gamma_tt_deg", "missing", "[0.001, 180]"]),
    ("missing-name", _del("", "name"), ["name", "None", "non-empty string"]),
    ("eps-out-of-range", _set("geometry", "density_eps", "0.7"), ["[geometry] density_eps", "0.7", "[0, 0.5]"]),
    ("plies-zero", _set("geometry", "plies", "0"), ["[geometry] plies", "= 0", "[1, 16]"]),
    ("negative-std", _set("flyaways", "loop_radius_std", "-0.1"), ["[flyaways] loop_radius_std", "-0.1", "[0, 1e+06]"]),
    ("string-for-float", _set("geometry", "ply_pitch", '"abc"'), ["[geometry] ply_pitch", "'abc'", "not a number"]),
    ("float-for-int", _set("geometry", "fibers_per_ply", "40.0"),
     ["[geometry] fibers_per_ply", "40.0", "integer", "[1, 1000]"]),
    ("bool-for-float", _set("optics", "beta_r_deg", "true"), ["[optics] beta_r_deg", "true", "not a number"]),
    ("bool-for-int", _set("geometry", "plies", "true"), ["[geometry] plies", "true", "integer", "[1, 16]"]),
    ("number-for-bool", _set("geometry", "ply_clockwise", "1"), ["[geometry] ply_clockwise", "1", "true or false"]),
    ("nan", _set("geometry", "density_beta", "nan"), ["[geometry] density_beta", "nan", "not finite", "[0, 100]"]),
    ("inf", _set("geometry", "fiber_pitch", "inf"), ["[geometry] fiber_pitch", "inf", "not finite", "[1e-06, 1e+06]"]),
    ("-inf-in-list", _set("optics", "r_color", "[0.5, -inf, 0.5]"), ["[optics] r_color", "-inf", "not finite", "[0, 1]"]),
    ("nan-in-pair", _set("geometry", "ply_semi_axes", "[nan, 0.01]"), ["[geometry] ply_semi_axes", "nan", "not finite"]),
    ("pair-too-short", _set("geometry", "ply_semi_axes", "[0.02]"),
     ["[geometry] ply_semi_axes", "[0.02]", "list of 2 numbers", "[1e-09, 1e+06]"]),
    ("pair-too-long", _set("geometry", "ply_semi_axes", "[0.02, 0.01, 0.01]"),
     ["[geometry] ply_semi_axes", "[0.02, 0.01, 0.01]", "list of 2 numbers"]),
    ("pair-not-list", _set("geometry", "ply_semi_axes", "0.02"), ["[geometry] ply_semi_axes", "0.02", "list of 2"]),
    ("rgb-too-short", _set("optics", "r_color", "[0.5, 0.5]"), ["[optics] r_color", "[0.5, 0.5]", "list of 3 numbers", "[0, 1]"]),
    ("rgb-element-out-of-range", _set("optics", "tt_color", "[0.5, 1.5, 0.5]"), ["[optics] tt_color", "1.5", "[0, 1]"]),
    ("unknown-key-in-section", _set("geometry", "plys", "3"), ["[geometry]", "unknown key", "'plys'", "plies"]),
    ("unknown-key-in-optics", _set("optics", "colour", "[1, 1, 1]"), ["[optics]", "unknown key", "'colour'", "r_color"]),
    ("unknown-top-level-key", _set("", "colour", '"red"'), ["unknown top-level key", "'colour'", "units"]),
    ("bad-units", _set("", "units", '"inch"'), ["units", "'inch'", "mm, cm, m"]),
    ("units-not-string", _set("", "units", "1"), ["units", "1", "mm, cm, m"]),
    ("unknown-major", _set("", "version", '"2.0"'), ["version", "'2.0'", "major", "1.0"]),
    ("wrong-format", _set("", "format", '"knit-asset-pack"'), ["format", "'knit-asset-pack'", "'knit-yarn-spec'"]),
    ("provenance-not-strings", _set("provenance", "seed", "7"), ["[provenance]", "table of strings"]),
    ("rho-min-above-max", _both(_set("geometry", "migration_rho_min", "0.9"), _set("geometry", "migration_rho_max", "0.8")),
     ["[geometry] migration_rho_min", "0.9", "migration_rho_max = 0.8"]),
    ("fiber-radius-equals-semi-axis", _set("geometry", "fiber_radius", "0.01"),
     ["[geometry] fiber_radius", "0.01", "smallest ply semi-axis", "(0, 0.01)"]),
    ("fiber-radius-above-semi-axis", _set("geometry", "fiber_radius", "0.05"), ["[geometry] fiber_radius", "0.05", "(0, 0.01)"]),
    ("plies-without-distance", _set("geometry", "ply_distance", "0.0"),
     ["[geometry] ply_distance", "0.0", "> 0", "plies = 3"]),
    ("hair-without-start-radius", _set("flyaways", "hair_density", "10.0"),
     ["[flyaways] hair_start_radius_mean", "0.0", "> 0", "hair_density"]),
    ("loop-without-radius", _set("flyaways", "loop_density", "10.0"),
     ["[flyaways] loop_radius_mean", "0.0", "> 0", "loop_density"]),
]


@pytest.mark.parametrize("mutate, expected", [pytest.param(m, e, id=i) for i, m, e in BAD])
def test_bad_input_message(mutate, expected):
    tables = _base()
    mutate(tables)
    with pytest.raises(FormatError) as info:
        ys.loads_spec(_render(tables), "bad.toml")
    msg = str(info.value)
    assert "\n" not in msg and "\r" not in msg, f"message is not one line: {msg!r}"
    assert msg.startswith("bad.toml: "), msg
    for part in expected:
        assert part.lower() in msg.lower(), f"{part!r} not in {msg!r}"


@pytest.mark.parametrize("text", ["name = \n", "[geometry\nplies = 3\n", 'name = "a"\nname = "b"\n', "a = [1,\n\n"])
def test_invalid_toml_is_one_line(text):
    with pytest.raises(FormatError) as info:
        ys.loads_spec(text, "broken.toml")
    msg = str(info.value)
    assert msg.startswith("broken.toml: not valid TOML"), msg
    assert "\n" not in msg


def test_base_spec_is_valid():
    spec = ys.loads_spec(_render(_base()))
    assert spec.geometry.plies == 3 and spec.geometry.ply_semi_axes == (0.02, 0.01)


@pytest.mark.parametrize("version", ['"1.7"', '"1.0"', '"1.12"'])
def test_higher_minor_version_is_accepted(version):
    tables = _base()
    tables[""]["version"] = version
    assert ys.loads_spec(_render(tables)).name == "test"


def test_missing_format_and_version_are_assumed():
    tables = _base()
    del tables[""]["format"], tables[""]["version"]
    assert ys.loads_spec(_render(tables)).name == "test"


def test_higher_minor_version_with_new_optional_key_is_accepted():
    tables = _base()
    tables[""]["version"] = '"1.1"'
    tables["optics"]["d_roughness"] = "0.3"
    assert ys.loads_spec(_render(tables)).name == "test"


def test_huge_integer_is_a_format_error():
    tables = _base()
    tables["geometry"]["ply_pitch"] = "1" + "0" * 400
    with pytest.raises(FormatError, match=r"\[geometry\] ply_pitch"):
        ys.loads_spec(_render(tables))


# --- atomic writes -------------------------------------------------------------------------------------------------

def _boom(*args, **kwargs):
    raise RuntimeError("serialisation failed")


def test_save_is_atomic_when_serialisation_fails(tmp_path, monkeypatch):
    monkeypatch.setattr(ys, "dumps_spec", _boom)
    with pytest.raises(RuntimeError):
        ys.save_spec(tmp_path / "out.toml", ys.load_preset("cotton1"))
    assert list(tmp_path.iterdir()) == []


def test_save_is_atomic_when_the_writer_fails(tmp_path, monkeypatch):
    real_write = Path.write_text

    def half_write(self, text, *args, **kwargs):
        real_write(self, text[: len(text) // 2], *args, **kwargs)
        raise OSError("disk full")

    monkeypatch.setattr(Path, "write_text", half_write)
    with pytest.raises(OSError, match="disk full"):
        ys.save_spec(tmp_path / "out.toml", ys.load_preset("cotton1"))
    monkeypatch.undo()
    assert list(tmp_path.iterdir()) == []


@pytest.mark.parametrize("failure", ["dumps", "writer"])
def test_save_failure_leaves_existing_file_untouched(tmp_path, monkeypatch, failure):
    target = tmp_path / "cotton1.toml"
    target.write_text("old content\n", encoding="utf-8")
    before = target.stat().st_mtime_ns
    if failure == "dumps":
        monkeypatch.setattr(ys, "dumps_spec", _boom)
    else:
        monkeypatch.setattr(Path, "write_text", _boom)
    with pytest.raises(RuntimeError):
        ys.save_spec(target, ys.load_preset("cotton1"))
    monkeypatch.undo()
    assert target.read_text(encoding="utf-8") == "old content\n"
    assert target.stat().st_mtime_ns == before
    assert [p.name for p in tmp_path.iterdir()] == ["cotton1.toml"]


def test_save_into_missing_folder_is_a_format_error(tmp_path):
    with pytest.raises(FormatError, match="does not exist"):
        ys.save_spec(tmp_path / "nope" / "out.toml", ys.load_preset("cotton1"))


# --- resolve_yarn --------------------------------------------------------------------------------------------------

def test_resolve_preset_name():
    assert ys.resolve_yarn("silk1") == ys.load_preset("silk1")


def test_resolve_file_path(tmp_path):
    path = tmp_path / "mine.toml"
    path.write_text(_render(_base()), encoding="utf-8")
    assert ys.resolve_yarn(str(path)).name == "test"
    assert ys.resolve_yarn(path).name == "test"


def test_resolve_unknown_name_lists_presets():
    with pytest.raises(FormatError) as info:
        ys.resolve_yarn("wool7")
    msg = str(info.value)
    assert "'wool7'" in msg and "\n" not in msg
    for name in PRESETS:
        assert name in msg


def test_load_unknown_preset_lists_presets():
    with pytest.raises(FormatError) as info:
        ys.load_preset("wool7")
    assert all(name in str(info.value) for name in PRESETS)


# --- sniff / validate / describe -----------------------------------------------------------------------------------

def test_sniff(tmp_path):
    assert ys.sniff(ys.PRESET_DIR / "cotton1.toml")
    spec_file = tmp_path / "spec.toml"
    spec_file.write_text(_render(_base()), encoding="utf-8")
    assert ys.sniff(spec_file)
    other = tmp_path / "pyproject.toml"
    other.write_text('[project]\nname = "x"\nversion = "1"\n[tool.ruff]\nline-length = 120\n', encoding="utf-8")
    assert not ys.sniff(other)
    binary = tmp_path / "pack.h5"
    binary.write_bytes(b"\x89HDF\r\n\x1a\n" + bytes(range(256)) * 8)
    assert not ys.sniff(binary)
    assert not ys.sniff(tmp_path / "missing.toml")
    assert not ys.sniff(tmp_path)  # a folder


def test_validate(tmp_path):
    assert ys.validate(ys.PRESET_DIR / "cotton1.toml") == []
    bad = tmp_path / "bad.toml"
    tables = _base()
    tables["geometry"]["density_eps"] = "0.7"
    bad.write_text(_render(tables), encoding="utf-8")
    problems = ys.validate(bad)
    assert len(problems) == 1 and "density_eps" in problems[0] and "\n" not in problems[0]
    missing = ys.validate(tmp_path / "missing.toml")
    assert len(missing) == 1 and "missing.toml" in missing[0]
    binary = tmp_path / "blob.toml"
    binary.write_bytes(b"\xff\xfe\x00garbage")
    assert len(ys.validate(binary)) == 1


@pytest.mark.parametrize("name", PRESETS)
def test_describe_is_json(name):
    d = ys.describe(ys.PRESET_DIR / f"{name}.toml")
    text = json.dumps(d)
    assert json.loads(text)["name"] == name
    spec = ys.load_preset(name)
    assert d["kind"] == "yarn-spec"
    assert d["fibers"] == spec.geometry.plies * spec.geometry.fibers_per_ply
    assert d["period"] == spec.geometry.ply_pitch
    assert d["radius"] > max(spec.geometry.ply_semi_axes)
    assert ys.spec_from_dict(d["spec"]) == spec


# --- YARN_SPEC.md --------------------------------------------------------------------------------------------------

def _doc():
    return DOC.read_text(encoding="utf-8")


def test_doc_field_table_is_generated():
    doc = _doc()
    assert doc.count("<!-- fields:begin -->") == 1 and doc.count("<!-- fields:end -->") == 1
    inner = doc.split("<!-- fields:begin -->", 1)[1].split("<!-- fields:end -->", 1)[0]
    assert inner.strip("\n") == ys.schema_markdown(), \
        "YARN_SPEC.md is out of date: paste yarn_spec.schema_markdown() between the fields markers"


def test_doc_examples_load():
    blocks = re.findall(r"```toml\n(.*?)```", _doc(), flags=re.S)
    assert len(blocks) >= 2
    assert ys.loads_spec(blocks[0], "YARN_SPEC.md example") == ys.load_preset("cotton1")
    for block in blocks[1:]:
        ys.loads_spec(block, "YARN_SPEC.md example")


def test_doc_names_every_preset_and_cross_check():
    doc = _doc()
    for name in PRESETS:
        assert f"`{name}`" in doc, name
    for key in ("migration_rho_min ≤ migration_rho_max", "fiber_radius < min(ply_semi_axes)",
                "ply_distance > 0", "hair_start_radius_mean > 0", "loop_radius_mean > 0"):
        assert key in doc, key


def test_no_temp_files_in_preset_dir():
    leftovers = [p.name for p in ys.PRESET_DIR.iterdir() if p.name.startswith(".") and p.suffix == ".tmp"]
    assert leftovers == []
    assert all(os.path.getsize(ys.PRESET_DIR / f"{n}.toml") > 0 for n in PRESETS)
