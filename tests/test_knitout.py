"""Knitout executed into stitch meshes (``knitrun.sim.knitout``): flat jersey, rib (front and back bed, by
transfers) and garter (a transfer every course) from small fixtures written here, and the public-domain
``basic-vol-1`` programs in ``../shared/fixtures/knitout`` (single jersey, alternate jersey, 2×2 rib); double-bed
fabrics other than tubes, decreases, tuck stitches, splits and malformed lines are one-line errors naming the line;
tubes (both beds in turn) are knitted in the round."""

from pathlib import Path

import numpy as np
import pytest
from click.testing import CliRunner

from cli.knitbake_cli import main as knitbake
from cli.knitrun_cli import main as knitrun
from data_formats import FormatError
from data_formats.stitch_mesh import is_round
from knitrun.sim.contact import contact_statistic
from knitrun.sim.knitout import knitout_chart, knitout_fabric, read_knitout, sniff
from knitrun.sim.simulate import simulate

FIXTURES = Path(__file__).resolve().parents[2] / "shared" / "fixtures" / "knitout"


def _program(passes, header=";!knitout-2\n;;Carriers: 1\ninhook 1\n"):
    """Knitout of ``passes``: each a list of lines, or a (direction, bed, needles) pass of knits."""
    lines = [header.rstrip("\n")]
    for p in passes:
        if isinstance(p, tuple):
            direction, bed, needles = p
            lines += [f"knit {direction} {bed}{n} 1" for n in needles]
        else:
            lines += p
    return "\n".join(lines) + "\nreleasehook 1\nouthook 1\n"


def _jersey(rows=3, n=4):
    return [("+" if r % 2 == 0 else "-", "f", range(n) if r % 2 == 0 else reversed(range(n))) for r in range(rows)]


def _tube(rows=3, n=4):
    """A tube on needles 0..n−1: each course a front pass left → right and a back pass right → left."""
    return [p for _ in range(rows) for p in (("+", "f", range(n)), ("-", "b", list(reversed(range(n)))))]


def test_flat_jersey_rib_and_garter(tmp_path):
    (tmp_path / "jersey.k").write_text(_program(_jersey()))
    assert knitout_chart(tmp_path / "jersey.k") == "kkkk\nkkkk\nkkkk"
    rib = _jersey(1) + [["xfer f1 b1", "xfer f3 b3"], [f"knit - {b}{n} 1" for b, n in (("b", 3), ("f", 2), ("b", 1),
                                                                                       ("f", 0))]]
    (tmp_path / "rib.k").write_text(_program(rib))
    assert knitout_chart(tmp_path / "rib.k") == "kpkp\nkkkk"
    garter = _jersey(1) + [[f"xfer f{n} b{n}" for n in range(4)], ("-", "b", [3, 2, 1, 0]),
                           [f"xfer b{n} f{n}" for n in range(4)], ("+", "f", range(4))]
    (tmp_path / "garter.k").write_text(_program(garter + [[f"drop f{n}" for n in range(4)]]))
    mesh = read_knitout(tmp_path / "garter.k")
    assert knitout_chart(tmp_path / "garter.k") == "kkkk\npppp\nkkkk" and len(mesh.stitch_type) == 12
    assert sniff(tmp_path / "garter.k")


def test_a_tube_is_knitted_in_the_round(tmp_path):
    """Front and back beds knit in turn: closed courses of 2n knit stitches, the yarn one spiral; simulated at rest
    and stretched along the tube its yarns touch (contact statistic of issue 14) except at the seam's jog."""
    cast_on = [[f"tuck + f{n} 1" for n in range(8)] + [f"tuck - b{n} 1" for n in reversed(range(8))]]
    (tmp_path / "tube.k").write_text(_program(cast_on + _tube(10, 8)))
    chart, in_the_round = knitout_fabric(tmp_path / "tube.k")
    assert in_the_round and chart.splitlines() == ["k" * 16] * 10
    mesh = read_knitout(tmp_path / "tube.k")
    assert is_round(mesh) and len(mesh.stitch_type) == 160 and (mesh.yarn_direction == 1).all()
    assert (mesh.course_right[mesh.column == 15] == np.flatnonzero(mesh.column == 0)).all()  # closed courses
    rest = mesh.vertices
    stretched = rest * np.array([1.0, 1.3, 1.0])  # along the tube's axis (y)
    curves, report = simulate(mesh, [rest, stretched])
    assert curves.points.shape[0] == 2 and np.isfinite(curves.points).all() and len(curves.closed) >= 1
    for frame in (0, 1):
        stats = contact_statistic(curves, report["yarn_radius"], frame)
        assert stats["p5"] >= 0.8 and 0.9 <= stats["p50"] <= 1.1, stats
    result = CliRunner().invoke(knitrun, ["pattern", str(tmp_path / "tube.k"), "-o", str(tmp_path / "tube.h5"),
                                          "--json"])
    assert result.exit_code == 0 and '"in_the_round": true' in result.output, result.output
    result = CliRunner().invoke(knitrun, ["pattern", str(tmp_path / "tube.k"), "--in-the-round", "-o",
                                          str(tmp_path / "again.h5")])
    assert result.exit_code == 1 and "gives its own shape" in result.output and not (tmp_path / "again.h5").exists()
    example = read_knitout(Path(__file__).resolve().parents[1] / "examples" / "knitout" / "tube.knitout")
    assert is_round(example) and len(example.stitch_type) == 48 * 30  # the docs' tube: 24 needles a bed, 30 courses


