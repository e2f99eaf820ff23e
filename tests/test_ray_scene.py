import numpy as np
import pytest

from knitbake.fibers.fiber_set import FiberSet
from knitbake.fibers.tessellate import radial_band, tessellate_fibers
from knitbake.trace.ray_scene import RayScene

SIDES = 6
R = 1e-3
MARGIN = 1e-4  # relative, on the band radii: float32 vertices and grazing rays
LENGTH = 0.04
AXES = [  # (start, unit direction) of the straight test fibers, well apart
    (np.array([0.0, 0.0, 0.0]), np.array([0.0, 0.0, 1.0])),
    (np.array([0.02, 0.01, 0.0]), np.array([0.48, -0.6, 0.64])),
]


def straight_fibers(n_points=9):
    polylines = [a + np.outer(np.linspace(0, LENGTH, n_points), d) for a, d in AXES]
    n = len(polylines)
    return FiberSet(np.concatenate(polylines), np.arange(n + 1) * n_points, np.full(n, R),
                    np.zeros(n, np.int8), np.zeros(n, np.int16))


@pytest.fixture(scope="module")
def scene():
    return RayScene(tessellate_fibers(straight_fibers(), sides=SIDES))


def cylinder_hits(o, d, a, axis, radius):
    """Entry and exit distances of unit rays (o, d) with the infinite cylinder (a, unit axis, radius); nan if none.
    Also the axial coordinates of both points."""
    q = o - a
    dp = d - np.outer(d @ axis, axis)
    qp = q - np.outer(q @ axis, axis)
    A, B, C = (dp * dp).sum(1), 2 * (dp * qp).sum(1), (qp * qp).sum(1) - radius**2
    disc = B * B - 4 * A * C
    root = np.sqrt(np.where(disc >= 0, disc, np.nan))
    t0, t1 = (-B - root) / (2 * A), (-B + root) / (2 * A)
    return t0, t1, q @ axis + t0 * (d @ axis), q @ axis + t1 * (d @ axis)


def aimed_rays(rng, n, a, axis, spread):
    """Rays from random points around a fiber, aimed at its middle part with a lateral offset up to spread."""
    target = a + np.outer(rng.uniform(0.3, 0.7, n) * LENGTH, axis)
    jitter = rng.uniform(-1, 1, (n, 3))
    target += spread * (jitter - np.outer(jitter @ axis, axis))
    d = rng.normal(size=(n, 3))
    d /= np.linalg.norm(d, axis=1, keepdims=True)
    return target - 0.01 * d, d


def in_middle(*axial):
    return np.all([(s > 0.05 * LENGTH) & (s < 0.95 * LENGTH) for s in axial], axis=0)


@pytest.mark.parametrize("f", [0, 1])
def test_hits_within_tessellation_band(scene, f):
    rng = np.random.default_rng(f)
    a, axis = AXES[f]
    lo, hi = np.array(radial_band(SIDES)) * (1 - MARGIN, 1 + MARGIN)
    o, d = aimed_rays(rng, 20000, a, axis, 1.5 * R)
    hits = scene.intersect(o, d)
    in_lo, _, s_lo, _ = cylinder_hits(o, d, a, axis, lo * R)
    in_hi, _, s_hi, _ = cylinder_hits(o, d, a, axis, hi * R)
    other_axes = [g for i, g in enumerate(AXES) if i != f]
    clear = ~np.any([cylinder_hits(o, d, b, b_axis, hi * R)[1] > 0 for b, b_axis in other_axes], axis=0)
    sure_hit = (in_hi > 0) & np.isfinite(in_lo) & in_middle(s_lo, s_hi) & clear
    sure_miss = np.isnan(in_hi) & clear
    assert sure_hit.sum() > 3000 and sure_miss.sum() > 3000
    assert np.all(hits.hit[sure_hit]) and np.all(hits.fiber[sure_hit] == f)
    assert not np.any(hits.hit[sure_miss])
    t = hits.t[sure_hit]
    assert np.all(t >= in_hi[sure_hit]) and np.all(t <= in_lo[sure_hit])
    # geometric normal within pi / sides of the radial direction at the hit
    p = o[sure_hit] + t[:, None] * d[sure_hit]
    radial = (p - a) - np.outer((p - a) @ axis, axis)
    radial /= np.linalg.norm(radial, axis=1, keepdims=True)
    cos = (hits.normal[sure_hit] * radial).sum(1)
    assert cos.min() > np.cos(np.pi / SIDES) - 1e-4
    assert np.allclose(np.linalg.norm(hits.normal[sure_hit], axis=1), 1.0)
    assert np.all(hits.u[sure_hit] >= 0) and np.all(hits.u[sure_hit] + hits.v[sure_hit] <= 1 + 1e-6)


