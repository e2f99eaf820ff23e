"""Stitch templates: the rest yarn of every stitch type in face coordinates, with its knots (Huang et al. 2025 §3.1,
Figs. 2-3).

Face coordinates
----------------
A face with ``b`` bottom edges (knit/purl 1, yarn-over 0, decrease 2; vertex slots as in ``STITCH_MESH.md``: the
``b + 1`` bottom vertices left → right, then TR = slot ``b + 1``, TL = slot ``b + 2``) is parameterised by (u, v) in
[0, 1]² through the *ruled map* M(u, v) = (1 − v)·bottom(u) + v·top(u), where top(u) runs linearly from TL (u = 0) to
TR (u = 1) and bottom(u) along the bottom polyline, each bottom edge taking an equal share of u (a yarn-over's bottom
is its single vertex). M is linear along every edge, so a point given on an edge is the same point for both faces
that share the edge. For a knit quad M is the bilinear map.

Points of a template
--------------------
* **Boundary points** lie on an edge, at fraction ``t`` from the edge's first to its second vertex slot:
  x = (1 − t)·V[v0] + t·V[v1]. They are where a yarn leaves the face, are computed from the edge's two vertices alone
  (so neighbours share them bit for bit), are never optimised and have no normal offset. The course yarn crosses the
  side edges at height ``SIDE_V`` (from the bottom vertex up), top and bottom edges are crossed at ``EDGE_T``
  (from the left).
* **Knot points** belong to knot j with centre x_k, direction d = (cos θ, sin θ) in the face plane, half-length l
  and yarn radius r (eq. 1): x = x_k + a·l·d + c·r·b with b = d × n = (sin θ, −cos θ), so (a, c) = (±1, 0) are
  the crossing points c0/c1 and (0, ±1) the contact points p0/p1. A point is lifted to 3-D by s·r along the face
  normal n (eq. 2: c0⁺ has s = +1, c0⁻ has s = −1; p0, p1 lie in the plane, s = 0; the relaxed knit template moves
  these lifts, keeping every crossing at least 2r thick).

Whatever θ and l are, c0/c1 stay symmetric about x_k, |p0 − p1| = 2r and (x_k − p0)·(c0 − x_k) = 0: the
constraints of eq. 4 hold by construction, and the solver's unknowns are Θ = (θ1, θ2, l1, l2).

Pieces and stitch types (drawn for a yarn travelling left → right; the solver never cares about direction)
-----------------------------------------------------------------------------------------------------
* Every face holds two knots: knot 0 left (d at rest pointing up-right: c1 lower-left, c0 upper-right), knot 1 right
  (its mirror image: c0 upper-left, c1 lower-right).
* ``ROLE_IN``: the face's own (course) yarn from the left side point, under c1 of knot 0, past p0, over c0, up to
  the top edge at t = ``EDGE_T[0]`` (the left leg of the loop this face makes). ``ROLE_OUT``: from the top edge at
  ``EDGE_T[1]`` over c0 of knot 1, past p1, under c1, out at the right side point (the right leg).
* ``ROLE_LOOP + k``: the head of the loop consumed through bottom edge k (knitted by the face below): in at the
  bottom edge's ``EDGE_T[0]``, over c1 of knot 0, past p1, under c0, across behind the legs to c0 of knot 1 (under),
  past p0, over c1, out at ``EDGE_T[1]``. The two yarns cross at c0 and c1 of each knot, one above and one below the
  plane: the new loop's legs are in front above the knots and behind below them, the old head behind them (the "V"
  of stockinette seen from the front).
* knit: IN, OUT, LOOP 0 (18 points: 6 boundary, 12 on the 8 planar knot points).
* purl: knit mirrored through the fabric plane (every s negated).
* k2tog / ssk (pentagons): IN, OUT and both consumed loops. The two loops share the knots (same x_k, θ, l: "two
  loops share a knot", Fig. 3a) but each keeps its own points: the inner loop uses the knot's own c0/c1/p, the
  outer one runs one yarn diameter further out on the same side (its points shifted by 2r·b towards its contact
  point: c = ±2 at c0/c1, ±3 at the contact point). k2tog (leaning right, the left loop ends on top) takes the left
  loop (edge 0) inner, ssk the right one (26 points).
* yarn-over (triangle, no loop consumed): IN and OUT only; its knots carry only its own legs ("two knots and an
  extra loop", Fig. 3b; nothing is pulled through a yarn-over, the knots keep the shape of its legs). Its knots sit
  higher (v = 0.6), where the triangle is wide enough (10 points).

Sizes at rest: the knot centres and the c0 − x_k axis are given in face coordinates (``TEMPLATE_FLOAT[:, F_KNOTS]``)
and mapped by M of the rest face, so templates lean with leaning faces; r is the yarn radius (a length, the same for
the whole mesh). The templates are drawn by hand (sized for the chart default 0.25 × 0.2 cm stitch and r = stitch
width / 8); knit and purl then take the relaxed knots and lifts of ``RELAXED`` (``relaxed_templates.json``, written by
``knitrun templates relax``, ``template_relax``: a periodic stockinette tile relaxed with yarn contact, as the paper
relaxes its templates, §5.1), which keep every (a, c) below, so eq. 4 holds, but lift the knot points off ±r where
the yarns need room. Yarn-over, k2tog and ssk take theirs from a relaxation in an eyelet context (``patch_relax``),
which may also move their knots and a decrease's outer-loop points. ``template_pieces(code, relaxed=False)`` and
``knots_of(code, relaxed=False)`` give the hand-drawn seed.

Shear shape
-----------
A sheared face squeezes the legs of neighbouring loops together in the plane, where the knots cannot move them apart
(their four unknowns do not reach the spans that touch). The relaxation therefore also gives the knit a shape for its
face sheared by κ_ref (``template_relax.relax_shear_shape``): a shift (Δu, Δv) of each knot centre, in face
coordinates, and a lift change Δs per knot point, both added on a face sheared that way. The face's shear is
κ = C₁₂/√(C₁₁C₂₂), C = FᵀF of its deformation gradient in the (course, wale) frame (``knot_solver.face_shear``): the
cosine of the angle between the deformed course and wale directions, 0 at rest, under stretch and under rotation.
The runtime adds w⁺ × the shape for shear one way and w⁻ × the shape for the other, w± = clamp(±κ/κ_ref, 0, 1); the
second shape is the first mirrored about the face's centre line (knot 0 ↔ knot 1 with Δu negated, IN ↔ OUT reversed,
the loop reversed), as the knit itself is mirror-symmetric. Purl keeps the knot shifts and negates the lift changes
with s. Types without a relaxed shear shape (yarn-over and the decreases, relaxed at rest in their context) have
κ_ref = 0 and no change.
"""

