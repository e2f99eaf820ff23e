"""Stitch meshes in memory (``StitchMesh``), in our HDF5 file (``format = "knit-stitch-mesh"``, version 1.0) and as a
Wavefront OBJ with a stitch-label sidecar. The full spec is ``STITCH_MESH.md``; in short:

* Frame: x along the course (left → right seen from the front, i.e. the right side of the fabric), y along the wale
  (up, towards later courses), z out of the front. Rest vertex positions are in ``units`` (e.g. ``"cm"``).
* A face is one stitch of flat knitting. It makes one loop (its top edge) and consumes ``b`` loops of the course
  below (its bottom edges): ``LOOPS_CONSUMED`` = knit 1, purl 1, yarn_over 0, k2tog 2, ssk 2.
* A face has ``b + 3`` vertices, counter-clockwise seen from the front, starting bottom-left: the ``b + 1`` bottom
  vertices left → right, then top-right, top-left. Edge ``k`` runs from vertex ``k`` to vertex ``k + 1`` (cyclic):
  edges ``0 .. b-1`` bottom (left → right), ``b`` right, ``b + 1`` top, ``b + 2`` left. So knit and purl faces are
  quads, decreases are pentagons whose extra vertex is the middle of the bottom (two wales below, one above) and a
  yarn-over is a triangle with a single bottom vertex (it consumes no loop: the eyelet).
* Adjacency (−1 = border): ``course_left``/``course_right`` share the face's left/right edge; ``wale_below[f, k]``
  shares bottom edge ``k`` (−1 padded to 2 columns); ``wale_above`` shares the top edge. Stored adjacency must be
  symmetric and equal to what the shared edges give.
* ``course`` counts from 0 at the bottom (first knitted); ``column`` from 0 at the left of each course; every
  course is one left → right chain of faces and (course, column) is unique. Knitting in the round (version 1.1): a
  course may be **closed** (its last face's ``course_right`` is its column-0 face: a tube); then every course is
  closed, and column 0 of each is its face of lowest index (the seam).
* Yarns: yarn ``y`` visits ``yarn_faces[yarn_offsets[y]:yarn_offsets[y+1]]`` in knitting order, travelling
  ``yarn_direction`` (+1 left → right, −1 right → left) through each face. A yarn knits whole consecutive courses,
  turning at the end of each (flat knitting: the direction flips between courses); in the round it enters each
  course at column 0, goes once round it and climbs into the next course's column 0 with the same direction (a
  spiral); every face is visited once.
"""

import dataclasses
from pathlib import Path

import h5py
import numpy as np

from .atomic import atomic_path
from .conventions import MAX_COORD
from .errors import FormatError, one_line, read_problems
from .hdf5_fields import check_format_attrs, dataset, sniff_hdf5, str_attr, string_dataset
from .input_files import open_hdf5, read_head, regular_file
from .text_statements import parse_vertex

FORMAT_NAME = "knit-stitch-mesh"
FORMAT_VERSION = "1.1"  # 1.1 adds closed courses (knitting in the round); flat meshes are written as "1.0"
FLAT_VERSION = "1.0"

STITCH_TYPES = ("knit", "purl", "yarn_over", "k2tog", "ssk")  # code = index
LOOPS_CONSUMED = np.array([1, 1, 0, 2, 2], dtype=np.int64)  # bottom edges per stitch type
EDGE_NAMES = ("bottom", "right", "top", "left")  # edge kinds 0..3
TWIN_KIND = np.array([2, 3, 0, 1])  # a bottom edge is shared with a top edge, a right edge with a left edge
INDEX_FIELDS = ("face_offsets", "face_vertices", "course_left", "course_right", "wale_below", "wale_above", "course",
                "column", "yarn_offsets", "yarn_faces")  # int64 arrays


@dataclasses.dataclass
class StitchMesh:
    """A flat-knitted stitch mesh at rest; see the module docstring for the conventions."""

    vertices: np.ndarray  # float64 (V, 3), in units
    face_offsets: np.ndarray  # int64 (F+1,)
    face_vertices: np.ndarray  # int64 (face_offsets[-1],)
    stitch_type: np.ndarray  # int8 (F,), index into STITCH_TYPES
    course_left: np.ndarray  # int64 (F,)
    course_right: np.ndarray  # int64 (F,)
    wale_below: np.ndarray  # int64 (F, 2)
    wale_above: np.ndarray  # int64 (F,)
    course: np.ndarray  # int64 (F,)
    column: np.ndarray  # int64 (F,)
    yarn_offsets: np.ndarray  # int64 (Y+1,)
    yarn_faces: np.ndarray  # int64 (F,)
    yarn_direction: np.ndarray  # int8 (F,), aligned with yarn_faces
    yarn_type: np.ndarray  # int32 (Y,), index into yarn_types
    yarn_types: list  # list[str]
    units: str


