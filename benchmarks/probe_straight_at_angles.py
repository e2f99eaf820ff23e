"""A scene's yarn against the bake's straight yarn at the same local angles (issue 13, stop 66): is a knitted yarn's
light what the straight yarn of the bake sends at each point's (v, θ_i, θ_o, φ), or something the straight yarn has
not got?

The closure stage stores what it closes on: ``correction/radiance_view`` and ``_ss``, the path-traced mean radiance
per unit irradiance of the bake's straight yarn per bin (v, θ_i, θ_o, φ), whole and of one scattering event
(ASSET_PACK.md §6). For every front shading point of the strips (``strip_shading.shading_points``), this takes the
point's yarn angles against the scene's one directional light (SHADING.md §3: t the yarn tangent, n the view's
direction in the normal plane, b = n × t, φ = −atan2(ω_i·b, ω_i·n)), looks both tables up there (quadrilinear, φ
repeated, the others clamped, as the renderer reads ξ), times E, and sums them into pixels with the points' MSAA
weights: the image the straight yarn predicts. Beside it, the scene's reference and a second fiber instance (traced
whole and with one event, as ``probe_split.py``) and the strips of the full model: totals (luminance) of the whole,
SS and MS = whole − SS over the reference's; each image's yarn-scale rel L1 against the reference (luminance, filtered
to the projected yarn diameter) over the second instance's, whole, SS and MS, as drawn and with its total scaled to
the reference's (where the light lies, apart from how much there is: a table indexed by (v, θ_i, θ_o, φ) alone places
nothing along the yarn's ply pattern); then per bin of the front point's v and |θ_o| (each pixel takes the angles of
its heaviest point).

The yarns are drawn white (``color`` 1: the tables are the uncoloured yarn's) and without flyaways (the bake's
regular fibers alone). ``--curves``, ``--scale`` as ``probe_split.py``'s (one course of a patch, its bends S times
gentler); ``--max-depth`` traces the references with paths of that many events instead of the scene's.

    .venv/bin/python benchmarks/probe_straight_at_angles.py --pack out/bench/cotton1_standard_66.h5 \\
        [--scene knit_patch_directional] [--curves 3] [--scale 1] [--spp 16] [--max-depth D]
"""

from __future__ import annotations

import argparse
import dataclasses
import sys
import tempfile
import time
from pathlib import Path

import h5py
import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
from probe_split import ROOT, kept_curves, rendered, traced  # noqa: E402

from data_formats.conventions import LUMINANCE, PHI_RANGE, THETA_RANGE  # noqa: E402
from data_formats.scene import EnvironmentLight, load_scene  # noqa: E402
from knitbake.compare.image_metrics import yarn_scale_metrics  # noqa: E402
from knitbake.compare.report import yarn_diameter_px  # noqa: E402
from knitrun.render import pipeline  # noqa: E402
from knitrun.render.ablations import combined  # noqa: E402
from knitrun.render.camera import scene_camera  # noqa: E402
from knitrun.shading.table_lookup import axis_cell  # noqa: E402


def point_angles(points, light_dir):
    """(v, θ_i, θ_o, φ) of each shading point (SHADING.md §3, yarn frame) for the light toward ``light_dir``."""
    wo, t = points["view_dir"], points["tangent"]
    n = wo - (wo * t).sum(axis=1)[:, None] * t
    n /= np.linalg.norm(n, axis=1)[:, None]
    b = np.cross(n, t)
    theta_i = np.arcsin(np.clip(t @ light_dir, -1.0, 1.0))
    theta_o = np.arcsin(np.clip((wo * t).sum(axis=1), -1.0, 1.0))
    return points["v"].astype(np.float64), theta_i, theta_o, -np.arctan2(b @ light_dir, n @ light_dir)


