"""Tests of data_formats.stitch_mesh: the StitchMesh type, its HDF5 file and the OBJ + labels files."""

import dataclasses
import json

import h5py
import numpy as np
import pytest

from data_formats.errors import FormatError
from data_formats.stitch_mesh import (STITCH_TYPES, describe, describe_obj, read_obj_stitch_mesh, read_stitch_mesh,
                                      sniff, sniff_obj, validate, validate_obj, validate_stitch_mesh,
                                      write_obj_stitch_mesh, write_stitch_mesh)
from tests.helpers import K2TOG, KNIT, assert_same, sample


def test_make_stitch_mesh_derives_hand_checked_adjacency_courses_and_yarn():
    m = sample()
    assert m.course_left.tolist() == [-1, 0, 1, 2, -1, 4, 5, 6, -1, 8, 9]
    assert m.course_right.tolist() == [1, 2, 3, -1, 5, 6, 7, -1, 9, 10, -1]
    assert m.wale_below.tolist() == [[-1, -1]] * 4 + [[0, -1], [1, 2], [-1, -1], [3, -1], [4, 5], [6, -1], [7, -1]]
    assert m.wale_above.tolist() == [4, 5, 5, 7, 8, 8, 9, 10, -1, -1, -1]
    assert m.course.tolist() == [0] * 4 + [1] * 4 + [2] * 3
    assert m.column.tolist() == [0, 1, 2, 3, 0, 1, 2, 3, 0, 1, 2]
    assert m.yarn_offsets.tolist() == [0, 11]
    assert m.yarn_faces.tolist() == [0, 1, 2, 3, 7, 6, 5, 4, 8, 9, 10]
    assert m.yarn_direction.tolist() == [1] * 4 + [-1] * 4 + [1] * 3
    assert (m.yarn_types, m.units, m.yarn_type.tolist()) == (["cotton1"], "cm", [0])
    assert m.stitch_type.dtype == np.int8 and m.wale_below.dtype == np.int64


def three_yarns():
    """The sample knitted with one yarn per course, two yarn types."""
    m = sample()
    return dataclasses.replace(m, yarn_offsets=np.array([0, 4, 8, 11], np.int64),
                               yarn_type=np.array([0, 1, 0], np.int32), yarn_types=["cotton1", "silk1"])


def test_hdf5_round_trip_is_exact_with_pentagons_triangles_and_several_yarns(tmp_path):
    m = three_yarns()
    validate_stitch_mesh(m)
    path = tmp_path / "m.h5"
    write_stitch_mesh(path, m)
    assert_same(read_stitch_mesh(path), m)
    with h5py.File(path) as f:
        assert (f.attrs["format"], f.attrs["version"], f.attrs["units"]) == ("knit-stitch-mesh", "1.0", "cm")
        assert [s.decode() for s in f["stitch_types"][()]] == list(STITCH_TYPES)


def test_stitch_codes_on_disk_are_read_by_name(tmp_path):
    m = sample()
    path = tmp_path / "m.h5"
    write_stitch_mesh(path, m)
    with h5py.File(path, "r+") as f:
        names = list(reversed(STITCH_TYPES))
        del f["stitch_types"], f["stitch_type"]
        f.create_dataset("stitch_types", data=np.array(names, dtype=object), dtype=h5py.string_dtype())
        f.create_dataset("stitch_type", data=np.array([names.index(STITCH_TYPES[t]) for t in m.stitch_type], np.int32))
    assert_same(read_stitch_mesh(path), m)


def test_obj_round_trip_with_labels_sidecar(tmp_path):
    m = sample()
    obj = tmp_path / "m.obj"
    write_obj_stitch_mesh(obj, m)
    labels = (tmp_path / "m.labels").read_text().split("\n")
    assert labels[1:12] == [STITCH_TYPES[t] for t in m.stitch_type]
    assert_same(read_obj_stitch_mesh(obj, yarn_type="cotton1"), m)
    other = tmp_path / "elsewhere.txt"
    write_obj_stitch_mesh(tmp_path / "n.obj", m, labels_path=other)
    assert not (tmp_path / "n.labels").exists()
    assert_same(read_obj_stitch_mesh(tmp_path / "n.obj", other, yarn_type="cotton1"), m)