def make_stitch_mesh(vertices, face_offsets, face_vertices, stitch_type, units="cm", yarn_type="unknown",
                     where="stitch mesh"):
    """Build a validated ``StitchMesh`` from faces alone: adjacency from shared edges, courses and columns from the
    course chains, and one yarn of type ``yarn_type`` knitting course 0 left → right, course 1 right → left, ..."""
    vertices = np.asarray(vertices, dtype=np.float64)
    face_offsets = np.asarray(face_offsets, dtype=np.int64)
    face_vertices = np.asarray(face_vertices, dtype=np.int64)
    stitch_type = np.asarray(stitch_type, dtype=np.int8)
    _check_vertices(vertices, where)
    _check_faces(vertices, face_offsets, face_vertices, stitch_type, where)
    left, right, below, above = derive_adjacency(len(vertices), face_offsets, face_vertices, stitch_type, where)
    course, column = derive_courses(left, right, below, where)
    if (left < 0).any():  # flat: course-major order, odd courses knitted right to left
        yarn_faces = np.lexsort((np.where(course % 2 == 1, -column, column), course))
        direction = np.where(course[yarn_faces] % 2 == 1, -1, 1).astype(np.int8)
    else:  # in the round: every course left to right from its seam, one spiral
        yarn_faces = np.lexsort((column, course))
        direction = np.ones(len(yarn_faces), np.int8)
    m = StitchMesh(vertices, face_offsets, face_vertices, stitch_type, left, right, below, above, course, column,
                   np.array([0, len(yarn_faces)], np.int64), yarn_faces, direction,
                   np.zeros(1, np.int32), [yarn_type], units)
    validate_stitch_mesh(m, where)
    return m


def face_edges(face_offsets, face_vertices, stitch_type):
    """Directed edges of all faces: (src, dst, face, slot, kind) with kind 0 bottom, 1 right, 2 top, 3 left."""
    sizes = np.diff(face_offsets)
    face = np.repeat(np.arange(len(sizes)), sizes)
    slot = np.arange(len(face_vertices)) - face_offsets[face]
    nxt = np.where(slot + 1 == sizes[face], face_offsets[face], np.arange(len(face_vertices)) + 1)
    b = LOOPS_CONSUMED[stitch_type][face]
    kind = np.select([slot < b, slot == b, slot == b + 1], [0, 1, 2], 3)
    return face_vertices, face_vertices[nxt], face, slot, kind


def _first_repeat(key, order):
    """The indices (i, j) of the first two equal entries of ``key`` in the stable sort ``order``, or None."""
    dup = np.flatnonzero(key[order][1:] == key[order][:-1])
    return None if dup.size == 0 else (order[dup[0]], order[dup[0] + 1])


def derive_adjacency(n_vertices, face_offsets, face_vertices, stitch_type, where="stitch mesh"):
    """(course_left, course_right, wale_below, wale_above) from shared edges of faces in the documented vertex order;
    ``FormatError`` naming the faces if an edge is used twice in one direction or pairs the wrong kinds of edges."""
    src, dst, face, slot, kind = face_edges(face_offsets, face_vertices, stitch_type)
    key = src * n_vertices + dst
    order = np.argsort(key, kind="stable")
    pair = _first_repeat(key, order)
    if pair is not None:
        e, e2 = pair
        raise FormatError(f"{where}: faces {face[e]} and {face[e2]} both use edge {src[e]}->{dst[e]} in the same "
                          f"direction, expected neighbouring faces to run counter-clockwise seen from the front")
    twin_key = dst * n_vertices + src
    pos = np.minimum(np.searchsorted(key[order], twin_key), len(key) - 1)
    twin = np.where(key[order][pos] == twin_key, order[pos], -1)
    has = np.flatnonzero(twin >= 0)
    bad = has[kind[twin[has]] != TWIN_KIND[kind[has]]]
    if bad.size:
        e, t = bad[0], twin[bad[0]]
        raise FormatError(f"{where}: face {face[e]} {EDGE_NAMES[kind[e]]} edge {src[e]}->{dst[e]} is shared with face "
                          f"{face[t]}'s {EDGE_NAMES[kind[t]]} edge, expected its {EDGE_NAMES[TWIN_KIND[kind[e]]]} edge "
                          f"(check the vertex order: counter-clockwise from the bottom-left)")
    n_faces = len(face_offsets) - 1
    other = np.where(twin >= 0, face[twin], -1)
    left, right, above = (np.full(n_faces, -1, np.int64) for _ in range(3))
    below = np.full((n_faces, 2), -1, np.int64)
    right[face[kind == 1]] = other[kind == 1]
    left[face[kind == 3]] = other[kind == 3]
    above[face[kind == 2]] = other[kind == 2]
    below[face[kind == 0], slot[kind == 0]] = other[kind == 0]
    return left, right, below, above


