"""Fibers swept along yarn curves (knitbake.fibers.fiber_sweep), curve evaluation and the closed-form stockinette
curves."""

import dataclasses
from pathlib import Path

import numpy as np
import pytest
from scipy.spatial import cKDTree
from scipy.spatial.transform import Rotation

from data_formats.curve_eval import curve_frames, initial_normal
from data_formats.curve_eval import dense_curve, evaluate, rest_length
from data_formats.yarn_curves import make_yarn_curves, read_yarn_curves
from data_formats.yarn_spec import load_preset
from knitbake.fibers.fiber_set import KIND_REGULAR
from knitbake.fibers.fiber_sweep import clip_axially, curve_seed, sweep_fibers
from knitbake.fibers.procedural_yarn import generate_fibers
from knitrun.sim.crane_stockinette import stockinette_curves, write_example_patch

COTTON = load_preset("cotton1")
LIGHT = dataclasses.replace(COTTON, geometry=dataclasses.replace(COTTON.geometry, fibers_per_ply=12))
PATCH = Path(__file__).resolve().parent.parent / "examples" / "scenes" / "knit_patch_6x6.h5"


def line(direction, origin=(0.0, 0.0, 0.0), length=1.0, n=11, curve_type="PL"):
    """One straight curve of n control points (3k+1 for BZ) evenly spaced from ``origin``."""
    d = np.asarray(direction, float) / np.linalg.norm(direction)
    pts = np.asarray(origin, float) + np.linspace(0.0, length, n)[:, None] * d
    return make_yarn_curves(pts, [0, n], curve_type=curve_type)


def sweep(yc, spec=COTTON, radius=None, frame=0, seed=5, **kw):
    return sweep_fibers(yc, frame, {0: spec}, {0: spec.radius if radius is None else radius}, seed=seed, **kw)


@pytest.mark.parametrize("curve_type", ["PL", "C0", "BS", "BZ"])
def test_straight_curve_along_z_reproduces_generate_fibers(curve_type):
    fs = sweep(line([0, 0, 1], curve_type=curve_type, n=10 if curve_type == "BZ" else 11))
    ref = generate_fibers(COTTON, length=1.0, seed=curve_seed(5, 0))
    assert ref.info["hairs"] > 0 and ref.info["loops"] > 0
    assert ref.points[:, 2].min() < 0 and ref.points[:, 2].max() > 1  # flyaways reach past the ends ...
    ref = clip_axially(ref, 0.0, 1.0)  # ... and the sweep cuts them there
    np.testing.assert_array_equal(fs.offsets, ref.offsets)
    np.testing.assert_allclose(fs.points, ref.points, rtol=0, atol=1e-14)
    np.testing.assert_array_equal(fs.radius, ref.radius)
    np.testing.assert_array_equal(fs.kind, ref.kind)


def test_open_ends_cut_every_fiber_at_the_end_planes():
    """A yarn is cut at its ends (module docstring, "Open curves"): no fiber of an open curve reaches past the end
    cross-sections, the cut points lie on them, and the flyaway length inside the yarn is kept."""
    yc = line([0, 0, 1], length=0.6)
    fs = sweep(yc)
    z = fs.points[:, 2]
    assert z.min() >= -1e-12 and z.max() <= 0.6 + 1e-12
    raw = generate_fibers(COTTON, length=0.6, seed=curve_seed(5, 0))
    assert ((raw.points[:, 2] < 0) | (raw.points[:, 2] > 0.6)).sum() > 10  # there was something to cut

    def inside_length(f):
        """Summed length of every fiber's segments, each clipped to the slab by its z-fraction inside."""
        total = 0.0
        for i in range(f.n_fibers):
            p = f.fiber(i)
            a, b = p[:-1], p[1:]
            lo, hi = np.minimum(a[:, 2], b[:, 2]), np.maximum(a[:, 2], b[:, 2])
            frac = np.where(hi > lo, (np.clip(hi, 0, 0.6) - np.clip(lo, 0, 0.6)) / np.where(hi > lo, hi - lo, 1), 1.0)
            total += (np.linalg.norm(b - a, axis=1) * frac).sum()
        return total

    np.testing.assert_allclose(inside_length(fs), inside_length(raw), rtol=1e-9)
    regular = raw.kind == KIND_REGULAR
    assert (fs.kind == KIND_REGULAR).sum() == regular.sum()


