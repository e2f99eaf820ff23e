"""Augmented stitch meshes (``.smobj``, ``data_formats.smobj``) from fixture files written here from the
textiles-lab format description: flat stockinette and 1×1 rib read into stitch meshes, simulate, and are recognised
by content; unsupported face types and malformed files are one-line errors naming the line, and write nothing."""

import numpy as np
import pytest
from click.testing import CliRunner

from cli.knitbake_cli import main as knitbake
from cli.knitrun_cli import main as knitrun
from data_formats import FormatError
from data_formats.smobj import read_smobj, sniff
from data_formats.stitch_mesh import load_stitch_mesh

LIBRARY = """L knit-to-left -l1 -y1 +l1 +y1
L knit-to-right -l1 +y1 +l1 -y1
L purl-to-left -l1 -y1 +l1 +y1
L purl-to-right -l1 +y1 +l1 -y1
L tuck-behind-to-right -l0 +y1 +l1 -y1
"""


def smobj_text(rows=3, cols=4, purl_columns=(), tuck=None, flip=False):
    """A flat R × C fabric on a unit grid: course r knitted left → right when r is even (``flip``: the other way),
    purl in ``purl_columns``; 'e' lines for every shared edge (the second one reversed, as on an oriented mesh)."""
    lines = [LIBRARY.strip(), "N 0"]
    lines += [f"v {x} {y} 0" for y in range(rows + 1) for x in range(cols + 1)]
    vid = lambda x, y: y * (cols + 1) + x + 1  # noqa: E731
    face = {}
    for r in range(rows):
        for c in range(cols):
            face[r, c] = len(face) + 1
            lines.append(f"f {vid(c, r)} {vid(c + 1, r)} {vid(c + 1, r + 1)} {vid(c, r + 1)}")
            right = (r % 2 == 0) != flip
            kind = 3 if c in purl_columns else 1
            lines.append(f"T {5 if (r, c) == tuck else kind + right}")
    for (r, c), f in face.items():
        if c + 1 < cols:
            lines.append(f"e {f}/2 {face[r, c + 1]}/-4")
        if r + 1 < rows:
            lines.append(f"e {f}/3 {face[r + 1, c]}/-1")
    return "\n".join(lines) + "\n"


def test_flat_stockinette_and_rib_read_into_stitch_meshes(tmp_path):
    (tmp_path / "st.smobj").write_text(smobj_text())
    mesh = read_smobj(tmp_path / "st.smobj")
    assert len(mesh.stitch_type) == 12 and set(mesh.stitch_type.tolist()) == {0}
    assert mesh.course.max() == 2 and mesh.column.max() == 3
    (tmp_path / "rib.smobj").write_text(smobj_text(purl_columns=(1, 3)))
    rib = load_stitch_mesh(tmp_path / "rib.smobj")
    assert rib.stitch_type.reshape(3, 4).tolist() == [[0, 1, 0, 1]] * 3
    assert sniff(tmp_path / "rib.smobj") and not sniff(tmp_path / "missing.smobj")


def test_an_smobj_is_simulated_and_recognised_by_content(tmp_path):
    (tmp_path / "fabric.txt").write_text(smobj_text(rows=4, cols=4))  # no telling extension: content decides
    runner = CliRunner()
    assert "valid stitch-mesh-smobj" in runner.invoke(knitbake, ["validate", str(tmp_path / "fabric.txt")]).output
    (tmp_path / "fabric.smobj").write_text(smobj_text(rows=4, cols=4))
    result = runner.invoke(knitrun, ["simulate", str(tmp_path / "fabric.smobj"), "--deform", "stretch-x=1.2",
                                     "-o", str(tmp_path / "y.h5")])
    assert result.exit_code == 0, result.output
    assert (tmp_path / "y.h5").is_file()


@pytest.mark.parametrize("text, message", [
    (smobj_text(tuck=(1, 2)), "face 7 has type 'tuck-behind-to-right' (-l0 +y1 +l1 -y1, library line 5), which "
                              "the simulator does not support"),
    (smobj_text(flip=True), "face 1 (course 0) is knitted left, but a flat knit's course 0 runs right"),
    (smobj_text().replace("T 2\n", "T 9\n", 1), "'T 9', expected 'T k' with k a library entry above"),
    (smobj_text().replace("e 1/2 2/-4", "e 1/2 3/-4"), "'e 1/2 3/-4' joins edges the faces' shared vertices do not"),
    (smobj_text().replace("e 1/2 2/-4", "e 1/2 99/-4"), "names a face or edge that does not exist"),
    (LIBRARY + "v 0 0 0\n", "no faces"),
    (smobj_text().replace("v 1 0 0", "v 1 0"), "'v 1 0', expected 'v x y z'"),
])
def test_unsupported_or_malformed_smobj_is_one_line_and_writes_nothing(tmp_path, text, message):
    (tmp_path / "bad.smobj").write_text(text)
    with pytest.raises(FormatError) as info:
        read_smobj(tmp_path / "bad.smobj")
    assert message in str(info.value) and "\n" not in str(info.value), str(info.value)
    result = CliRunner().invoke(knitrun, ["simulate", str(tmp_path / "bad.smobj"), "-o", str(tmp_path / "y.h5")])
    assert result.exit_code == 1 and len(result.output.strip().splitlines()) == 1 and not (tmp_path / "y.h5").exists()


def test_the_smobj_geometry_is_kept(tmp_path):
    (tmp_path / "st.smobj").write_text(smobj_text(rows=2, cols=2))
    mesh = read_smobj(tmp_path / "st.smobj", units="mm")
    assert mesh.units == "mm" and np.array_equal(mesh.vertices[4], [1.0, 1.0, 0.0])
