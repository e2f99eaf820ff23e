"""Knot solver: templates and eq. 4, exact rest state, analytic Jacobians, monotone damped Gauss-Newton, agreement
with a dense least-squares solve, unit invariance, knot spacing blend, and finite output at the extremes."""

import functools

import numpy as np
import pytest
from scipy.optimize import least_squares

from data_formats.errors import FormatError
from data_formats.stitch_mesh import LOOPS_CONSUMED, STITCH_TYPES, make_stitch_mesh
from knitrun.sim.deformations import deform, deformation_frames
from knitrun.sim.knit_chart import chart_to_mesh, pattern_chart
from knitrun.sim.knot_solver import R_KNOTS, W_SIZE, damped_solve, face_shear, knot_points, shear_weights
from knitrun.sim.simulate import face_problem, knot_centres, prepare, solve_frame
from knitrun.sim.stitch_templates import (F_A, F_C, F_DS_NEG, F_DS_POS, F_S, F_SHEAR, I_KNOT, K2TOG, KNIT, MAX_POINTS,
                                          N_POINTS, PURL, SSK, TEMPLATE_FLOAT, TEMPLATE_INT, YARN_OVER, piece_ranges,
                                          shear_shape_off)

MIXED_CHART = """
ppk\\k
kko/kk
k\\okpp
kkppkk
"""  # purl, yarn-overs and both decreases, not periodic


@functools.lru_cache(maxsize=None)
def mixed_model():
    return prepare(chart_to_mesh(MIXED_CHART))


@functools.lru_cache(maxsize=None)
def eyelet_model():
    return prepare(chart_to_mesh(pattern_chart("eyelet", 7, 8)))


def random_frame(mesh, rng, stretch=(0.6, 1.8), shear=0.6, noise=0.01):
    c = 0.5 * (mesh.vertices.min(axis=0) + mesh.vertices.max(axis=0))
    v = deform(mesh.vertices, "stretch-x", rng.uniform(*stretch), 1.0, c)
    v = deform(v, "stretch-y", rng.uniform(0.7, 1.4), 1.0, c)
    v = deform(v, "shear", rng.uniform(-shear, shear), 1.0, c)
    return v + rng.normal(0, noise, v.shape) * [1, 1, 0]


# --- templates ------------------------------------------------------------------------------------------------------

def test_template_sizes_and_pieces():
    boundary = lambda code: int((TEMPLATE_INT[code, I_KNOT, :N_POINTS[code]] < 0).sum())  # noqa: E731
    assert [N_POINTS[c] for c in (KNIT, PURL, YARN_OVER, K2TOG, SSK)] == [18, 18, 10, 26, 26]
    for code in range(len(STITCH_TYPES)):
        pieces = piece_ranges(code)
        assert len(pieces) == 2 + LOOPS_CONSUMED[code]  # two legs and one head per consumed loop
        assert boundary(code) == 2 * len(pieces)  # every piece starts and ends on an edge
        for _, start, stop in pieces:
            assert TEMPLATE_INT[code, I_KNOT, start] < 0 and TEMPLATE_INT[code, I_KNOT, stop - 1] < 0
        knots = TEMPLATE_INT[code, I_KNOT, :N_POINTS[code]]
        assert set(knots[knots >= 0].tolist()) == {0, 1}  # two knots in every face, yarn-over included


def test_purl_is_knit_mirrored_through_the_plane():
    assert np.array_equal(TEMPLATE_INT[PURL], TEMPLATE_INT[KNIT])
    lifts = (F_S, F_DS_POS, F_DS_NEG)  # the lifts and the shear shape's lift changes flip; knots and shifts stay
    rows = [r for r in range(TEMPLATE_FLOAT.shape[1]) if r not in lifts]
    assert np.array_equal(TEMPLATE_FLOAT[PURL, rows], TEMPLATE_FLOAT[KNIT, rows])
    assert np.array_equal(TEMPLATE_FLOAT[PURL, lifts], -TEMPLATE_FLOAT[KNIT, lifts])
    assert TEMPLATE_FLOAT[KNIT, F_SHEAR, 0] > 0 and np.abs(TEMPLATE_FLOAT[KNIT, F_DS_POS]).max() > 0


