"""The hair canopy against the reference's fibers: how much of a directional light other yarns' flyaways keep off the
regular fibers the camera sees, traced, and what ``knitrun.render.hair_canopy`` makes of it (issue 13).

Geometry only, no shading. Per pixel, the camera ray's first regular fiber of the reference's draw (the scene's
fiber seed; flyaways passed through) is a receiver; from it a ray toward the light is traced twice over the
reference's fibers: with only the regular fibers and the receiver's own yarn's flyaways within
``yarn_bounce.REACH_RADII`` radii of rest arc length passed through (its own layer, the lone yarn's), and with every
flyaway blocking but those. The cos-weighted share of the first ray's lit receivers the second leaves lit is the
traced canopy; a third ray, blocked by the regular fibers and that own layer alone, gives the own layer's share
(which the model leaves out: the lone yarn has it too). The model's is the same mean of ``canopy_transmittance`` over the receivers: at the receiver itself
(the model's own geometry), and as the renderer takes it (``pipeline._canopy``: at each polyline point's tube
surface toward the light, interpolated along the curves; here the point nearest the receiver on a polyline of
0.2 radii spacing). The hair shells are the pack's (``hair_shells`` of its flyaway coverage).

    .venv/bin/python benchmarks/probe_hair_canopy.py --pack out/bench/cotton1_standard_56.h5 \\
        [--scenes knit_patch_grazing,knit_patch_directional]
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path
from types import SimpleNamespace

import numpy as np
from scipy.spatial import cKDTree

from data_formats.asset_pack import read_pack
from data_formats.curve_eval import dense_curve
from data_formats.scene import EnvironmentLight, load_scene, read_curves
from knitbake.fibers.fiber_set import KIND_REGULAR
from knitbake.fibers.fiber_sweep import sweep_fibers
from knitbake.trace.embree_curves import CurveScene, closest_hits
from knitbake.trace.path_tracer import camera_rays
from knitbake.trace.reference import _concat, _only_curves
from knitrun.render.camera import scene_camera, tan_half_fov
from knitrun.render.hair_canopy import canopy_grid, canopy_transmittance, hair_shells
from knitrun.render.strip_raster import vertex_tangents
from knitrun.render.yarn_bounce import REACH_RADII

sys.path.insert(0, str(Path(__file__).resolve().parent))
from probe_regions import PATCH_BOXES, parse_box  # noqa: E402

ROOT = Path(__file__).resolve().parent.parent
SPACING_RADII = 0.2  # the dense polylines' spacing


def dense_polylines(scene, radius):
    """(points (P, 3), curve (P,), rest arc length (P,), offsets) of the scene's curves at SPACING_RADII radii."""
    curves = read_curves(scene.yarns[0].curves, scene.units)
    points, curve, arc = [], [], []
    for c in range(len(curves.offsets) - 1):
        xyz, s = dense_curve(curves, c, scene.render.frame)
        at = np.arange(s[0], s[-1], SPACING_RADII * radius)
        points.append(np.stack([np.interp(at, s, xyz[:, k]) for k in range(3)], axis=1))
        curve.append(np.full(len(at), c))
        arc.append(at)
    offsets = np.concatenate([[0], np.cumsum([len(a) for a in arc])]).astype(np.int64)
    return np.concatenate(points), np.concatenate(curve), np.concatenate(arc), offsets


def first_hits(scene_curves, segment_fiber, origins, directions, passes):
    """First hit of each ray that ``passes(fiber, ray, hit point)`` does not pass through: (t, fiber; −1 none)."""
    n = len(origins)
    t_total, fiber = np.zeros(n), np.full(n, -1)
    live, at = np.arange(n), origins.copy()
    for _ in range(100):
        if len(live) == 0:
            break
        t, seg, _, _ = closest_hits(scene_curves, at[live], directions[live])
        hit = seg >= 0
        t_total[live[~hit]] = np.inf
        live, t = live[hit], t[hit]
        f = segment_fiber[seg[hit]]
        through = passes(f, live, at[live] + directions[live] * t[:, None])
        stop = live[~through]
        t_total[stop] += t[~through]
        fiber[stop] = f[~through]
        step = t[through] + 1e-4
        live = live[through]
        t_total[live] += step
        at[live] += directions[live] * step[:, None]
    return t_total, fiber


def reference_fibers(scene):
    """(fibers, their ``CurveScene``) of the reference's draw of ``scene`` (its fiber seed and frame; one yarn entry,
    as the example scenes have)."""
    if len(scene.yarns) != 1:
        raise SystemExit(f"{scene.name}: one yarn entry expected")
    entry = scene.yarns[0]
    curves = read_curves(entry.curves, scene.units)
    drawn = _only_curves(curves, np.isin(curves.yarn_type, entry.yarn_type_indices))
    fibers = _concat([sweep_fibers(drawn, scene.render.frame, {i: entry.spec for i in entry.yarn_type_indices},
                                   {i: entry.radius for i in entry.yarn_type_indices}, seed=scene.render.seed)])
    return fibers, CurveScene(fibers)