def derive_courses(course_left, course_right, wale_below, where="stitch mesh"):
    """(course, column) of every face: each chain of course neighbours starting at a left border is one course, and
    so is each closed chain (knitting in the round; column 0 at its face of lowest index); the chain without faces
    below is course 0 and each chain's faces above form the next course. Open and closed courses do not mix."""
    n_faces = len(course_left)
    chain = np.full(n_faces, -1, np.int64)
    column = np.full(n_faces, -1, np.int64)
    flat = bool((course_left < 0).any())
    starts = np.flatnonzero(course_left < 0).tolist() if flat else []
    n_chains = 0
    for f in (list(starts) if flat else range(n_faces)):  # in the round: each cycle from its lowest face index
        if chain[f] >= 0:
            continue
        if not flat:
            starts.append(f)
        g, col = f, 0
        while g >= 0 and chain[g] < 0:
            chain[g], column[g] = n_chains, col
            col, g = col + 1, int(course_right[g])
        n_chains += 1
        if not flat and g != f:
            raise FormatError(f"{where}: face {g}: two faces of one closed course have it as course_right, expected "
                              f"each course to be one chain")
    if (chain < 0).any():
        f = int(np.flatnonzero(chain < 0)[0])
        raise FormatError(f"{where}: face {f}: its course is closed (knitting in the round) while others have borders, "
                          f"expected every course flat or every course closed")
    starts = np.array(starts, np.int64)
    has = wale_below >= 0
    pairs = np.unique(np.stack([chain[np.nonzero(has)[0]], chain[wale_below[has]]], axis=1), axis=0)
    above_chain = np.full(len(starts), -1, np.int64)
    below_count = np.bincount(pairs[:, 0], minlength=len(starts))
    above_count = np.bincount(pairs[:, 1], minlength=len(starts))
    for counts, word in ((below_count, "below"), (above_count, "above")):
        bad = np.flatnonzero(counts > 1)
        if bad.size:
            raise FormatError(f"{where}: face {starts[bad[0]]}: its course has faces of {counts[bad[0]]} different "
                              f"courses {word} it, expected one course per row (flat knitting)")
    above_chain[pairs[:, 1]] = pairs[:, 0]
    roots = np.flatnonzero(below_count == 0)
    if len(roots) != 1:
        raise FormatError(f"{where}: faces {', '.join(map(str, starts[roots[:3]]))} each start a course with no "
                          f"faces below, expected exactly one bottom course")
    course_of_chain = np.full(len(starts), -1, np.int64)
    c, k = int(roots[0]), 0
    while c >= 0 and course_of_chain[c] < 0:
        course_of_chain[c], c, k = k, int(above_chain[c]), k + 1
    if (course_of_chain < 0).any():
        f = starts[np.flatnonzero(course_of_chain < 0)[0]]
        raise FormatError(f"{where}: face {f}: its course is not stacked on the bottom course, expected every course "
                          f"to sit on the one below")
    return course_of_chain[chain], column


def validate_stitch_mesh(m, where="stitch mesh"):
    """Raise ``FormatError`` (prefixed by ``where``, naming the face) if ``m`` breaks a convention of the module."""
    _check_vertices(m.vertices, where)
    _check_faces(m.vertices, m.face_offsets, m.face_vertices, m.stitch_type, where)
    n_faces = len(m.stitch_type)
    for name, shape, dtype in (("course_left", (n_faces,), np.int64), ("course_right", (n_faces,), np.int64),
                               ("wale_below", (n_faces, 2), np.int64), ("wale_above", (n_faces,), np.int64),
                               ("course", (n_faces,), np.int64), ("column", (n_faces,), np.int64),
                               ("yarn_faces", (n_faces,), np.int64), ("yarn_direction", (n_faces,), np.int8)):
        _check_array(getattr(m, name), name, shape, dtype, where)
    _check_adjacency(m, where)
    _check_courses(m, where)
    _check_yarns(m, where)
    if not isinstance(m.units, str) or not m.units:
        raise FormatError(f"{where}: units: got {m.units!r}, expected a non-empty unit name such as 'cm'")


def _shape_dtype(arr):
    return f"{arr.dtype} {arr.shape}" if isinstance(arr, np.ndarray) else type(arr).__name__


def _check_array(arr, name, shape, dtype, where):
    if not isinstance(arr, np.ndarray) or arr.dtype != dtype or arr.shape != shape:
        raise FormatError(f"{where}: {name}: got {_shape_dtype(arr)}, expected {np.dtype(dtype)} {shape}")


def _check_vertices(vertices, where):
    if not isinstance(vertices, np.ndarray) or vertices.dtype != np.float64 or vertices.ndim != 2 \
            or vertices.shape[1] != 3 or len(vertices) < 3:
        raise FormatError(f"{where}: vertices: got {_shape_dtype(vertices)}, expected float64 (V>=3, 3)")
    bad = np.flatnonzero(~np.isfinite(vertices).all(axis=1))
    if bad.size:
        raise FormatError(f"{where}: vertex {bad[0]}: coordinates {tuple(vertices[bad[0]].tolist())} are not "
                          f"finite, expected finite numbers")
    bad = np.flatnonzero(np.abs(vertices).max(axis=1) > MAX_COORD)
    if bad.size:
        raise FormatError(f"{where}: vertex {bad[0]}: coordinates {tuple(vertices[bad[0]].tolist())}, expected "
                          f"numbers in [{-MAX_COORD:g}, {MAX_COORD:g}]")