from __future__ import annotations

import contextlib
import json
import math
from pathlib import Path

import numpy as np

from data_formats.errors import FormatError
from data_formats.stitch_mesh import LOOPS_CONSUMED, STITCH_TYPES

KNIT, PURL, YARN_OVER, K2TOG, SSK = (STITCH_TYPES.index(n) for n in ("knit", "purl", "yarn_over", "k2tog", "ssk"))
SIDE_V = 0.3  # side edges are crossed 30 % up from their bottom vertex
EDGE_T = (0.2, 0.8)  # top and bottom edges are crossed at 20 % and 80 % from the left
ROLE_IN, ROLE_OUT, ROLE_LOOP = 0, 1, 2  # piece roles; ROLE_LOOP + k: the loop consumed through bottom edge k
N_KNOTS = 2  # knots per face, every stitch type
N_UNKNOWNS = 2 * N_KNOTS  # Θ = (θ1, θ2, l1, l2)
STITCH_KNOTS = (((0.35, 0.4), (0.08, 0.1)), ((0.65, 0.4), (-0.08, 0.1)))  # per knot: centre, c0 − centre (face)
YARN_OVER_KNOTS = (((0.3, 0.6), (0.07, 0.1)), ((0.7, 0.6), (-0.07, 0.1)))
RELAXED_PATH = Path(__file__).with_name("relaxed_templates.json")  # ``knitrun templates relax`` writes it


def _edge(name, b, t):
    """Boundary point spec (v0, v1, t) for edge ``name`` ('left', 'right', 'top', 'bottomK') of a face with b."""
    if name == "left":
        return (0, b + 2, SIDE_V)
    if name == "right":
        return (b, b + 1, SIDE_V)
    if name == "top":
        return (b + 2, b + 1, t)
    k = int(name[len("bottom"):])
    return (k, k + 1, t)