def test_clip_axially_splits_a_hair_that_leaves_and_comes_back():
    from knitbake.fibers.fiber_set import KIND_HAIR, FiberSet

    p = np.array([[0, 0, 0.5], [0, 0, 1.5], [0.1, 0, 0.5], [0.2, 0, -1.0], [0.3, 0, 2.0]], float)
    fs = FiberSet(p, np.array([0, 5]), np.array([0.01]), np.array([KIND_HAIR], np.int8), np.array([0], np.int16))
    out = clip_axially(fs, 0.0, 1.0)
    assert out.n_fibers == 3 and np.all(out.kind == KIND_HAIR) and np.all(out.radius == 0.01)
    np.testing.assert_allclose(out.fiber(0), [[0, 0, 0.5], [0, 0, 1.0]])
    np.testing.assert_allclose(out.fiber(1), [[0.05, 0, 1.0], [0.1, 0, 0.5], [0.1 + 0.1 / 3, 0, 0.0]])
    np.testing.assert_allclose(out.fiber(2), [[0.2 + 0.1 / 3, 0, 0.0], [0.2 + 0.2 / 3, 0, 1.0]])


def test_radius_scales_the_yarn_uniformly():
    fs = sweep(line([0, 0, 1]), radius=2 * COTTON.radius)
    ref = generate_fibers(COTTON, length=0.5, seed=curve_seed(5, 0))  # half as many (twice as long) periods
    ref = clip_axially(ref, 0.0, 0.5)
    np.testing.assert_allclose(fs.points, 2 * ref.points, rtol=0, atol=1e-14)
    np.testing.assert_allclose(fs.radius, 2 * ref.radius)
    assert fs.info["curves"][0]["scale"] == pytest.approx(2.0)


def test_rotated_translated_line_gives_rigidly_moved_fibers():
    u, o = np.array([0.3, -0.8, 0.5]) / np.linalg.norm([0.3, -0.8, 0.5]), np.array([1.0, 2.0, -3.0])
    fs = sweep(line(u, o, length=0.8))
    n0 = initial_normal(u)
    frame = np.stack([n0, np.cross(u, n0), u], axis=1)  # yarn x, y, z -> N, B, T
    ref = clip_axially(generate_fibers(COTTON, length=0.8, seed=curve_seed(5, 0)), 0.0, 0.8)
    np.testing.assert_allclose(fs.points, o + ref.points @ frame.T, rtol=0, atol=1e-13)


def wave(n=200):
    s = np.linspace(0.0, 1.5, n)
    return np.stack([0.2 * np.sin(3 * s), 0.1 * np.cos(2 * s), s], axis=1)


@pytest.mark.parametrize("curve", ["line", "wave"])
def test_a_curve_moved_rigidly_between_frames_moves_its_fibers_rigidly(curve):
    p0 = wave() if curve == "wave" else np.linspace(0, 1, 11)[:, None] * [0.0, 0.0, 1.0]
    t0 = p0[1] - p0[0]
    axis = np.cross(t0, [0.2, 1.0, 0.4])  # any axis perpendicular to the start tangent
    q = Rotation.from_rotvec(2.0 * axis / np.linalg.norm(axis))
    c = np.array([0.5, -1.0, 2.0])
    yc = make_yarn_curves(np.stack([p0, q.apply(p0) + c]), [0, len(p0)], curve_type="PL")
    f0, f1 = sweep(yc, spec=LIGHT, frame=0), sweep(yc, spec=LIGHT, frame=1)
    np.testing.assert_allclose(f1.points, q.apply(f0.points) + c, rtol=0, atol=1e-12)


def test_rmf_has_no_twist_on_a_planar_curve():
    t = np.linspace(0, 3, 300)
    xyz = np.stack([t, 0.5 * np.sin(2 * t), 0 * t], axis=1)
    sigma = np.concatenate([[0], np.cumsum(np.linalg.norm(np.diff(xyz, axis=0), axis=1))])
    tt, n, _ = curve_frames(xyz, sigma, False)
    assert np.abs(n[:, 2]).max() < 1e-12  # the normal stays in the plane: the binormal is ±z throughout
    np.testing.assert_allclose(np.cross(tt, n)[:, 2], np.cross(tt, n)[0, 2], atol=1e-12)
    _, n_z, _ = curve_frames(xyz, sigma, False, np.array([0.0, 0.0, 1.0]))
    np.testing.assert_allclose(n_z, np.broadcast_to([0.0, 0.0, 1.0], n_z.shape), atol=1e-12)