def _check_faces(vertices, offsets, fv, stitch_type, where):
    if not isinstance(stitch_type, np.ndarray) or stitch_type.dtype != np.int8 or stitch_type.ndim != 1 \
            or len(stitch_type) < 1:
        raise FormatError(f"{where}: stitch_type: got {_shape_dtype(stitch_type)}, expected int8 (F>=1,)")
    n_faces = len(stitch_type)
    _check_array(offsets, "face_offsets", (n_faces + 1,), np.int64, where)
    if not isinstance(fv, np.ndarray) or fv.dtype != np.int64 or fv.ndim != 1:
        raise FormatError(f"{where}: face_vertices: got {_shape_dtype(fv)}, expected int64 (face_offsets[-1],)")
    bad = np.flatnonzero((stitch_type < 0) | (stitch_type >= len(STITCH_TYPES)))
    if bad.size:
        raise FormatError(f"{where}: face {bad[0]}: stitch_type = {stitch_type[bad[0]]}, expected a code 0..4 "
                          f"({', '.join(STITCH_TYPES)})")
    if offsets[0] != 0 or offsets[-1] != len(fv):
        raise FormatError(f"{where}: face_offsets: runs from {offsets[0]} to {offsets[-1]}, expected 0 to the length "
                          f"{len(fv)} of face_vertices")
    expected = LOOPS_CONSUMED[stitch_type] + 3
    bad = np.flatnonzero(np.diff(offsets) != expected)
    if bad.size:
        f = bad[0]
        raise FormatError(f"{where}: face {f} ({STITCH_TYPES[stitch_type[f]]}): {offsets[f + 1] - offsets[f]} "
                          f"vertices, expected {expected[f]} ({LOOPS_CONSUMED[stitch_type[f]]} bottom edges + 3)")
    bad = np.flatnonzero((fv < 0) | (fv >= len(vertices)))
    if bad.size:
        f = int(np.searchsorted(offsets, bad[0], side="right") - 1)
        raise FormatError(f"{where}: face {f}: vertex index {fv[bad[0]]} out of range, expected 0..{len(vertices) - 1}")
    face = np.repeat(np.arange(n_faces), np.diff(offsets))
    key = np.sort(face * len(vertices) + fv)
    dup = np.flatnonzero(key[1:] == key[:-1])
    if dup.size:
        f, v = divmod(int(key[dup[0]]), len(vertices))
        raise FormatError(f"{where}: face {f}: vertex {v} appears twice, expected distinct vertices")


def _check_adjacency(m, where):
    n_faces = len(m.stitch_type)
    faces = np.arange(n_faces)
    for name in ("course_left", "course_right", "wale_below", "wale_above"):
        arr = getattr(m, name).reshape(n_faces, -1)
        bad = np.argwhere((arr < -1) | (arr >= n_faces) | (arr == faces[:, None]))
        if bad.size:
            f, k = bad[0]
            label = f"{name}[{k}]" if name == "wale_below" else name
            raise FormatError(f"{where}: face {f}: {label} = {arr[f, k]}, expected -1 or another face index "
                              f"0..{n_faces - 1}")
    bad = np.argwhere((m.wale_below >= 0) & (np.arange(2)[None, :] >= LOOPS_CONSUMED[m.stitch_type][:, None]))
    if bad.size:
        f, k = bad[0]
        raise FormatError(f"{where}: face {f} ({STITCH_TYPES[m.stitch_type[f]]}): wale_below[{k}] = "
                          f"{m.wale_below[f, k]}, expected -1 (it has {LOOPS_CONSUMED[m.stitch_type[f]]} bottom edges)")
    for name, other, back in (("course_right", "course_left", m.course_left),
                              ("course_left", "course_right", m.course_right)):
        arr = getattr(m, name)
        bad = np.flatnonzero((arr >= 0) & (back[np.maximum(arr, 0)] != faces))
        if bad.size:
            f, g = bad[0], arr[bad[0]]
            raise FormatError(f"{where}: face {f}: {name} = {g} but face {g}: {other} = {back[g]}, expected {f} "
                              f"(adjacency must be symmetric)")
    f_of, k_of = np.nonzero(m.wale_below >= 0)
    g = m.wale_below[f_of, k_of]
    bad = np.flatnonzero(m.wale_above[g] != f_of)
    if bad.size:
        f, k, g = f_of[bad[0]], k_of[bad[0]], g[bad[0]]
        raise FormatError(f"{where}: face {f}: wale_below[{k}] = {g} but face {g}: wale_above = {m.wale_above[g]}, "
                          f"expected {f} (adjacency must be symmetric)")
    up = np.flatnonzero(m.wale_above >= 0)
    bad = up[(m.wale_below[m.wale_above[up]] != up[:, None]).all(axis=1)]
    if bad.size:
        f, g = bad[0], m.wale_above[bad[0]]
        raise FormatError(f"{where}: face {f}: wale_above = {g} but face {g}: wale_below = "
                          f"{m.wale_below[g].tolist()}, expected it to contain {f} (adjacency must be symmetric)")
    derived = derive_adjacency(len(m.vertices), m.face_offsets, m.face_vertices, m.stitch_type, where)
    for name, want in zip(("course_left", "course_right", "wale_below", "wale_above"), derived):
        have = getattr(m, name).reshape(n_faces, -1)
        bad = np.argwhere(have != want.reshape(n_faces, -1))
        if bad.size:
            f, k = bad[0]
            label = f"{name}[{k}]" if name == "wale_below" else name
            raise FormatError(f"{where}: face {f}: {label} = {have[f, k]}, but the shared edges of the faces give "
                              f"{want.reshape(n_faces, -1)[f, k]}, expected adjacency to match the faces' edges")