@pytest.mark.parametrize("code", range(len(STITCH_TYPES)))
def test_every_crossing_is_at_least_a_yarn_diameter_thick(code):
    """At c0 and c1 of every knot the two yarns pass one over the other at least 2r apart along the normal (eq. 2
    puts them exactly ±r; the relaxed knit template lifts them, ``template_relax``)."""
    for j in range(2):
        for a in (1.0, -1.0):
            rows = (TEMPLATE_INT[code, I_KNOT] == j) & (TEMPLATE_FLOAT[code, F_A] == a) \
                & (TEMPLATE_FLOAT[code, F_C] == 0)
            s = TEMPLATE_FLOAT[code, F_S, rows]
            if len(s) == 2:
                assert abs(s[0] - s[1]) >= 2 - 1e-12


@pytest.mark.parametrize("code", range(len(STITCH_TYPES)))
def test_eq4_constraints_hold_for_any_unknowns(code):
    rng = np.random.default_rng(code)
    radius = 0.03
    for _ in range(5):
        theta = np.concatenate([rng.uniform(-np.pi, np.pi, 2), rng.uniform(0.001, 0.2, 2)])
        knots = rng.normal(size=(2, 2))
        ws = np.zeros((MAX_POINTS, W_SIZE))
        knot_points(theta, knots, code, TEMPLATE_INT, TEMPLATE_FLOAT, radius, ws)
        for j in range(2):
            def points(a, c):
                rows = (TEMPLATE_INT[code, I_KNOT] == j) & (TEMPLATE_FLOAT[code, F_A] == a) \
                    & (TEMPLATE_FLOAT[code, F_C] == c)
                return ws[np.flatnonzero(rows), :2]
            c0s, c1s = points(1, 0), points(-1, 0)  # c0⁺ and c0⁻ (c1⁺, c1⁻) share the planar point
            c0, c1 = c0s[0], c1s[0]
            p0s = [p for p in points(0, 1)] + [2 * knots[j] - p for p in points(0, -1)]  # p1 = 2 x_k − p0
            assert len(p0s) and np.ptp(c0s, axis=0).max() < 1e-12 and np.ptp(c1s, axis=0).max() < 1e-12
            np.testing.assert_allclose((c0 + c1) / 2, knots[j], atol=1e-12)
            for p0 in p0s:
                assert np.linalg.norm(2 * (p0 - knots[j])) == pytest.approx(2 * radius, rel=1e-12)  # |p0 − p1| = 2r
                assert np.dot(knots[j] - p0, c0 - knots[j]) == pytest.approx(0, abs=1e-12)
                np.testing.assert_allclose(p0, p0s[0], atol=1e-12)  # both yarns agree on the knot's p0/p1


# --- rest state -----------------------------------------------------------------------------------------------------

def test_at_rest_the_optimizer_returns_the_template_exactly():
    model = mixed_model()
    mesh = model.mesh
    start = solve_frame(model, mesh.vertices, iterations=0)
    solved = solve_frame(model, mesh.vertices, iterations=5)
    assert solved.energy.max() < 1e-24  # zero energy, before and after every iteration
    rest_theta = model.rest[:, [R_KNOTS + 2, R_KNOTS + 6, R_KNOTS + 3, R_KNOTS + 7]]
    np.testing.assert_allclose(start.theta, rest_theta, rtol=0, atol=1e-14)
    np.testing.assert_allclose(solved.theta, start.theta, rtol=0, atol=1e-14)  # zero step
    np.testing.assert_allclose(solved.points, model.rest_points, rtol=0, atol=1e-14)


# --- Gauss-Newton ---------------------------------------------------------------------------------------------------

@pytest.mark.parametrize("code", range(len(STITCH_TYPES)))
def test_analytic_jacobian_matches_finite_differences(code):
    model = mixed_model()
    rng = np.random.default_rng(7)
    v = random_frame(model.mesh, rng)
    f = int(np.flatnonzero(model.mesh.stitch_type == code)[0])
    theta0, fun, jac = face_problem(model, v, f)
    theta = theta0 + rng.normal(0, 0.05, 4) * [1, 1, 0.1, 0.1]
    step = 1e-6 * np.array([1, 1, model.length_scale, model.length_scale])
    numeric = np.stack([(fun(theta + e) - fun(theta - e)) / (2 * e.sum()) for e in np.diag(step)], axis=1)
    np.testing.assert_allclose(jac(theta), numeric, rtol=1e-5, atol=1e-6 * np.abs(numeric).max())


