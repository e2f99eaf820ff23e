"""Relaxation of the yarn-over and decrease templates in a knitted context (issue 14; the knit tile is
``template_relax``): their faces are not periodic on their own, so they are relaxed where they occur, in an eyelet
chart at rest, around knit faces that already carry the relaxed knit template.

Method
------
The context is ``knitrun pattern eyelet`` (``CONTEXT``: courses × stitches) simulated at rest through the runtime
itself (``simulate.prepare``, the rest solve, ``yarn_points``: 4 Catmull-Rom rendering points per control segment),
so the relaxed points are exactly what a user's simulation draws. Unknowns (90): for the yarn-over, k2tog and ssk
templates, each knot's centre and axis (u, v, du, dv), the lift s (along the face normal, in r) of every knot point,
and the (a, c) of a decrease's outer-loop points (which are not eq. 4 points); every crossing and contact point keeps
its hand-drawn (a, c), so eq. 4 holds in the plane as for knit. The unknowns are bounded near the seed
(``KNOT_REACH``, ``LIFT_REACH``, ``OUTER_REACH``): the relaxation untangles the hand-drawn shapes locally, without
stretching a control segment across a face (the simulator's yarns have no step longer than a stitch width).
Energy, over the rendering points of faces of those types (lengths in r; the same terms and weights as
``template_relax``; the anchor in radii):

    E = W_CONTACT Σ_pairs max(0, 2r − d_pq)²/r²  +  W_BEND Σ_k α_k² r/Δs_k  +  W_LENGTH ((ℓ − ℓ_0)/r)²
      + W_ANCHOR Σ |y − y_seed|²

with the pairs those of rendering points closer than ``PAIR_RADII`` r, on different curves or more than
``EXCLUDE_RADII`` r apart along one, at least one of them in such a face; α_k the turning angle at a rendering point
of such a face, ℓ their yarn length (ℓ_0 the seed's). Rounds of scipy ``least_squares`` with a fixed pair set until
it is stable, as for the tile; a result that swaps a crossing is refused (``template_relax.check_crossings``).

``relax_in_patch`` changes the packed templates (``stitch_templates.TEMPLATE_FLOAT``) while it runs and restores
them before it returns.
"""

from __future__ import annotations

import math
import time

import numpy as np
from scipy.optimize import least_squares
from scipy.spatial import cKDTree

from data_formats.yarn_curves import control_polygon_arclength
from knitrun.sim import stitch_templates as st
from knitrun.sim.contact import contact_statistic
from knitrun.sim.knit_chart import chart_to_mesh, pattern_chart
from knitrun.sim.knot_solver import prepare_faces
from knitrun.sim.simulate import RADIUS_PER_STITCH, prepare, simulate, solve_frame, yarn_points
from knitrun.sim.template_relax import (EXCLUDE_RADII, MAX_ROUNDS, PAIR_RADII, SOLVER_TOL, W_ANCHOR, W_BEND,
                                        W_CONTACT, W_LENGTH, check_crossings)

CONTEXT = ("eyelet", 8, 8)
RELAXED_TYPES = (st.YARN_OVER, st.K2TOG, st.SSK)
MAX_NFEV = 400  # solver steps per round at most (each pays a finite-difference Jacobian: one residual per unknown);
# a round converges at SOLVER_TOL well before (the context's 6 rounds take 45-60 s on 2 cores)
KNOT_REACH = 0.1  # bounds: knot centres and axes move at most this far from the seed (face coordinates),
LIFT_REACH = 2.0  # lifts s at most this far (radii),
OUTER_REACH = 1.0  # and a decrease's outer-loop points' (a, c) at most this far (units of l and r)


def _norms(v):
    """Euclidean norms of the rows of an (n, 3) array (``np.linalg.norm(v, axis=1)`` without its overhead: the
    residuals run once per unknown for every finite-difference Jacobian)."""
    return np.sqrt(np.einsum("ij,ij->i", v, v))