def _check_courses(m, where):
    for name in ("course", "column"):
        bad = np.flatnonzero(getattr(m, name) < 0)
        if bad.size:
            raise FormatError(f"{where}: face {bad[0]}: {name} = {getattr(m, name)[bad[0]]}, expected >= 0")
    closed = is_round(m)
    if closed:
        if (m.course_left < 0).any() or (m.course_right < 0).any():
            f = int(np.flatnonzero((m.course_left < 0) | (m.course_right < 0))[0])
            raise FormatError(f"{where}: face {f}: a course border in a mesh knitted in the round, expected every "
                              f"course flat or every course closed")
        seam = m.column == 0
        lowest = np.full(int(m.course.max()) + 1, np.iinfo(np.int64).max)
        np.minimum.at(lowest, m.course, np.arange(len(m.course)))
        bad = np.flatnonzero(seam != (np.arange(len(m.course)) == lowest[m.course]))
        if bad.size:
            f = bad[0]
            raise FormatError(f"{where}: face {f}: column = {m.column[f]}, expected column 0 exactly at the face of "
                              f"lowest index of each closed course (its seam)")
    else:
        bad = np.flatnonzero((m.column == 0) != (m.course_left < 0))
        if bad.size:
            f = bad[0]
            raise FormatError(f"{where}: face {f}: column = {m.column[f]} with course_left = {m.course_left[f]}, "
                              f"expected column 0 exactly at a course's left border")
    r = np.flatnonzero(m.course_right >= 0)
    g = m.course_right[r]
    wraps = closed & (m.column[g] == 0)  # the last face of a closed course, back at its seam
    bad = r[(m.course[g] != m.course[r]) | ((m.column[g] != m.column[r] + 1) & ~wraps)]
    if bad.size:
        f, g = bad[0], m.course_right[bad[0]]
        raise FormatError(f"{where}: face {f} (course {m.course[f]}, column {m.column[f]}): its right neighbour {g} "
                          f"is at course {m.course[g]}, column {m.column[g]}, expected course {m.course[f]}, column "
                          f"{m.column[f] + 1}")
    up = np.flatnonzero(m.wale_above >= 0)
    bad = up[m.course[m.wale_above[up]] != m.course[up] + 1]
    if bad.size:
        f, g = bad[0], m.wale_above[bad[0]]
        raise FormatError(f"{where}: face {f} (course {m.course[f]}): the face above, {g}, is in course "
                          f"{m.course[g]}, expected {m.course[f] + 1}")
    key = m.course * (int(m.column.max()) + 1) + m.column
    pair = _first_repeat(key, np.argsort(key, kind="stable"))
    if pair is not None:
        f, g = pair
        raise FormatError(f"{where}: faces {f} and {g} are both at course {m.course[f]}, column {m.column[f]}, "
                          f"expected one chain of faces per course")


def _check_yarns(m, where):
    n_faces = len(m.stitch_type)
    off = m.yarn_offsets
    if not isinstance(off, np.ndarray) or off.dtype != np.int64 or off.ndim != 1 or len(off) < 2:
        raise FormatError(f"{where}: yarn_offsets: got {_shape_dtype(off)}, expected int64 (Y+1,) with Y >= 1")
    if off[0] != 0 or off[-1] != n_faces or (np.diff(off) < 1).any():
        raise FormatError(f"{where}: yarn_offsets: {off.tolist()!s:.80}, expected to rise strictly from 0 to the "
                          f"face count {n_faces}")
    _check_array(m.yarn_type, "yarn_type", (len(off) - 1,), np.int32, where)
    if not isinstance(m.yarn_types, list) or not m.yarn_types or not all(isinstance(s, str) and s
                                                                          for s in m.yarn_types):
        raise FormatError(f"{where}: yarn_types: got {m.yarn_types!r:.80}, expected a non-empty list of names")
    bad = np.flatnonzero((m.yarn_type < 0) | (m.yarn_type >= len(m.yarn_types)))
    if bad.size:
        raise FormatError(f"{where}: yarn {bad[0]}: yarn_type = {m.yarn_type[bad[0]]}, expected an index "
                          f"0..{len(m.yarn_types) - 1} into yarn_types")
    bad = np.flatnonzero((m.yarn_faces < 0) | (m.yarn_faces >= n_faces))
    if bad.size:
        raise FormatError(f"{where}: yarn_faces[{bad[0]}] = {m.yarn_faces[bad[0]]}, expected a face index "
                          f"0..{n_faces - 1}")
    visits = np.bincount(m.yarn_faces, minlength=n_faces)
    bad = np.flatnonzero(visits != 1)
    if bad.size:
        raise FormatError(f"{where}: face {bad[0]}: visited by {visits[bad[0]]} yarn passes, expected exactly 1")
    bad = np.flatnonzero(np.abs(m.yarn_direction) != 1)
    if bad.size:
        raise FormatError(f"{where}: yarn_direction[{bad[0]}] = {m.yarn_direction[bad[0]]}, expected +1 "
                          f"(left -> right) or -1 (right -> left)")
    f, d = m.yarn_faces, m.yarn_direction.astype(np.int64)
    ahead = np.where(d > 0, m.course_right[f], m.course_left[f])  # next face along the direction of travel
    first, last = off[:-1], off[1:] - 1
    closed = is_round(m)
    if closed:  # in the round: a yarn starts at a seam and ends a course next to its seam
        bad = np.flatnonzero(m.column[f[first]] != 0)
        if bad.size:
            raise FormatError(f"{where}: yarn {bad[0]}: starts at face {f[first[bad[0]]]} (column "
                              f"{m.column[f[first[bad[0]]]]}), expected a yarn knitting in the round to start at a "
                              f"seam (column 0)")
        bad = np.flatnonzero(m.column[ahead[last]] != 0)
        if bad.size:
            raise FormatError(f"{where}: yarn {bad[0]}: ends at face {f[last[bad[0]]]} before going round its "
                              f"course, expected it to end next to its seam")
    else:
        behind = np.where(d > 0, m.course_left[f], m.course_right[f])
        bad = np.flatnonzero(behind[first] >= 0)
        if bad.size:
            raise FormatError(f"{where}: yarn {bad[0]}: starts at face {f[first[bad[0]]]} inside its course, expected "
                              f"it to start at the course border behind its direction of travel")
        bad = np.flatnonzero(ahead[last] >= 0)
        if bad.size:
            raise FormatError(f"{where}: yarn {bad[0]}: ends at face {f[last[bad[0]]]} inside its course, expected it "
                              f"to end at the course border")
    step = np.ones(n_faces - 1, bool)
    step[off[1:-1] - 1] = False  # no step from one yarn to the next
    p = np.flatnonzero(step)
    same = m.course[f[p + 1]] == m.course[f[p]]
    if closed:  # after a course's last face: the seam of the next course, in the same direction
        turn = (m.column[ahead[p]] == 0) & (m.column[f[p + 1]] == 0) & (d[p + 1] == d[p])
        rule = "after the last one the seam of the next course in the same direction (knitting in the round)"
    else:  # at a course's border: a turn into the next course with the opposite direction
        turn = (ahead[p] < 0) & (d[p + 1] == -d[p])
        rule = "at its end a turn into the next course with the opposite direction"
    ok = np.where(same, (ahead[p] == f[p + 1]) & (d[p + 1] == d[p]),
                  turn & (m.course[f[p + 1]] == m.course[f[p]] + 1))
    bad = p[~ok]
    if bad.size:
        q = bad[0]
        raise FormatError(f"{where}: yarn_faces[{q}..{q + 1}]: the yarn goes from face {f[q]} (course {m.course[f[q]]},"
                          f" direction {d[q]:+d}) to face {f[q + 1]} (course {m.course[f[q + 1]]}, direction "
                          f"{d[q + 1]:+d}), expected the next face {'round' if closed else 'along'} the course, or "
                          f"{rule}")


