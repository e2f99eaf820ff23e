"""Relaxation of the knit stitch template on a periodic tile (Huang et al. 2025 §5.1, after Leaf et al. 2018): an
offline step (``knitrun templates relax``) whose result, ``relaxed_templates.json`` beside this module, the stitch
templates read (``stitch_templates``).

The tile
--------
Stockinette at rest: every face the chart's rest rectangle, ``WIDTH`` × ``ASPECT``·``WIDTH`` (lengths here in stitch
widths, so ``WIDTH`` = 1), yarn radius r = ``RADIUS`` (the simulator's default r = stitch width / 8). One course
yarn over one stitch period is the polygon side point → IN's three knot points → top-edge point (t = 0.2) → the
head of its loop, drawn in the face above (that face's LOOP piece, six knot points, shifted up one course) →
top-edge point (t = 0.8) → OUT's three knot points → the next face's side point. The fabric is this polygon repeated
every ``WIDTH`` along the course and every course height up: the tile is periodic in both directions, and the face
edges stay where the stitch mesh puts them (boundary points fixed on their edges, §5.1). Curves are the runtime's
uniform Catmull-Rom through the control points (``yarn_assembly.render_points``), sampled ``SAMPLES`` per segment.

Energy (dimensionless; lengths in units of r)
---------------------------------------------
Unknowns (10): knot 0's centre (u, v) and axis (du, dv) in face coordinates, and the lift s (along the face normal,
in r) of each knot point on knot 0: IN's three and the loop's three. Knot 1 and the other knot points are their
mirror images about the face's centre line x = WIDTH/2 (stockinette seen from the front is mirror-symmetric; without
the mirror the solve finds lopsided minima that read as chains of S shapes). Every knot point keeps its hand-drawn
(a, c), so eq. 4 still holds in the plane (c0⁺/c0⁻ share a planar point, |p0 − p1| = 2r) and the runtime's knot
solver and its measurements (knot centres, Fig. 9) are unchanged; only eq. 2's lift ±r becomes free, and a crossing
may grow thicker than 2r where the yarns need room. With d_pq the distance between dense samples p and q of two
*different parts* of the yarns (another course, or the same course more than ``EXCLUDE_RADII`` r along it, incl. the
periodic copies), ℓ the yarn length per period, α_i the turning angle at dense sample i and Δs_i its mean adjacent
segment length:

    E = W_CONTACT Σ_pairs max(0, D − d_pq)²/r²                     contact, D = 2r (1 − ``COMPRESSION``)
      + W_BEND Σ_i α_i² r / Δs_i                                   bending (∫ κ² ds, a discrete elastic rod)
      + W_LENGTH ((ℓ − ℓ_0)/r)²                                    stretching of the period's yarn, ℓ_0 the seed's
      + W_ANCHOR |y − y_seed|²                                     a weak pull to the seed, y in radii
      + Σ_F W_DEFORMED W_CONTACT Σ_pairs(F) max(0, D − d_pq)²/r²    contact of the tile deformed by F

The last line keeps the yarns apart when the face deforms: the tile is also laid out as the runtime's knot
interpolation lays it out on a face deformed by each affine map F of ``DEFORMATIONS`` (shear ±0.3 of the face
plane: knot centres and axes mapped by F, eqs. 1-2 on them, ``template_positions``) and its contact priced there
too, with weight ``W_DEFORMED``. That weight is a trade (BENCHMARKS.md, "Contact between simulated yarns"): more of it
keeps sheared knits apart, but tilts the knots so that the knot solver preserves yarn lengths under stretch-y no
better than naive interpolation (Huang et al. 2025 Fig. 9; the test asks for ≥ 10 % better). 0.1 keeps that test;
shear 0.3 then leaves a 5th percentile of 0.77 where 0.5 would give 0.80, which the shear shape (below) closes.

The shear shape
---------------
Whatever that weight, a face sheared by 0.3 squeezes the legs of neighbouring loops together in the plane (5th
percentile 0.77 in the simulated knits). So the knit gets a second set of unknowns for its face sheared by ``SHEAR``
(``relax_shear_shape``, run after the rest tile): a shift (Δu, Δv) of each knot centre (face coordinates) and a lift
change Δs of each of the 12 knot points, 16 in all, no mirror symmetry (the shear breaks it; shear the other way takes
the mirror image, ``stitch_templates``, "Shear shape"). On the tile laid out on the sheared face (knot interpolation,
as above) with x the unknowns in radii, L_i the control polygon's segment lengths and L_i⁰ the rest tile's:

    E_shear = W_CONTACT Σ_pairs max(0, D − d_pq)²/r² + W_BEND Σ_i α_i² r / Δs_i + W_LENGTH ((ℓ − ℓ_F)/r)²
            + W_SEGMENTS Σ_i ((L_i − L_i⁰)/r)² + W_ANCHOR |x|²

ℓ_F the sheared tile's yarn length before the change. The segment term is what keeps the knot solver's length error
(Huang et al. 2025 Fig. 9, per control segment against the rest template) from growing: lifts alone meet the contact
but lengthen the short segments round the knots (RMS error at shear 0.3: 0.034 → 0.108 after the knot solve); with
the knot shifts and ``W_SEGMENTS`` the knots move instead. The runtime blends the shape in linearly with the face's
shear up to ``SHEAR``'s and keeps it beyond (``knot_solver.shear_weights``).

The contact pairs are those closer than ``PAIR_RADII`` r at the start of a round; a round is one scipy
``least_squares`` solve (trust region reflective, finite-difference Jacobian) with that fixed set; rounds repeat
until the set no longer changes or ``MAX_ROUNDS`` is reached (convergence criterion: the set is stable and the solver
reports its ftol/xtol/gtol met at ``SOLVER_TOL``; the result says ``converged``). The tight tolerance is what makes the
shipped file reproducible on another machine: stopped at scipy's default 1e-8, the solve ends where rounding steered
it along the energy's flat directions (another CPU moved the decreases' points by up to 7e-4); converged, the spread is
2e-5 (``tests/test_template_relax.py``). ``check_crossings`` then refuses a result in which a yarn passed through
another (the order along the normal at a crossing swapped). Purl is the knit template mirrored through the fabric plane
(``stitch_templates``), so it is relaxed with it. Yarn-over, k2tog and ssk are relaxed next, in
an eyelet context around the relaxed knit (``patch_relax``); ``relax_templates`` runs both.

The result is the knit template's two knots (u, v, du, dv), every knot point's (a, c, s) by piece role and the knit's
shear shape (format 1.1); the runtime maps them as before (eqs. 1-2 of ``stitch_templates``), so a deformed face
moves the relaxed points with its knots. Measured before/after: BENCHMARKS.md, "Contact between simulated yarns".
"""

