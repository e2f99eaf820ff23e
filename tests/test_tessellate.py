import numpy as np
import pytest
import trimesh

from knitbake.fibers.fiber_set import FiberSet
from knitbake.fibers.tessellate import MERGE_TOL, radial_band, ring_radius_factor, tessellate_fibers, tube_counts


def fiber_set(polylines, radius):
    points = np.concatenate([np.asarray(p, float) for p in polylines])
    offsets = np.concatenate([[0], np.cumsum([len(p) for p in polylines])])
    n = len(polylines)
    return FiberSet(points, offsets, np.broadcast_to(np.asarray(radius, float), (n,)).copy(),
                    np.zeros(n, np.int8), np.zeros(n, np.int16))


def helix(n_points=65, turns=1.0, radius=0.02, pitch=0.3):
    a = np.linspace(0.0, 2.0 * np.pi * turns, n_points)
    return np.c_[radius * np.cos(a), radius * np.sin(a), pitch * a / (2.0 * np.pi)]


def line(start, end, n_points):
    return np.linspace(start, end, n_points)


def fiber_mesh(mesh, f):
    """The tube of fiber f alone, as a trimesh with its own vertex numbering."""
    tris = mesh.triangles[mesh.tri_fiber == f]
    used = np.unique(tris)
    return trimesh.Trimesh(mesh.vertices[used], np.searchsorted(used, tris), process=False)


def distance_to_line(p, a, d):
    d = d / np.linalg.norm(d)
    q = p - a
    return np.linalg.norm(q - np.outer(q @ d, d), axis=1)


@pytest.mark.parametrize("sides", [3, 6, 8])
@pytest.mark.parametrize("caps", [True, False])
def test_counts_and_fiber_index(sides, caps):
    lengths = [2, 5, 17]
    fs = fiber_set([helix(n) for n in lengths], 1e-3)
    mesh = tessellate_fibers(fs, sides=sides, caps=caps)
    per_fiber = [tube_counts(n, sides, caps) for n in lengths]
    assert mesh.vertices.shape == (sum(v for v, _ in per_fiber), 3)
    assert mesh.triangles.shape == (sum(t for _, t in per_fiber), 3)
    assert mesh.vertices.dtype == np.float32 and mesh.triangles.dtype == np.int32 and mesh.tri_fiber.dtype == np.int32
    assert np.array_equal(mesh.tri_fiber, np.repeat(np.arange(3), [t for _, t in per_fiber]))
    v = mesh.vertices.astype(np.float64)[mesh.triangles]
    area = 0.5 * np.linalg.norm(np.cross(v[:, 1] - v[:, 0], v[:, 2] - v[:, 0]), axis=1)
    assert area.min() > 1e-3 * (1e-3) ** 2


@pytest.mark.parametrize("sides", [3, 5, 6, 12])
def test_capped_tubes_are_closed_and_outward(sides):
    fs = fiber_set([helix(40), line([0, 0, 0], [0.1, 0.05, 0.2], 4)], 2e-3)
    mesh = tessellate_fibers(fs, sides=sides)
    for f in range(fs.n_fibers):
        tube = fiber_mesh(mesh, f)
        assert tube.is_watertight and tube.is_winding_consistent
        assert tube.volume > 0  # outward normals
    open_tube = fiber_mesh(tessellate_fibers(fs, sides=sides, caps=False), 0)
    assert not open_tube.is_watertight


@pytest.mark.parametrize("fit", ["inscribed", "perimeter"])
def test_straight_tube_radius(fit):
    sides, r = 6, 1e-3
    direction = np.array([0.3, -0.5, 0.8])
    fs = fiber_set([line([0, 0, 0], [0, 0, 0.05], 6), line([0.1, 0.1, 0], [0.1, 0.1, 0] + 0.05 * direction, 3)], r)
    mesh = tessellate_fibers(fs, sides=sides, fit=fit)
    verts = mesh.vertices.astype(np.float64)
    k = ring_radius_factor(sides, fit)
    assert np.allclose(distance_to_line(verts[:36], np.zeros(3), np.array([0, 0, 1.0])), k * r, rtol=1e-5)
    assert np.allclose(distance_to_line(verts[36:], np.array([0.1, 0.1, 0]), direction), k * r, rtol=1e-4)
    # the polygon's perimeter is the circle's for "perimeter"
    ring = verts[:sides]
    perimeter = np.linalg.norm(ring - np.roll(ring, 1, axis=0), axis=1).sum()
    expected = 2 * np.pi * r if fit == "perimeter" else 2 * sides * r * np.sin(np.pi / sides)
    assert perimeter == pytest.approx(expected, rel=1e-5)


def test_radial_band():
    c = np.cos(np.pi / 6)
    assert radial_band(6, "inscribed") == pytest.approx((c, 1.0))
    lo, hi = radial_band(6, "perimeter")
    assert hi == pytest.approx(np.pi / 6 / np.sin(np.pi / 6)) and lo == pytest.approx(hi * c)
    assert lo < 1.0 < hi