def _knot(j, a, c, s):
    return ("knot", j, a, c, s)


def load_relaxed(path=RELAXED_PATH):
    """{stitch type name: {"knots": ((centre, axis), (centre, axis)), "points": {role: [(a, c, s), ...]}, "shear":
    (κ_ref, ((Δu, Δv), (Δu, Δv)), {role: [Δs, ...]}) or None}} from a relaxed-template document (``template_relax``;
    the shear shape since format 1.1); {} when the file is absent (the hand-drawn templates then stand).
    ``FormatError`` for a file that is not one."""
    if not Path(path).is_file():
        return {}
    try:
        document = json.loads(Path(path).read_text())
        if document.get("format") != "knit-relaxed-templates" or str(document.get("version", "")).split(".")[0] != "1":
            raise FormatError("not a knit-relaxed-templates 1.x document")
        out = {}
        for name, entry in document["stitch_types"].items():
            knots = tuple(((float(k[0]), float(k[1])), (float(k[2]), float(k[3]))) for k in entry["knots"])
            points = {int(role): [tuple(float(x) for x in abc) for abc in spec]
                      for role, spec in entry["points"].items()}
            if len(knots) != N_KNOTS or not all(len(abc) == 3 for spec in points.values() for abc in spec):
                raise FormatError(f"stitch type {name!r}: expected {N_KNOTS} knots and (a, c, s) triples")
            values = np.array([x for k in knots for pair in k for x in pair]
                              + [x for spec in points.values() for abc in spec for x in abc])
            if not np.isfinite(values).all():
                raise FormatError(f"stitch type {name!r}: a value is not finite")
            shear = entry.get("shear")
            if shear is not None:
                kappa = float(shear["kappa"])
                shifts = tuple((float(k[0]), float(k[1])) for k in shear["knots"])
                lifts = {int(role): [float(x) for x in spec] for role, spec in shear["lifts"].items()}
                if not (math.isfinite(kappa) and kappa > 0) or len(shifts) != N_KNOTS or \
                        not np.isfinite([x for k in shifts for x in k] + [x for v in lifts.values() for x in v]).all():
                    raise FormatError(f"stitch type {name!r}: a shear shape needs κ > 0, {N_KNOTS} finite knot shifts "
                                      "and finite lifts")
                if {role: len(spec) for role, spec in lifts.items()} != {role: len(spec) for role, spec in
                                                                         points.items()}:
                    raise FormatError(f"stitch type {name!r}: shear lifts must match the relaxed points piece by "
                                      "piece")
                shear = (kappa, shifts, lifts)
            out[name] = {"knots": knots, "points": points, "shear": shear}
    except (ValueError, KeyError, TypeError, AttributeError, IndexError) as exc:
        raise FormatError(f"{path}: {exc}, expected a knit-relaxed-templates file (knitrun templates relax)") from None
    return out


RELAXED = load_relaxed()


def template_pieces(code, relaxed=True):
    """[(role, [point spec, ...]), ...] of stitch type ``code``; a point spec is ('edge', v0, v1, t) or
    ('knot', j, a, c, s). With ``relaxed``, every type takes the relaxed knot points of ``RELAXED`` where it has them
    (purl mirrored from knit); False gives the hand-drawn templates (the relaxations' seed)."""
    b = int(LOOPS_CONSUMED[code])
    edge = lambda name, t=0.0: ("edge",) + _edge(name, b, t)  # noqa: E731
    legs = [(ROLE_IN, [edge("left"), _knot(0, -1, 0, -1), _knot(0, 0, 1, 0), _knot(0, 1, 0, 1),
                       edge("top", EDGE_T[0])]),
            (ROLE_OUT, [edge("top", EDGE_T[1]), _knot(1, 1, 0, 1), _knot(1, 0, -1, 0), _knot(1, -1, 0, -1),
                        edge("right")])]

    def loop(k, shift):  # shift 0: the inner loop on the knots' own points; 2: one yarn diameter further out
        return (ROLE_LOOP + k, [edge(f"bottom{k}", EDGE_T[0]), _knot(0, -1, -shift, 1), _knot(0, 0, -1 - shift, 0),
                                _knot(0, 1, -shift, -1), _knot(1, 1, shift, -1), _knot(1, 0, 1 + shift, 0),
                                _knot(1, -1, shift, 1), edge(f"bottom{k}", EDGE_T[1])])

    if code in (KNIT, PURL):
        pieces = legs + [loop(0, 0)]
    elif code == YARN_OVER:
        pieces = legs
    else:
        inner = 0 if code == K2TOG else 1
        pieces = legs + [loop(inner, 0), loop(1 - inner, 2)]
    name = "knit" if code == PURL else STITCH_TYPES[code]
    if relaxed and name in RELAXED:
        pieces = [(role, with_relaxed_points(points, RELAXED[name]["points"].get(role))) for role, points in pieces]
    if code == PURL:  # knit mirrored through the fabric plane
        pieces = [(role, [p[:4] + (-p[4],) if p[0] == "knot" else p for p in points]) for role, points in pieces]
    return pieces


