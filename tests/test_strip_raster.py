"""Strip rasterizer: analytic coverage, depth test, perspective-correct arc length, v across the strip, MSAA
coverage, crack-free joints, determinism across thread counts, camera projection, and degenerate input."""

import numba
import numpy as np
import pytest

from knitrun.render.camera import Camera, project, tan_half_fov
from knitrun.render.strip_raster import (SAMPLE_PATTERNS, rasterize_before, rasterize_behind, rasterize_depth,
                                         rasterize_strips, rasterize_visibility, sample_attributes)

Z_UP = np.array([0.0, 0.0, 1.0])
Y_UP = np.array([0.0, 1.0, 0.0])


def ortho_camera(width=64, height=48, view_height=4.0, distance=5.0):
    """Orthographic camera looking down −z at the origin: 1 px = view_height / height scene units, +y up."""
    return Camera(np.array([0.0, 0.0, distance]), np.zeros(3), Y_UP, width, height, ortho_height=view_height)


def single(points, camera, radius=0.25, rest=None, msaa=1, **kw):
    points = np.asarray(points, float)
    if rest is None:
        rest = np.concatenate([[0.0], np.cumsum(np.linalg.norm(np.diff(points, axis=0), axis=1))])
    return rasterize_strips(points, [0, len(points)], [False], rest, radius, [7], camera, msaa=msaa, **kw)


def finite(g):
    return all(np.isfinite(a).all() for a in (g.depth, g.arclength, g.v, g.tangent))


def test_straight_strip_area_matches_analytic():
    cam = ortho_camera()
    px = cam.ortho_height / cam.height
    a, b = np.array([-1.23, -0.31, 0.2]), np.array([1.41, 0.52, -0.4])
    radius = 0.17
    g = single([a, b], cam, radius=radius, msaa=4)
    length_px = np.linalg.norm((b - a)[:2]) / px  # the camera looks along z: the visible length
    area_px = 2 * radius / px * length_px
    assert abs(g.coverage.mean(axis=2).sum() - area_px) < length_px / 4  # well within one pixel row
    assert np.all(g.yarn[g.coverage] == 7) and np.all(g.curve[g.coverage] == 0) and np.all(g.segment[g.coverage] == 0)
    assert np.all(g.curve[~g.coverage] == -1) and np.all(g.depth[~g.coverage] == 0)
    t = (b - a) / np.linalg.norm(b - a)
    assert np.allclose(g.tangent[g.coverage], t, atol=1e-6)


def test_depth_test_keeps_the_nearer_strip_in_any_order():
    cam = Camera(np.array([0.0, 0.0, 6.0]), np.zeros(3), Y_UP, 64, 64, fov_deg=40.0)
    horizontal = [[-1.0, 0.0, 0.3], [1.0, 0.0, 0.3]]  # nearer to the camera
    vertical = [[0.0, -1.0, 0.0], [0.0, 1.0, 0.0]]
    for order in ((horizontal, vertical), (vertical, horizontal)):
        pts = np.array(order[0] + order[1])
        g = rasterize_strips(pts, [0, 2, 4], [False, False], [0, 2.0, 0, 2.0], 0.2, [0, 1], cam, msaa=4)
        near_curve = 0 if order[0] is horizontal else 1
        assert np.all(g.curve[30:34, 30:34] == near_curve)
        assert np.allclose(g.depth[32, 32], 6.0 - 0.3, atol=0.02)
        assert np.all(g.curve[20:24, 31:33] == 1 - near_curve)  # only the vertical strip reaches the top