from __future__ import annotations

import json
import math
import time

import numpy as np
from scipy.optimize import least_squares

from data_formats.atomic import atomic_path

WIDTH = 1.0
ASPECT = 0.8  # course height / stitch width of the chart default (0.2 / 0.25 cm)
RADIUS = 1.0 / 8.0
SAMPLES = 8  # Catmull-Rom samples per control segment
EXCLUDE_RADII = 8.0  # as the contact statistic (knitrun.sim.contact)
COMPRESSION = 0.0  # contact distance 2r (1 − COMPRESSION): 0 = the yarns do not squeeze
PAIR_RADII = 3.0
W_CONTACT, W_BEND, W_LENGTH, W_ANCHOR = 100.0, 1.0, 100.0, 0.01
W_DEFORMED = 0.1  # weight of each sheared tile's contact term, relative to the rest tile's (see the module docstring)
W_SEGMENTS = 1000.0  # the shear shape's hold on each control segment's rest length (module docstring)
ANCHOR_SCALE = np.array([WIDTH, ASPECT * WIDTH, WIDTH, ASPECT * WIDTH] + [RADIUS] * 6) / RADIUS  # unknowns → radii
SHAPE_SCALE = np.array([WIDTH, ASPECT * WIDTH] * 2 + [RADIUS] * 12) / RADIUS  # the shear shape's unknowns → radii
MAX_ROUNDS = 8
SOLVER_TOL = 1e-10  # least_squares' ftol, xtol and gtol (see the module docstring)
IDENTITY = np.eye(2)
# The tile is relaxed at rest and, for its contact term only, under these affine deformations of the face plane
# (knot interpolation of the runtime: ``template_positions``), each with its weight; the rest tile comes first.
SHEAR = np.array([[1.0, 0.3], [0.0, 1.0]])  # the sheared face the knit's shear shape is relaxed for
MIRROR = np.diag([-1.0, 1.0])  # the face mirrored about its centre line: shear the other way is MIRROR·SHEAR·MIRROR
DEFORMATIONS = {"rest": (IDENTITY, 1.0),
                "shear 0.3": (SHEAR, W_DEFORMED),
                "shear -0.3": (MIRROR @ SHEAR @ MIRROR, W_DEFORMED)}