def test_obj_round_trip_keeps_coordinates_exactly(tmp_path):
    m = sample()
    m.vertices[:] += np.random.default_rng(3).normal(scale=1e-3, size=m.vertices.shape) * np.pi
    write_obj_stitch_mesh(tmp_path / "m.obj", m)
    np.testing.assert_array_equal(read_obj_stitch_mesh(tmp_path / "m.obj").vertices, m.vertices)


OBJ_TEXT = """# two knit stitches over two, then a k2tog
mtllib none.mtl
o patch
v 0 0 0
v 1 0 0
v 2 0 0
vt 0 0
vn 0 0 1
v 0 1 0 1.0
v 1 1 0
v 2 1 0
v 0.5 2 0   # apex course
v 1.5 2 0
g knits
usemtl wool
f 1/1/1 2/1/1 5/1/1 4/1/1
f 2//1 3//1 6//1 5//1
s off
f -5 -4 -3 -1 -2
"""


def test_obj_reader_handles_other_statements_slashes_and_negative_indices(tmp_path):
    obj, labels = tmp_path / "a.obj", tmp_path / "a.labels"
    obj.write_text(OBJ_TEXT)
    labels.write_text("# labels\nknit\n\nknit   # second\nk2tog\n")
    m = read_obj_stitch_mesh(obj, units="mm")
    assert m.stitch_type.tolist() == [KNIT, KNIT, K2TOG] and m.units == "mm"
    assert m.face_vertices[-5:].tolist() == [3, 4, 5, 7, 6]  # -5 -4 -3 -1 -2 relative to the 8 vertices so far
    assert m.wale_below.tolist() == [[-1, -1], [-1, -1], [0, 1]] and m.wale_above.tolist() == [2, 2, -1]
    assert m.vertices[3].tolist() == [0, 1, 0]
    obj.write_text(OBJ_TEXT.replace("f -5 -4 -3 -1 -2", "f 5 6 8 7 4"))  # the pentagon starting at the wrong corner
    with pytest.raises(FormatError, match=r"face 0 top edge 4->3 is shared with face 2's left edge, expected its "
                                          r"bottom edge \(check the vertex order"):
        read_obj_stitch_mesh(obj)


def test_obj_without_labels_is_all_knit_and_rejects_other_shapes(tmp_path):
    obj = tmp_path / "q.obj"
    obj.write_text("v 0 0 0\nv 1 0 0\nv 1 1 0\nv 0 1 0\nf 1 2 3 4\n")
    m = read_obj_stitch_mesh(obj)
    assert m.stitch_type.tolist() == [KNIT] and m.yarn_types == ["unknown"]
    obj.write_text(OBJ_TEXT)
    with pytest.raises(FormatError, match=r"line 19: face 2 has 5 vertices but is labelled knit, expected 4 "
                                          r"\(no labels file"):
        read_obj_stitch_mesh(obj)


@pytest.mark.parametrize("text, fragment", [
    ("v 0 0\nv 1 0 0\nv 1 1 0\nf 1 2 3\n", "line 1: vertex 0: 'v 0 0'"),
    ("v 0 0 0\nv 1 nan 0\nv 1 1 0\nf 1 2 3\n", "line 2: vertex 1: coordinates (1.0, nan, 0.0) are not finite"),
    ("v 0 0 0\nv 1 0 0\nv 1 1 0\nv 0 1 0\nf 1 2 3 9\n", "line 5: face 0: vertex 9 (1-based) does not exist"),
    ("v 0 0 0\nv 1 0 0\nv 1 1 0\nf 1 2\n", "line 4: face 0: 'f 1 2', expected 'f' and at least 3"),
    ("v 0 0 0\nv 1 0 0\nv 1 1 0\nf 1 0 3\n", "line 4: face 0"),
    ("v 0 0 0\n", "1 vertices and 0 faces"),
])
def test_bad_obj_lines_give_one_line_errors(tmp_path, text, fragment):
    obj = tmp_path / "bad.obj"
    obj.write_text(text)
    with pytest.raises(FormatError) as info:
        read_obj_stitch_mesh(obj)
    assert fragment in str(info.value) and "\n" not in str(info.value) and str(obj) in str(info.value)
    assert validate_obj(obj) == [str(info.value)]


