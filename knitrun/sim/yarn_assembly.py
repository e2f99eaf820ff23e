"""Join per-face control points into continuous yarns in knitting order, and up-sample them for rendering.

Face points
-----------
The solver writes the template points of face f (``stitch_templates``: piece by piece) to rows
``point_offset[f] : point_offset[f + 1]`` of one (N, 3) buffer. Boundary points shared by two faces appear in both
faces' rows with bit-identical coordinates; a yarn takes each shared point once.

Yarn order (``yarn_layout``)
----------------------------
A stitch-mesh yarn visits its faces in knitting order (``yarn_faces``, ``yarn_direction``). Through face f travelling
left → right it takes f's IN piece (left side point, left leg up to the top edge), then the head of the loop f makes,
which is the loop piece of the face above that consumes it (without its two end points, which are f's top points),
then f's OUT piece (right leg down to the right side point). Right → left it takes the same points in reverse. Where
f has no face above (the last course) the yarn goes straight from the top of one leg to the top of the other (a
bind-off). A face's first side point is dropped when the previous face of the yarn is its course neighbour (the
shared point); at the turn into the next course the yarn joins the two side points with one segment.
Loops consumed from nowhere (``wale_below`` = −1: the cast-on under course 0) form extra curves, one per run of
neighbouring faces of a course, loop after loop, with the yarn type of the yarn that knits those faces.

Up-sampling (``upsample_plan``, ``render_points``)
--------------------------------------------------
Each curve's control polygon is sampled on its uniform Catmull-Rom spline at ``samples`` points per segment
(t = 0, 1/S, ..., (S−1)/S; end points duplicated for the end segments) plus its last point: a curve of n control
points gives (n − 1)·S + 1 rendering points, which lie on the spline through the control points.
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np
from numba import njit, prange

from data_formats.numba_setup import FASTMATH
from data_formats.stitch_mesh import LOOPS_CONSUMED
from knitrun.sim.stitch_templates import N_POINTS, ROLE_IN, ROLE_LOOP, ROLE_OUT, piece_ranges


class YarnLayout(NamedTuple):
    """Control points of every curve as rows of the face-point buffer: curve c is ``index[offsets[c]:offsets[c+1]]``."""

    index: np.ndarray  # int64 (P,)
    offsets: np.ndarray  # int64 (C+1,)
    yarn_type: np.ndarray  # int32 (C,)
    cast_on: np.ndarray  # bool (C,): the curve is a cast-on run (not one of the mesh's yarns)


class UpsamplePlan(NamedTuple):
    """Index form of the Catmull-Rom up-sampling of a ``YarnLayout``: segment i uses face-point rows
    ``seg_index[i]`` (p_{-1}, p_0, p_1, p_2) and writes rendering rows ``seg_out[i] : seg_out[i] + samples``; each
    curve's last point (row ``last_index[c]``) goes to ``last_out[c]``."""

    seg_index: np.ndarray  # int64 (S, 4)
    seg_out: np.ndarray  # int64 (S,)
    last_index: np.ndarray  # int64 (C,)
    last_out: np.ndarray  # int64 (C,)
    offsets: np.ndarray  # int64 (C+1,): rendering points of each curve
    samples: int


def face_point_offsets(stitch_type):
    """(F+1,) int64: face f's points are rows point_offset[f]:point_offset[f+1] of the face-point buffer."""
    return np.concatenate([[0], np.cumsum(N_POINTS[stitch_type])]).astype(np.int64)


_PIECES = [{role: (start, stop) for role, start, stop in piece_ranges(code)} for code in range(len(N_POINTS))]


def _piece_rows(stitch_type, point_offset, f, role):
    start, stop = _PIECES[stitch_type[f]][role]
    return list(range(point_offset[f] + start, point_offset[f] + stop))