def test_rays_from_inside_bounding_box(scene):
    """Origins anywhere in the bounding box of fiber 0, inside or outside the tube."""
    rng = np.random.default_rng(7)
    a, axis = AXES[0]
    lo, hi = np.array(radial_band(SIDES)) * (1 - MARGIN, 1 + MARGIN)
    n = 20000
    o = np.c_[rng.uniform(-1.2 * R, 1.2 * R, (n, 2)), rng.uniform(0.2, 0.8, n) * LENGTH]
    d = rng.normal(size=(n, 3))
    d /= np.linalg.norm(d, axis=1, keepdims=True)
    hits = scene.intersect(o, d)
    rho = np.linalg.norm(o[:, :2], axis=1)
    in_lo, out_lo, s_in_lo, s_out_lo = cylinder_hits(o, d, a, axis, lo * R)
    in_hi, out_hi, s_in_hi, s_out_hi = cylinder_hits(o, d, a, axis, hi * R)
    inside = (rho < lo * R) & in_middle(s_out_lo, s_out_hi)
    outside = (rho > hi * R) & np.isfinite(in_lo) & (in_lo > 0) & in_middle(s_in_lo, s_in_hi)
    assert inside.sum() > 1000 and outside.sum() > 1000
    assert np.all(hits.hit[inside | outside])
    assert np.all(hits.t[inside] >= out_lo[inside]) and np.all(hits.t[inside] <= out_hi[inside])
    assert np.all(hits.t[outside] >= in_hi[outside]) and np.all(hits.t[outside] <= in_lo[outside])
    # leaving the tube from inside, the outward normal faces along the ray
    assert np.all((hits.normal[inside] * d[inside]).sum(1) > 0)


def test_distances_ignore_direction_length_and_eps(scene):
    rng = np.random.default_rng(3)
    o, d = aimed_rays(rng, 2000, *AXES[0], 0.5 * R)
    unit = scene.intersect(o, d)
    scaled = scene.intersect(o, 7.5 * d)
    assert np.array_equal(unit.prim, scaled.prim)
    assert np.allclose(unit.t[unit.hit], scaled.t[unit.hit], rtol=1e-6)
    # a ray starting on the surface and leaving it does not hit its own triangle
    h = unit.hit
    p = o[h] + unit.t[h, None] * d[h]
    again = scene.intersect(p, unit.normal[h] + 0.3 * d[h])
    assert not np.any(again.prim == unit.prim[h])
    assert np.all(again.t[again.hit] > scene.eps)


def test_occluded_matches_intersect(scene):
    rng = np.random.default_rng(4)
    o, d = aimed_rays(rng, 5000, *AXES[1], 2 * R)
    hits = scene.intersect(o, d)
    t = np.where(hits.hit, hits.t, 0.01)
    assert np.array_equal(scene.occluded(o, d, np.inf), hits.hit)
    assert np.array_equal(scene.occluded(o, d, 1.01 * t), hits.hit)
    assert not np.any(scene.occluded(o, d, 0.99 * t))
    short = scene.intersect(o, d, tmax=0.99 * t)
    assert not np.any(short.hit) and np.all(np.isinf(short.t)) and np.all(short.fiber == -1)


def test_thread_count_does_not_change_results():
    mesh = tessellate_fibers(straight_fibers())
    rng = np.random.default_rng(5)
    o, d = aimed_rays(rng, 30000, *AXES[0], 2 * R)
    one = RayScene(mesh, threads=1, chunk=1000)
    two = RayScene(mesh, threads=2, chunk=1000)
    h1, h2 = one.intersect(o, d), two.intersect(o, d)
    for name in ("t", "prim", "fiber", "normal", "u", "v"):
        assert np.array_equal(getattr(h1, name), getattr(h2, name))
    assert np.array_equal(one.occluded(o, d, 0.02), two.occluded(o, d, 0.02))


def test_bad_input(scene):
    o, d = np.zeros((4, 3)), np.ones((4, 3))
    with pytest.raises(ValueError, match="shape"):
        scene.intersect(o, d[:3])
    with pytest.raises(ValueError, match="shape"):
        scene.intersect(o[:, :2], d[:, :2])
    bad = o.copy()
    bad[2, 1] = np.nan
    with pytest.raises(ValueError, match=r"origins\[2\]"):
        scene.intersect(bad, d)
    zero = d.copy()
    zero[3] = 0
    with pytest.raises(ValueError, match=r"directions\[3\] is zero"):
        scene.intersect(o, zero)
    with pytest.raises(ValueError, match="tmax"):
        scene.occluded(o, d, -1.0)
    with pytest.raises(ValueError, match="tmax"):
        scene.occluded(o, d, np.ones(3))
    with pytest.raises(ValueError, match="numeric"):
        scene.intersect("abc", d)
    mesh = tessellate_fibers(straight_fibers())
    with pytest.raises(ValueError, match="eps"):
        RayScene(mesh, eps=0.0)
    mesh.triangles = mesh.triangles[:0]
    with pytest.raises(ValueError, match="no triangles"):
        RayScene(mesh)