class _Patch:
    """The context mesh, its model and the bookkeeping the residuals need (fixed over the relaxation)."""

    def __init__(self):
        self.mesh = chart_to_mesh(pattern_chart(*CONTEXT))
        self.model = prepare(self.mesh)
        self.radius = self.model.radius
        # (code, row, column) of TEMPLATE_FLOAT per unknown, its size in radii and how far it may move from the seed
        self.slots, scale, reach = [], [], []
        for code in RELAXED_TYPES:
            for k in range(4 * st.N_KNOTS):  # u, v, du, dv of each knot, in stitch widths: 1/RADIUS_PER_STITCH r
                self.slots.append((code, st.F_KNOTS, k))
                scale.append(1.0 / RADIUS_PER_STITCH)
                reach.append(KNOT_REACH)
            for i in np.flatnonzero(st.TEMPLATE_INT[code, st.I_KNOT, :st.N_POINTS[code]] >= 0):
                self.slots.append((code, st.F_S, int(i)))
                scale.append(1.0)
                reach.append(LIFT_REACH)
                if abs(st.TEMPLATE_FLOAT[code, st.F_C, i]) >= 2:  # a decrease's outer loop: not an eq. 4 point
                    self.slots += [(code, st.F_A, int(i)), (code, st.F_C, int(i))]
                    scale += [1.0, 1.0]
                    reach += [OUTER_REACH, OUTER_REACH]
        self.scale, self.reach = np.array(scale), np.array(reach)
        self.slot_index = tuple(np.array(self.slots).T)  # TEMPLATE_FLOAT[slot_index] = the unknowns, in order
        plan = self.model.plan
        n_render = int(plan.offsets[-1])
        face_of_point = np.searchsorted(self.model.point_offset, np.arange(self.model.point_offset[-1]),
                                        side="right") - 1
        render_face = np.empty(n_render, np.int64)
        for k in range(plan.samples):  # rendering point seg_out[s] + k lies on segment s, from control point
            render_face[plan.seg_out + k] = face_of_point[plan.seg_index[:, 1]]  # seg_index[s, 1]
        render_face[plan.last_out] = face_of_point[plan.last_index]
        self.curve = np.repeat(np.arange(len(plan.offsets) - 1), np.diff(plan.offsets))
        self.active = np.isin(self.mesh.stitch_type[render_face], RELAXED_TYPES)
        self.first = np.zeros(n_render, bool)
        self.first[plan.offsets[:-1]] = True
        self.last = np.zeros(n_render, bool)
        self.last[plan.offsets[1:] - 1] = True
        # the residuals' index sets, fixed: rendering points whose turning angle counts (inner points of such faces)
        # and the first points of the segments whose length counts
        self.bent = np.flatnonzero(self.active & ~self.first & ~self.last)
        self.counted = np.flatnonzero(self.active[:-1] & ~self.last[:-1])

    def points(self, y):
        """Rendering points of the rest patch with the unknowns ``y`` installed in the packed templates."""
        st.TEMPLATE_FLOAT[self.slot_index] = y
        m = self.mesh
        bad = np.zeros(len(m.stitch_type), np.int8)
        prepare_faces(m.vertices, m.face_offsets, m.face_vertices, m.stitch_type, st.TEMPLATE_INT, st.TEMPLATE_FLOAT,
                      self.radius, self.model.rest, bad)
        # at rest knot interpolation is the template itself: no Gauss-Newton iterations needed
        return yarn_points(self.model, solve_frame(self.model, m.vertices, iterations=0).points)

    def pairs(self, points):
        tree = cKDTree(points)
        pairs = tree.query_pairs(PAIR_RADII * self.radius, output_type="ndarray")
        if not len(pairs):
            return pairs.reshape(0, 2)
        p, q = pairs[:, 0], pairs[:, 1]
        arc = control_polygon_arclength(points, self.model.plan.offsets)
        other = (self.curve[p] != self.curve[q]) | (np.abs(arc[p] - arc[q]) > EXCLUDE_RADII * self.radius)
        return pairs[other & (self.active[p] | self.active[q])]

    def length(self, points):
        k = self.counted
        return float(_norms(np.take(points, k + 1, axis=0) - np.take(points, k, axis=0)).sum())

    def residuals(self, y, pairs, seed, length0):
        pts = self.points(y)
        r = self.radius
        d = _norms(np.take(pts, pairs[:, 0], axis=0) - np.take(pts, pairs[:, 1], axis=0))
        contact = np.maximum(0.0, 2.0 * r - d) / r
        k = self.bent
        here = np.take(pts, k, axis=0)
        e_in, e_out = here - np.take(pts, k - 1, axis=0), np.take(pts, k + 1, axis=0) - here
        n_in, n_out = _norms(e_in), _norms(e_out)
        cos = np.einsum("ij,ij->i", e_in, e_out) / np.maximum(n_in * n_out, 1e-300)
        ds = np.maximum(0.5 * (n_in + n_out), 1e-12)
        bend = np.arccos(np.clip(cos, -1.0, 1.0)) * np.sqrt(r / ds)
        return np.concatenate([math.sqrt(W_CONTACT) * contact, math.sqrt(W_BEND) * bend,
                               [math.sqrt(W_LENGTH) * (self.length(pts) - length0) / r],
                               math.sqrt(W_ANCHOR) * (y - seed) * self.scale])


