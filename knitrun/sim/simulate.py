"""Knot simulation of a stitch mesh: rest mesh + per-frame vertex positions → ``YarnCurves`` (Huang et al. 2025 §3,
§5.2).

``prepare`` computes once what is fixed over an animation (rest frames and knots of every face, rest lengths and
angles of the templates, the yarn order, the up-sampling plan, the rest arc length). ``solve_frame`` runs the per-face
knot solver (``knot_solver``) on one frame's vertices; ``yarn_points`` joins and up-samples the result;
``simulate`` does both for every frame and reports timings and energies. ``face_problem``, ``knot_centres``,
``control_segment_lengths`` and ``course_knot_spacing`` expose the per-face problem and the measurements that tests
and benchmarks compare (dense reference solves, Huang et al. 2025 Fig. 9).

Conventions
-----------
* Lengths are in the mesh's ``units``. The yarn radius r defaults to ``RADIUS_PER_STITCH`` × the length scale h
  (the median rest length of the faces' top edges, i.e. one stitch width): 0.25 cm stitches (the chart default) give
  r = 0.031 cm, about cotton1's. The templates are sized and relaxed for that ratio; another radius (more than 5 %
  off) is simulated but named in ``report["warnings"]`` (``template_size_warnings``). Energies are dimensionless
  (lengths divided by h, ``knot_solver``).
* Output points are the Catmull-Rom samples of the control points (``samples`` per control segment, curve type
  ``"PL"``: rendering vertices), or the control points themselves for ``samples = 1`` (curve type ``"C0"``).
* ``rest_arclength`` is the cumulative length of the rendering points of the rest mesh (not of frame 0), the same
  for every frame, so texture coordinates along a yarn do not slide when it stretches.
* Vertex input must be finite: a non-finite coordinate is a ``FormatError`` naming the frame, face and vertex; the
  output is checked too and never holds NaN or Inf.
"""

from __future__ import annotations

import dataclasses
import math
import numbers
import time

import numba
import numpy as np

from data_formats.errors import FormatError
from data_formats.yarn_curves import control_polygon_arclength, make_yarn_curves
from knitrun.sim.knot_solver import (EPS_LENGTH, MAX_RESIDUALS, R_TARGETS, REST_SIZE, W_SIZE, face_setup, knot_points,
                                     prepare_faces, residuals, solve_faces)
from knitrun.sim.stitch_templates import (F_A, F_C, I_KNOT, I_PIECES, MAX_POINTS, N_KNOTS, N_UNKNOWNS, TEMPLATE_FLOAT,
                                          TEMPLATE_INT)
from knitrun.sim.yarn_assembly import face_point_offsets, render_points, upsample_plan, yarn_layout

RADIUS_PER_STITCH = 1.0 / 8.0  # default yarn radius / stitch width: a stitch 4 yarn diameters wide
RADIUS_TOLERANCE = 0.05  # a yarn radius more than this far (relative) off the one it was built for: a warning
CHUNKS_PER_THREAD = 16  # faces are split in this many chunks per thread (each chunk allocates its scratch once)


@dataclasses.dataclass
class KnotModel:
    """Everything fixed over an animation of one stitch mesh (see ``prepare``)."""

    mesh: object  # StitchMesh
    radius: float
    length_scale: float
    params: np.ndarray  # (radius, length_scale, w_angle, w_length, beta), the kernel's layout
    iterations: int
    point_offset: np.ndarray  # (F+1,) rows of each face in the face-point buffer
    rest: np.ndarray  # (F, REST_SIZE) rest rows of knot_solver.prepare_faces
    layout: object  # YarnLayout
    plan: object  # UpsamplePlan
    rest_points: np.ndarray  # (N, 3) face points of the rest mesh
    rest_arclength: np.ndarray  # (P,) of the rendering points


@dataclasses.dataclass
class FrameSolution:
    """One frame solved: face points (N, 3), Θ per face (F, 4), energy per face after each iteration (F, it+1)."""

    points: np.ndarray
    theta: np.ndarray
    energy: np.ndarray


def _check_number(name, value, low, low_ok=True):
    ok = isinstance(value, numbers.Real) and not isinstance(value, bool) and math.isfinite(value) \
        and (value >= low if low_ok else value > low)
    if not ok:
        raise FormatError(f"{name} = {value!r}, expected a finite number {'>=' if low_ok else '>'} {low}")
    return float(value)