def is_round(m) -> bool:
    """True for a stitch mesh knitted in the round (closed courses: no face has a left border)."""
    return len(m.course_left) > 0 and not (m.course_left < 0).any()


def summary(m):
    """JSON-serializable statistics of ``m`` shared by the ``describe`` functions of both file formats."""
    per_course = np.bincount(m.course)
    return {
        "units": m.units,
        "vertices": len(m.vertices),
        "faces": len(m.stitch_type),
        "courses": len(per_course),
        "in_the_round": is_round(m),
        "stitches_per_course": [int(per_course.min()), int(per_course.max())],
        "faces_per_stitch_type": dict(zip(STITCH_TYPES, np.bincount(m.stitch_type, minlength=5).tolist())),
        "faces_per_size": {str(n): int(c) for n, c in enumerate(np.bincount(np.diff(m.face_offsets))) if c},
        "yarns": len(m.yarn_type),
        "yarn_types": list(m.yarn_types),
        "bounds": [m.vertices.min(axis=0).tolist(), m.vertices.max(axis=0).tolist()],
    }


# --- HDF5 file ---------------------------------------------------------------------------------------------------

def write_stitch_mesh(path, m):
    """Validate ``m`` and write it atomically as a knit-stitch-mesh HDF5 file."""
    validate_stitch_mesh(m, str(path))
    with atomic_path(path) as tmp, h5py.File(tmp, "w") as f:
        f.attrs["format"] = FORMAT_NAME
        f.attrs["version"] = FORMAT_VERSION if is_round(m) else FLAT_VERSION
        f.attrs["units"] = m.units
        f.create_dataset("vertices", data=m.vertices)
        for name in INDEX_FIELDS + ("stitch_type", "yarn_direction", "yarn_type"):
            f.create_dataset(name, data=getattr(m, name))
        for name, names in (("stitch_types", list(STITCH_TYPES)), ("yarn_types", m.yarn_types)):
            f.create_dataset(name, data=np.array(names, dtype=object), dtype=h5py.string_dtype())


def read_stitch_mesh(path):
    """Read and fully validate a knit-stitch-mesh HDF5 file; raise ``FormatError`` on any problem."""
    where = str(path)
    with open_hdf5(path, f"a {FORMAT_NAME} file") as f:
        check_format_attrs(f, where, FORMAT_NAME, FORMAT_VERSION)
        names = string_dataset(f, "stitch_types", where)
        unknown = [n for n in names if n not in STITCH_TYPES]
        if unknown:
            raise FormatError(f"{where}: stitch_types: unknown stitch type {unknown[0]!r:.40}, expected names from "
                              f"{', '.join(STITCH_TYPES)}")
        codes = dataset(f, "stitch_type", "iu", where)
        bad = np.flatnonzero((codes < 0) | (codes >= len(names)))
        if bad.size:
            raise FormatError(f"{where}: face {bad[0]}: stitch_type = {codes.flat[bad[0]]}, expected an index "
                              f"0..{len(names) - 1} into stitch_types")
        direction = dataset(f, "yarn_direction", "i", where)
        bad = np.flatnonzero(np.abs(direction) != 1)
        if bad.size:
            raise FormatError(f"{where}: yarn_direction[{bad[0]}] = {direction.flat[bad[0]]}, expected +1 "
                              f"(left -> right) or -1 (right -> left)")
        yarn_type = dataset(f, "yarn_type", "iu", where)
        if yarn_type.size and (yarn_type.min() < -2**31 or yarn_type.max() >= 2**31):
            raise FormatError(f"{where}: yarn_type: values outside int32, expected indices into yarn_types")
        fields = {name: dataset(f, name, "iu", where) for name in INDEX_FIELDS}
        for name, arr in fields.items():
            if arr.dtype == np.uint64 and arr.size and arr.max() >= 2**63:
                raise FormatError(f"{where}: {name}: value {arr.max()} does not fit int64")
        m = StitchMesh(
            vertices=dataset(f, "vertices", "f", where).astype(np.float64),
            stitch_type=np.array([STITCH_TYPES.index(n) for n in names], np.int8)[codes],  # by name, not code
            yarn_direction=direction.astype(np.int8),
            yarn_type=yarn_type.astype(np.int32),
            yarn_types=string_dataset(f, "yarn_types", where),
            units=str_attr(f, "units", where),
            **{name: arr.astype(np.int64) for name, arr in fields.items()},
        )
    validate_stitch_mesh(m, where)
    return m