def knots_of(code, relaxed=True):
    """((centre, c0 − centre), …) of the two knots of stitch type ``code`` in face coordinates: the relaxed ones (with
    ``relaxed`` and a relaxed document; purl takes knit's), else the hand-drawn ones."""
    name = "knit" if code == PURL else STITCH_TYPES[code]
    if relaxed and name in RELAXED:
        return RELAXED[name]["knots"]
    return YARN_OVER_KNOTS if code == YARN_OVER else STITCH_KNOTS


def with_relaxed_points(points, coefficients):
    """The piece's points with its knot points' (a, c, s) replaced, in order, by ``coefficients`` (if given)."""
    if coefficients is None:
        return points
    knots = [i for i, p in enumerate(points) if p[0] == "knot"]
    if len(knots) != len(coefficients):
        raise FormatError(f"{RELAXED_PATH}: a piece has {len(coefficients)} relaxed points, the template "
                          f"{len(knots)}")
    out = list(points)
    for i, (a, c, s) in zip(knots, coefficients):
        out[i] = ("knot", points[i][1], a, c, s)
    return out


# Packed layout read by the kernels (plain arrays, first index the stitch-type code, last the point index i):
I_KNOT, I_V0, I_V1, I_PIECES, I_ROLES = range(5)  # rows of TEMPLATE_INT
F_T, F_A, F_C, F_S, F_KNOTS, F_DS_POS, F_DS_NEG, F_SHEAR = range(8)  # rows of TEMPLATE_FLOAT


def pack_templates(relaxed=True):
    """(TEMPLATE_INT, TEMPLATE_FLOAT) of all stitch types (``relaxed`` False: the hand-drawn ones):

    * ``TEMPLATE_INT[c, I_KNOT, i]``: knot index of point i, −1 for a boundary point; ``I_V0``/``I_V1``: the boundary
      point's edge vertex slots; ``I_PIECES``: [n_pieces, start_0, ..., start_n_pieces] (piece q is points
      start_q .. start_{q+1} − 1, the last start = the point count); ``I_ROLES``: the role of each piece.
    * ``TEMPLATE_FLOAT[c, F_T, i]``: a boundary point's edge fraction t; ``F_A``, ``F_C``, ``F_S``: a knot point's
      eq. 1-2 coefficients a, c, s; ``F_KNOTS``: [u_0, v_0, du_0, dv_0, u_1, v_1, du_1, dv_1], each knot's rest centre
      and c0 − centre in face coordinates.
    * The shear shape (module docstring, "Shear shape"): ``F_DS_POS``, ``F_DS_NEG``: a knot point's lift changes for
      shear either way; ``F_SHEAR``: [κ_ref (0: no shape), (Δu_0, Δv_0, Δu_1, Δv_1) either way] (9 numbers).
    """
    all_pieces = [template_pieces(code, relaxed) for code in range(len(STITCH_TYPES))]
    max_points = max(sum(len(p) for _, p in pieces) for pieces in all_pieces)
    ints = np.zeros((len(all_pieces), 5, max_points), np.int64)
    floats = np.zeros((len(all_pieces), 8, max_points), np.float64)
    for code, pieces in enumerate(all_pieces):
        ints[code, I_KNOT] = -1
        ints[code, I_PIECES, 0] = len(pieces)
        i = 0
        for q, (role, points) in enumerate(pieces):
            ints[code, I_PIECES, 1 + q], ints[code, I_ROLES, q] = i, role
            for p in points:
                if p[0] == "edge":
                    ints[code, I_V0, i], ints[code, I_V1, i], floats[code, F_T, i] = p[1:]
                else:
                    ints[code, I_KNOT, i] = p[1]
                    floats[code, F_A, i], floats[code, F_C, i], floats[code, F_S, i] = p[2:]
                i += 1
        ints[code, I_PIECES, 1 + len(pieces)] = i
        (uv0, axis0), (uv1, axis1) = knots_of(code, relaxed)
        floats[code, F_KNOTS, :8] = [*uv0, *axis0, *uv1, *axis1]
        kappa, shifts, lifts = shear_shape(code, pieces, relaxed)
        floats[code, F_SHEAR, :9] = [kappa, *shifts[0], *shifts[1]]
        floats[code, F_DS_POS, :len(lifts[0])], floats[code, F_DS_NEG, :len(lifts[1])] = lifts
    return ints, floats


