"""Asset pack: round trips, partial reads, corrupt inputs, atomic writes, and the spec/schema agreement."""

import json
import math
from pathlib import Path

import h5py
import numpy as np
import pytest

from data_formats import asset_pack as ap
from data_formats.asset_pack import checks as ap_checks, writer as ap_writer
from data_formats.errors import FormatError
from tests.helpers import BCSDF, SIZES, YARN, full_tables, provenance, write_full

def write_minimal(path):
    ap.write_pack(path, YARN, provenance(), BCSDF, {}, {})


# --- round trips --------------------------------------------------------------------------------------------------

def test_round_trip_every_table(tmp_path):
    path = tmp_path / "full.h5"
    tables, errors, attrs = write_full(path)
    assert ap.validate(path) == []
    assert ap.sniff(path)
    pack = ap.read_pack(path)
    assert set(pack.tables) == set(tables)
    for name, arr in tables.items():
        got = pack.tables[name]
        assert got.dtype == np.float32 and got.shape == arr.shape
        np.testing.assert_allclose(got, arr.astype(np.float32), rtol=0, atol=0)
        info = pack.info[name]
        if np.ndim(errors[name]) == 0:
            assert info.error_estimate == pytest.approx(errors[name]) and name not in pack.stderr
        else:
            np.testing.assert_array_equal(pack.stderr[name], errors[name].astype(np.float32))
            assert info.error_estimate == pytest.approx(float(errors[name].astype(np.float32).max()))
            assert info.error_statistic == "max"
        assert info.error_kind
    assert pack.yarn == YARN
    prov = provenance()
    for key in prov:
        assert pack.provenance[key] == prov[key]
    for key, value in BCSDF.items():
        assert pack.fiber_bcsdf[key] == pytest.approx(value)
    assert len(pack.mip_chain("textures/normal")) == 3
    assert pack.info["textures/flyaway/mip0"].attrs["half_width"] == pytest.approx(0.09)
    assert pack.info["textures/ao/mip1"].attrs["half_width"] == pytest.approx(YARN["radius"])
    assert pack.info["textures/flyaway/mip2"].attrs["error_kind"] == "exact (deterministic ray casting)"
    # self-describing axes: fixed tables carry the schema's axes, I_M the caller's
    xi = pack.info["correction/xi_M"]
    assert [a.name for a in xi.axes] == ["v", "theta_d", "channel"]
    assert xi.axes[1].range == pytest.approx((-math.pi / 2, math.pi / 2)) and xi.axes[1].wrap == "clamp"
    np.testing.assert_allclose(xi.attrs["axis1_samples"], ap.cell_centres(-math.pi / 2, math.pi / 2, SIZES["N_theta"]))
    im = pack.info["environment/I_M_TT_D"]
    assert [a.name for a in im.axes] == ["cos_theta_j", "sin_theta_o", "phi_j_minus_phi_o", "log10_lambda", "channel"]
    assert im.axes[2].wrap == "repeat" and im.axes[3].range == (-0.5, 4.0)
    assert pack.info["correction/xi_N"].axes[1].wrap == "repeat"


def test_round_trip_minimal_pack(tmp_path):
    path = tmp_path / "min.h5"
    write_minimal(path)
    assert ap.validate(path) == []
    pack = ap.read_pack(path)
    assert pack.tables == {} and pack.info == {} and pack.yarn == YARN
    assert pack.schema_version == ap.SCHEMA_VERSION
    d = ap.describe(path)
    json.dumps(d)
    assert d["kind"] == "asset-pack" and d["tables"] == {} and d["yarn"]["name"] == "cotton1"


def test_describe_lists_every_table_with_error(tmp_path):
    path = tmp_path / "full.h5"
    tables, errors, _ = write_full(path)
    d = json.loads(json.dumps(ap.describe(path)))
    assert set(d["tables"]) == set(tables)
    t = d["tables"]["correction/xi_M"]
    assert t["shape"] == [SIZES["N_v"], SIZES["N_theta"], 3] and t["per_entry_errors"] is True
    assert t["error_estimate"] == pytest.approx(float(errors["correction/xi_M"].astype(np.float32).max()))
    assert d["provenance"]["timings"]["correction"] == 30.25