SHIFTS = [(i, j) for i in range(-2, 3) for j in range(-2, 3)]
FORMAT = "knit-relaxed-templates"
VERSION = "1.1"  # 1.1: the knit's shear shape


# --- the knit tile, at rest or under an affine deformation F of the face plane ----------------------------------------

def _face_vertex(slot, height):
    """Rest rectangle of a knit face (b = 1): slots BL, BR, TR, TL."""
    return np.array([(0.0, 0.0), (WIDTH, 0.0), (WIDTH, height), (0.0, height)][slot])


def _shift(F, i, j):
    """The tile's period (i along the course, j up the wale) under F, as a 3-D offset."""
    return np.append(F @ np.array([i * WIDTH, j * ASPECT * WIDTH]), 0.0)


def knot_frames(knots, F=IDENTITY):
    """[(centre (2,), d (2,), b (2,), l)] of the knots, each ``((u, v), (du, dv))`` (``stitch_templates``' form: centre
    and c0 − centre in face coordinates), on the rest rectangle mapped by F as the runtime's knot interpolation maps
    them (``knot_solver`` steps 3 and 5: centre F x_k, axis F (c0 − x_k), so l = |F (c0 − x_k)|)."""
    height = ASPECT * WIDTH
    out = []
    for (u, v), (du, dv) in knots:
        axis = F @ np.array([du * WIDTH, dv * height])
        half = float(np.hypot(*axis))
        d = axis / half
        out.append((F @ np.array([u * WIDTH, v * height]), d, np.array([d[1], -d[0]]), half))
    return out


def template_positions(pieces, knots, F=IDENTITY):
    """{role: (n, 3) positions} of a knit face's pieces (``stitch_templates.template_pieces`` form) on the rest face
    mapped by F: boundary points on the mapped edges, knot points by eqs. 1-2 on the mapped knots."""
    height = ASPECT * WIDTH
    frames = knot_frames(knots, F)
    out = {}
    for role, points in pieces:
        xyz = []
        for p in points:
            if p[0] == "edge":
                _, v0, v1, t = p
                xy = F @ ((1.0 - t) * _face_vertex(v0, height) + t * _face_vertex(v1, height))
                xyz.append((xy[0], xy[1], 0.0))
            else:
                _, j, a, c, s = p
                centre, d, b, half = frames[j]
                xy = centre + a * half * d + c * RADIUS * b
                xyz.append((xy[0], xy[1], s * RADIUS))
        out[role] = np.array(xyz)
    return out


