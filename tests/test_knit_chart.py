"""Tests of knitrun.sim.knit_chart: chart parsing, chart → StitchMesh, named patterns."""

import dataclasses
from pathlib import Path

import h5py
import numpy as np
import pytest

from data_formats.errors import FormatError
from data_formats.stitch_mesh import (STITCH_TYPES, is_round, read_obj_stitch_mesh, read_stitch_mesh,
                                      validate_stitch_mesh, write_obj_stitch_mesh, write_stitch_mesh)
from knitrun.sim.knit_chart import PATTERNS, chart_to_mesh, parse_chart, pattern_chart
from tests.helpers import K2TOG, KNIT, PURL, SSK, YO, assert_same, sample

SAMPLE_CHART = r"""
# the hand-built mesh of test_stitch_mesh.sample()
\ k k    # course 2: ssk, knit, knit
p/ok     # course 1: purl, k2tog, yarn-over, knit

....     # course 0
"""


def signed_areas(m):
    """Shoelace area of every face in the xy plane (positive: counter-clockwise seen from +z, the front)."""
    out = []
    for a, b in zip(m.face_offsets[:-1], m.face_offsets[1:]):
        x, y = m.vertices[m.face_vertices[a:b], 0], m.vertices[m.face_vertices[a:b], 1]
        out.append(0.5 * np.sum(x * np.roll(y, -1) - np.roll(x, -1) * y))
    return np.array(out)


def assert_symmetric(m):
    """Adjacency checked face by face, independently of validate_stitch_mesh."""
    for f in range(len(m.stitch_type)):
        if m.course_right[f] >= 0:
            assert m.course_left[m.course_right[f]] == f
        if m.course_left[f] >= 0:
            assert m.course_right[m.course_left[f]] == f
        for g in m.wale_below[f][m.wale_below[f] >= 0]:
            assert m.wale_above[g] == f
        if m.wale_above[f] >= 0:
            assert f in m.wale_below[m.wale_above[f]]


def test_chart_gives_the_hand_built_mesh():
    assert_same(chart_to_mesh(SAMPLE_CHART, stitch_width=1, stitch_height=1), sample())


def test_chart_orientation_first_line_is_top_first_character_is_left():
    m = chart_to_mesh("pk\nkk\n", stitch_width=0.5, stitch_height=0.25, units="mm", yarn_type="silk1")
    assert m.stitch_type.tolist() == [KNIT, KNIT, PURL, KNIT] and m.course.tolist() == [0, 0, 1, 1]
    purl = m.vertices[m.face_vertices[m.face_offsets[2]:m.face_offsets[3]]]
    assert purl[:, 0].max() == 0.5 and purl[:, 1].min() == 0.25  # left stitch of the upper course
    assert (m.units, m.yarn_types) == ("mm", ["silk1"])
    np.testing.assert_allclose(signed_areas(m), 0.125)


def test_aliases_comments_blank_lines_and_spaces():
    courses = parse_chart("# top\n\n . - o/\\ k \t\n\n  p k p k p k p # bottom\n")
    assert [c.tolist() for c in courses] == [[PURL, KNIT] * 3 + [PURL], [KNIT, PURL, YO, K2TOG, SSK, KNIT]]
    assert all(c.dtype == np.int8 for c in courses)


@pytest.mark.parametrize("text, fragment", [
    ("kkk\nkxk\n", "line 2, column 2: 'x' is not a stitch symbol"),
    ("kk\n\n  k*k  # note\n", "line 3, column 4: '*' is not a stitch symbol"),
    ("kkk/k\nkkkk\n", "line 1, column 4: stitch 4 of course 1 needs stitch 5 of the course below (line 2), which "
                      "has only 4"),
    ("k/ok\nkk\n", "line 1, column 2: stitch 2 of course 1 needs stitch 3"),
    ("kkk\nkkkk\n", "line 1, column 3: course 1 ends having consumed 3 of the 4 stitches"),
    ("# nothing\n\n", "no stitches"),
])
def test_chart_errors_name_line_and_column(text, fragment):
    with pytest.raises(FormatError) as info:
        chart_to_mesh(text)
    assert fragment in str(info.value) and "\n" not in str(info.value), str(info.value)