def test_damped_solve_matches_a_dense_solve():
    rng = np.random.default_rng(3)
    h = 0.25
    for lam in (0.0, 1e-2, 10.0):
        j = rng.normal(size=(30, 4)) * [1, 1, 1 / h, 1 / h]
        a, g = j.T @ j, rng.normal(size=4)
        delta, lw = np.zeros(4), np.zeros((4, 4))
        assert damped_solve(a, g, lam, h, lw, delta)
        mu = 0.25 * (a[0, 0] + a[1, 1] + h * h * (a[2, 2] + a[3, 3]))
        expected = np.linalg.solve(a + lam * mu * np.diag([1, 1, 1 / h**2, 1 / h**2]), -g)
        np.testing.assert_allclose(delta, expected, rtol=1e-10)
    assert not damped_solve(np.zeros((4, 4)), np.ones(4), 1.0, h, np.zeros((4, 4)), np.zeros(4))  # singular: no step


def test_energy_never_increases_across_iterations():
    model = mixed_model()
    rng = np.random.default_rng(11)
    for _ in range(6):
        history = solve_frame(model, random_frame(model.mesh, rng, stretch=(0.2, 4.0), shear=1.5),
                              iterations=6).energy
        assert np.isfinite(history).all()
        assert (np.diff(history, axis=1) <= 0).all()
        assert (history[:, -1] < history[:, 0]).mean() > 0.9  # and it does go down


def gn_versus_dense(model, n_frames, seed):
    """E_3/E_* − 1 for every face of ``n_frames`` random stretch/shear frames: E_3 after the default three
    iterations, E_* a fully converged dense Levenberg-Marquardt solve of the same problem from the same start."""
    rng = np.random.default_rng(seed)
    ratios = []
    for _ in range(n_frames):
        v = random_frame(model.mesh, rng)
        e3 = solve_frame(model, v).energy[:, -1]
        for f in range(len(model.mesh.stitch_type)):
            theta0, fun, jac = face_problem(model, v, f)
            best = least_squares(fun, theta0, jac=jac, method="lm", xtol=1e-15, ftol=1e-15, gtol=1e-15)
            ratios.append(e3[f] / (2 * best.cost) - 1)
    return np.array(ratios)


def test_three_iterations_are_within_5_percent_of_a_converged_dense_solve():
    ratios = gn_versus_dense(eyelet_model(), n_frames=4, seed=1)
    assert ratios.min() > -1e-6  # the dense solve is converged: nothing better than it
    assert np.median(ratios) < 0.005 and np.percentile(ratios, 95) < 0.02 and ratios.max() < 0.05


# --- conventions ----------------------------------------------------------------------------------------------------

def test_results_do_not_depend_on_the_mesh_unit():
    mesh = chart_to_mesh(MIXED_CHART)
    mm = chart_to_mesh(MIXED_CHART, stitch_width=2.5, stitch_height=2.0, units="mm")
    v = deformation_frames(mesh.vertices, ["stretch-x=1.4", "shear=0.3"])[0]
    cm_run, mm_run = solve_frame(prepare(mesh), v), solve_frame(prepare(mm), 10 * v)
    np.testing.assert_allclose(mm_run.energy, cm_run.energy, rtol=1e-9, atol=1e-12)
    np.testing.assert_allclose(mm_run.points, 10 * cm_run.points, rtol=1e-9, atol=1e-9)


def test_beta_blends_knot_spacing_between_rest_and_interpolated():
    mesh = chart_to_mesh(pattern_chart("stockinette", 3, 3))
    v = deformation_frames(mesh.vertices, ["stretch-x=2.0"])[0]
    for beta, expected in ((1.0, 2.0), (0.5, 1.5), (0.0, 1.0)):
        model = prepare(mesh, beta=beta)
        k, k0 = knot_centres(model, solve_frame(model, v).points), knot_centres(model, model.rest_points)
        ratio = np.linalg.norm(k[:, 1] - k[:, 0], axis=1) / np.linalg.norm(k0[:, 1] - k0[:, 0], axis=1)
        np.testing.assert_allclose(ratio, expected, rtol=1e-12)  # d = d_0 + β (d_1 − d_0)


# --- the templates' shear shape -------------------------------------------------------------------------------------

