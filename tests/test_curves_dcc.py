"""Yarn curves for DCC tools (``data_formats.curves_dcc``): OBJ polylines round-trip (points, open and closed
curves, yarn types, curve type, units), malformed OBJ files give one-line errors and write nothing, and a USD file
opened back with ``pxr`` has the curves, widths (diameters), frames and rest arc lengths written."""

import numpy as np
import pytest
from click.testing import CliRunner

from cli.knitrun_cli import main as knitrun
from data_formats import FormatError
from data_formats.curves_dcc import read_obj_curves, sniff_obj_curves, write_obj_curves, write_usd_curves
from data_formats.yarn_curves import make_yarn_curves, read_yarn_curves, write_yarn_curves


def _curves(curve_type="PL", frames=3, radius=0.03):
    rng = np.random.default_rng(0)
    counts = [4, 7, 6]  # also valid Bézier counts: open 3k+1 (4, 7), closed 3k (6)
    base = rng.normal(size=(sum(counts), 3))
    points = np.stack([base * (1 + 0.1 * t) for t in range(frames)])
    return make_yarn_curves(points, np.concatenate([[0], np.cumsum(counts)]), closed=[False, False, True],
                            yarn_type=[0, 1, 1], yarn_types=["cotton1", "silk1"], curve_type=curve_type,
                            units="mm", frame_time=0.04, radius=radius)


@pytest.mark.parametrize("curve_type", ["PL", "BZ"])
def test_obj_polylines_round_trip(tmp_path, curve_type):
    yc = _curves(curve_type)
    write_obj_curves(tmp_path / "y.obj", yc, frame=2)
    assert sniff_obj_curves(tmp_path / "y.obj")
    back = read_obj_curves(tmp_path / "y.obj")
    np.testing.assert_allclose(back.points[0], yc.points[2], rtol=1e-8, atol=1e-9)
    assert back.closed.tolist() == yc.closed.tolist() and back.offsets.tolist() == yc.offsets.tolist()
    assert back.yarn_types == yc.yarn_types and back.yarn_type.tolist() == yc.yarn_type.tolist()
    assert (back.curve_type, back.units) == (curve_type, "mm")


def test_a_plain_obj_of_polylines_reads_with_defaults(tmp_path):
    (tmp_path / "p.obj").write_text("v 0 0 0\nv 1 0 0\nv 1 1 0\nv 0 1 0\no hoop\nl 1 2 3 4 1\nl -2 -1\n")
    yc = read_obj_curves(tmp_path / "p.obj", units="m")
    assert yc.closed.tolist() == [True, False] and np.diff(yc.offsets).tolist() == [4, 2]
    assert yc.yarn_types == ["hoop"] and yc.units == "m" and yc.curve_type == "PL"


@pytest.mark.parametrize("text, message", [
    ("v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\nl 1 2\n", "line 4: a face ('f')"),
    ("v 0 0 0\nv 1 0 0\nl 1 5\n", "line 3: 'l 1 5', expected 'l' and at least 2 indices of vertices defined above"),
    ("v 0 0 0\nv 1 0 0\n", "no 'l' statements"),
    ("v 0 0\nv 1 0 0\nl 1 2\n", "line 1: 'v 0 0', expected 'v x y z'"),
    ("# knit: units=furlong\nv 0 0 0\nv 1 0 0\nl 1 2\n", "header units='furlong'"),
    ("v 0 0 0\nv 1e300 0 0\nl 1 2\n", "expected numbers in [-1e+09, 1e+09]"),
])
def test_malformed_obj_polylines_are_one_line_errors_and_write_nothing(tmp_path, text, message):
    (tmp_path / "bad.obj").write_text(text)
    with pytest.raises(FormatError) as info:
        read_obj_curves(tmp_path / "bad.obj")
    assert message in str(info.value) and "\n" not in str(info.value)
    result = CliRunner().invoke(knitrun, ["convert", str(tmp_path / "bad.obj"), str(tmp_path / "out.h5")])
    assert result.exit_code == 1 and not (tmp_path / "out.h5").exists()


def test_convert_takes_obj_both_ways(tmp_path):
    write_yarn_curves(tmp_path / "y.h5", _curves())
    runner = CliRunner()
    assert runner.invoke(knitrun, ["convert", str(tmp_path / "y.h5"), str(tmp_path / "y.obj"), "--frame", "1"]
                         ).exit_code == 0
    result = runner.invoke(knitrun, ["convert", str(tmp_path / "y.obj"), str(tmp_path / "z.h5")])
    assert result.exit_code == 0 and "yarn-curves-obj" in result.output, result.output
    np.testing.assert_allclose(read_yarn_curves(tmp_path / "z.h5").points[0], _curves().points[1], rtol=1e-6,
                               atol=1e-6)  # float32 on disk


@pytest.mark.parametrize("suffix", [".usda", ".usdc"])
def test_usd_basis_curves_open_back_with_their_curves_widths_and_frames(tmp_path, suffix):
    from pxr import Usd, UsdGeom

    yc = _curves("BS", frames=3, radius=0.03)
    path = tmp_path / f"y{suffix}"
    write_usd_curves(path, yc)
    assert sorted(p.name for p in tmp_path.iterdir()) == [path.name]  # no temporary left
    stage = Usd.Stage.Open(str(path))
    assert UsdGeom.GetStageMetersPerUnit(stage) == pytest.approx(0.001)
    assert stage.GetTimeCodesPerSecond() == pytest.approx(25.0)
    open_, closed = UsdGeom.BasisCurves(stage.GetPrimAtPath("/Yarns/open")), \
        UsdGeom.BasisCurves(stage.GetPrimAtPath("/Yarns/closed"))
    assert list(open_.GetCurveVertexCountsAttr().Get()) == [4, 7]
    assert list(closed.GetCurveVertexCountsAttr().Get()) == [6]
    assert open_.GetBasisAttr().Get() == "bspline" and open_.GetWrapAttr().Get() == "pinned"
    assert closed.GetWrapAttr().Get() == "periodic" and open_.GetTypeAttr().Get() == "cubic"
    assert list(open_.GetWidthsAttr().Get()) == pytest.approx([0.06]) and open_.GetWidthsInterpolation() == "constant"
    points = open_.GetPointsAttr()
    assert points.GetTimeSamples() == [0.0, 1.0, 2.0]
    for t in range(3):
        np.testing.assert_allclose(np.array(points.Get(t)), yc.points[t, :11], rtol=1e-6, atol=1e-6)
    rest = UsdGeom.PrimvarsAPI(closed).GetPrimvar("restArclength")
    assert rest.GetInterpolation() == "vertex"
    np.testing.assert_allclose(np.array(rest.Get()), yc.rest_arclength[11:], rtol=1e-6)
    assert list(open_.GetPrim().GetCustomDataByKey("knit:yarnTypes")) == ["cotton1", "silk1"]


def test_usd_needs_a_radius_for_its_widths(tmp_path):
    with pytest.raises(FormatError, match="carry no yarn radius"):
        write_usd_curves(tmp_path / "y.usda", _curves(radius=None))
    assert not list(tmp_path.iterdir())
    write_yarn_curves(tmp_path / "y.h5", _curves(radius=None))
    result = CliRunner().invoke(knitrun, ["convert", str(tmp_path / "y.h5"), str(tmp_path / "y.usda"), "--radius",
                                          "0.05"])
    assert result.exit_code == 0, result.output