def prepare(mesh, radius=None, iterations=3, w_angle=1.0, w_length=100.0, beta=1.0, samples=4):
    """``KnotModel`` of a ``StitchMesh`` at rest. ``radius``: yarn radius in mesh units (default: module docstring);
    ``iterations``: Gauss-Newton iterations; ``w_angle``, ``w_length``: energy weights (eq. 3); ``beta``: knot spacing
    blend; ``samples``: rendering points per control segment. ``FormatError`` for bad values or a rest face with no
    area (naming the face)."""
    n_faces = len(mesh.stitch_type)
    sizes = np.diff(mesh.face_offsets)
    tr = mesh.face_vertices[mesh.face_offsets[:-1] + sizes - 2]
    tl = mesh.face_vertices[mesh.face_offsets[:-1] + sizes - 1]
    length_scale = float(np.median(np.linalg.norm(mesh.vertices[tr] - mesh.vertices[tl], axis=1)))
    if not length_scale > 0:
        raise FormatError(f"stitch mesh: median top-edge length is {length_scale}, expected faces with a size")
    radius = RADIUS_PER_STITCH * length_scale if radius is None else _check_number("radius", radius, 0, False)
    for name, value in (("w_angle", w_angle), ("w_length", w_length)):
        _check_number(name, value, 0)
    if w_angle + w_length <= 0:
        raise FormatError("w_angle = w_length = 0, expected at least one positive energy weight")
    beta = _check_number("beta", beta, -math.inf)  # any finite blend
    for name, value, low in (("iterations", iterations, 0), ("samples", samples, 1)):
        if not isinstance(value, numbers.Integral) or isinstance(value, bool) or value < low:
            raise FormatError(f"{name} = {value!r}, expected an integer >= {low}")
    rest = np.zeros((n_faces, REST_SIZE))
    bad = np.zeros(n_faces, np.int8)
    prepare_faces(mesh.vertices, mesh.face_offsets, mesh.face_vertices, mesh.stitch_type, TEMPLATE_INT, TEMPLATE_FLOAT,
                  radius, rest, bad)
    if bad.any():
        f = int(np.flatnonzero(bad)[0])
        raise FormatError(f"stitch mesh: face {f}: the rest face has no area, expected a proper polygon at rest")
    point_offset = face_point_offsets(mesh.stitch_type)
    layout = yarn_layout(mesh, point_offset)
    plan = upsample_plan(layout, samples)
    model = KnotModel(mesh, radius, length_scale, np.array([radius, length_scale, w_angle, w_length, beta]),
                      int(iterations), point_offset, rest, layout, plan, None, None)
    model.rest_points = solve_frame(model, mesh.vertices).points
    model.rest_arclength = control_polygon_arclength(yarn_points(model, model.rest_points), plan.offsets)
    return model


def check_vertices(model, vertices, where="vertices"):
    """``vertices`` as float64 (V, 3); ``FormatError`` for a wrong shape or a non-finite coordinate (naming the first
    face that uses it)."""
    v = np.asarray(vertices, dtype=np.float64)
    if v.shape != model.mesh.vertices.shape:
        raise FormatError(f"{where}: shape {v.shape}, expected the mesh's {model.mesh.vertices.shape}")
    bad = ~np.isfinite(v).all(axis=1)
    if bad.any():
        corners = np.flatnonzero(bad[model.mesh.face_vertices])
        if not corners.size:
            i = int(np.flatnonzero(bad)[0])
            raise FormatError(f"{where}: vertex {i} = {tuple(v[i].tolist())} (in no face) is not finite, expected "
                              f"finite coordinates")
        f = int(np.searchsorted(model.mesh.face_offsets, corners[0], side="right") - 1)
        i = int(model.mesh.face_vertices[corners[0]])
        raise FormatError(f"{where}: face {f}: vertex {i} = {tuple(v[i].tolist())} is not finite, expected finite "
                          f"coordinates")
    return v