def test_arclength_is_perspective_correct_and_linear_in_rest_length():
    cam = Camera(np.array([0.3, -0.2, 3.0]), np.zeros(3), Y_UP, 96, 64, fov_deg=50.0)
    a, b = np.array([-1.5, -0.2, -2.0]), np.array([1.5, 0.3, 1.0])  # strongly foreshortened
    g = single([a, b], cam, radius=0.05, rest=[1.0, 7.0], msaa=4)
    fwd, right, up = cam.basis()
    rows, cols, samples = np.nonzero(g.coverage)
    assert len(rows) > 100
    pattern = SAMPLE_PATTERNS[4][samples]
    sx = (2 * (cols + pattern[:, 0]) - cam.width) / cam.height
    sy = 1 - 2 * (rows + pattern[:, 1]) / cam.height
    rays = fwd + tan_half_fov(cam) * (sx[:, None] * right + sy[:, None] * up)
    hits = cam.position + g.depth[rows, cols, samples][:, None] * rays / np.linalg.norm(rays, axis=1, keepdims=True)
    along = (hits - a) @ (b - a) / np.linalg.norm(b - a) ** 2  # 0 at a, 1 at b
    assert np.allclose(g.arclength[rows, cols, samples], 1.0 + 6.0 * along, atol=2e-3)


@pytest.mark.parametrize("k", sorted(SAMPLE_PATTERNS))
def test_v_spans_the_strip_from_minus_b_to_plus_b(k):
    cam = ortho_camera()
    radius = 0.3
    g = single([[-1.0, 0.01, 0.0], [1.0, 0.01, 0.0]], cam, radius=radius, msaa=k)
    # b = ω_o × t = z × x = +y: v = (y − 0.01) / radius at every covered sample, at the pattern's positions.
    rows, cols, samples = np.nonzero(g.coverage)
    assert len(np.unique(samples)) == k
    y = (1 - 2 * (rows + SAMPLE_PATTERNS[k][samples, 1]) / cam.height) * cam.ortho_height / 2
    assert np.allclose(g.v[rows, cols, samples], (y - 0.01) / radius, atol=1e-5)
    reach = 0.95 if k >= 4 else 0.7  # 1 and 2 samples per pixel sit up to half a pixel from a strip edge
    assert g.v[g.coverage].min() < -reach and g.v[g.coverage].max() > reach
    assert np.allclose(g.depth[g.coverage], 5.0)


@pytest.mark.parametrize("x", [32.0, 32.13, 31.77, 10.5])
def test_msaa8_coverage_of_a_half_pixel_strip(x):
    cam = ortho_camera()
    px = cam.ortho_height / cam.height
    wx = (x - cam.width / 2) * px  # a vertical strip centred on screen column x, half a pixel wide
    g = single([[wx, -1.0, 0.0], [wx, 1.0, 0.0]], cam, radius=px / 4, msaa=8)
    rows = g.coverage.any(axis=(1, 2))
    assert rows.sum() >= 20
    per_row = g.coverage.mean(axis=2).sum(axis=1)[rows][1:-1]  # whole rows (the ends are cut across samples)
    assert np.allclose(per_row, 0.5)


def test_joints_have_no_cracks_and_closed_curves_wrap():
    cam = ortho_camera(96, 96, view_height=4.0)
    n = 37
    angle = 2 * np.pi * np.arange(n) / n
    ring = np.stack([1.5 * np.cos(angle), 1.5 * np.sin(angle), 0.2 * np.sin(3 * angle)], axis=1)
    rest = np.concatenate([[0.0], np.cumsum(np.linalg.norm(np.diff(ring, axis=0), axis=1))])
    radius = 0.08  # 1.9 px
    g = rasterize_strips(ring, [0, n], [True], rest, radius, [0], cam, msaa=1)
    assert finite(g)
    # Every pixel centre within radius / 2 of the polyline (closing segment included) is covered.
    ys, xs = np.mgrid[0:96, 0:96] + 0.5
    centres = np.stack([(xs - 48) / 24, (48 - ys) / 24], axis=-1).reshape(-1, 2)
    a, b = ring[:, :2], np.roll(ring, -1, axis=0)[:, :2]
    f = np.clip(np.einsum("psk,sk->ps", centres[:, None] - a, b - a) / ((b - a) ** 2).sum(1), 0, 1)
    dist = np.linalg.norm(centres[:, None] - (a + f[..., None] * (b - a)), axis=2).min(axis=1)
    assert g.coverage[..., 0].reshape(-1)[dist < radius / 2].all()
    closing = g.segment == n - 1
    assert closing.any()
    assert g.arclength[closing].max() > rest[-1] and g.arclength[closing].max() <= rest[-1] + 1.5 * 2 * np.pi / n