def test_face_shear_is_the_cosine_between_the_deformed_course_and_wale():
    turn = np.array([[np.cos(0.7), -np.sin(0.7)], [np.sin(0.7), np.cos(0.7)]])
    for gamma in (0.0, 0.3, -0.5, 2.0):
        simple = np.array([[1.0, gamma], [0.0, 1.0]])
        expected = gamma / np.sqrt(1 + gamma ** 2)
        for f in (simple, turn @ simple, 3.0 * simple):  # turning or scaling the face leaves its shear
            assert face_shear(f) == pytest.approx(expected, abs=1e-15)
    for f in (np.eye(2), np.diag([1.5, 0.7]), turn, np.diag([2.0, 2.0]) @ turn):  # rest, stretch, rotation
        assert abs(face_shear(f)) < 1e-15
    for f in (np.zeros((2, 2)), np.array([[1.0, 0.0], [0.0, 0.0]]), np.full((2, 2), np.nan),
              np.array([[np.inf, 1.0], [0.0, 1.0]])):  # collapsed or not finite: no shear, never NaN
        assert face_shear(f) == 0.0
    kappa = face_shear(np.array([[1.0, 0.3], [0.0, 1.0]]))
    assert shear_weights(np.array([[1.0, 0.15], [0.0, 1.0]]), kappa) == pytest.approx((0.52, 0.0), abs=0.01)
    assert shear_weights(np.array([[1.0, -0.3], [0.0, 1.0]]), kappa) == pytest.approx((0.0, 1.0), abs=1e-12)
    assert shear_weights(np.array([[1.0, 0.9], [0.0, 1.0]]), kappa) == (1.0, 0.0)  # held beyond the relaxed shear
    assert shear_weights(np.array([[1.0, 0.3], [0.0, 1.0]]), 0.0) == (0.0, 0.0)  # a template without a shape


def test_the_shear_shape_moves_only_sheared_faces():
    """Rest, stretch and bending leave the points as without the shape; shear moves them (knots and lifts)."""
    model = prepare(chart_to_mesh(pattern_chart("rib1x1", 4, 4)))
    frames = {spec: deformation_frames(model.mesh.vertices, [spec])[0]
              for spec in ("stretch-x=1.5", "stretch-y=1.5", "cylinder=0.5", "shear=0.3")}
    frames["rest"] = model.mesh.vertices
    shaped = {name: solve_frame(model, v).points for name, v in frames.items()}
    with shear_shape_off():
        plain = {name: solve_frame(model, v).points for name, v in frames.items()}
    for name in frames:
        moved = np.abs(shaped[name] - plain[name]).max() / model.radius
        assert (moved > 0.1) if name == "shear=0.3" else (moved < 1e-9), (name, moved)


# --- extremes -------------------------------------------------------------------------------------------------------

def extreme_frames(mesh):
    rng = np.random.default_rng(5)
    frames = {f"{spec}": deformation_frames(mesh.vertices, [spec])[0]
              for spec in ("stretch-x=20", "stretch-y=20", "stretch-x=0.05", "stretch-y=0.05", "stretch-x=0",
                           "stretch-x=-1")}
    frames["all faces on one point"] = np.ones_like(mesh.vertices)
    flipped = mesh.vertices.copy()
    face = mesh.face_vertices[mesh.face_offsets[5]:mesh.face_offsets[6]]
    flipped[face[-1]] = flipped[face[0]] - (flipped[face[-1]] - flipped[face[0]])  # TL pushed below BL
    frames["one face inverted"] = flipped
    frames["non-planar"] = mesh.vertices + rng.normal(0, 0.1, mesh.vertices.shape)
    frames["crumpled"] = rng.normal(0, 0.3, mesh.vertices.shape)
    frames["huge"] = mesh.vertices * 1e100
    return frames


def test_extreme_deformations_give_finite_output():
    model = mixed_model()
    for name, v in extreme_frames(model.mesh).items():
        solved = solve_frame(model, v)
        assert np.isfinite(solved.points).all() and np.isfinite(solved.energy).all(), name
        assert (np.diff(solved.energy, axis=1) <= 0).all(), name


def test_non_finite_input_is_a_one_line_error_naming_the_face():
    model = mixed_model()
    v = model.mesh.vertices.copy()
    v[9, 0] = np.nan
    with pytest.raises(FormatError, match=r"face \d+: vertex 9 .*not finite") as err:
        solve_frame(model, v)
    assert "\n" not in str(err.value)
    with pytest.raises(FormatError, match=r"face 0: the simulation overflowed to non-finite values"):
        solve_frame(model, model.mesh.vertices * 1e300)  # squares overflow: refused, never written


def test_a_rest_face_without_area_is_rejected():
    good = chart_to_mesh("kk\n")
    v = good.vertices.copy()
    v[4] = v[3]  # face 0's top-left onto its top-right: a triangle in a quad's slots is fine ...
    v[1] = v[0]  # ... but with the bottom collapsed too the face has no area
    bad = make_stitch_mesh(v, good.face_offsets, good.face_vertices, good.stitch_type)
    with pytest.raises(FormatError, match="face 0: the rest face has no area"):
        prepare(bad)