def test_collinear_and_duplicate_points():
    r = 1e-3
    pts = np.array([[0, 0, 0], [0, 0, 0.01], [0, 0, 0.01], [0, 0, 0.02], [0, 0, 0.03], [0, 0, 0.03 + 1e-9]])
    mesh = tessellate_fibers(fiber_set([pts], r), sides=6)
    assert np.all(np.isfinite(mesh.vertices))
    assert mesh.vertices.shape[0] == 4 * 6  # the two near-duplicates merged
    rings = mesh.vertices.reshape(4, 6, 3).astype(np.float64)
    assert np.allclose(rings[:, :, :2], rings[0, :, :2], atol=1e-9)  # no twist along a straight fiber
    assert np.allclose(rings[:, 0, 2], [0, 0.01, 0.02, 0.03 + 1e-9])  # last point kept exactly
    assert fiber_mesh(mesh, 0).is_watertight


def test_helix_frames_do_not_twist_and_keep_radius():
    sides, r = 8, 1e-3
    pts = helix(65, turns=2.0)
    mesh = tessellate_fibers(fiber_set([pts], r), sides=sides, fit="inscribed")
    rings = mesh.vertices.reshape(len(pts), sides, 3).astype(np.float64)
    seg = np.diff(pts, axis=0)
    seg_dir = seg / np.linalg.norm(seg, axis=1, keepdims=True)
    # wall edges between consecutive rings are parallel to their segment: no rotation about the tangent
    edges = rings[1:] - rings[:-1]
    sideways = np.linalg.norm(np.cross(edges, seg_dir[:, None, :]), axis=2)
    assert sideways.max() < 1e-4 * r
    # mitre rings keep the tube radius on both adjacent segments
    for k in range(1, len(pts) - 1):
        for a in (k - 1, k):
            assert np.allclose(distance_to_line(rings[k], pts[a], seg_dir[a]), r, rtol=1e-4)


def test_hairpin_and_sharp_bend_are_finite():
    pts = np.array([[0, 0, 0], [0, 0, 0.01], [0, 0, 0], [0.01, 0, 0.001], [0.01, 0.01, 0.001]])
    mesh = tessellate_fibers(fiber_set([pts], 1e-3))
    assert np.all(np.isfinite(mesh.vertices))
    assert fiber_mesh(mesh, 0).is_watertight


def test_bad_input():
    ok = [line([0, 0, 0], [0, 0, 1], 3), line([1, 0, 0], [1, 0, 1], 3)]
    with pytest.raises(ValueError, match="sides"):
        tessellate_fibers(fiber_set(ok, 1e-3), sides=2)
    with pytest.raises(ValueError, match="sides"):
        tessellate_fibers(fiber_set(ok, 1e-3), sides=6.0)
    with pytest.raises(ValueError, match="fit"):
        tessellate_fibers(fiber_set(ok, 1e-3), fit="outer")
    with pytest.raises(ValueError, match="fiber 1 has radius 0.0"):
        tessellate_fibers(fiber_set(ok, [1e-3, 0.0]))
    with pytest.raises(ValueError, match="fiber 0 has radius nan"):
        tessellate_fibers(fiber_set(ok, [np.nan, 1e-3]))
    bad = [ok[0], ok[1].copy()]
    bad[1][2, 1] = np.inf
    with pytest.raises(ValueError, match="fiber 1 has a non-finite point"):
        tessellate_fibers(fiber_set(bad, 1e-3))
    with pytest.raises(ValueError, match="fiber 1 has 1 points"):
        tessellate_fibers(fiber_set([ok[0], [[0, 0, 0]]], 1e-3))
    with pytest.raises(ValueError, match="fiber 0 has zero length"):
        tessellate_fibers(fiber_set([[[0, 0, 0], [0, 0, 0.1 * MERGE_TOL * 1e-3]], ok[1]], 1e-3))


def test_tri_segment_names_the_nearest_axis_segment():
    """Every triangle's centroid lies within the tube radius of the axis segment tri_segment names."""
    t = np.linspace(0, 4 * np.pi, 40)
    helix = np.c_[0.3 * np.cos(t), 0.3 * np.sin(t), 0.1 * t]
    fibers = FiberSet(np.r_[helix, helix + [1.0, 0, 0]], np.array([0, 40, 80]), np.array([0.02, 0.03]),
                      np.zeros(2, np.int8), np.zeros(2, np.int16))
    mesh = tessellate_fibers(fibers, sides=8)
    centroid = mesh.vertices[mesh.triangles].astype(np.float64).mean(axis=1)
    a = mesh.axis_points[mesh.tri_segment]
    b = mesh.axis_points[mesh.tri_segment + 1]
    s = np.clip(((centroid - a) * (b - a)).sum(1) / ((b - a) ** 2).sum(1), 0, 1)
    dist = np.linalg.norm(centroid - (a + s[:, None] * (b - a)), axis=1)
    assert np.all(dist <= mesh.tube_radius[mesh.tri_fiber] * 1.001)
    assert np.all(np.isin(mesh.tri_segment[mesh.tri_fiber == 1], np.arange(40, 79)))
