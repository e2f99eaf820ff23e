"""Knitout executed into stitch meshes (``knitrun.sim.knitout``): flat jersey, rib (front and back bed, by
transfers) and garter (a transfer every course) from small fixtures written here, and the public-domain
``basic-vol-1`` programs in ``../shared/fixtures/knitout`` (single jersey, alternate jersey, 2×2 rib); double-bed
fabrics, decreases, tuck stitches, splits and malformed lines are one-line errors naming the line."""

from pathlib import Path

import pytest
from click.testing import CliRunner

from cli.knitbake_cli import main as knitbake
from cli.knitrun_cli import main as knitrun
from data_formats import FormatError
from knitrun.sim.knitout import knitout_chart, read_knitout, sniff

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


@pytest.mark.parametrize("passes, message", [
    (_jersey(1) + [("-", "b", [3, 2, 1, 0])], "line 8: column 3 is knit twice in course 0 (also line 7): a double-bed"),
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