def period_polygon(pos, roles, F=IDENTITY):
    """(15, 3) control polygon of one course yarn over one stitch (module docstring) from the positions of a knit
    face's pieces; ``roles`` = (IN, OUT, LOOP)."""
    rin, rout, rloop = roles
    up = _shift(F, 0, 1)
    return np.concatenate([pos[rin][:4], pos[rin][4:5], pos[rloop][1:-1] + up, pos[rloop][-1:] + up,
                           pos[rout][1:4]])


def dense_period(polygon, F=IDENTITY):
    """Uniform Catmull-Rom samples (SAMPLES per segment) of the polygon repeated every period along the course."""
    n = len(polygon)
    shift = _shift(F, 1, 0)
    ext = np.concatenate([polygon[-1:] - shift, polygon, polygon[:2] + shift])  # Q_{-1} … Q_{n+1}
    t = np.arange(SAMPLES) / SAMPLES
    t2, t3 = t * t, t * t * t
    w = np.stack([0.5 * (-t + 2 * t2 - t3), 0.5 * (2 - 5 * t2 + 3 * t3), 0.5 * (t + 4 * t2 - 3 * t3),
                  0.5 * (t3 - t2)], axis=1)
    windows = np.stack([ext[i:i + 4] for i in range(n)])  # segment i: Q_{i-1}, Q_i, Q_{i+1}, Q_{i+2}
    return np.einsum("tk,skd->std", w, windows).reshape(-1, 3)


def _arc(dense, F=IDENTITY):
    """Arc length at every dense sample, the period length and the segment lengths (the last closes the period)."""
    closing = dense[0] + _shift(F, 1, 0)
    seg = np.linalg.norm(np.diff(np.concatenate([dense, closing[None]]), axis=0), axis=1)
    return np.concatenate([[0.0], np.cumsum(seg[:-1])]), float(seg.sum()), seg


def candidate_pairs(dense, limit, F=IDENTITY):
    """(p, q, shift index) of sample pairs of different parts closer than ``limit``."""
    s, length, _ = _arc(dense, F)
    found = []
    for k, (i, j) in enumerate(SHIFTS):
        other = dense + _shift(F, i, j)
        d = np.linalg.norm(dense[:, None, :] - other[None, :, :], axis=2)
        near = d < limit
        if j == 0:
            near &= np.abs(s[None, :] + i * length - s[:, None]) > EXCLUDE_RADII * RADIUS
        p, q = np.nonzero(near)
        found.append(np.column_stack([p, q, np.full(len(p), k)]))
    return np.concatenate(found)


def pair_distances(dense, pairs, F=IDENTITY):
    shift = np.array([_shift(F, i, j) for i, j in SHIFTS])
    return np.linalg.norm(dense[pairs[:, 0]] - dense[pairs[:, 1]] - shift[pairs[:, 2]], axis=1)


def _unknowns_to_template(y, pieces, roles):
    """(pieces, knots) of a knit face for the unknowns y: knot 0 = (u, v), (du, dv); knot 1 its mirror image
    (1 − u, v), (−du, dv); the knot points keep their (a, c) (eq. 4 holds in the plane) and take the lifts s of y:
    IN's three points and the loop's three on knot 0, mirrored onto OUT's and the loop's on knot 1."""
    u, v, du, dv = y[:4]
    knots = (((u, v), (du, dv)), ((WIDTH - u, v), (-du, dv)))
    lifts = {roles[0]: list(y[4:7]), roles[1]: list(y[4:7])[::-1], roles[2]: list(y[7:10]) + list(y[7:10])[::-1]}
    out = []
    for role, points in pieces:
        it = iter(lifts[role])
        out.append((role, [p if p[0] == "edge" else p[:4] + (float(next(it)),) for p in points]))
    return out, knots


def _polygon(y, pieces, roles, F=IDENTITY):
    new_pieces, knots = _unknowns_to_template(y, pieces, roles)
    return period_polygon(template_positions(new_pieces, knots, F), roles, F)


def _contact(dense, pairs, F):
    return np.maximum(0.0, 2.0 * RADIUS * (1.0 - COMPRESSION) - pair_distances(dense, pairs, F)) / RADIUS