def test_bad_labels_name_line_and_count(tmp_path):
    obj, labels = tmp_path / "a.obj", tmp_path / "a.labels"
    write_obj_stitch_mesh(obj, sample())
    labels.write_text("knit\nkint\n")
    with pytest.raises(FormatError, match=r"a.labels: line 2: label 'kint' for face 1, expected one of knit, purl"):
        read_obj_stitch_mesh(obj)
    labels.write_text("knit\n" * 3)
    with pytest.raises(FormatError, match=r"3 labels, expected one per face of .*a.obj \(11\)"):
        read_obj_stitch_mesh(obj)


def quads_obj(tmp_path, faces, n_vertices=8):
    """An OBJ of knit quads on a 4x2 vertex grid (0-3 at y=0, 4-7 at y=1) plus extra vertices up to n_vertices."""
    xy = [(x, 0) for x in range(4)] + [(x, 1) for x in range(4)] + [(x, 5) for x in range(n_vertices - 8)]
    path = tmp_path / "q.obj"
    path.write_text("".join(f"v {x} {y} 0\n" for x, y in xy)
                    + "".join("f " + " ".join(str(v + 1) for v in f) + "\n" for f in faces))
    return path


@pytest.mark.parametrize("faces, n_vertices, fragment", [
    ([(0, 1, 5, 4), (5, 6, 2, 1)], 8, "faces 0 and 1 both use edge 1->5 in the same direction"),
    ([(0, 1, 5, 4), (2, 6, 5, 1)], 8, "face 0 right edge 1->5 is shared with face 1's top edge, expected its left"),
    ([(0, 1, 5, 4), (2, 3, 7, 6)], 8, "faces 0, 1 each start a course with no faces below, expected exactly one"),
    ([(0, 1, 5, 4), (1, 2, 6, 5), (2, 0, 4, 6), (4, 5, 9, 8)], 10,
     "face 0: its course is closed (knitting in the round) while others have borders"),
])
def test_obj_topology_errors_name_faces(tmp_path, faces, n_vertices, fragment):
    path = quads_obj(tmp_path, faces, n_vertices)
    with pytest.raises(FormatError) as info:
        read_obj_stitch_mesh(path)
    assert fragment in str(info.value), str(info.value)


def broken(change):
    m = three_yarns()
    change(m)
    return m


def set_item(name, index, value):
    return lambda m: getattr(m, name).__setitem__(index, value)


@pytest.mark.parametrize("change, fragment", [
    (set_item("vertices", (3, 1), np.inf), "vertex 3: coordinates (3.0, inf, 0.0) are not finite"),
    (set_item("face_vertices", 2, 99), "face 0: vertex index 99 out of range, expected 0..18"),
    (set_item("face_vertices", 0, 1), "face 0: vertex 1 appears twice"),
    (set_item("stitch_type", 5, KNIT), "face 5 (knit): 5 vertices, expected 4"),
    (set_item("stitch_type", 5, 7), "face 5: stitch_type = 7, expected a code 0..4"),
    (set_item("face_offsets", -1, 40), "face_offsets: runs from 0 to 40"),
    (set_item("course_left", 5, 7), "face 4: course_right = 5 but face 5: course_left = 7, expected 4 (adjacency "
                                    "must be symmetric)"),
    (set_item("wale_above", 1, 4), "face 5: wale_below[0] = 1 but face 1: wale_above = 4, expected 5"),
    (set_item("wale_below", (9, 0), 7), "face 9: wale_below[0] = 7 but face 7: wale_above = 10, expected 9"),
    (set_item("wale_below", (0, 1), 4), "face 0 (knit): wale_below[1] = 4, expected -1"),
    (set_item("course_right", 3, 3), "face 3: course_right = 3, expected -1 or another face"),
    (lambda m: (m.course_right.__setitem__(0, -1), m.course_left.__setitem__(1, -1)),
     "face 1: course_left = -1, but the shared edges of the faces give 0"),
    (set_item("course", 9, 1), "face 8 (course 2, column 0): its right neighbour 9 is at course 1"),
    (set_item("column", 10, 5), "face 9 (course 2, column 1): its right neighbour 10 is at course 2, column 5"),
    (set_item("column", 4, 1), "face 4: column = 1 with course_left = -1"),
    (set_item("yarn_faces", 1, 0), "face 0: visited by 2 yarn passes, expected exactly 1"),
    (set_item("yarn_direction", 5, 1), "yarn_faces[4..5]: the yarn goes from face 7 (course 1, direction -1) to "
                                       "face 6"),
    (set_item("yarn_direction", 0, 2), "yarn_direction[0] = 2, expected +1"),
    (lambda m: setattr(m, "yarn_faces", m.yarn_faces[[1, 0, 2, 3, 4, 5, 6, 7, 8, 9, 10]]),
     "yarn 0: starts at face 1 inside its course"),
    (lambda m: setattr(m, "yarn_offsets", np.array([0, 3, 8, 11])), "yarn 1: starts at face 3 inside its course"),
    (lambda m: setattr(m, "yarn_offsets", np.array([0, 8, 8, 11])), "expected to rise strictly from 0"),
    (set_item("yarn_type", 1, 2), "yarn 1: yarn_type = 2, expected an index 0..1"),
    (lambda m: setattr(m, "course_left", m.course_left.astype(np.int32)), "course_left: got int32 (11,), expected "
                                                                          "int64 (11,)"),
    (lambda m: setattr(m, "units", ""), "units: got ''"),
    (lambda m: setattr(m, "yarn_types", []), "yarn_types: got [], expected a non-empty list"),
])
def test_validate_stitch_mesh_names_what_is_wrong(change, fragment):
    with pytest.raises(FormatError) as info:
        validate_stitch_mesh(broken(change), "mesh")
    assert fragment in str(info.value), str(info.value)
    assert "\n" not in str(info.value) and str(info.value).startswith("mesh: ")