def test_rmf_on_a_helix_turns_against_frenet_at_the_torsion_rate_without_flips():
    a, b = 1.0, 0.3
    c = np.hypot(a, b)
    t = np.linspace(0, 4 * np.pi, 2001)
    xyz, s = np.stack([a * np.cos(t), a * np.sin(t), b * t], axis=1), c * t
    tt, n, _ = curve_frames(xyz, s, False)
    assert (n[1:] * n[:-1]).sum(axis=1).min() > 0.9999  # continuous: ≤ 0.8° per step, no flip
    frenet_t = np.stack([-a * np.sin(t), a * np.cos(t), b + 0 * t], axis=1) / c
    frenet_n = np.stack([-np.cos(t), -np.sin(t), 0 * t], axis=1)
    frenet_b = np.cross(frenet_t, frenet_n)
    theta = np.unwrap(np.arctan2((n * frenet_b).sum(1), (n * frenet_n).sum(1)))
    tau = b / (a * a + b * b)  # Bishop frame: θ' = −τ relative to Frenet
    np.testing.assert_allclose(theta - theta[0], -tau * s, atol=1e-4)


def test_stretched_curve_keeps_fibers_at_their_rest_arc_length():
    z = np.linspace(0.0, 1.0, 21)
    p0 = np.stack([0 * z, 0 * z, z], axis=1)
    p1 = p0.copy()
    p1[10:, 2] = 0.5 + 3.0 * (z[10:] - 0.5)  # first half unchanged, second half stretched 3x
    yc = make_yarn_curves(np.stack([p0, p1, 2 * p0]), [0, 21], curve_type="PL")
    f0, f1, f2 = (sweep(yc, spec=LIGHT, frame=k, flyaways=False) for k in range(3))
    z0 = f0.points[:, 2]
    np.testing.assert_allclose(f1.points[:, 2], np.where(z0 <= 0.5, z0, 0.5 + 3 * (z0 - 0.5)), atol=1e-12)
    np.testing.assert_allclose(f2.points[:, 2], 2 * z0, atol=1e-12)
    for f in (f1, f2):
        np.testing.assert_allclose(f.points[:, :2], f0.points[:, :2], atol=1e-12)  # same twist at the same σ


def test_curved_curve_scaled_2x_keeps_fibers_at_the_same_arc_length_coordinate():
    phi = np.linspace(0.0, 2.0, 401)  # arc of a circle of radius 0.6 in the xy plane; frame 1 twice as large
    p0 = 0.6 * np.stack([np.cos(phi), np.sin(phi), 0 * phi], axis=1)
    yc = make_yarn_curves(np.stack([p0, 2 * p0]), [0, len(phi)], curve_type="PL")
    f0, f1 = (sweep(yc, spec=LIGHT, frame=k, flyaways=False) for k in range(2))
    angle = [np.arctan2(f.points[:, 1], f.points[:, 0]) for f in (f0, f1)]  # arc-length coordinate / radius
    # exact up to the one-sided end tangents: a chord is off the arc's tangent by half its angle (0.0025 rad), which
    # tilts the end cross-sections and moves their points by ≤ 0.0025 · yarn radius / arc radius ≈ 1.2e-4 rad
    np.testing.assert_allclose(angle[1], angle[0], atol=1.5e-4)
    inner = (angle[0] > 0.01) & (angle[0] < 1.99)
    np.testing.assert_allclose(angle[1][inner], angle[0][inner], atol=1e-6)
    offset = [np.hypot(np.linalg.norm(f.points[:, :2], axis=1) - r, f.points[:, 2]) for f, r in ((f0, .6), (f1, 1.2))]
    # distance from the centre line kept, up to the chords' sag below the arc: 1.2 · (0.0025)² / 2 ≈ 4e-6
    np.testing.assert_allclose(offset[1], offset[0], atol=5e-6)


