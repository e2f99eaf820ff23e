"""Tests of data_formats.yarn_curves: the YarnCurves type and the knit-yarn-curves HDF5 file."""

import json

import h5py
import numpy as np
import pytest

from data_formats.errors import FormatError
from data_formats.yarn_curves import (YarnCurves, describe, make_yarn_curves, read_yarn_curves, sniff, validate,
                                      validate_curves, write_yarn_curves)

F32_RTOL = 2.0**-24  # float32 round-to-nearest: relative error at most half an ulp (unit roundoff)


def sample(frames=3):
    """Three curves (open, closed, open) over ``frames`` frames, two yarn types."""
    rng = np.random.default_rng(7)
    points = rng.normal(scale=5.0, size=(frames, 11, 3))
    return make_yarn_curves(points, [0, 4, 8, 11], closed=[False, True, False], yarn_type=[1, 0, 1],
                            yarn_types=["cotton1", "wool2"], units="cm", frame_time=1 / 24)


def write_then_edit(path, edit):
    """Write the sample, then change the file with ``edit(h5py.File)``."""
    write_yarn_curves(path, sample())
    with h5py.File(path, "r+") as f:
        edit(f)


def assert_rejected(path, *fragments):
    with pytest.raises(FormatError) as info:
        read_yarn_curves(path)
    message = str(info.value)
    assert "\n" not in message and str(path) in message
    for fragment in fragments:
        assert fragment in message
    assert validate(path) == [message]


def test_round_trip_multi_frame_mixed_closed(tmp_path):
    yc = sample(frames=4)
    path = tmp_path / "c.h5"
    write_yarn_curves(path, yc)
    back = read_yarn_curves(path)
    assert back.points.dtype == np.float64 and back.points.shape == (4, 11, 3)
    np.testing.assert_allclose(back.points, yc.points, rtol=F32_RTOL, atol=0)  # stored as float32
    for name in ("offsets", "closed", "yarn_type", "rest_arclength"):
        np.testing.assert_array_equal(getattr(back, name), getattr(yc, name))
        assert getattr(back, name).dtype == getattr(yc, name).dtype
    assert back.closed.tolist() == [False, True, False]
    assert (back.yarn_types, back.curve_type, back.units, back.frame_time) == (["cotton1", "wool2"], "C0", "cm",
                                                                                1 / 24)
    with h5py.File(path) as f:
        assert f["points"].dtype == np.float32
        assert (f.attrs["format"], f.attrs["version"]) == ("knit-yarn-curves", "1.1")
        assert "radius" not in f.attrs  # unknown radius: no attribute
    assert back.radius is None


def test_radius_round_trips_and_a_1_0_file_reads_without_it(tmp_path):
    yc = make_yarn_curves(np.arange(12.0).reshape(4, 3), [0, 4], radius=0.03125)
    write_yarn_curves(tmp_path / "r.h5", yc)
    assert read_yarn_curves(tmp_path / "r.h5").radius == 0.03125
    plain = tmp_path / "plain.h5"
    write_yarn_curves(plain, make_yarn_curves(np.arange(12.0).reshape(4, 3), [0, 4]))
    with h5py.File(plain, "a") as f:
        f.attrs["version"] = "1.0"
    assert read_yarn_curves(plain).radius is None


@pytest.mark.parametrize("value", [-0.1, 0.0, float("nan"), float("inf")])
def test_bad_radius_rejected(tmp_path, value):
    with pytest.raises(FormatError, match="radius"):
        make_yarn_curves(np.arange(12.0).reshape(4, 3), [0, 4], radius=value)
    path = tmp_path / "r.h5"
    write_yarn_curves(path, make_yarn_curves(np.arange(12.0).reshape(4, 3), [0, 4], radius=0.5))
    with h5py.File(path, "a") as f:
        f.attrs["radius"] = value
    assert_rejected(path, "radius")