def _residuals(y, pieces, roles, pairs, seed, length0):
    """``pairs``: one candidate set per entry of ``DEFORMATIONS`` (the first is the rest tile)."""
    dense = dense_period(_polygon(y, pieces, roles))
    contact = [math.sqrt(W_CONTACT) * _contact(dense, pairs[0], IDENTITY)]
    for (F, weight), pp in zip(list(DEFORMATIONS.values())[1:], pairs[1:]):
        contact.append(math.sqrt(W_CONTACT * weight) * _contact(dense_period(_polygon(y, pieces, roles, F), F), pp, F))
    return np.concatenate(contact + _rod_residuals(dense, length0) + [math.sqrt(W_ANCHOR) * (y - seed) * ANCHOR_SCALE])


def _rod_residuals(dense, length0, F=IDENTITY):
    """[bending residuals (per dense sample), [stretching residual]] of the period's yarn ``dense`` (laid out under F)
    against the yarn length ``length0``: the rod terms of the energy (module docstring)."""
    _, length, seg = _arc(dense, F)
    e_in = np.diff(np.concatenate([dense, dense[:1] + _shift(F, 1, 0)]), axis=0)
    e_prev = np.roll(e_in, 1, axis=0)
    cos = np.einsum("ij,ij->i", e_prev, e_in) / np.maximum(np.linalg.norm(e_prev, axis=1) *
                                                           np.linalg.norm(e_in, axis=1), 1e-300)
    angle = np.arccos(np.clip(cos, -1.0, 1.0))
    ds = 0.5 * (seg + np.roll(seg, 1))
    bend = angle * np.sqrt(RADIUS / np.maximum(ds, 1e-12))
    return [math.sqrt(W_BEND) * bend, [math.sqrt(W_LENGTH) * (length - length0) / RADIUS]]


def _all_pairs(y, pieces, roles):
    return [candidate_pairs(dense_period(_polygon(y, pieces, roles, F), F), PAIR_RADII * RADIUS, F)
            for F, _ in DEFORMATIONS.values()]


def tile_contact(polygon, F=IDENTITY):
    """Contact statistic of the tile: d/2r at every dense sample to the nearest other part (as
    ``knitrun.sim.contact``, on the dense samples), percentiles 5 and 50 and the minimum."""
    dense = dense_period(polygon, F)
    pairs = candidate_pairs(dense, 2.0 * 2.0 * RADIUS, F)
    d = pair_distances(dense, pairs, F)
    nearest = np.full(len(dense), 2.0)
    np.minimum.at(nearest, pairs[:, 0], d / (2.0 * RADIUS))
    return {"p5": round(float(np.percentile(nearest, 5)), 4), "p50": round(float(np.median(nearest)), 4),
            "min": round(float(nearest.min()), 4)}


def check_crossings(pieces, points):
    """Raise RuntimeError if the relaxation changed which yarn lies on top at a crossing: at every seed crossing
    point (a = ±1, c = 0) of a knot, the pieces meeting there must keep their order along the normal (s)."""
    seed, relaxed = {}, {}
    for role, spec in pieces:
        knot_points = [p for p in spec if p[0] == "knot"]
        for p, (_, _, s) in zip(knot_points, points.get(str(role), [p[2:] for p in knot_points])):
            if p[3] == 0 and abs(p[2]) == 1:
                seed.setdefault((p[1], p[2]), []).append(p[4])
                relaxed.setdefault((p[1], p[2]), []).append(s)
    for key, before in seed.items():
        after = relaxed[key]
        if len(before) == 2 and np.sign(before[0] - before[1]) != np.sign(after[0] - after[1]):
            raise RuntimeError(f"relaxation swapped the yarns at knot {key[0]}, a = {key[1]:+d}: s {before} → "
                               f"{[round(x, 3) for x in after]} (a yarn passed through another)")