def sniff(path):
    """True if ``path`` is an HDF5 file whose root attribute ``format`` is ``"knit-stitch-mesh"``; never raises."""
    return sniff_hdf5(path, FORMAT_NAME)


def describe(path):
    """JSON-serializable summary of a knit-stitch-mesh file; raises ``FormatError`` if the file is invalid."""
    m = read_stitch_mesh(path)
    with open_hdf5(path, f"a {FORMAT_NAME} file") as f:
        version = str_attr(f, "version", str(path))
    return {"kind": "stitch-mesh", "version": version, **summary(m)}


def validate(path):
    """Problems found in a knit-stitch-mesh file (empty list: valid); never raises for bad content."""
    return read_problems(read_stitch_mesh, path, any_error=True)


# --- Wavefront OBJ + labels sidecar ------------------------------------------------------------------------------

OBJ_KEYWORDS = {"v", "vt", "vn", "vp", "f", "l", "p", "g", "o", "s", "usemtl", "mtllib", "cstype", "deg", "curv",
                "surf", "parm", "end", "mg", "lod", "bevel", "c_interp", "d_interp", "shadow_obj", "trace_obj"}
SNIFF_BYTES = 1 << 20


def labels_path_for(obj_path):
    """The default labels sidecar of an OBJ file: the same path with the suffix ``.labels``."""
    return Path(obj_path).with_suffix(".labels")


def read_obj_stitch_mesh(obj_path, labels_path=None, units="cm", yarn_type="unknown"):
    """Read a stitch mesh from a Wavefront OBJ (``v`` and ``f`` lines; faces in the documented vertex order) and its
    labels file (one stitch-type name per face, in face order). ``labels_path=None`` uses the sidecar
    ``labels_path_for(obj_path)`` if it exists, otherwise every face is knit. Adjacency, courses and one yarn are
    derived as in ``make_stitch_mesh``; OBJ carries no units or yarn data, hence ``units`` and ``yarn_type``."""
    where = str(obj_path)
    vertices, face_offsets, face_vertices, face_lines = parse_obj(obj_path, where)
    n_faces = len(face_offsets) - 1
    labels_path = _resolve_labels(obj_path, labels_path)
    if labels_path is None:
        stitch_type = np.zeros(n_faces, np.int8)
    else:
        stitch_type = _read_labels(labels_path, n_faces, where)
    sizes = np.diff(face_offsets)
    bad = np.flatnonzero(sizes != LOOPS_CONSUMED[stitch_type] + 3)
    if bad.size:
        f = bad[0]
        raise FormatError(f"{where}: line {face_lines[f]}: face {f} has {sizes[f]} vertices but is labelled "
                          f"{STITCH_TYPES[stitch_type[f]]}, expected {LOOPS_CONSUMED[stitch_type[f]] + 3}"
                          + ("" if labels_path is not None else " (no labels file: every face is read as knit)"))
    return make_stitch_mesh(vertices, face_offsets, face_vertices, stitch_type, units, yarn_type, where)


def _resolve_labels(obj_path, labels_path):
    """``labels_path``, or for None the sidecar if it exists, else None (every face knit)."""
    if labels_path is None and labels_path_for(obj_path).is_file():
        return labels_path_for(obj_path)
    return labels_path


def _read_text(path, where):
    try:
        return regular_file(path, "an OBJ stitch mesh").read_text(encoding="utf-8")
    except UnicodeDecodeError as e:
        raise FormatError(f"{where}: not UTF-8 text (byte {e.start}), expected a text file")
    except OSError as e:
        raise FormatError(f"{where}: cannot read ({one_line(e)})")


def parse_obj(path, where):
    vertices, vertex_lines, faces, face_lines = [], [], [], []
    for lineno, line in enumerate(_read_text(path, where).splitlines(), 1):
        tokens = line.split("#", 1)[0].split()
        if not tokens or tokens[0] not in ("v", "f"):
            continue  # other OBJ statements (vn, vt, g, usemtl, ...) carry nothing we use
        if tokens[0] == "v":
            vertices.append(parse_vertex(tokens, where, lineno, line, label=f"vertex {len(vertices)}: "))
            vertex_lines.append(lineno)
        else:
            try:
                idx = [int(t.split("/", 1)[0]) for t in tokens[1:]]
            except ValueError:
                idx = []
            if len(idx) < 3 or 0 in idx:
                raise FormatError(f"{where}: line {lineno}: face {len(faces)}: {line.strip()!r:.60}, expected 'f' and "
                                  f"at least 3 nonzero vertex indices")
            faces.append([i - 1 if i > 0 else len(vertices) + i for i in idx])  # negative: relative to this line
            face_lines.append(lineno)
    if len(vertices) < 3 or not faces:
        raise FormatError(f"{where}: {len(vertices)} vertices and {len(faces)} faces, expected an OBJ mesh with 'v' "
                          f"and 'f' lines")
    vertices = np.array(vertices, np.float64)
    bad = np.flatnonzero(~np.isfinite(vertices).all(axis=1))
    if bad.size:
        raise FormatError(f"{where}: line {vertex_lines[bad[0]]}: vertex {bad[0]}: coordinates "
                          f"{tuple(vertices[bad[0]].tolist())} are not finite, expected finite numbers")
    for f, face in enumerate(faces):  # Python ints: an index past int64 is named, not an OverflowError
        bad = [i for i in face if not 0 <= i < len(vertices)]
        if bad:
            raise FormatError(f"{where}: line {face_lines[f]}: face {f}: vertex {bad[0] + 1} (1-based) does not exist, "
                              f"expected 1..{len(vertices)}")
    fv = np.array([i for face in faces for i in face], np.int64)
    offsets = np.concatenate([[0], np.cumsum([len(face) for face in faces])]).astype(np.int64)
    return vertices, offsets, fv, face_lines