def test_frame_time_none_and_curve_type_round_trip(tmp_path):
    yc = make_yarn_curves(np.arange(21.0).reshape(7, 3), [0, 7], curve_type="BZ", units="mm")
    write_yarn_curves(tmp_path / "b.h5", yc)
    back = read_yarn_curves(tmp_path / "b.h5")
    assert (back.frame_time, back.curve_type, back.units, back.yarn_types) == (None, "BZ", "mm", ["unknown"])


def test_rest_arclength_from_frame_zero_restarts_per_curve():
    line = [[0, 0, 0], [3, 4, 0], [3, 4, 2], [10, 0, 0], [10, 0, 1]]
    yc = make_yarn_curves(np.array([line, np.zeros((5, 3))]), [0, 3, 5])
    np.testing.assert_array_equal(yc.rest_arclength, [0, 5, 7, 0, 1])


def test_reader_accepts_float64_points_exactly(tmp_path):
    yc = sample()
    path = tmp_path / "d.h5"
    write_then_edit(path, lambda f: (f.__delitem__("points"), f.create_dataset("points", data=yc.points)))
    np.testing.assert_array_equal(read_yarn_curves(path).points, yc.points)


def test_minor_version_is_readable(tmp_path):
    path = tmp_path / "v.h5"
    write_then_edit(path, lambda f: f.attrs.__setitem__("version", "1.7"))
    assert validate(path) == []


@pytest.mark.parametrize("version, fragment", [("2.0", "unsupported knit-yarn-curves version 2.0"),
                                               ("one", "expected 'MAJOR.MINOR'")])
def test_wrong_version_rejected(tmp_path, version, fragment):
    path = tmp_path / "v.h5"
    write_then_edit(path, lambda f: f.attrs.__setitem__("version", version))
    assert_rejected(path, fragment)


def test_wrong_format_name_rejected(tmp_path):
    path = tmp_path / "f.h5"
    write_then_edit(path, lambda f: f.attrs.__setitem__("format", "knit-asset-pack"))
    assert_rejected(path, "format = 'knit-asset-pack'", "expected 'knit-yarn-curves'")
    assert not sniff(path)


@pytest.mark.parametrize("name", ["points", "offsets", "closed", "yarn_type", "rest_arclength", "yarn_types"])
def test_missing_dataset_rejected(tmp_path, name):
    path = tmp_path / "m.h5"
    write_then_edit(path, lambda f: f.__delitem__(name))
    assert_rejected(path, f"missing dataset '{name}'")


def test_missing_attribute_rejected(tmp_path):
    path = tmp_path / "a.h5"
    write_then_edit(path, lambda f: f.attrs.__delitem__("units"))
    assert_rejected(path, "missing root attribute 'units'")


def test_nan_inside_rejected_naming_frame_curve_point(tmp_path):
    path = tmp_path / "n.h5"

    def put_nan(f):
        f["points"][2, 9, 1] = np.nan  # curve 2 starts at point 8

    write_then_edit(path, put_nan)
    assert_rejected(path, "frame 2, curve 2, point 1", "not finite")


def test_offsets_not_increasing_rejected(tmp_path):
    path = tmp_path / "o.h5"
    write_then_edit(path, lambda f: f["offsets"].write_direct(np.array([0, 4, 3, 11], np.int64)))
    assert_rejected(path, "curve 1", "expected at least 2")


def test_wrong_shape_rejected(tmp_path):
    path = tmp_path / "s.h5"
    write_then_edit(path, lambda f: (f.__delitem__("closed"), f.create_dataset("closed", data=np.zeros(2, np.uint8))))
    assert_rejected(path, "closed", "expected bool (3,)")


def test_closed_values_other_than_0_1_rejected(tmp_path):
    path = tmp_path / "c.h5"
    write_then_edit(path, lambda f: f["closed"].write_direct(np.array([0, 2, 1], np.uint8)))
    assert_rejected(path, "closed", "expected 0 or 1")