def closed_curve(kind, n=256):
    t = 2 * np.pi * np.arange(n) / n
    if kind == "circle":
        pts = 0.3 * np.stack([np.cos(t), np.sin(t), 0 * t], axis=1)
    else:  # trefoil knot: frame holonomy −2.2 rad
        pts = 0.12 * np.stack([np.sin(t) + 2 * np.sin(2 * t), np.cos(t) - 2 * np.cos(2 * t), -np.sin(3 * t)], axis=1)
    return make_yarn_curves(pts, [0, n], closed=[True], curve_type="C0")


@pytest.mark.parametrize("kind", ["circle", "trefoil"])
def test_closed_curve_sweep_has_no_seam_gap(kind):
    yc = closed_curve(kind)
    fs = sweep(yc, spec=LIGHT, flyaways=False)
    facts = fs.info["curves"][0]
    assert (abs(facts["holonomy"]) > 2.0) == (kind == "trefoil")
    assert facts["periods"] >= 2 and abs(facts["axial_stretch"] - 1) <= 1 / (2 * facts["periods"])
    regular = np.flatnonzero(fs.kind == KIND_REGULAR)
    ends = fs.points[fs.offsets[regular + 1] - 1]
    starts = fs.points[fs.offsets[regular]]
    gap = np.linalg.norm(ends - starts[facts["seam_successor"]], axis=1).max()
    assert gap < 1e-6 * LIGHT.radius
    seg = np.linalg.norm(np.diff(fs.fiber(0), axis=0), axis=1)
    assert seg.max() < 3 * np.median(seg)  # no jump inside a fiber either
    xyz, sigma = dense_curve(yc, 0, 0)
    _, n, _ = curve_frames(xyz, sigma, True)
    np.testing.assert_allclose(n[-1], n[0], atol=1e-12)
    assert (n[1:] * n[:-1]).sum(axis=1).min() > 0.99  # the holonomy is spread, not a kink


def test_deterministic_and_seeded_per_curve():
    yc = make_yarn_curves(np.concatenate([line([0, 0, 1]).points[0], line([0, 0, 1], (1, 0, 0)).points[0]]),
                          [0, 11, 22], curve_type="PL")
    a, b, c = sweep(yc, spec=LIGHT, seed=1), sweep(yc, spec=LIGHT, seed=1), sweep(yc, spec=LIGHT, seed=2)
    np.testing.assert_array_equal(a.points, b.points)
    assert a.points.shape != c.points.shape or not np.array_equal(a.points, c.points)
    r0, r1 = (a.info["curves"][i]["fibers"] for i in range(2))
    first = a.points[a.offsets[r0[0]]:a.offsets[r0[0] + 1]]
    second = a.points[a.offsets[r1[0]]:a.offsets[r1[0] + 1]] - [1.0, 0.0, 0.0]
    assert first.shape != second.shape or not np.allclose(first, second)  # identical curves, different fibers
    assert curve_seed(1, 0) != curve_seed(1, 1) and curve_seed(1, 0) == curve_seed(1, 0)


def test_missing_yarn_type_and_bad_frame_are_clear_errors():
    yc = line([0, 0, 1])
    with pytest.raises(ValueError, match="no yarn spec or radius for yarn type 0"):
        sweep_fibers(yc, 0, {}, {}, 0)
    with pytest.raises(ValueError, match="frame = 3"):
        sweep(yc, frame=3)


@pytest.mark.parametrize("curve_type, closed", [(t, c) for t in ("PL", "C0", "BS", "BZ") for c in (False, True)])
def test_dense_curve_keeps_rest_arclength_at_control_points(curve_type, closed):
    rng = np.random.default_rng(3)
    pts = rng.normal(size=(9 if closed else 10, 3))
    yc = make_yarn_curves(pts, [0, len(pts)], closed=[closed], curve_type=curve_type)
    xyz, sigma = dense_curve(yc, 0, 0, samples_per_segment=6)
    assert np.isfinite(xyz).all() and (np.diff(sigma) >= 0).all()
    assert sigma[0] == 0 and sigma[-1] == pytest.approx(rest_length(yc, 0))
    on_curve = np.arange(0, len(pts) + closed, 3 if curve_type == "BZ" else 1)
    np.testing.assert_allclose(sigma[::6], np.append(yc.rest_arclength, rest_length(yc, 0))[on_curve])
    if curve_type in ("PL", "C0", "BZ"):  # interpolating types pass through their on-curve control points
        np.testing.assert_allclose(xyz[::6], np.concatenate([pts, pts[:1]])[on_curve], atol=1e-12)
    if closed:
        np.testing.assert_array_equal(xyz[-1], xyz[0])
    else:  # open B-spline with phantom end points interpolates its ends
        np.testing.assert_allclose(evaluate(pts, False, "BS", 4)[[0, -1]], pts[[0, -1]], atol=1e-12)