@pytest.mark.parametrize("passes, message", [
    (_jersey(1) + [["knit - b3 1", "knit - b2 1", "knit - f1 1", "knit - f0 1"]],
     "line 9: column 2 is knit on both beds in course 0 (also line 6) and the pass from line 8 knits on both beds: "
     "a double-bed fabric (interlock"),
    (_tube(2) + [["xfer f1 b1"]], "line 20: a transfer in a tube"),
    (_tube(1) + [("+", "f", range(4)), ("-", "b", [3, 2, 0])], "course 1 has no stitch in column(s) [1] of needles "
     "0..3 on one bed of the tube"),
    (_jersey(1) + [["xfer f1 f2"], ("-", "f", [3, 2, 0])], "knit on f2 holding 2 loops (a decrease"),
    (_jersey(1) + [["tuck + f1 1"]], "tuck on f1 holding a loop (a tuck stitch)"),
    (_jersey(1) + [["split + f1 b1 1"]], "split: not supported"),
    (_jersey(1) + [["knit f1 1"]], "expected 'knit +|- needle carriers'"),
    (_jersey(1) + [["knit + fs1 1"]], "needle 'fs1', expected f<n> or b<n>"),
    (_jersey(1) + [["twist f1"]], "'twist' is not a knitout operation"),
    (_jersey(2) + [("+", "f", [0, 1])], "course 2 has no stitch in column(s) [2, 3]"),
])
def test_what_the_simulator_cannot_take_is_one_line(tmp_path, passes, message):
    (tmp_path / "bad.k").write_text(_program(passes))
    with pytest.raises(FormatError) as info:
        read_knitout(tmp_path / "bad.k")
    assert message in str(info.value) and "\n" not in str(info.value), str(info.value)
    result = CliRunner().invoke(knitrun, ["pattern", str(tmp_path / "bad.k"), "-o", str(tmp_path / "m.h5")])
    assert result.exit_code == 1 and not (tmp_path / "m.h5").exists()


def test_not_knitout(tmp_path):
    (tmp_path / "x.k").write_text("knit + f1 1\n")
    assert not sniff(tmp_path / "x.k")
    with pytest.raises(FormatError, match="line 1 is not ';!knitout-N'"):
        read_knitout(tmp_path / "x.k")


@pytest.mark.skipif(not FIXTURES.is_dir(), reason=f"knitout fixtures not found at {FIXTURES}")
def test_the_basic_vol_1_programs(tmp_path):
    faces = {name: len(read_knitout(FIXTURES / f"{name}.knitout").stitch_type)
             for name in ("singlejersey", "altjersey", "rib-2x2")}
    assert faces == {"singlejersey": 9920, "altjersey": 5120, "rib-2x2": 9920}
    top = knitout_chart(FIXTURES / "rib-2x2.knitout").splitlines()[0]
    assert top[:8] == "kkppkkpp"
    for name in ("interlock", "MilanoRib"):
        with pytest.raises(FormatError, match="double-bed fabric"):
            read_knitout(FIXTURES / f"{name}.knitout")
    runner = CliRunner()
    assert "valid knitout" in runner.invoke(knitbake, ["validate", str(FIXTURES / "singlejersey.knitout")]).output
    result = runner.invoke(knitrun, ["simulate", str(FIXTURES / "rib-2x2.knitout"), "--deform", "stretch-x=1.3",
                                     "--frames", "2", "-o", str(tmp_path / "y.h5")])
    assert result.exit_code == 0, result.output
