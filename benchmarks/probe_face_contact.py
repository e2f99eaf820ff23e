"""Probe (issue 14, item 2): does a contact residual in the per-face knot solve keep sheared knits apart?

Per face of a 12 × 12 chart sheared 0.3, the face's least-squares problem (``simulate.face_problem``: the knot
solver's length and angle residuals in Θ = (θ1, θ2, l1, l2)) gets one more residual per pair of knot points of
different pieces of the face closer than 3r at rest, √w · min(0, d − d_rest)/h (penalised only when closer than at
rest), and is solved to convergence (scipy LM). The contact statistic of the result is printed next to the product's
(3 Gauss-Newton iterations), with how many of those pairs start closer than at rest, and next to the two
interpolations the solver starts from or replaces: knot interpolation (0 iterations) and the naive affine map of every
template point (``naive``), so the loss of contact can be traced to the step that causes it.

    .venv/bin/python benchmarks/probe_face_contact.py [--pattern stockinette] [--weight 1000]

Not product code: it answers whether the knot solver's four unknowns per face can keep the yarns apart when told to.
"""

import argparse
import math

import numpy as np
from scipy.optimize import least_squares

from data_formats.yarn_curves import make_yarn_curves
from knitrun.sim import stitch_templates as st
from knitrun.sim.contact import contact_statistic
from knitrun.sim.deformations import deformation_frames
from knitrun.sim.knit_chart import chart_to_mesh, pattern_chart
from knitrun.sim.knot_solver import W_SIZE, face_setup, knot_points
from knitrun.sim.simulate import face_problem, prepare, solve_frame, yarn_points


def face_points(model, vertices, f):
    """(code, frame, knots, Θ_init, workspace) of face f for ``vertices`` (the kernel's own set-up)."""
    m = model.mesh
    a, b = m.face_offsets[f], m.face_offsets[f + 1]
    v = np.zeros((5, 3))
    v[:b - a] = vertices[m.face_vertices[a:b]]
    code = int(m.stitch_type[f])
    frame, fmat, knots, theta, ws = np.empty((4, 3)), np.empty((2, 2)), np.empty((2, 2)), np.empty(4), \
        np.zeros((st.MAX_POINTS, W_SIZE))
    face_setup(v, b - a, code, st.TEMPLATE_INT, st.TEMPLATE_FLOAT, model.rest[f].copy(), model.params[4],
               model.radius, frame, fmat, knots, theta, ws)
    return code, frame, knots, theta, ws


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--pattern", default="stockinette")
    parser.add_argument("--weight", type=float, default=1000.0)
    args = parser.parse_args()
    mesh = chart_to_mesh(pattern_chart(args.pattern, 12, 12))
    model = prepare(mesh)
    vertices = deformation_frames(mesh.vertices, ["shear=0.3"], 1)[0]
    radius, h = model.params[0], model.params[1]
    product = solve_frame(model, vertices).points
    probed = product.copy()
    closer = total = 0
    for f in range(len(mesh.stitch_type)):
        code, _, knots, theta, ws = face_points(model, mesh.vertices, f)
        knot_points(theta, knots, code, st.TEMPLATE_INT, st.TEMPLATE_FLOAT, radius, ws)
        rest = ws[:, :3].copy()
        ranges = st.piece_ranges(code)
        piece = np.full(st.MAX_POINTS, -1)
        for q, (_, i0, i1) in enumerate(ranges):
            piece[i0:i1] = q
        kp = [i for i in range(ranges[-1][2]) if st.TEMPLATE_INT[code, st.I_KNOT, i] >= 0]
        pairs = [(i, j, float(np.linalg.norm(rest[i] - rest[j]))) for n, i in enumerate(kp) for j in kp[n + 1:]
                 if piece[i] != piece[j] and np.linalg.norm(rest[i] - rest[j]) < 3 * radius]
        code, frame, knots, _, ws = face_points(model, vertices, f)
        theta0, residuals, _ = face_problem(model, vertices, f)

        def points(th, ws=ws, knots=knots, code=code):
            w = ws.copy()
            knot_points(np.asarray(th, np.float64), knots, code, st.TEMPLATE_INT, st.TEMPLATE_FLOAT, radius, w)
            return w[:, :3]

        def all_residuals(th, pairs=pairs, residuals=residuals, points=points):
            p = points(th)
            contact = [math.sqrt(args.weight) * min(0.0, float(np.linalg.norm(p[i] - p[j])) - d0) / h
                       for i, j, d0 in pairs]
            return np.concatenate([residuals(th), contact])

        start = points(theta0)
        closer += sum(1 for i, j, d0 in pairs if np.linalg.norm(start[i] - start[j]) < d0 - 1e-9)
        total += len(pairs)
        p = points(least_squares(all_residuals, theta0, method="lm", max_nfev=200).x)
        for i in kp:
            probed[model.point_offset[f] + i] = frame[0] + p[i, 0] * frame[1] + p[i, 1] * frame[2] + p[i, 2] * frame[3]
    runs = (("naive interpolation of control points (x = F X)", solve_frame(model, vertices, naive=True).points),
            ("knot interpolation (0 iterations)", solve_frame(model, vertices, iterations=0).points),
            ("product (3 Gauss-Newton iterations)", product), (f"with contact residuals, w = {args.weight:g}", probed))
    for name, pts in runs:
        curves = make_yarn_curves(yarn_points(model, pts), model.plan.offsets, curve_type="PL")
        s = contact_statistic(curves, radius)
        print(f"{args.pattern}, shear 0.3, {name}: p5 {s['p5']:.4f}, median {s['p50']:.4f}")
    print(f"knot-point pairs of different pieces within 3r at rest: {total}; "
          f"closer than at rest at the start: {closer}")


if __name__ == "__main__":
    main()