def subdivide(p, sub=8):
    """Polyline p with every segment cut into ``sub`` (closest distances then err by ≤ chord / sub)."""
    fine = p[:-1, None] + np.linspace(0, 1, sub, endpoint=False)[:, None] * np.diff(p, axis=0)[:, None]
    return np.concatenate([fine.reshape(-1, 3), p[-1:]])


def test_stockinette_rows_interloop_without_interpenetration():
    radius, sps = 0.03, 48
    yc = stockinette_curves(4, 4, radius)
    assert yc.points.shape == (1, 4 * (4 * sps + 1), 3) and np.isfinite(yc.points).all()
    assert yc.curve_type == "PL" and not yc.closed.any() and yc.yarn_types == ["cotton1"]
    rows = [subdivide(yc.points[0, yc.offsets[i]:yc.offsets[i + 1]]) for i in range(4)]
    between = min(cKDTree(rows[j]).query(rows[i])[0].min() for i in range(4) for j in range(i + 1, 4))
    pairs = cKDTree(rows[0]).query_pairs(3 * radius, output_type="ndarray")
    apart = np.abs(pairs[:, 0] - pairs[:, 1]) > 8 * sps // 3  # more than a third of a stitch apart along the row
    within = np.linalg.norm(rows[0][pairs[apart, 0]] - rows[0][pairs[apart, 1]], axis=1).min()
    print(f"stockinette closest approach: rows {between / radius:.3f} r, within a row {within / radius:.3f} r")
    assert 1.85 * radius < between < 2.1 * radius and within > 1.85 * radius
    assert np.ptp(rows[0][:, 2]) == pytest.approx(2 * radius / 0.8)  # depth 2·d·s
    assert rows[1][0, 1] - rows[0][0, 1] == pytest.approx(4.5 * radius / 0.8)  # row spacing w·s
    # interlooping: where row 0 peaks (its head, at the back, −z) row 1 passes in front (its legs, +z)
    head = rows[0][np.argmax(rows[0][:, 1])]
    near = rows[1][np.argmin(np.linalg.norm(rows[1][:, :2] - head[:2], axis=1))]
    assert head[2] < 0 < near[2]


def test_stockinette_sweep_and_example_file(tmp_path):
    fs = sweep_fibers(stockinette_curves(2, 1), 0, {0: LIGHT}, {0: 0.03}, seed=0)
    assert np.isfinite(fs.points).all() and fs.n_fibers > 2 * 3 * 12
    yc = write_example_patch(tmp_path / "p.h5", 2, 3)
    back = read_yarn_curves(tmp_path / "p.h5")
    np.testing.assert_allclose(back.points, yc.points, rtol=2**-24)
    shipped = read_yarn_curves(PATCH)
    np.testing.assert_allclose(shipped.points, stockinette_curves(6, 6).points, rtol=2**-24, atol=1e-9)


@pytest.mark.parametrize("curve_type", ["C0", "BS"])
def test_rest_coordinate_follows_current_arc_length_inside_a_segment(curve_type):
    z = np.array([0.0, 0.3, 1.0, 1.4, 2.4])  # uneven spacing: the spline's speed varies along each segment
    yc = make_yarn_curves(z[:, None] * [0.0, 0.0, 1.0], [0, 5], curve_type=curve_type)
    xyz, sigma = dense_curve(yc, 0, 0, samples_per_segment=16)
    speed = np.diff(xyz[:, 2])
    assert speed.max() > 2 * speed.min() > 0
    if curve_type == "C0":  # through the control points: rest = control-polygon length = z
        np.testing.assert_allclose(sigma, xyz[:, 2], atol=1e-12)
    else:  # linear in z within every segment, matching the rest coordinates of the control points
        seg = np.repeat(np.arange(4), 16)
        frac = (xyz[:-1, 2] - xyz[seg * 16, 2]) / (xyz[seg * 16 + 16, 2] - xyz[seg * 16, 2])
        np.testing.assert_allclose(sigma[:-1], z[seg] + frac * (z[seg + 1] - z[seg]), atol=1e-12)