def solve_frame(model, vertices, naive=False, iterations=None, where="vertices", out=None):
    """Solve one frame (``knot_solver.solve_faces``); ``naive``: naive interpolation of control points instead;
    ``iterations`` overrides the model's (0: knot interpolation without optimisation); ``out``: a ``FrameSolution``
    of an earlier call with as many iterations, filled again instead of allocating (an animation loop's buffers)."""
    v = check_vertices(model, vertices, where)
    iterations = model.iterations if iterations is None else int(iterations)
    m = model.mesh
    n_faces = len(m.stitch_type)
    if out is None or out.energy.shape != (n_faces, iterations + 1):
        out = FrameSolution(np.empty((model.point_offset[-1], 3)), np.empty((n_faces, N_UNKNOWNS)),
                            np.empty((n_faces, iterations + 1)))
    n_chunks = max(1, min(n_faces, CHUNKS_PER_THREAD * numba.get_num_threads()))
    solve_faces(v, m.face_offsets, m.face_vertices, m.stitch_type, model.point_offset, model.rest, TEMPLATE_INT,
                TEMPLATE_FLOAT, model.params, iterations, naive, n_chunks, out.points, out.theta, out.energy)
    bad = np.flatnonzero(~np.isfinite(out.energy).all(axis=1))  # the kernel marks faces with non-finite points
    if bad.size:
        raise FormatError(f"{where}: face {bad[0]}: the simulation overflowed to non-finite values (vertex "
                          f"coordinates too large?)")
    return out


def yarn_points(model, face_points, out=None):
    """Rendering points (P, 3) of all curves from a frame's face points (``yarn_assembly``), into ``out`` if given."""
    p = model.plan
    out = np.empty((p.offsets[-1], 3)) if out is None else out
    render_points(face_points, p.seg_index, p.seg_out, p.last_index, p.last_out, p.samples, out)
    return out


def simulate(mesh, frames, radius=None, frame_time=None, progress=None, **options):
    """Simulate every frame of ``frames`` ((T, V, 3) vertex positions, or a list of (V, 3)) on ``mesh``; ``options``
    as in ``prepare``; ``progress(done, total)`` is called after each frame.

    Returns (``YarnCurves``, report): report holds ``ms_per_frame`` (each frame's solve + assembly), its median,
    ``prepare_s`` (rest data, yarn order and the rest solve, which pays Numba compile or cache load), ``curves_s``
    (building and validating the yarn curves of all frames), ``seconds`` (the whole call), the total
    energy of each frame after the last iteration (``frame_energy``), of the last frame after each iteration
    (``energy_history``), ``final_energy`` (the last frame's, after the last iteration) and counts."""
    t0 = time.perf_counter()
    model = prepare(mesh, radius=radius, **options)
    prepare_s = time.perf_counter() - t0
    if len(frames) < 1:
        raise FormatError("no frames to simulate, expected at least one")
    out = np.empty((len(frames), model.plan.offsets[-1], 3))
    times, frame_energy, solution = [], [], None
    for t, vertices in enumerate(frames):
        t1 = time.perf_counter()
        solution = solve_frame(model, vertices, where=f"frame {t}", out=solution)
        yarn_points(model, solution.points, out=out[t])
        times.append((time.perf_counter() - t1) * 1e3)
        frame_energy.append(float(solution.energy[:, -1].sum()))
        if progress is not None:
            progress(t + 1, len(frames))
    t1 = time.perf_counter()
    curves = make_yarn_curves(out, model.plan.offsets, yarn_type=model.layout.yarn_type,
                              yarn_types=mesh.yarn_types, rest_arclength=model.rest_arclength,
                              curve_type="PL" if model.plan.samples > 1 else "C0", units=mesh.units,
                              frame_time=frame_time, radius=model.radius)
    curves_s = time.perf_counter() - t1
    history = solution.energy.sum(axis=0)
    report = {"faces": len(mesh.stitch_type), "frames": len(out), "curves": len(model.plan.offsets) - 1,
              "control_points": len(model.layout.index), "render_points": int(model.plan.offsets[-1]),
              "threads": numba.get_num_threads(), "prepare_s": prepare_s, "curves_s": curves_s,
              "seconds": time.perf_counter() - t0, "ms_per_frame": times,
              "ms_per_frame_median": float(np.median(times)), "frame_energy": frame_energy,
              "energy_history": history.tolist(), "final_energy": float(history[-1]), "yarn_radius": model.radius,
              "length_scale": model.length_scale, "warnings": template_size_warnings(model)}
    return curves, report