def test_bad_sizes_and_patterns_rejected():
    for kwargs in ({"stitch_width": 0}, {"stitch_height": float("nan")}, {"stitch_width": "1"}):
        with pytest.raises(FormatError, match="expected a positive finite length"):
            chart_to_mesh("k", **kwargs)
    with pytest.raises(FormatError, match="unknown, expected one of stockinette, garter"):
        pattern_chart("cable", 4, 4)
    for rows, cols in ((0, 4), (4, -1), (2.5, 4), (True, 3)):
        with pytest.raises(FormatError, match="expected an integer >= 1"):
            pattern_chart("seed", rows, cols)


def test_shaped_chart_with_increases_and_decreases():
    chart = "kk/\n\\k\\k\nk/okoo\nkkkk\n"  # 4 → 6 → 4 → 3 stitches
    m = chart_to_mesh(chart)
    validate_stitch_mesh(m)
    assert np.bincount(m.course).tolist() == [4, 6, 4, 3]
    assert (signed_areas(m) > 0).all()
    assert_symmetric(m)
    sizes = np.diff(m.face_offsets)
    for code, size, below in ((KNIT, 4, 1), (YO, 3, 0), (K2TOG, 5, 2), (SSK, 5, 2)):
        assert (sizes[m.stitch_type == code] == size).all()
        if code != KNIT:  # knit faces of course 0 have nothing below
            assert ((m.wale_below[m.stitch_type == code] >= 0).sum(axis=1) == below).all()
    assert (m.wale_above[m.course == 3] == -1).all() and (m.wale_above[m.course < 3] >= 0).all()
    # the yarn zigzags: course 1 right to left, ending at its column 0
    assert m.yarn_faces[4:10].tolist() == [9, 8, 7, 6, 5, 4] and (m.yarn_direction[4:10] == -1).all()


@pytest.mark.parametrize("name", sorted(PATTERNS))
def test_every_named_pattern_makes_a_valid_mesh(name):
    rows, cols = 11, 13
    text = pattern_chart(name, rows, cols)
    assert text.startswith(f"# {name}: {rows} courses x {cols} stitches")
    m = chart_to_mesh(text)
    validate_stitch_mesh(m)
    assert_symmetric(m)
    assert len(m.stitch_type) == rows * cols and np.bincount(m.course).tolist() == [cols] * rows
    assert m.column.max() == cols - 1 and (signed_areas(m) > 0).all()
    np.testing.assert_allclose(m.vertices.max(axis=0), [cols * 0.25, rows * 0.2, 0])
    t, r, c = m.stitch_type, m.course, m.column
    expected = {"stockinette": np.zeros_like(t), "garter": r % 2, "rib1x1": c % 2, "rib2x2": (c % 4 >= 2),
                "seed": (r + c) % 2}
    if name in expected:
        np.testing.assert_array_equal(t, expected[name])
    grid = np.zeros((rows, cols), int)
    grid[r, c] = t
    if name == "diamond":
        assert set(t.tolist()) == {KNIT, PURL} and grid[5, 6] == PURL
        assert (grid[[0, 0, -1, -1], [0, -1, 0, -1]] == KNIT).all()
        np.testing.assert_array_equal(grid, grid[::-1])
        np.testing.assert_array_equal(grid, grid[:, ::-1])
        assert (grid == PURL).sum(axis=1).tolist() == [0, 3, 5, 7, 9, 11, 9, 7, 5, 3, 0]
    if name == "eyelet":
        assert grid[2].tolist() == [KNIT, YO, K2TOG, KNIT] * 3 + [KNIT]
        assert grid[6].tolist() == [KNIT, SSK, YO, KNIT] * 3 + [KNIT]
        assert (np.delete(grid, [2, 6, 10], axis=0) == KNIT).all()
        assert grid[10].tolist() == grid[2].tolist()


def test_pattern_text_round_trips_through_parse_chart():
    text = pattern_chart("eyelet", 4, 6)
    assert text.splitlines()[1:] == ["kkkkkk", "ko/kkk", "kkkkkk", "kkkkkk"]  # no room for a second pair
    assert [STITCH_TYPES[t] for t in parse_chart(text)[2]] == ["knit", "yarn_over", "k2tog"] + ["knit"] * 3