def write_then_edit(path, edit):
    write_stitch_mesh(path, sample())
    with h5py.File(path, "r+") as f:
        edit(f)


def replace(name, data):
    return lambda f: (f.__delitem__(name), f.create_dataset(name, data=data))


def assert_rejected(path, *fragments):
    with pytest.raises(FormatError) as info:
        read_stitch_mesh(path)
    message = str(info.value)
    assert "\n" not in message and str(path) in message
    for fragment in fragments:
        assert fragment in message, message
    assert validate(path) == [message]


@pytest.mark.parametrize("edit, fragments", [
    (lambda f: f.attrs.__setitem__("version", "2.0"), ["unsupported knit-stitch-mesh version 2.0", "1.x"]),
    (lambda f: f.attrs.__setitem__("version", "one"), ["version = 'one', expected 'MAJOR.MINOR'"]),
    (lambda f: f.attrs.__setitem__("format", "knit-yarn-curves"), ["format = 'knit-yarn-curves'"]),
    (lambda f: f.attrs.__delitem__("units"), ["missing root attribute 'units'"]),
    (lambda f: f.__delitem__("wale_below"), ["missing dataset 'wale_below'"]),
    (lambda f: f.__delitem__("yarn_types"), ["missing dataset 'yarn_types'"]),
    (replace("vertices", np.where(np.arange(19)[:, None] == 6, np.nan, np.zeros((19, 3)))),
     ["vertex 6: coordinates (nan, nan, nan) are not finite"]),
    (lambda f: f["face_vertices"].__setitem__(3, 25), ["face 0: vertex index 25 out of range"]),
    (replace("vertices", np.zeros((19, 2))), ["vertices: got float64 (19, 2), expected float64 (V>=3, 3)"]),
    (replace("face_offsets", np.arange(12.0)), ["face_offsets: got float64, expected a numeric dataset of kind 'iu'"]),
    (replace("stitch_type", np.array([0] * 10 + [9])), ["face 10: stitch_type = 9, expected an index 0..4"]),
    (replace("yarn_direction", np.full(11, 3)), ["yarn_direction[0] = 3, expected +1"]),
    (replace("stitch_types", np.array(["knit", "cable"], dtype=object)), ["unknown stitch type 'cable'"]),
])
def test_corrupt_hdf5_files_give_one_line_errors(tmp_path, edit, fragments):
    path = tmp_path / "bad.h5"
    write_then_edit(path, edit)
    assert_rejected(path, *fragments)