def test_deterministic_across_thread_counts():
    cam = Camera(np.array([0.4, 0.3, 2.5]), np.array([0.0, 0.1, 0.0]), Y_UP, 80, 60, fov_deg=45.0)
    rng = np.random.default_rng(3)
    rows = [np.stack([np.linspace(-1, 1, 40), np.full(40, y), 0.1 * np.sin(9 * np.linspace(-1, 1, 40) + y)], 1)
            for y in np.linspace(-0.8, 0.8, 12)]
    pts = np.concatenate(rows) + rng.normal(0, 0.002, (480, 3))
    offsets = 40 * np.arange(13)
    rest = np.tile(np.linspace(0, 2, 40), 12)
    before = numba.get_num_threads()
    results = []
    try:
        for threads in (1, min(2, numba.config.NUMBA_NUM_THREADS)):
            numba.set_num_threads(threads)
            results.append(rasterize_strips(pts, offsets, np.zeros(12, bool), rest, 0.06, np.arange(12), cam,
                                            msaa=4, tile=16))
    finally:
        numba.set_num_threads(before)
    for field in ("coverage", "depth", "curve", "yarn", "segment", "arclength", "v", "tangent"):
        assert np.array_equal(getattr(results[0], field), getattr(results[1], field)), field
    assert results[0].coverage.mean() > 0.2


@pytest.mark.parametrize("ortho", [False, True])
def test_depth_alone_is_the_g_buffers_depth_and_a_reused_depth_map_is_overwritten(ortho):
    """``rasterize_depth`` (shadow maps) writes the G-buffer's msaa-1 depth bit for bit and +inf where no strip is;
    drawing another scene into the depth map of a previous one (``out``) gives what a fresh map gives."""
    cam = ortho_camera(80, 60) if ortho else Camera(np.array([0.4, 0.3, 2.5]), np.array([0.0, 0.1, 0.0]), Y_UP, 80,
                                                   60, fov_deg=45.0)
    xs = np.linspace(-1, 1, 30)
    scenes = [(np.stack([xs, np.full(30, y), 0.2 * np.sin(7 * xs + y)], 1), 0.15) for y in (-0.5, 0.0, 0.4)]
    scenes.append((np.stack([np.full(30, 0.3), xs, 0.1 * xs], 1), 0.3))
    depth_out = None
    for pts, radius in scenes:
        rest = np.linspace(0, 2, 30)
        g = rasterize_strips(pts, [0, 30], [False], rest, radius, [0], cam)
        depth = rasterize_depth(pts, [0, 30], [False], rest, radius, cam)
        assert depth.dtype == np.float32 and depth.shape == (60, 80)
        assert np.array_equal(depth, np.where(g.coverage[:, :, 0], g.depth[:, :, 0], np.float32(np.inf)))
        assert np.isfinite(depth).any() and not np.isfinite(depth).all()
        depth_out = rasterize_depth(pts, [0, 30], [False], rest, radius, cam, out=depth_out)
        assert np.array_equal(depth_out, depth)


@pytest.mark.parametrize("ortho", [False, True])
def test_attributes_of_some_samples_of_the_visibility_buffer_are_the_g_buffers(ortho):
    """The renderer's path (``rasterize_visibility``, then ``sample_attributes`` at a few samples) gives the
    G-buffer's attributes bit for bit at those samples, whatever samples are asked, and refuses uncovered ones."""
    cam = ortho_camera(80, 60) if ortho else Camera(np.array([0.4, 0.3, 2.5]), np.array([0.0, 0.1, 0.0]), Y_UP, 80,
                                                   60, fov_deg=45.0)
    xs = np.linspace(-1, 1, 30)
    pts = np.concatenate([np.stack([xs, np.full(30, y), 0.2 * np.sin(7 * xs + y)], 1) for y in (-0.5, 0.0, 0.4)])
    offsets, rest, yarn = [0, 30, 60, 90], np.tile(np.linspace(0, 2, 30), 3), [3, 1, 2]
    g = rasterize_strips(pts, offsets, False, rest, 0.15, yarn, cam, msaa=4)
    vis = rasterize_visibility(pts, offsets, False, rest, 0.15, yarn, cam, msaa=4)
    assert np.array_equal(vis.coverage, g.coverage) and np.array_equal(vis.curve, g.curve)
    assert np.array_equal(vis.depth, g.depth)
    covered = np.argwhere(g.coverage)
    assert len(covered) > 100 and len(set(g.curve[g.coverage].tolist())) == 3
    rng = np.random.default_rng(5)
    some = covered[rng.choice(len(covered), 50, replace=False)]
    attributes = sample_attributes(vis, *some.T)
    for name in ("yarn", "segment", "arclength", "v", "tangent"):
        expected = getattr(g, name)[tuple(some.T)]
        assert attributes[name].dtype == expected.dtype and np.array_equal(attributes[name], expected), name
    uncovered = np.argwhere(~g.coverage)[:1]
    with pytest.raises(ValueError, match="not covered"):
        sample_attributes(vis, *uncovered.T)


