"""Preview image of a yarn's fibers: cross-section and side view, for ``knitbake fibers --preview`` and the demo.

Left panel: the cross-section at z = z_start seen along −z — every fiber's centre where it crosses that plane,
drawn as a disc of the fiber radius (regular fibers grey-blue by ply, flyaways orange), with the outer yarn
radius as a circle. Right panel: an orthographic side view (camera on +x looking at −x, z to the right) ray cast
with Embree against the fibers as round linear curves (``embree_curves``: each polyline swept by a sphere of the
fiber radius), shaded by |n·l| with l toward the camera and up. Both panels share the pixel scale
``pixels_per_unit``. Coordinates and lengths are in the spec's units.
"""

from __future__ import annotations

import numpy as np
from PIL import Image, ImageDraw

from data_formats.atomic import atomic_path
from knitbake.fibers.fiber_set import KIND_REGULAR, FiberSet
from knitbake.trace.embree_curves import CurveScene, closest_hits

PLY_COLOURS = np.array([[110, 140, 200], [120, 190, 150], [200, 150, 120], [170, 130, 200], [200, 200, 120]])
FLYAWAY_COLOUR = (240, 140, 40)
BACKGROUND = (24, 24, 28)


def crossing_points(fibers: FiberSet, z: float):
    """(points (n, 3), fiber index (n,)) where fiber polylines cross the plane z (linear interpolation)."""
    p = fibers.points
    seg_start = np.ones(p.shape[0] - 1, dtype=bool)
    seg_start[fibers.offsets[1:-1] - 1] = False  # no segment joins two fibers
    a, b = p[:-1], p[1:]
    lo, hi = np.minimum(a[:, 2], b[:, 2]), np.maximum(a[:, 2], b[:, 2])
    cross = seg_start & (lo <= z) & (z < hi)
    idx = np.flatnonzero(cross)
    t = (z - a[idx, 2]) / (b[idx, 2] - a[idx, 2])
    pts = a[idx] + t[:, None] * (b[idx] - a[idx])
    fiber = np.searchsorted(fibers.offsets, idx, side="right") - 1
    return pts, fiber


def cross_section_image(fibers: FiberSet, yarn_radius: float, size: int) -> Image.Image:
    img = Image.new("RGB", (size, size), BACKGROUND)
    draw = ImageDraw.Draw(img)
    scale = 0.45 * size / yarn_radius
    cx = cy = size / 2
    draw.ellipse([cx - yarn_radius * scale, cy - yarn_radius * scale, cx + yarn_radius * scale,
                  cy + yarn_radius * scale], outline=(90, 90, 90))
    pts, fib = crossing_points(fibers, fibers.z_start + 1e-9 * yarn_radius)
    for (x, y, _), f in zip(pts, fib):
        r = max(fibers.radius[f] * scale, 1.0)
        colour = (tuple(int(c) for c in PLY_COLOURS[fibers.ply[f] % len(PLY_COLOURS)])
                  if fibers.kind[f] == KIND_REGULAR else FLYAWAY_COLOUR)
        draw.ellipse([cx + x * scale - r, cy - y * scale - r, cx + x * scale + r, cy - y * scale + r], fill=colour)
    return img


def side_view_image(fibers: FiberSet, yarn_radius: float, height: int) -> tuple[Image.Image, dict]:
    """Orthographic side view; returns the image and ray statistics (rays, curve segments, covered fraction)."""
    scene = CurveScene(fibers)
    extent_y = 1.6 * yarn_radius  # half height shown
    length = fibers.z_end - fibers.z_start
    width = max(1, int(round(height * length / (2 * extent_y))))
    ys = extent_y * (1 - 2 * (np.arange(height) + 0.5) / height)
    zs = fibers.z_start + length * (np.arange(width) + 0.5) / width
    yy, zz = np.meshgrid(ys, zs, indexing="ij")
    origins = np.stack([np.full(yy.size, 10 * yarn_radius), yy.ravel(), zz.ravel()], axis=1)
    dirs = np.tile([-1.0, 0.0, 0.0], (yy.size, 1))
    _, segment, normal, _ = closest_hits(scene, origins, dirs)
    hit = segment >= 0
    light = np.array([1.0, 0.6, 0.3]) / np.linalg.norm([1.0, 0.6, 0.3])
    shade = np.abs(normal @ light)
    kind = np.where(hit, fibers.kind[scene.segment_fiber[np.maximum(segment, 0)]], -1)
    base = np.where((kind == KIND_REGULAR)[:, None], [[200, 200, 215]], [FLYAWAY_COLOUR])
    rgb = np.where(hit[:, None], base * (0.25 + 0.75 * shade[:, None]), [BACKGROUND])
    img = Image.fromarray(rgb.reshape(height, width, 3).clip(0, 255).astype(np.uint8))
    stats = {"rays": int(yy.size), "segments": scene.n_segments, "coverage": float(hit.mean())}
    scene.close()
    return img, stats


def preview(fibers: FiberSet, yarn_radius: float, path, height: int = 320) -> dict:
    """Write the two-panel PNG to ``path``; returns ray statistics of the side view."""
    left = cross_section_image(fibers, yarn_radius, height)
    right, stats = side_view_image(fibers, yarn_radius, height)
    img = Image.new("RGB", (left.width + 8 + right.width, height), (0, 0, 0))
    img.paste(left, (0, 0))
    img.paste(right, (left.width + 8, 0))
    with atomic_path(path) as tmp:
        img.save(tmp, format="PNG")
    return stats