def test_minor_version_and_extra_content_are_readable(tmp_path):
    path = tmp_path / "v.h5"
    write_then_edit(path, lambda f: (f.attrs.__setitem__("version", "1.7"), f.create_dataset("later", data=[1])))
    assert_same(read_stitch_mesh(path), sample())


def test_truncated_and_non_hdf5_files_rejected(tmp_path):
    good = tmp_path / "good.h5"
    write_stitch_mesh(good, sample())
    data = good.read_bytes()
    (tmp_path / "cut.h5").write_bytes(data[: len(data) // 2])
    (tmp_path / "text.h5").write_text("hello")
    for name, reason in (("cut.h5", "unreadable HDF5 (truncated or corrupt"), ("text.h5", "not an HDF5 file"),
                         ("missing.h5", "no such file")):
        assert_rejected(tmp_path / name, reason, "expected a knit-stitch-mesh file")


def test_writers_refuse_bad_meshes_and_leave_no_files(tmp_path):
    bad = broken(set_item("vertices", (0, 0), np.nan))
    with pytest.raises(FormatError, match="vertex 0"):
        write_stitch_mesh(tmp_path / "m.h5", bad)
    with pytest.raises(FormatError, match="vertex 0"):
        write_obj_stitch_mesh(tmp_path / "m.obj", bad)
    assert list(tmp_path.iterdir()) == []
    write_stitch_mesh(tmp_path / "m.h5", sample())
    before = (tmp_path / "m.h5").read_bytes()
    with pytest.raises(FormatError, match="symmetric"):
        write_stitch_mesh(tmp_path / "m.h5", broken(set_item("course_left", 5, 7)))
    assert (tmp_path / "m.h5").read_bytes() == before and len(list(tmp_path.iterdir())) == 1


def test_sniff_checks_content_and_never_raises(tmp_path):
    h5, obj = tmp_path / "m.h5", tmp_path / "m.obj"
    write_stitch_mesh(h5, sample())
    write_obj_stitch_mesh(obj, sample())
    other_h5 = tmp_path / "other.h5"
    with h5py.File(other_h5, "w") as f:
        f.attrs["format"] = "knit-yarn-curves"
    (tmp_path / "notes.obj").write_text("hello world\nv 1 2 3\nf 1 2 3\n")
    (tmp_path / "verts.obj").write_text("v 1 2 3\nv 1 2 4\n")
    assert sniff(h5) and not sniff(obj) and not sniff(other_h5)
    assert sniff_obj(obj)
    assert not sniff_obj(h5) and not sniff_obj(tmp_path / "notes.obj") and not sniff_obj(tmp_path / "verts.obj")
    for f in (sniff, sniff_obj):
        assert not f(tmp_path / "missing") and not f(tmp_path)


def test_describe_and_validate_both_formats(tmp_path):
    h5, obj = tmp_path / "m.h5", tmp_path / "m.obj"
    write_stitch_mesh(h5, three_yarns())
    write_obj_stitch_mesh(obj, three_yarns())
    info = json.loads(json.dumps(describe(h5)))
    assert info == {"kind": "stitch-mesh", "version": "1.0", "units": "cm", "vertices": 19, "faces": 11,
                    "courses": 3, "in_the_round": False, "stitches_per_course": [3, 4],
                    "faces_per_stitch_type": {"knit": 7, "purl": 1, "yarn_over": 1, "k2tog": 1, "ssk": 1},
                    "faces_per_size": {"3": 1, "4": 8, "5": 2}, "yarns": 3, "yarn_types": ["cotton1", "silk1"],
                    "bounds": [[0.0, 0.0, 0.0], [4.0, 3.0, 0.0]]}
    info_obj = json.loads(json.dumps(describe_obj(obj)))
    assert info_obj["kind"] == "stitch-mesh-obj" and info_obj["labels"] == str(tmp_path / "m.labels")
    assert info_obj["faces_per_stitch_type"] == info["faces_per_stitch_type"] and info_obj["yarns"] == 1
    assert validate(h5) == [] and validate_obj(obj) == []
    (tmp_path / "m.labels").write_text("knit\n")
    assert len(validate_obj(obj)) == 1 and "1 labels" in validate_obj(obj)[0]
    with pytest.raises(FormatError):
        describe_obj(obj)