def relax_knit(pieces, knots, roles, progress=None):
    """Relax the knit template (module docstring) from the hand-drawn ``pieces`` and ``knots``. Returns a dict:
    ``knots`` [[u, v, du, dv], …], ``points`` {role: [(a, c, s), …] for the knot points of each piece in template
    order}, the tile's contact before/after, energies, yarn lengths per period, rounds, solver status, seconds."""
    t0 = time.perf_counter()
    (u, v), (du, dv) = knots[0]
    lifts = {role: [p[4] for p in spec if p[0] == "knot"] for role, spec in pieces}
    seed = np.array([u, v, du, dv, *lifts[roles[0]], *lifts[roles[2]][:3]])
    if not np.allclose(_polygon(seed, pieces, roles), period_polygon(template_positions(pieces, knots), roles)):
        raise RuntimeError("the seed template is not mirror-symmetric about the face's centre line")
    polygon0 = _polygon(seed, pieces, roles)
    length0 = _arc(dense_period(polygon0))[1]
    y = seed.copy()
    rounds, pairs_prev, status, converged = 0, None, None, False
    for rounds in range(1, MAX_ROUNDS + 1):
        pairs = _all_pairs(y, pieces, roles)
        if pairs_prev is not None and all(np.array_equal(a, b) for a, b in zip(pairs, pairs_prev)) \
                and status is not None and status > 0:
            converged = True
            break
        result = least_squares(_residuals, y, args=(pieces, roles, pairs, seed, length0), method="trf",
                               x_scale=1.0 / ANCHOR_SCALE, max_nfev=400,
                               ftol=SOLVER_TOL, xtol=SOLVER_TOL, gtol=SOLVER_TOL)
        y, status, pairs_prev = result.x, int(result.status), pairs
        if progress is not None:
            progress(rounds, float(result.cost), sum(len(p) for p in pairs))
    new_pieces, new_knots = _unknowns_to_template(y, pieces, roles)
    points = {str(role): [list(p[2:]) for p in spec if p[0] == "knot"] for role, spec in new_pieces}
    check_crossings(pieces, points)
    relaxed = _polygon(y, pieces, roles)

    def energy(yy, pp):
        return 0.5 * float(np.sum(_residuals(yy, pieces, roles, pp, seed, length0) ** 2))

    contact = {name: {"before": tile_contact(_polygon(seed, pieces, roles, F), F),
                      "after": tile_contact(_polygon(y, pieces, roles, F), F)}
               for name, (F, _) in DEFORMATIONS.items()}
    return {"knots": [[*c, *a] for c, a in new_knots], "points": points,
            "contact_before": contact["rest"]["before"], "contact_after": contact["rest"]["after"],
            "contact_deformed": contact,
            "energy_before": energy(seed, _all_pairs(seed, pieces, roles)),
            "energy_after": energy(y, _all_pairs(y, pieces, roles)),
            "length_before": length0, "length_after": _arc(dense_period(relaxed))[1], "rounds": rounds,
            "solver_status": status, "converged": converged, "seconds": time.perf_counter() - t0}


def _with_lift_changes(pieces, ds):
    """``pieces`` with ``ds`` (one per knot point, pieces in order) added to their knot points' lifts s."""
    it = iter(ds)
    return [(role, [p if p[0] == "edge" else p[:4] + (p[4] + float(next(it)),) for p in points])
            for role, points in pieces]


def _with_knot_shifts(knots, shifts):
    """``knots`` with their centres moved by ``shifts`` [Δu_0, Δv_0, Δu_1, Δv_1] (face coordinates)."""
    return tuple(((u + shifts[2 * j], v + shifts[2 * j + 1]), axis) for j, ((u, v), axis) in enumerate(knots))


def _segment_lengths(polygon, F=IDENTITY):
    """Lengths of the period polygon's control segments, the closing one (to the next period) last."""
    closing = polygon[0] + _shift(F, 1, 0)
    return np.linalg.norm(np.diff(np.concatenate([polygon, closing[None]]), axis=0), axis=1)