def test_spec_example_chart_is_valid():
    spec = (Path(__file__).parents[1] / "data_formats" / "STITCH_MESH.md").read_text()
    example = spec.split("Example (")[1].split("```")[1]
    m = chart_to_mesh(example)
    assert np.bincount(m.course).tolist() == [4, 4, 3]
    assert [STITCH_TYPES[t] for t in m.stitch_type[4:]] == ["knit", "yarn_over", "k2tog", "knit", "knit", "knit",
                                                            "ssk"]


def test_a_chart_knitted_in_the_round_is_a_tube_of_closed_courses(tmp_path):
    """Every course closes on its seam (column 0, its lowest face), the yarn spirals left → right through every
    course in order, the rest shape is a cylinder of circumference n w about y with its faces facing out, and both
    file formats keep it (HDF5 as version 1.1; OBJ by its shared seam vertices)."""
    m = chart_to_mesh(pattern_chart("rib2x2", 5, 12), in_the_round=True)
    assert is_round(m) and len(m.stitch_type) == 60
    last = np.flatnonzero(m.column == 11)
    assert (m.course_right[last] == np.flatnonzero(m.column == 0)).all() and (m.course_left >= 0).all()
    assert (m.yarn_faces == np.lexsort((m.column, m.course))).all() and (m.yarn_direction == 1).all()
    radius = np.hypot(m.vertices[:, 0], m.vertices[:, 2])
    assert np.allclose(radius, 12 * 0.25 / (2 * np.pi))
    centre = np.stack([m.vertices[m.face_vertices[a:b]].mean(axis=0) for a, b in zip(m.face_offsets[:-1],
                                                                                          m.face_offsets[1:])])
    v = m.vertices[m.face_vertices.reshape(-1, 4)]
    normal = np.cross(v[:, 1] - v[:, 0], v[:, 3] - v[:, 0])  # counter-clockwise from the bottom-left: out of the face
    assert (np.einsum("ij,ij->i", normal[:, [0, 2]], centre[:, [0, 2]]) > 0).all()  # the front faces out of the tube
    write_stitch_mesh(tmp_path / "t.h5", m)
    with h5py.File(tmp_path / "t.h5") as f:
        assert f.attrs["version"] == "1.1"
    assert_same(read_stitch_mesh(tmp_path / "t.h5"), m)
    write_obj_stitch_mesh(tmp_path / "t.obj", m)
    assert_same(read_obj_stitch_mesh(tmp_path / "t.obj", units="cm", yarn_type="cotton1"), m)
    eyelet = chart_to_mesh(pattern_chart("eyelet", 8, 12), in_the_round=True)  # decreases and yarn-overs close too
    assert is_round(eyelet) and (eyelet.course_right >= 0).all()


def test_in_the_round_errors():
    with pytest.raises(FormatError, match="the cast-on has 2 loop.s., expected at least 3 stitches round a tube"):
        chart_to_mesh("kk\nkk", in_the_round=True)
    m = chart_to_mesh(pattern_chart("stockinette", 3, 6), in_the_round=True)
    rolled = dataclasses.replace(m, yarn_faces=np.roll(m.yarn_faces, -1))
    with pytest.raises(FormatError, match="yarn 0: starts at face 1 .column 1., expected a yarn knitting in the round"):
        validate_stitch_mesh(rolled)
    back = dataclasses.replace(m, yarn_direction=-m.yarn_direction)  # from each seam the other way round
    with pytest.raises(FormatError, match="yarn 0: ends at face 17 before going round its course"):
        validate_stitch_mesh(back)
    order = np.lexsort((np.where(m.column == 0, 0, 6 - m.column), m.course))
    validate_stitch_mesh(dataclasses.replace(m, yarn_faces=order, yarn_direction=-np.ones_like(m.yarn_direction)))
    shifted = dataclasses.replace(m, column=(m.column + 1) % 6)
    with pytest.raises(FormatError, match="expected column 0 exactly at the face of lowest index"):
        validate_stitch_mesh(shifted)