def quadrilinear(table, v, theta_i, theta_o, phi):
    """``table`` (N_v, N_θ, N_θ, N_φ, 3) at each point (ASSET_PACK.md §4.3: v and θ clamped, φ repeated)."""
    n_v, n_theta, _, n_phi, _ = table.shape
    axes = ((v, -1.0, 1.0, n_v, False), (theta_i, *THETA_RANGE, n_theta, False),
            (theta_o, *THETA_RANGE, n_theta, False), (phi, *PHI_RANGE, n_phi, True))
    cells = [np.array([axis_cell(float(x), lo, hi, n, rep) for x in values]).T for values, lo, hi, n, rep in axes]
    out = np.zeros((len(v), 3))
    for corner in range(16):
        index, weight = [], np.ones(len(v))
        for a, (i0, i1, f) in enumerate(cells):
            upper = (corner >> a) & 1
            index.append((i1 if upper else i0).astype(np.int64))
            weight = weight * (f if upper else 1.0 - f)
        out += weight[:, None] * table[tuple(index)]
    return out


def straight_prediction(scene, pack):
    """(whole, single) (H, W, 3) images the bake's straight yarn predicts for ``scene`` (module docstring), and the
    front points' (pixel, angles) for binning."""
    lights = [light for light in scene.lights if not isinstance(light, EnvironmentLight)]
    renderer = pipeline.Renderer(scene, {"cotton1": pack}, dataclasses.replace(combined("full"), flyaways=False))
    lines = pipeline._polylines(scene, renderer.curves, renderer.frame_index(None), renderer.samples_per_segment)
    camera = scene_camera(scene)
    points = renderer._raster(lines, camera).points
    light_dir = np.asarray(lights[0].unit_direction, np.float64)
    angles = point_angles(points, light_dir)
    with h5py.File(pack) as f:
        tables = f["correction/radiance_view"][()], f["correction/radiance_view_ss"][()]
    pixel = np.repeat(np.arange(camera.height * camera.width), np.diff(points["start"]))
    images = []
    for table in tables:
        value = quadrilinear(table, *angles) * np.asarray(lights[0].irradiance, np.float64)
        image = np.zeros((camera.height * camera.width, 3))
        np.add.at(image, pixel, points["weight"][:, None] * value)
        images.append(image.reshape(camera.height, camera.width, 3))
    heaviest = np.full(camera.height * camera.width, -1)
    order = np.argsort(points["weight"], kind="stable")
    heaviest[pixel[order]] = order
    return images, heaviest, angles


def placement_rows(rows, d, camera_shape):
    """Print each image's yarn-scale rel L1 against the reference (luminance, filtered to the yarn's projected
    diameter ``d`` px), whole, SS and MS, over the other fiber instance's (the floor), as it is and with its total
    scaled to the reference's: the second says whether the light is placed where the fibers put it."""
    ref = rows["reference"]
    inst = rows["other fiber instance"]

    def error(test, part, matched):
        a, r = test[part].reshape(camera_shape), ref[part].reshape(camera_shape)
        if matched and a.sum() > 0:
            a = a * (r.sum() / a.sum())
        if not r.sum() > 0:
            return float("nan")
        return yarn_scale_metrics(np.repeat(a[..., None], 3, -1), np.repeat(r[..., None], 3, -1), d)["rel_l1"]

    def over(err, floor):  # a dash where there is no floor (identical instances, or no light in that half)
        return f"{err / floor:.2f}×" if floor > 0 and np.isfinite(err) else "—"

    floors = [error(inst, q, False) for q in range(3)]
    floors_m = [error(inst, q, True) for q in range(3)]
    print(f"\nyarn-scale rel L1 (d = {d:.1f} px) over the other instance's (whole, SS, MS); the floors "
          + ", ".join(f"{f:.3f}" for f in floors) + " (means matched: " + ", ".join(f"{f:.3f}" for f in floors_m)
          + ")\n\n| image | as drawn | means matched |\n|---|---|---|")
    for name, value in rows.items():
        if name in ("reference", "other fiber instance"):
            continue
        print(f"| {name} | " + ", ".join(over(error(value, q, False), floors[q]) for q in range(3)) + " | "
              + ", ".join(over(error(value, q, True), floors_m[q]) for q in range(3)) + " |")