def _read_labels(path, n_faces, obj_where):
    where = str(path)
    codes = []
    for lineno, line in enumerate(_read_text(path, where).splitlines(), 1):
        name = line.split("#", 1)[0].strip()
        if not name:
            continue
        if name not in STITCH_TYPES:
            raise FormatError(f"{where}: line {lineno}: label {name!r:.40} for face {len(codes)}, expected one of "
                              f"{', '.join(STITCH_TYPES)}")
        codes.append(STITCH_TYPES.index(name))
    if len(codes) != n_faces:
        raise FormatError(f"{where}: {len(codes)} labels, expected one per face of {obj_where} ({n_faces})")
    return np.array(codes, np.int8)


def write_obj_stitch_mesh(obj_path, m, labels_path=None):
    """Validate ``m`` and write its rest vertices and faces as OBJ plus the labels file (default: the sidecar
    ``labels_path_for(obj_path)``), both atomically. Coordinates are written exactly (shortest round-trip repr);
    courses, adjacency and yarns are not stored (the reader derives them), nor are units and yarn types."""
    validate_stitch_mesh(m, str(obj_path))
    labels_path = labels_path_for(obj_path) if labels_path is None else Path(labels_path)
    header = (f"# {FORMAT_NAME} as OBJ: units {m.units}; stitch labels in {labels_path.name}; each face counter-"
              f"clockwise from the front, starting bottom-left: bottom vertices left to right, top-right, top-left\n")
    lines = [f"v {x!r} {y!r} {z!r}" for x, y, z in m.vertices.tolist()]
    fv = (m.face_vertices + 1).tolist()
    lines += ["f " + " ".join(map(str, fv[a:b])) for a, b in zip(m.face_offsets[:-1], m.face_offsets[1:])]
    labels = [STITCH_TYPES[t] for t in m.stitch_type.tolist()]
    with atomic_path(obj_path) as obj_tmp, atomic_path(labels_path) as labels_tmp:
        Path(obj_tmp).write_text(header + "\n".join(lines) + "\n", encoding="utf-8")
        Path(labels_tmp).write_text(f"# stitch type of each face of {Path(obj_path).name}, in face order\n"
                                    + "\n".join(labels) + "\n", encoding="utf-8")


def sniff_obj(path):
    """True if ``path`` looks like Wavefront OBJ text: its first MiB is UTF-8, every complete line is blank, a
    comment or an OBJ statement, it has a ``v`` line, and an ``f`` line unless the file is longer; never raises."""
    head = read_head(path, SNIFF_BYTES + 1)
    if head is None:
        return False
    try:
        whole = len(head) <= SNIFF_BYTES
        text = head[:SNIFF_BYTES].decode("utf-8", errors="strict" if whole else "ignore")
        lines = text.splitlines() if whole else text.splitlines()[:-1]
        starts = {line.split()[0] for line in lines if line.strip() and not line.lstrip().startswith("#")}
        return "\x00" not in text and starts <= OBJ_KEYWORDS and "v" in starts and ("f" in starts or not whole)
    except Exception:
        return False


def describe_obj(path, labels_path=None):
    """JSON-serializable summary of an OBJ stitch mesh (labels as in ``read_obj_stitch_mesh``); raises
    ``FormatError`` if the mesh is invalid."""
    m = read_obj_stitch_mesh(path, labels_path)
    labels_path = _resolve_labels(path, labels_path)
    return {"kind": "stitch-mesh-obj", "labels": None if labels_path is None else str(labels_path), **summary(m)}


def validate_obj(path, labels_path=None):
    """Problems found in an OBJ stitch mesh and its labels (empty list: valid); never raises for bad content."""
    return read_problems(read_obj_stitch_mesh, path, labels_path, any_error=True)


def load_stitch_mesh(path):
    """A stitch mesh from our HDF5 file, an OBJ (+ its .labels sidecar) or an augmented stitch mesh ``.smobj``
    (``data_formats.smobj``), by content / extension."""
    from . import smobj

    if Path(path).suffix.lower() == ".obj":
        return read_obj_stitch_mesh(path)
    if not Path(path).is_file():
        raise FormatError(f"{path}: no such file")
    if Path(path).suffix.lower() == ".smobj" or smobj.sniff(path):
        return smobj.read_smobj(path)
    if not sniff(path):
        raise FormatError(f"{path}: not a stitch mesh, expected a knit-stitch-mesh .h5 file, an .obj (+ .labels) or "
                          f"an .smobj")
    return read_stitch_mesh(path)
