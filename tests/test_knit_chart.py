"""Tests of knitrun.sim.knit_chart: chart parsing, chart → StitchMesh, named patterns."""

from pathlib import Path

import numpy as np
import pytest

from data_formats.errors import FormatError
from data_formats.stitch_mesh import STITCH_TYPES, validate_stitch_mesh
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