def test_sniff_is_content_based(tmp_path):
    path = tmp_path / "pack.bin"
    write_minimal(path)
    assert ap.sniff(path)
    other = tmp_path / "other.h5"
    with h5py.File(other, "w") as f:
        f.attrs["format"] = "knit-yarn-curves"
    assert not ap.sniff(other)
    text = tmp_path / "x.h5"
    text.write_text("hello")
    assert not ap.sniff(text) and not ap.sniff(tmp_path / "missing.h5") and not ap.sniff(tmp_path)


# --- partial reads ------------------------------------------------------------------------------------------------

def test_reading_a_subset_reads_only_those_datasets(tmp_path, monkeypatch):
    path = tmp_path / "full.h5"
    write_full(path)
    touched = []
    orig_getitem = h5py.Dataset.__getitem__
    orig_read_direct = h5py.Dataset.read_direct
    orig_array = h5py.Dataset.__array__

    def spy_getitem(self, *a, **k):
        touched.append(self.name)
        return orig_getitem(self, *a, **k)

    def spy_read_direct(self, *a, **k):
        touched.append(self.name)
        return orig_read_direct(self, *a, **k)

    def spy_array(self, *a, **k):
        touched.append(self.name)
        return orig_array(self, *a, **k)

    monkeypatch.setattr(h5py.Dataset, "__getitem__", spy_getitem)
    monkeypatch.setattr(h5py.Dataset, "read_direct", spy_read_direct)
    monkeypatch.setattr(h5py.Dataset, "__array__", spy_array)
    pack = ap.read_pack(path, tables=["correction/xi_M", "textures/coverage/mip1"])
    assert set(pack.tables) == {"correction/xi_M", "textures/coverage/mip1"}
    assert set(touched) == {"/correction/xi_M", "/correction/xi_M_stderr", "/textures/coverage/mip1"}
    assert len(pack.info) > 20  # metadata of every table is still known
    touched.clear()
    ap.describe(path)
    assert touched == []


def test_subset_read_ignores_corrupt_data_it_does_not_load(tmp_path):
    path = tmp_path / "full.h5"
    write_full(path)
    with h5py.File(path, "r+") as f:
        f["shadowing/psi_GM"][0, 0, 0] = np.nan
    assert ap.read_pack(path, tables=["correction/xi_N"]).tables["correction/xi_N"].shape == (5, 8, 3)
    with pytest.raises(FormatError, match=r"shadowing/psi_GM: 1 non-finite"):
        ap.read_pack(path, tables=["shadowing/psi_GM"])


def test_unknown_or_absent_table_request(tmp_path):
    path = tmp_path / "min.h5"
    write_minimal(path)
    with pytest.raises(FormatError, match=r"'correction/xi_M' is not in this pack"):
        ap.read_pack(path, tables=["correction/xi_M"])
    with pytest.raises(FormatError, match=r"'nonsense' is not in the schema"):
        ap.read_pack(path, tables=["nonsense"])


# --- corrupt inputs -----------------------------------------------------------------------------------------------

def _expect_bad(path, pattern):
    probs = ap.validate(path)
    assert probs, "validate found no problem"
    assert any(__import__("re").search(pattern, p) for p in probs), probs
    assert all("\n" not in p and str(path) in p for p in probs)
    with pytest.raises(FormatError, match=pattern) as exc:
        ap.read_pack(path)
    assert "\n" not in str(exc.value) and str(path) in str(exc.value)
    assert not ap.sniff(path) or "format" not in pattern