def template_size_warnings(model) -> list:
    """One-line warnings when the yarn radius is off the radius the stitch templates are sized (and relaxed) for,
    ``RADIUS_PER_STITCH`` × the stitch width, by more than ``RADIUS_TOLERANCE``: thicker yarns overlap, thinner
    ones leave gaps. The remedy is to scale the stitch mesh, not the yarn."""
    sized = RADIUS_PER_STITCH * model.length_scale
    ratio = model.radius / sized
    if abs(ratio - 1.0) <= RADIUS_TOLERANCE:
        return []
    return [f"yarn radius {model.radius:.4g} is {ratio:.2f}× the {sized:.4g} the stitch templates are sized for "
            f"(stitch width {model.length_scale:.4g} / {1 / RADIUS_PER_STITCH:g}): the simulated yarns will "
            f"{'overlap' if ratio > 1 else 'leave gaps'}; scale the stitch mesh by {ratio:.3g} to fit this yarn"]


def face_problem(model, vertices, f):
    """The least-squares problem the solver solves on face f for ``vertices``, for reference solvers and tests:
    (Θ_init, residuals(Θ) → r (n,), jacobian(Θ) → J (n, 4)), r and J exactly as the kernel computes them."""
    m = model.mesh
    start, stop = m.face_offsets[f], m.face_offsets[f + 1]
    v = np.zeros((5, 3))
    v[:stop - start] = check_vertices(model, vertices)[m.face_vertices[start:stop]]
    code, rest = int(m.stitch_type[f]), model.rest[f].copy()
    frame, fmat, knots, theta, ws = np.empty((4, 3)), np.empty((2, 2)), np.empty((2, 2)), np.empty(4), \
        np.zeros((MAX_POINTS, W_SIZE))
    radius, h, w_angle, w_length, beta = model.params
    face_setup(v, stop - start, code, TEMPLATE_INT, TEMPLATE_FLOAT, rest, beta, radius, frame, fmat, knots, theta, ws)
    n_pieces = TEMPLATE_INT[code, I_PIECES, 0]
    n_res = 2 * int(TEMPLATE_INT[code, I_PIECES, 1 + n_pieces]) - 3 * n_pieces

    def evaluate(th, want_jac):
        w, rj = ws.copy(), np.zeros((MAX_RESIDUALS, 1 + N_UNKNOWNS))
        knot_points(np.asarray(th, np.float64), knots, code, TEMPLATE_INT, TEMPLATE_FLOAT, radius, w)
        residuals(code, TEMPLATE_INT, w, rest[R_TARGETS:], math.sqrt(w_length), math.sqrt(w_angle), 1.0 / h,
                  EPS_LENGTH * h, rj, want_jac)
        return rj[:n_res]

    return theta.copy(), lambda th: evaluate(th, False)[:, 0], lambda th: evaluate(th, True)[:, 1:]


def knot_centres(model, face_points):
    """(F, 2, 3) knot centres of every face from a frame's face points: the midpoint of each knot's crossing points
    c0 and c1 of the face's own yarn (eq. 4: (c0 + c1)/2 = x_k, the ±r normal offsets cancel)."""
    ti, tf = TEMPLATE_INT, TEMPLATE_FLOAT
    pick = np.zeros((len(ti), N_KNOTS, 2), np.int64)
    for code in range(len(ti)):
        for j in range(N_KNOTS):
            for k, a in enumerate((1.0, -1.0)):  # c0 (a = +1) and c1 (a = −1) on the knot itself (c = 0)
                on_knot = (ti[code, I_KNOT] == j) & (tf[code, F_A] == a) & (tf[code, F_C] == 0)
                pick[code, j, k] = np.flatnonzero(on_knot)[0]
    rows = model.point_offset[:-1, None, None] + pick[model.mesh.stitch_type]
    return 0.5 * (face_points[rows[..., 0]] + face_points[rows[..., 1]])


def control_segment_lengths(model, face_points):
    """Lengths of every control-polygon segment of every curve (curves concatenated, no segment between curves)."""
    steps = np.linalg.norm(np.diff(face_points[model.layout.index], axis=0), axis=1)
    return np.delete(steps, model.layout.offsets[1:-1] - 1)


def course_knot_spacing(model, face_points):
    """Distances between consecutive knot centres along every course (faces left to right, two knots each)."""
    mesh = model.mesh
    knots = knot_centres(model, face_points)
    order = np.lexsort((mesh.column, mesh.course))
    k = knots[order].reshape(-1, 3)
    steps = np.linalg.norm(np.diff(k, axis=0), axis=1)
    last = np.flatnonzero(np.diff(mesh.course[order]))  # no step from one course's last knot to the next course
    return np.delete(steps, 2 * last + 1)