def shear_shape(code, pieces, relaxed=True):
    """(κ_ref, knot shifts (2, 4): [Δu_0, Δv_0, Δu_1, Δv_1] for shear one way and the other, lift changes (2, n) over
    ``pieces``' points in order, 0 at boundary points) of stitch type ``code``: the relaxed knit's shear shape and its
    mirror image, purl's lifts negated (module docstring, "Shear shape"); zeros for a type without one."""
    n = sum(len(points) for _, points in pieces)
    name = "knit" if code == PURL else STITCH_TYPES[code]
    shear = RELAXED.get(name, {}).get("shear") if relaxed else None
    if shear is None:
        return 0.0, np.zeros((2, 4)), np.zeros((2, n))
    kappa, ((du0, dv0), (du1, dv1)), lifts = shear
    mirror = {ROLE_IN: ROLE_OUT, ROLE_OUT: ROLE_IN}
    sign = -1.0 if code == PURL else 1.0
    pos, neg = [], []
    for role, points in pieces:
        knots = [i for i, p in enumerate(points) if p[0] == "knot"]
        here, there = np.zeros(len(points)), np.zeros(len(points))
        here[knots] = sign * np.asarray(lifts[role])
        there[knots] = sign * np.asarray(lifts[mirror.get(role, role)])[::-1]
        pos.append(here)
        neg.append(there)
    shifts = np.array([[du0, dv0, du1, dv1], [-du1, dv1, -du0, dv0]])
    return kappa, shifts, np.array([np.concatenate(pos), np.concatenate(neg)])


TEMPLATE_INT, TEMPLATE_FLOAT = pack_templates()
MAX_POINTS = TEMPLATE_INT.shape[2]


@contextlib.contextmanager
def shear_shape_off():
    """Every type's shear shape switched off (κ_ref = 0) in the packed templates while the block runs (the kernels
    read ``TEMPLATE_FLOAT`` at every call): the runtime as before the shape existed, for comparisons."""
    saved = TEMPLATE_FLOAT[:, F_SHEAR, 0].copy()
    TEMPLATE_FLOAT[:, F_SHEAR, 0] = 0.0
    try:
        yield
    finally:
        TEMPLATE_FLOAT[:, F_SHEAR, 0] = saved


def piece_ranges(code):
    """[(role, start, stop), ...]: the pieces of stitch type ``code`` as point ranges."""
    row = TEMPLATE_INT[code, I_PIECES]
    return [(int(TEMPLATE_INT[code, I_ROLES, q]), int(row[1 + q]), int(row[2 + q])) for q in range(row[0])]


N_POINTS = np.array([piece_ranges(c)[-1][2] for c in range(len(STITCH_TYPES))], np.int64)  # points per type
MAX_SEGMENTS = max(sum(b - a - 1 for _, a, b in piece_ranges(c)) for c in range(len(STITCH_TYPES)))
MAX_ANGLES = max(sum(b - a - 2 for _, a, b in piece_ranges(c)) for c in range(len(STITCH_TYPES)))