def main():
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--pack", type=Path, required=True, help="a pack with the closure's split tables")
    parser.add_argument("--scene", default="knit_patch_directional", help="an example scene with one directional light")
    parser.add_argument("--curves", default=None, help="keep only these curves (e.g. 3: one course)")
    parser.add_argument("--scale", type=float, default=1.0, help="scale what is kept (probe_split.py --scale)")
    parser.add_argument("--spp", type=int, default=None, help="reference spp (default: the scene's)")
    parser.add_argument("--max-depth", type=int, default=None, help="reference path depth (default: the scene's)")
    args = parser.parse_args()
    path = ROOT / "examples" / "scenes" / f"{args.scene}.toml"
    if not path.is_file():
        parser.error(f"--scene: no example scene {args.scene}")
    if not args.pack.is_file():
        parser.error(f"--pack: no file {args.pack}")
    with h5py.File(args.pack) as f:
        if "correction/radiance_view_ss" not in f:
            parser.error(f"--pack: {args.pack} has no correction/radiance_view_ss (bake it without --whole-xi)")
    if not args.scale > 0:
        parser.error(f"--scale must be > 0, not {args.scale}")
    scene = load_scene(path)
    if sum(not isinstance(light, EnvironmentLight) for light in scene.lights) != 1 or len(scene.lights) != 1:
        parser.error(f"--scene: {args.scene} must have one directional light and nothing else")
    try:
        keep = None if args.curves is None else [int(c) for c in args.curves.split(",")]
    except ValueError:
        parser.error(f"--curves: {args.curves!r} is not a comma-separated list of curve indices")
    folder = tempfile.mkdtemp(prefix="knit-probe-straight-")
    try:
        scene = kept_curves(scene, keep, args.scale, folder)
    except ValueError as error:
        parser.error(f"--curves: {error}")
    scene = dataclasses.replace(scene, yarns=tuple(dataclasses.replace(y, color=(1.0, 1.0, 1.0)) for y in scene.yarns))
    if args.max_depth is not None:
        scene = dataclasses.replace(scene, render=dataclasses.replace(scene.render, max_depth=args.max_depth))
    spp = args.spp or scene.render.spp
    t0 = time.perf_counter()
    reference = traced(scene, spp, 0, 0, flyaways=False)[:2]
    instance = traced(scene, spp, 1, 1, flyaways=False)[:2]
    strips = rendered(scene, args.pack, "full", flyaways=False)
    predicted, heaviest, (v, _, theta_o, _) = straight_prediction(scene, args.pack)
    print(f"{args.scene}, curves {args.curves or 'all'}, scale {args.scale:g}, {spp} spp, max depth "
          f"{scene.render.max_depth}, white, no flyaways ({time.perf_counter() - t0:.0f} s)\n")

    def parts(pair):  # luminance per pixel of the whole, SS, MS
        whole, single = ((np.asarray(x)[..., :3] @ LUMINANCE).ravel() for x in pair)
        return whole, single, whole - single

    rows = {"reference": parts(reference), "other fiber instance": parts(instance), "strips (full)": parts(strips),
            "straight yarn at the same angles": parts(predicted)}
    ref = rows["reference"]
    print("| image | whole / reference | SS / reference | MS / reference |\n|---|---|---|---|")
    for name, value in rows.items():
        print(f"| {name} | " + " | ".join(f"{a.sum() / b.sum():.3f}" for a, b in zip(value, ref)) + " |")
    placement_rows(rows, yarn_diameter_px(scene), camera_shape=np.shape(reference[0])[:2])
    covered = heaviest >= 0
    for label, key, edges in (("v", v, [-0.5, 0.0, 0.5]), ("|θ_o| (deg)", np.degrees(np.abs(theta_o)), [10, 25, 40])):
        which = np.full(len(heaviest), -1)
        which[covered] = np.digitize(key[heaviest[covered]], edges)
        print(f"\n| {label} | share of the reference's MS | reference / straight: whole, SS, MS | "
              f"strips / straight: whole, SS, MS |\n|---|---|---|---|")
        for j in range(len(edges) + 1):
            m = which == j
            if ref[0][m].sum() <= 0:
                continue
            lo = f"{edges[j - 1]:g}" if j else "−∞"
            hi = f"{edges[j]:g}" if j < len(edges) else "∞"
            straight = rows["straight yarn at the same angles"]
            print(f"| [{lo}, {hi}) | {ref[2][m].sum() / ref[2].sum():.3f} | "
                  + ", ".join(f"{ref[q][m].sum() / straight[q][m].sum():.2f}" for q in range(3)) + " | "
                  + ", ".join(f"{rows['strips (full)'][q][m].sum() / straight[q][m].sum():.2f}" for q in range(3))
                  + " |")


if __name__ == "__main__":
    main()