def test_project_matches_the_camera_rays():
    for cam in (Camera(np.array([1.0, 2.0, 3.0]), np.array([0.2, 0.0, -0.5]), Z_UP, 40, 30, fov_deg=35.0),
                Camera(np.array([1.0, 2.0, 3.0]), np.array([0.2, 0.0, -0.5]), Z_UP, 40, 30, ortho_height=2.0)):
        fwd, right, up = cam.basis()
        X, Y, z = np.array([3.25, 20.0, 39.9]), np.array([0.5, 15.0, 29.0]), np.array([0.5, 2.0, 7.0])
        sx, sy = (2 * X - cam.width) / cam.height, 1 - 2 * Y / cam.height
        offset = sx[:, None] * right + sy[:, None] * up
        if cam.ortho_height > 0:
            pts = cam.position + cam.ortho_height / 2 * offset + z[:, None] * fwd
        else:
            pts = cam.position + z[:, None] * (fwd + tan_half_fov(cam) * offset)
        assert np.allclose(np.stack(project(cam, pts)), np.stack([X, Y, z]))


def test_degenerate_input_gives_finite_buffers():
    cam = Camera(np.array([0.0, 0.0, 4.0]), np.zeros(3), Y_UP, 32, 24, fov_deg=40.0)
    empty = rasterize_strips(np.zeros((0, 3)), [0], [], np.zeros(0), [], [], cam, msaa=4)
    assert not empty.coverage.any() and finite(empty) and np.all(empty.segment == -1)
    # Zero-length segments inside a curve are skipped without breaking the strip around them.
    g = single([[-1, 0, 0], [0, 0, 0], [0, 0, 0], [0, 0, 0], [1, 0, 0]], cam)
    assert finite(g) and g.coverage[11:13, 9:23].all() and not np.isin(g.segment[g.coverage], [1, 2]).any()
    # A segment pointing at the camera is skipped; the rest of its curve is drawn.
    g = single([[0, 0, -1.0], [0, 0, 1.0], [1, 0, 1.0]], cam)
    assert finite(g) and g.coverage.any() and not (g.segment == 0).any()
    # A curve through the camera (near-plane clipping): finite, every depth at least the near distance.
    for msaa in (1, 8):
        g = single([[-0.5, -0.3, 3.0], [0.0, 0.0, 4.0], [0.3, 0.2, 5.0], [1.0, 1.0, -2.0]], cam, radius=0.1,
                   msaa=msaa, near=1e-3)
        assert finite(g) and g.coverage.any() and g.depth[g.coverage].min() >= 1e-3
    bad = np.zeros((5, 3))
    bad[3, 1] = np.nan
    with pytest.raises(ValueError, match="curve 1"):
        rasterize_strips(bad, [0, 2, 5], [False, False], np.zeros(5), 0.1, [0, 0], cam)
    with pytest.raises(ValueError, match="msaa"):
        single([[0, 0, 0], [1, 0, 0]], cam, msaa=3)  # 1, 2, 4, 8, 16 are the patterns


def test_frustum_culling_drops_only_invisible_segments():
    cam = ortho_camera()
    x = np.linspace(-40.0, 40.0, 401)  # most segments far outside the 5.3 × 4 view
    g = single(np.stack([x, 0.3 * np.sin(x), np.zeros_like(x)], 1), cam, radius=0.1, msaa=1)
    visible = np.flatnonzero(np.abs(x[:-1]) < 2.8)
    drawn = np.unique(g.segment[g.coverage])
    assert set(drawn) <= set(visible) and len(drawn) >= len(visible) - 2