def _contact(patch):
    curves, report = simulate(patch.mesh, patch.mesh.vertices[None])
    return contact_statistic(curves, report["yarn_radius"])


def relax_in_patch(progress=None) -> dict:
    """Relax the yarn-over, k2tog and ssk templates (module docstring) around the knit template now packed. Returns
    {stitch type name: {"knots", "points", figures}} in the form of ``template_relax.relax_templates``' entries, and
    the context's contact statistic before and after under "context"."""
    t0 = time.perf_counter()
    saved = st.TEMPLATE_FLOAT.copy()
    try:
        patch = _Patch()
        seed = np.array([saved[slot] for slot in patch.slots])
        before = _contact(patch)
        pts0 = patch.points(seed)
        length0 = patch.length(pts0)
        y, pairs_prev, status, rounds, converged = seed.copy(), None, None, 0, False
        for rounds in range(1, MAX_ROUNDS + 1):
            pairs = patch.pairs(patch.points(y))
            if pairs_prev is not None and np.array_equal(pairs, pairs_prev) and status is not None and status > 0:
                converged = True
                break
            result = least_squares(patch.residuals, y, args=(pairs, seed, length0), method="trf",
                                   bounds=(seed - patch.reach, seed + patch.reach), x_scale=1.0 / patch.scale,
                                   tr_solver="lsmr", max_nfev=MAX_NFEV,
                                   ftol=SOLVER_TOL, xtol=SOLVER_TOL, gtol=SOLVER_TOL)
            y, status, pairs_prev = result.x, int(result.status), pairs
            if progress is not None:
                progress(rounds, float(result.cost), len(pairs))

        def energy(values):
            return 0.5 * float(np.sum(patch.residuals(values, patch.pairs(patch.points(values)), seed,
                                                      length0) ** 2))

        energy_before, energy_after = energy(seed), energy(y)
        length_after = patch.length(patch.points(y))
        after = _contact(patch)
    finally:
        st.TEMPLATE_FLOAT[...] = saved
    relaxed = saved.copy()
    for slot, value in zip(patch.slots, y.tolist()):
        relaxed[slot] = value
    out = {}
    for code in RELAXED_TYPES:
        pieces = st.template_pieces(code, relaxed=False)
        points, i = {}, 0
        for role, spec in pieces:
            points[str(role)] = []
            for p in spec:
                if p[0] == "knot":
                    points[str(role)].append([float(relaxed[code, row, i]) for row in (st.F_A, st.F_C, st.F_S)])
                i += 1
        check_crossings(pieces, points)
        knots = relaxed[code, st.F_KNOTS, :4 * st.N_KNOTS].reshape(st.N_KNOTS, 4)
        out[st.STITCH_TYPES[code]] = {"knots": knots.tolist(), "points": points}
    out["context"] = {"chart": list(CONTEXT), "contact_before": before, "contact_after": after,
                      "energy_before": energy_before, "energy_after": energy_after, "length_before": length0,
                      "length_after": length_after, "rounds": rounds, "solver_status": status,
                      "converged": converged, "seconds": time.perf_counter() - t0}
    return out