def _shaped_polygon(x, pieces, knots, roles, F):
    """Period polygon of the tile laid out on a face deformed by F with the shear shape x = (4 knot shifts, lift
    changes)."""
    return period_polygon(template_positions(_with_lift_changes(pieces, x[4:]), _with_knot_shifts(knots, x[:4]), F),
                          roles, F)


def _shape_residuals(x, pieces, knots, roles, pairs, length0, segments0, F):
    polygon = _shaped_polygon(x, pieces, knots, roles, F)
    dense = dense_period(polygon, F)
    return np.concatenate([math.sqrt(W_CONTACT) * _contact(dense, pairs, F)] + _rod_residuals(dense, length0, F)
                          + [math.sqrt(W_SEGMENTS) * (_segment_lengths(polygon, F) - segments0) / RADIUS,
                             math.sqrt(W_ANCHOR) * x * SHAPE_SCALE])


def relax_shear_shape(pieces, knots, roles, F=SHEAR, progress=None):
    """The knit's shear shape (``stitch_templates``, "Shear shape"): the knot shifts (Δu, Δv) and lift changes Δs
    that relax the tile laid out on a face deformed by ``F`` (knot interpolation, ``template_positions``) from the
    rest template ``pieces``, ``knots``. Energy (module docstring, "The shear shape") on the deformed tile; 16
    unknowns, no mirror symmetry (the shear breaks it); rounds of fixed contact pairs as ``relax_knit``. Returns a
    dict: ``kappa`` (F's shear κ, ``knot_solver.face_shear``), ``knots`` [[Δu, Δv], …], ``lifts`` {role: [Δs, …]},
    the deformed tile's contact and control-segment RMS length error (against the rest tile) before/after, both at
    half the shape on a face sheared half as much and the mirrored shape on the face sheared the other way; rounds,
    solver status, seconds."""
    from knitrun.sim.knot_solver import face_shear

    t0 = time.perf_counter()
    n = 4 + sum(p[0] == "knot" for _, points in pieces for p in points)
    segments0 = _segment_lengths(period_polygon(template_positions(pieces, knots), roles))

    def polygon(x, FF=F):
        return _shaped_polygon(x, pieces, knots, roles, FF)

    def figures(x, FF):
        p = polygon(x, FF)
        rms = float(np.sqrt(np.mean((_segment_lengths(p, FF) / segments0 - 1.0) ** 2)))
        return {**tile_contact(p, FF), "segment_error": round(rms, 4)}

    length0 = _arc(dense_period(polygon(np.zeros(n)), F), F)[1]
    x, pairs_prev, status, converged = np.zeros(n), None, None, False
    for rounds in range(1, MAX_ROUNDS + 1):
        pairs = candidate_pairs(dense_period(polygon(x), F), PAIR_RADII * RADIUS, F)
        if pairs_prev is not None and np.array_equal(pairs, pairs_prev) and status is not None and status > 0:
            converged = True
            break
        result = least_squares(_shape_residuals, x, args=(pieces, knots, roles, pairs, length0, segments0, F),
                               method="trf", x_scale=1.0 / SHAPE_SCALE, max_nfev=400,
                               ftol=SOLVER_TOL, xtol=SOLVER_TOL, gtol=SOLVER_TOL)
        x, status, pairs_prev = result.x, int(result.status), pairs
        if progress is not None:
            progress(rounds, float(result.cost), len(pairs))
    lifts, it = {}, iter(x[4:])
    for role, points in pieces:
        lifts[str(role)] = [float(next(it)) for p in points if p[0] == "knot"]
    shaped = _with_lift_changes(pieces, x[4:])
    check_crossings(pieces, {str(role): [list(p[2:]) for p in spec if p[0] == "knot"] for role, spec in shaped})
    mirror = np.concatenate([[-x[2], x[3], -x[0], x[1]], lifts[str(roles[1])][::-1], lifts[str(roles[0])][::-1],
                             lifts[str(roles[2])][::-1]])
    half = IDENTITY + 0.5 * (F - IDENTITY)
    return {"kappa": float(face_shear(F)), "deformation": F.tolist(), "knots": x[:4].reshape(2, 2).tolist(),
            "lifts": lifts, "before": figures(np.zeros(n), F), "after": figures(x, F),
            "half": figures(x * min(1.0, face_shear(half) / face_shear(F)), half),
            "mirrored": figures(mirror, MIRROR @ F @ MIRROR),
            "rounds": rounds, "solver_status": status, "converged": converged, "seconds": time.perf_counter() - t0}