@pytest.mark.parametrize("ortho", [False, True])
def test_the_k_nearest_strips_before_a_ceiling_come_nearest_first_from_one_depth_test(ortho):
    """``rasterize_before``: at each sample the K nearest strips, nearest first, each with the depth and slot it has
    drawn alone, among those less than the reach behind the strip another buffer has there (anywhere where it has
    none); a strip is counted once at a sample, and the K-th layer is what K rounds of depth peeling find."""
    cam = ortho_camera(64, 64) if ortho else Camera(np.array([0.0, 0.0, 6.0]), np.zeros(3), Y_UP, 64, 64,
                                                    fov_deg=40.0)
    lines = [[[-1.0, 0.0, 0.3], [1.0, 0.0, 0.3]], [[0.0, -1.0, 0.0], [0.0, 1.0, 0.0]],
             [[-1.0, -1.0, -0.5], [1.0, 1.0, -0.5]]]  # horizontal nearest, vertical, diagonal farthest
    pts = np.array([p for line in lines for p in line])
    offsets, rest, radius = [0, 2, 4, 6], np.tile([0.0, 2.0], 3), np.full(3, 0.2)
    wall = [[-2.0, 0.6, -0.25], [2.0, 0.6, -0.25]]  # a wide strip between the vertical and the diagonal strips
    front = rasterize_visibility(np.array(wall), [0, 2], False, [0.0, 4.0], 0.6, [9], cam, msaa=4)
    layers = rasterize_before(pts, offsets, False, rest, radius, [0, 1, 2], cam, front, 0.0, layers=3)
    alone = [rasterize_visibility(pts[2 * c:2 * c + 2], [0, 2], False, rest[:2], 0.2, [c], cam, msaa=4)
             for c in range(3)]
    free = rasterize_visibility(pts, offsets, False, rest, radius, [0, 1, 2], cam, msaa=4)
    peeled = [free, rasterize_behind(free, cam, 1e-4)]  # a gap: the floor from a float32 depth lets a strip in again
    peeled.append(rasterize_behind(peeled[1], cam, 1e-4))
    open_ = ~front.coverage
    for m in range(3):  # where the wall is not: every strip, nearest first, as depth peeling finds them
        assert np.array_equal(layers[m].curve[open_], peeled[m].curve[open_])
        assert np.array_equal(layers[m].depth[open_], peeled[m].depth[open_])
    for c in range(3):
        at = [layers[m].curve == c for m in range(3)]
        assert np.all(sum(a.astype(int) for a in at) <= 1)  # each strip once per sample
        for a, layer in zip(at, layers):
            assert np.array_equal(layer.depth[a], alone[c].depth[a]) and np.array_equal(layer.slot[a] >= 0, a[a])
    behind_wall = front.coverage & alone[2].coverage
    assert behind_wall.sum() > 20
    assert not any(np.any(layer.curve[behind_wall] == 2) for layer in layers)  # beyond the ceiling: dropped
    both = open_ & alone[0].coverage & alone[1].coverage & alone[2].coverage
    assert both.sum() > 4 and np.all(layers[0].curve[both] == 0) and np.all(layers[1].curve[both] == 1) and \
        np.all(layers[2].curve[both] == 2)
    one = rasterize_before(pts, offsets, False, rest, radius, [0, 1, 2], cam, front, 0.0)
    assert len(one) == 1 and np.array_equal(one[0].curve, layers[0].curve)