def probe(name, pack_path):
    scene = load_scene(ROOT / "examples" / "scenes" / f"{name}.toml")
    radius = scene.yarns[0].radius
    fibers, scene_curves = reference_fibers(scene)
    kind = fibers.kind.copy()
    segment_fiber = scene_curves.segment_fiber
    points, curve, arc, offsets = dense_polylines(scene, radius)
    tree = cKDTree(points)
    camera = scene_camera(scene)
    fwd, right, up = camera.basis()
    n_pix = camera.width * camera.height
    origins, directions = np.empty((n_pix, 3)), np.empty((n_pix, 3))
    camera_rays(np.asarray(camera.position, float), fwd, right, up, camera.width, camera.height,
                tan_half_fov(camera), float(camera.ortho_height), 0, 0, 1, origins, directions)
    t, fiber = first_hits(scene_curves, segment_fiber, origins, directions, lambda f, i, p: kind[f] != KIND_REGULAR)
    seen = np.flatnonzero(fiber >= 0)
    # the receiver: the hit point's nearest dense polyline point gives its curve and rest arc length; its normal
    # is the direction from that axis point
    receiver = origins[seen] + directions[seen] * t[seen, None]
    _, near = tree.query(receiver)
    normal = receiver - points[near]
    normal /= np.linalg.norm(normal, axis=1, keepdims=True)
    lights = [light for light in scene.lights if not isinstance(light, EnvironmentLight)]
    if not lights:
        raise SystemExit(f"{name}: no directional light")
    light = np.asarray(lights[0].unit_direction, np.float64)
    start = receiver + normal * 2e-4
    toward = np.broadcast_to(light, start.shape).copy()

    def own_layer(f, i, p):
        _, nb = tree.query(p)
        return (kind[f] != KIND_REGULAR) & (curve[nb] == curve[near[i]]) & \
            (np.abs(arc[nb] - arc[near[i]]) < REACH_RADII * radius)

    lit_bodies = first_hits(scene_curves, segment_fiber, start, toward, lambda f, i, p: kind[f] != KIND_REGULAR)[1] < 0
    lit_all = first_hits(scene_curves, segment_fiber, start, toward, own_layer)[1] < 0
    lit_own = first_hits(scene_curves, segment_fiber, start, toward,
                         lambda f, i, p: (kind[f] != KIND_REGULAR) & ~own_layer(f, i, p))[1] < 0
    pack = read_pack(pack_path)
    fly = pack.info["textures/flyaway/mip0"]
    shells = hair_shells(np.asarray(pack.mip_chain("textures/flyaway")[0])[..., 3].mean(axis=(0, 2)),
                         fly.attrs["half_width"] / pack.info["textures/coverage/mip0"].attrs["half_width"])
    lines = SimpleNamespace(points=points, offsets=offsets, rest=arc)
    grid = canopy_grid(lines, np.full(len(offsets) - 1, radius), [shells] * (len(offsets) - 1), light)
    at_receiver = canopy_transmittance(grid, receiver, curve[near], arc[near])
    tangent = vertex_tangents(points, offsets)
    across = light - (tangent @ light)[:, None] * tangent
    across /= np.maximum(np.linalg.norm(across, axis=1, keepdims=True), 1e-12)
    at_polyline = canopy_transmittance(grid, points + across * radius, curve, arc)[near]
    cos = np.clip(np.einsum("ij,j->i", normal, light), 0.0, None)
    rows, cols = seen // camera.width, seen % camera.width
    boxes = [("all", (0, camera.height, 0, camera.width))] + \
        ([parse_box(b) for b in PATCH_BOXES] if (camera.height, camera.width) == (512, 512) else [])
    print(f"\n{name}: light {np.round(light, 3).tolist()}, {len(seen)} receivers\n")
    print("| box | lit by the bodies (cos-weighted) | own layer, traced | traced canopy | model at the receivers | "
          "model as rendered |")
    print("|---|---|---|---|---|---|")
    for box, (y0, y1, x0, x1) in boxes:
        m = (rows >= y0) & (rows < y1) & (cols >= x0) & (cols < x1)
        base = float((cos * lit_bodies)[m].sum())
        if base <= 0.0:
            print(f"| {box} | no lit receiver | | | | |")
            continue
        print(f"| {box} | {base / max(float(cos[m].sum()), 1e-12):.3f} | {(cos * lit_own)[m].sum() / base:.3f} | "
              f"{(cos * lit_all)[m].sum() / base:.3f} | "
              f"{(cos * lit_bodies * at_receiver)[m].sum() / base:.3f} | "
              f"{(cos * lit_bodies * at_polyline)[m].sum() / base:.3f} |")


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--pack", required=True, help="the asset pack of cotton1 (its flyaway coverage)")
    parser.add_argument("--scenes", default="knit_patch_grazing,knit_patch_directional",
                        help="comma-separated example scene names with a directional light")
    args = parser.parse_args(argv)
    for name in [s for s in args.scenes.split(",") if s]:
        probe(name, args.pack)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