def relax_templates(progress=None) -> dict:
    """The relaxed-template document (``relaxed_templates.json``): format, version, the tile and energy parameters
    and, per relaxed stitch type, its knot points' (a, c, s) by piece role, with the before/after figures.

    Reproducible: BLAS runs on one thread meanwhile (threadpoolctl), so this machine regenerates the file bit for
    bit (the solver's matrix products otherwise sum in an order that depends on BLAS's thread count), and both solves
    converge tightly (``SOLVER_TOL``), so another machine's rounding moves no point by more than ~2e-5."""
    from threadpoolctl import threadpool_limits

    with threadpool_limits(limits=1, user_api="blas"):
        return _relax_templates(progress)


def _relax_templates(progress):
    from knitrun.sim import stitch_templates as st
    from knitrun.sim.patch_relax import relax_in_patch

    pieces = st.template_pieces(st.KNIT, relaxed=False)
    roles = (st.ROLE_IN, st.ROLE_OUT, st.ROLE_LOOP)
    result = relax_knit(pieces, st.STITCH_KNOTS, roles, progress)
    new_pieces = [(role, st.with_relaxed_points(points, [tuple(p) for p in result["points"][str(role)]]))
                  for role, points in pieces]
    new_knots = tuple((tuple(k[:2]), tuple(k[2:])) for k in result["knots"])
    result["shear"] = relax_shear_shape(new_pieces, new_knots, roles, SHEAR, progress)
    # the other types are relaxed around the relaxed knit: pack it for the while, then put everything back
    saved = dict(st.RELAXED), st.TEMPLATE_INT.copy(), st.TEMPLATE_FLOAT.copy()
    try:
        st.RELAXED.clear()
        st.RELAXED["knit"] = {"knots": new_knots,
                              "points": {int(role): [tuple(abc) for abc in spec]
                                         for role, spec in result["points"].items()},
                              "shear": (result["shear"]["kappa"], tuple(map(tuple, result["shear"]["knots"])),
                                        {int(role): spec for role, spec in result["shear"]["lifts"].items()})}
        st.TEMPLATE_INT[...], st.TEMPLATE_FLOAT[...] = st.pack_templates(True)
        others = relax_in_patch(progress)
    finally:
        st.RELAXED.clear()
        st.RELAXED.update(saved[0])
        st.TEMPLATE_INT[...], st.TEMPLATE_FLOAT[...] = saved[1], saved[2]
    context = others.pop("context")
    return {"format": FORMAT, "version": VERSION,
            "tile": {"width": WIDTH, "aspect": ASPECT, "radius": RADIUS, "samples": SAMPLES},
            "energy": {"w_contact": W_CONTACT, "w_bend": W_BEND, "w_length": W_LENGTH, "w_anchor": W_ANCHOR,
                       "compression": COMPRESSION, "exclude_radii": EXCLUDE_RADII, "pair_radii": PAIR_RADII,
                       "max_rounds": MAX_ROUNDS},
            "context": context, "stitch_types": {"knit": result, **others}}


def write_relaxed(path, document):
    """Write the document as JSON atomically (no half-written file)."""
    with atomic_path(path) as tmp:
        with open(tmp, "w") as fh:
            json.dump(document, fh, indent=1)
            fh.write("\n")