def test_truncated_and_non_hdf5_files_rejected(tmp_path):
    good = tmp_path / "good.h5"
    write_yarn_curves(good, sample())
    data = good.read_bytes()
    cut = tmp_path / "cut.h5"
    cut.write_bytes(data[: len(data) // 2])
    problems = validate(cut)
    assert len(problems) == 1 and str(cut) in problems[0] and "\n" not in problems[0]
    with pytest.raises(FormatError):
        read_yarn_curves(cut)
    text = tmp_path / "text.h5"
    text.write_text("hello")
    assert_rejected(text, "not an HDF5 file", "expected a knit-yarn-curves file")


def test_writer_refuses_nan_and_leaves_no_file(tmp_path):
    yc = sample()
    yc.points[1, 5, 0] = np.nan  # curve 1 starts at point 4
    path = tmp_path / "out.h5"
    with pytest.raises(FormatError, match=r"frame 1, curve 1, point 1: .*not finite"):
        write_yarn_curves(path, yc)
    assert list(tmp_path.iterdir()) == []


def test_writer_refuses_coordinates_past_the_bound_and_keeps_old_file(tmp_path):
    """1e39 is finite in float64 and inf in float32; like any coordinate beyond ±1e9 it is refused before writing."""
    path = tmp_path / "out.h5"
    write_yarn_curves(path, sample())
    before = path.read_bytes()
    yc = sample()
    yc.points[0, 0, 2] = 1e39
    with pytest.raises(FormatError, match=r"frame 0, curve 0, point 0: .*1e\+39\), expected numbers in \[-1e\+09"):
        write_yarn_curves(path, yc)
    assert path.read_bytes() == before and list(tmp_path.iterdir()) == [path]


def test_validate_curves_rejects_broken_in_memory_data():
    good = sample()

    def broken(**changes):
        fields = {name: getattr(good, name) for name in YarnCurves.__dataclass_fields__}
        return YarnCurves(**{**fields, **changes})

    arc = good.rest_arclength.copy()
    arc[2] = arc[1] - 1.0
    cases = [
        (broken(rest_arclength=arc), "curve 0, point 2: rest_arclength decreases"),
        (broken(yarn_type=np.array([0, 2, 0], np.int32)), r"yarn_type\[1\] = 2"),
        (broken(curve_type="XX"), "curve_type: got 'XX'"),
        (broken(curve_type="BZ"), "curve 1: closed Bézier curve has 4 points, expected 3k"),  # open 4 = 3+1 is fine
        (broken(points=good.points.astype(np.float32)), "points: got float32"),
        (broken(frame_time=-1.0), "frame_time: got -1.0"),
    ]
    for yc, fragment in cases:
        with pytest.raises(FormatError, match=fragment):
            validate_curves(yc)
    validate_curves(good)


def test_sniff_never_raises_and_checks_content(tmp_path):
    path = tmp_path / "noext"
    write_yarn_curves(path, sample())
    other = tmp_path / "other.h5"
    with h5py.File(other, "w") as f:
        f.attrs["format"] = "something-else"
    assert sniff(path) and not sniff(other)
    assert not sniff(tmp_path / "missing.h5") and not sniff(tmp_path)


def test_describe_is_json_and_correct(tmp_path):
    square = np.array([[0, 0, 0], [2, 0, 0], [2, 2, 0], [0, 2, 0]], float)
    yc = make_yarn_curves(np.concatenate([square, square + [0, 0, 5]]), [0, 4, 8], closed=[True, False],
                          yarn_type=[0, 1], yarn_types=["a", "b"])
    path = tmp_path / "sq.h5"
    write_yarn_curves(path, yc)
    info = json.loads(json.dumps(describe(path)))
    assert info["kind"] == "yarn-curves" and info["curves"] == 2 and info["points"] == 8 and info["frames"] == 1
    assert info["closed_curves"] == 1 and info["curves_per_yarn_type"] == [1, 1]
    assert info["bounds"] == [[0, 0, 0], [2, 2, 5]]
    assert info["total_length"] == pytest.approx(8 + 6)  # closed square 8, open 3-sided square 6