def test_truncated_file(tmp_path):
    path = tmp_path / "full.h5"
    write_full(path)
    data = path.read_bytes()
    path.write_bytes(data[: len(data) // 3])
    _expect_bad(path, r"truncated or corrupt|unreadable")
    assert not ap.sniff(path)
    path.write_bytes(b"")
    _expect_bad(path, r"not an HDF5 file")


def test_wrong_format_name(tmp_path):
    path = tmp_path / "p.h5"
    write_minimal(path)
    with h5py.File(path, "r+") as f:
        f.attrs["format"] = "knit-yarn-curves"
    _expect_bad(path, r"format is 'knit-yarn-curves', expected 'knit-asset-pack'")
    with pytest.raises(FormatError, match="format"):
        ap.describe(path)


def test_unknown_major_version_fails_closed_higher_minor_accepted(tmp_path):
    path = tmp_path / "p.h5"
    write_full(path, levels=1)
    for other in ("3.0", "1.1"):  # a newer major, and the last 1.x (whose I_M held every lobe)
        with h5py.File(path, "r+") as f:
            f.attrs["schema_version"] = other
        _expect_bad(path, rf"unknown major version {other[0]}; this reader supports 2\.x")
    with h5py.File(path, "r+") as f:
        f.attrs["schema_version"] = "2.8"
        f.create_dataset("textures/new_thing", data=np.zeros(3))  # a member a later minor version added
        f.create_group("future_group")
    assert ap.validate(path) == []
    assert ap.read_pack(path).schema_version == "2.8"
    with h5py.File(path, "r+") as f:
        f.attrs["schema_version"] = "2.0"
    _expect_bad(path, r"textures/new_thing: unknown dataset")
    with h5py.File(path, "r+") as f:
        f.attrs["schema_version"] = "one"
    _expect_bad(path, r"schema_version is 'one', expected a \"major.minor\"")


def test_missing_required_group_and_attr(tmp_path):
    path = tmp_path / "p.h5"
    write_minimal(path)
    with h5py.File(path, "r+") as f:
        del f["yarn"].attrs["radius"]
    _expect_bad(path, r"yarn\.radius is missing")
    write_minimal(path)
    with h5py.File(path, "r+") as f:
        del f["provenance"]
    _expect_bad(path, r"group /provenance is missing")
    write_minimal(path)
    with h5py.File(path, "r+") as f:
        f["fiber_bcsdf"].attrs["beta_r"] = -0.1
    _expect_bad(path, r"fiber_bcsdf\.beta_r is -0\.1, expected an angle in radians in \(0")
    write_minimal(path)
    with h5py.File(path, "r+") as f:
        f["provenance"].attrs["timings"] = "{not json"
    _expect_bad(path, r"provenance\.timings is not valid JSON")


def test_nan_written_behind_our_back(tmp_path):
    path = tmp_path / "p.h5"
    write_full(path, levels=1)
    with h5py.File(path, "r+") as f:
        f["dual_scattering/beta_f"][3, 1] = np.inf
    _expect_bad(path, r"dual_scattering/beta_f: 1 non-finite value\(s\) \(first inf at index \(3, 1\)\)")
    write_full(path, levels=1)
    with h5py.File(path, "r+") as f:
        f["correction/xi_M_stderr"][0, 0, 0] = np.nan
    _expect_bad(path, r"correction/xi_M_stderr: 1 non-finite")


def test_missing_error_estimate_and_bad_axes(tmp_path):
    path = tmp_path / "p.h5"
    write_full(path, levels=1)
    with h5py.File(path, "r+") as f:
        del f["environment/I_M_TT_D"].attrs["error_estimate"]
    _expect_bad(path, r"environment/I_M_TT_D: attr error_estimate is missing")
    write_full(path, levels=1)
    with h5py.File(path, "r+") as f:
        del f["textures/ao/mip0"].attrs["error_kind"]
    _expect_bad(path, r"textures/ao/mip0: attr error_kind is missing")
    write_full(path, levels=1)
    with h5py.File(path, "r+") as f:
        f["correction/xi_N"].attrs["axis1_range"] = np.array([0.0, 2 * math.pi])
    _expect_bad(path, r"correction/xi_N: attr axis1_range is \[0\.0, 6\.28")


def test_shape_and_range_problems_in_file(tmp_path):
    path = tmp_path / "p.h5"
    write_full(path, levels=2)
    with h5py.File(path, "r+") as f:  # xi_N with a different N_v than xi_M
        del f["correction/xi_N"]
        f.create_dataset("correction/xi_N", data=np.ones((4, 8, 3), np.float32))
        for k, v in ap_checks.axis_attrs(ap.resolve_table("correction/xi_N")[0], (4, 8, 3)).items():
            f["correction/xi_N"].attrs[k] = ap_checks.encode_extra(v)
        for k in ("units", "error_kind", "error_statistic"):
            f["correction/xi_N"].attrs[k] = f["correction/xi_M"].attrs[k]
        f["correction/xi_N"].attrs["error_estimate"] = 0.0
    _expect_bad(path, r"correction/xi_N: shape \(4, 8, 3\) does not match \(N_v, N_phi, 3\) with N_v = 5")
    write_full(path, levels=3)
    with h5py.File(path, "r+") as f:
        del f["textures/normal/mip1"]
    _expect_bad(path, r"textures/normal: mip levels \[0, 2\] are not contiguous from mip0 \(missing mip1\)")
    write_full(path, levels=1)
    with h5py.File(path, "r+") as f:
        f["textures/coverage/mip0"][0, 0] = 1.5
    _expect_bad(path, r"textures/coverage/mip0: value 1\.5 above 1")


# --- writer refusals ----------------------------------------------------------------------------------------------

def _no_files(folder):
    return sorted(p.name for p in Path(folder).iterdir())


def test_writer_refuses_nan_and_leaves_nothing(tmp_path):
    tables, errors, attrs = full_tables()
    tables["shadowing/psi_GN"] = tables["shadowing/psi_GN"].copy()
    tables["shadowing/psi_GN"][2, 3, 1] = np.nan
    path = tmp_path / "p.h5"
    pattern = r"shadowing/psi_GN: 1 non-finite value\(s\) \(first nan at index \(2, 3, 1\)"
    with pytest.raises(FormatError, match=pattern):
        ap.write_pack(path, YARN, provenance(), BCSDF, tables, errors, attrs)
    assert _no_files(tmp_path) == []


@pytest.mark.parametrize("mutate, pattern", [
    (lambda t, e, a: e.pop("correction/xi_N"), r"correction/xi_N: no error estimate"),
    (lambda t, e, a: e.__setitem__("correction/xi_M", np.zeros((2, 2))), r"correction/xi_M_stderr: shape \(2, 2\)"),
    (lambda t, e, a: e.__setitem__("environment/I_M_TT_D", -1.0), r"errors\['environment/I_M_TT_D'\] is -1\.0"),
    (lambda t, e, a: e.__setitem__("environment/I_M_TT_D", float("nan")), r"errors\['environment/I_M_TT_D'\] is nan"),
    (lambda t, e, a: t.__setitem__("correction/xi_M", np.ones((5, 7, 4))), r"does not match \(N_v, N_theta, 3\)"),
    (lambda t, e, a: t.__setitem__("correction/xi_M", np.ones((5, 7, 3), np.int64)), r"dtype is int64"),
    (lambda t, e, a: t.__setitem__("dual_scattering/a_f", np.full((7, 3), 1e39)), r"overflow float32"),
    (lambda t, e, a: t.__setitem__("textures/ao/mip1", np.ones((3, 8))), r"textures/ao/mip1: shape \(3, 8\) does not"),
    (lambda t, e, a: t.__setitem__("textures/unknown/mip0", np.ones((3, 8))), r"'textures/unknown/mip0' is not in"),
    (lambda t, e, a: a["textures/flyaway/mip0"].pop("half_width"), r"half_width'\] is missing"),
    (lambda t, e, a: a.__setitem__("correction/xi_M", {"axes": []}), r"axes of correction/xi_M are fixed"),
    (lambda t, e, a: a["environment/I_M_TT_D"]["axes"][1].__setitem__("wrap", "mirror"), r"axis1_wrap is 'mirror'"),
    (lambda t, e, a: a["environment/I_M_TT_D"]["axes"][0].__setitem__("range", [1, 0]), r"axis0_range is \[1\.0, 0\.0\]"),
    (lambda t, e, a: t["textures/tangent/mip0"].__setitem__((0, 0), [2.0, 0, 0]), r"tangent/mip0 channel 0: value 2"),
])
def test_writer_refuses_bad_tables(tmp_path, mutate, pattern):
    tables, errors, attrs = full_tables()
    mutate(tables, errors, attrs)
    path = tmp_path / "p.h5"
    with pytest.raises(FormatError, match=pattern) as exc:
        ap.write_pack(path, YARN, provenance(), BCSDF, tables, errors, attrs)
    assert "\n" not in str(exc.value) and str(path) in str(exc.value)
    assert _no_files(tmp_path) == []


@pytest.mark.parametrize("group, key, value, pattern", [
    ("yarn", "units", "inch", r"yarn\.units is 'inch', expected one of"),
    ("yarn", "radius", 0.0, r"yarn\.radius is 0\.0, expected a finite number in \(0"),
    ("yarn", "plies", 2.5, r"yarn\.plies is 2\.5, expected an integer"),
    ("provenance", "seed", -1, r"provenance\.seed is -1"),
    ("provenance", "created", "yesterday", r"provenance\.created is 'yesterday', expected an ISO 8601"),
    ("provenance", "yarn_spec_toml", "[[[", r"provenance\.yarn_spec_toml is not valid TOML"),
    ("provenance", "sample_counts", {"x": 1.5}, r"provenance\.sample_counts is .*integers ≥ 0"),
    ("fiber_bcsdf", "r_color", [1, 2], r"fiber_bcsdf\.r_color is \[1, 2\], expected 3 numbers"),
    ("fiber_bcsdf", "gamma_tt", None, r"fiber_bcsdf\.gamma_tt is missing"),
])
def test_writer_refuses_bad_attrs(tmp_path, group, key, value, pattern):
    yarn, prov, bcsdf = dict(YARN), provenance(), dict(BCSDF)
    target = {"yarn": yarn, "provenance": prov, "fiber_bcsdf": bcsdf}[group]
    if value is None:
        del target[key]
    else:
        target[key] = value
    path = tmp_path / "p.h5"
    with pytest.raises(FormatError, match=pattern):
        ap.write_pack(path, yarn, prov, bcsdf, {}, {})
    assert _no_files(tmp_path) == []


def test_failed_write_leaves_existing_pack_untouched(tmp_path, monkeypatch):
    path = tmp_path / "p.h5"
    write_full(path, levels=1)
    before = path.read_bytes()
    # refused before writing
    tables, errors, attrs = full_tables(seed=1, levels=1)
    tables["environment/I_M_TT_D"][0, 0, 0, 0, 0] = np.nan
    with pytest.raises(FormatError):
        ap.write_pack(path, YARN, provenance(), BCSDF, tables, errors, attrs)
    assert path.read_bytes() == before and _no_files(tmp_path) == ["p.h5"]
    # failure in the middle of writing (after the temporary file exists)
    calls = []

    def failing(f, name, data, attrs):
        calls.append(name)
        if len(calls) == 5:
            raise OSError("disk full")
        return orig(f, name, data, attrs)

    orig = ap_writer._write_dataset
    monkeypatch.setattr(ap_writer, "_write_dataset", failing)
    tables, errors, attrs = full_tables(seed=2, levels=1)
    with pytest.raises(OSError, match="disk full"):
        ap.write_pack(path, YARN, provenance(), BCSDF, tables, errors, attrs)
    assert len(calls) == 5
    assert path.read_bytes() == before and _no_files(tmp_path) == ["p.h5"]
    assert ap.validate(path) == []


def test_created_defaults_to_now(tmp_path):
    prov = provenance()
    del prov["created"]
    path = tmp_path / "p.h5"
    ap.write_pack(path, YARN, prov, BCSDF, {}, {})
    import datetime
    created = datetime.datetime.fromisoformat(ap.read_pack(path).provenance["created"])
    assert abs((datetime.datetime.now(datetime.timezone.utc) - created).total_seconds()) < 120


# --- the spec and the schema agree --------------------------------------------------------------------------------

def test_spec_document_contains_the_generated_schema():
    doc = (Path(ap.__file__).parent.parent / "ASSET_PACK.md").read_text(encoding="utf-8")
    assert ap.schema_markdown() in doc, "ASSET_PACK.md is out of date: paste ap.schema_markdown() into it"
    for spec in ap.TABLES:
        assert f"`{spec.name}`" in doc


def test_cell_centre_rule_matches_lookup_formula():
    # the spec's lookup: t = (x − lo)/(hi − lo)·N − 0.5 lands exactly on sample k at its position
    lo, hi, n = -math.pi / 2, math.pi / 2, 8
    s = ap.cell_centres(lo, hi, n)
    np.testing.assert_allclose((s - lo) / (hi - lo) * n - 0.5, np.arange(n), atol=1e-12)
    assert s[0] > lo and s[-1] < hi