def yarn_layout(mesh, point_offset):
    """``YarnLayout`` of a ``StitchMesh`` (module docstring): its yarns first, in order, then the cast-on runs."""
    st = mesh.stitch_type
    curves, types, cast_on = [], [], []
    face_yarn = np.empty(len(st), np.int64)
    for y in range(len(mesh.yarn_offsets) - 1):
        o0, o1 = mesh.yarn_offsets[y], mesh.yarn_offsets[y + 1]
        face_yarn[mesh.yarn_faces[o0:o1]] = y
        rows, prev = [], -1
        for f, direction in zip(mesh.yarn_faces[o0:o1].tolist(), mesh.yarn_direction[o0:o1].tolist()):
            above = int(mesh.wale_above[f])
            middle = []
            if above >= 0:
                k = int(np.flatnonzero(mesh.wale_below[above] == f)[0])
                middle = _piece_rows(st, point_offset, above, ROLE_LOOP + k)[1:-1]
            chain = _piece_rows(st, point_offset, f, ROLE_IN) + middle + _piece_rows(st, point_offset, f, ROLE_OUT)
            entry = mesh.course_left[f]
            if direction < 0:
                chain, entry = chain[::-1], mesh.course_right[f]
            rows += chain[1:] if prev >= 0 and prev == entry else chain
            prev = f
        curves.append(rows)
        types.append(mesh.yarn_type[y])
        cast_on.append(False)
    orphans = [(int(mesh.course[f]), int(mesh.column[f]), int(k), int(f))
               for f, k in zip(*np.nonzero(mesh.wale_below < 0)) if k < LOOPS_CONSUMED[st[f]]]
    run, last = [], None
    for course, _, k, f in sorted(orphans) + [(None, None, None, None)]:
        joins = last is not None and f is not None and course == last[0] and f in (last[1], mesh.course_right[last[1]])
        if run and not joins:
            curves.append(run)
            types.append(mesh.yarn_type[face_yarn[last[1]]])
            cast_on.append(True)
            run = []
        if f is not None:
            run += _piece_rows(st, point_offset, f, ROLE_LOOP + k)
            last = (course, f)
    offsets = np.concatenate([[0], np.cumsum([len(c) for c in curves])]).astype(np.int64)
    return YarnLayout(np.array([r for c in curves for r in c], np.int64), offsets, np.array(types, np.int32),
                      np.array(cast_on, bool))


def upsample_plan(layout, samples):
    """``UpsamplePlan`` of ``layout`` with ``samples`` (≥ 1) rendering points per control segment."""
    counts = np.diff(layout.offsets)
    out_offsets = np.concatenate([[0], np.cumsum((counts - 1) * samples + 1)]).astype(np.int64)
    seg_index, seg_out = [], []
    for c in range(len(counts)):
        idx = layout.index[layout.offsets[c]:layout.offsets[c + 1]]
        n = len(idx)
        i = np.arange(n - 1)
        seg_index.append(np.stack([idx[np.maximum(i - 1, 0)], idx[i], idx[i + 1], idx[np.minimum(i + 2, n - 1)]], 1))
        seg_out.append(out_offsets[c] + i * samples)
    return UpsamplePlan(np.concatenate(seg_index).astype(np.int64), np.concatenate(seg_out).astype(np.int64),
                        layout.index[layout.offsets[1:] - 1].copy(), out_offsets[1:] - 1, out_offsets, int(samples))


@njit(parallel=True, cache=True, fastmath=FASTMATH)
def render_points(face_points, seg_index, seg_out, last_index, last_out, samples, out):
    """Uniform Catmull-Rom samples of every control segment (``UpsamplePlan``) into ``out`` (rendering rows)."""
    for s in prange(seg_index.shape[0]):
        i0, i1, i2, i3 = seg_index[s, 0], seg_index[s, 1], seg_index[s, 2], seg_index[s, 3]
        for k in range(samples):
            t = k / samples
            t2, t3 = t * t, t * t * t
            w0 = 0.5 * (-t + 2.0 * t2 - t3)
            w1 = 0.5 * (2.0 - 5.0 * t2 + 3.0 * t3)
            w2 = 0.5 * (t + 4.0 * t2 - 3.0 * t3)
            w3 = 0.5 * (t3 - t2)
            for d in range(3):
                out[seg_out[s] + k, d] = w0 * face_points[i0, d] + w1 * face_points[i1, d] \
                    + w2 * face_points[i2, d] + w3 * face_points[i3, d]
    for c in range(last_index.shape[0]):
        for d in range(3):
            out[last_out[c], d] = face_points[last_index[c], d]