@pytest.mark.parametrize("ortho", [False, True])
def test_a_peeled_layer_is_the_next_strip_behind_the_front_one(ortho):
    """Depth peeling (``rasterize_behind``): where a strip lies over two others, the peeled layer holds the nearest
    strip more than the gap behind the front one (the same sample's depth the front layer would give that strip
    alone), and nothing where the front layer has no strip; a strip within the gap of the front (its own tube) is
    skipped."""
    cam = ortho_camera(64, 64) if ortho else Camera(np.array([0.0, 0.0, 6.0]), np.zeros(3), Y_UP, 64, 64,
                                                    fov_deg=40.0)
    front = [[-1.0, 0.0, 0.3], [1.0, 0.0, 0.3]]  # horizontal, nearest
    within = [[-1.0, 0.1, 0.25], [1.0, 0.1, 0.25]]  # inside the front yarn's tube (0.05 behind, radius 0.2)
    middle = [[0.0, -1.0, 0.0], [0.0, 1.0, 0.0]]  # vertical
    back = [[-1.0, -1.0, -0.5], [1.0, 1.0, -0.5]]  # diagonal, farthest
    pts = np.array(front + within + middle + back)
    offsets, rest, radius = [0, 2, 4, 6, 8], np.tile([0.0, 2.0], 4), np.full(4, 0.2)
    vis = rasterize_visibility(pts, offsets, False, rest, radius, [0, 1, 2, 3], cam, msaa=4)
    peeled = rasterize_behind(vis, cam, radius)
    alone = {c: rasterize_visibility(pts[2 * c:2 * c + 2], [0, 2], False, rest[:2], 0.2, [c], cam, msaa=4)
             for c in (2, 3)}
    assert np.all(vis.curve[31:33, 31:33] == 0)
    assert np.all(peeled.curve[31:33, 31:33] == 2)  # the middle strip, not the one inside the front tube
    assert np.array_equal(peeled.depth[31:33, 31:33], alone[2].depth[31:33, 31:33])
    assert np.all(peeled.curve[~vis.coverage] == -1)  # nothing behind where nothing is in front
    where = (vis.curve == 2) & alone[3].coverage  # the middle strip over the diagonal one, off the front strip
    assert where.sum() > 20 and np.all(peeled.curve[where] == 3)
    assert np.array_equal(peeled.depth[where], alone[3].depth[where])
    lone = vis.coverage & ~(alone[2].coverage | alone[3].coverage) & (vis.curve != 1)
    assert lone.sum() > 20 and np.all(peeled.curve[lone] == -1)  # the front strip alone: nothing behind it


@pytest.mark.parametrize("ortho", [False, True])
def test_the_depth_maps_second_layer_is_the_peeled_buffers_depth(ortho):
    """``rasterize_depth`` with ``behind_gap`` (shadow maps' second layer) gives, bit for bit, the depth of
    ``rasterize_visibility`` at msaa 1 peeled by ``rasterize_behind`` with that gap per curve, +inf where the peeled
    buffer has no strip; the first map is the one-layer map. The scene of the test above, one curve's gap larger
    than the distance to the strip behind it (so the per-curve gap is read, not the first curve's)."""
    cam = ortho_camera(64, 64) if ortho else Camera(np.array([0.0, 0.0, 6.0]), np.zeros(3), Y_UP, 64, 64,
                                                    fov_deg=40.0)
    pts = np.array([[-1.0, 0.0, 0.3], [1.0, 0.0, 0.3], [-1.0, 0.1, 0.25], [1.0, 0.1, 0.25],
                    [0.0, -1.0, 0.0], [0.0, 1.0, 0.0], [-1.0, -1.0, -0.5], [1.0, 1.0, -0.5]])
    offsets, rest, radius = [0, 2, 4, 6, 8], np.tile([0.0, 2.0], 4), np.full(4, 0.2)
    gap = np.array([0.2, 0.2, 0.6, 0.2])  # behind the vertical strip, the diagonal (0.5 away) is skipped
    front, behind = rasterize_depth(pts, offsets, False, rest, radius, cam, behind_gap=gap)
    vis = rasterize_visibility(pts, offsets, False, rest, radius, 0, cam, msaa=1)
    peeled = rasterize_behind(vis, cam, gap)
    np.testing.assert_array_equal(front, rasterize_depth(pts, offsets, False, rest, radius, cam))
    expected = np.where(peeled.curve[..., 0] >= 0, peeled.depth[..., 0], np.float32(np.inf))
    np.testing.assert_array_equal(behind, expected)
    assert np.isfinite(behind).sum() > 40
    assert np.any(np.isfinite(front) & ~np.isfinite(behind) & (vis.curve[..., 0] == 2))
