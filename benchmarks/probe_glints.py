"""Where the strips miss the fibers' glints (issue 13): which fiber tangent meets the R lobe's specular condition at
the places a scene's strips are darkest against the reference.

Reads a ``bench_compare.py --out`` folder (``<scene>/reference.exr`` and ``strip_full.exr``). Both images are filtered
to the scene's projected yarn diameter d (``knitbake.compare.report.yarn_diameter_px``); of the reference's lit pixels
(above ``LIT`` of its largest) the fraction ``--worst`` where the strips' error is largest and the strips darker are the
*missed* pixels. For those and for ``--sample`` lit pixels drawn at random, the ray through the pixel's centre is met
with the reference's own fibers (``knitbake.fibers.fiber_sweep.sweep_fibers`` of the scene's curves with the reference's
fiber seed, the scene's seed, as ``knitbake.trace.reference.build_reference`` draws them): the fiber segment it crosses
first, near the strips' shading point there (the pixel's heaviest, ``shading_points``; a pixel whose ray meets no fiber
there is left out, and counted). Each pixel gives three tangents: that fiber's, the strips' yarn tangent and the strips'
shading tangent t_f (the pack's tangent texture read as ``shade_regular`` reads it, after the axial parallax and with
the fiber bend of the renderer's ``Features``), with the specular mismatch |θ_i + θ_o − 2α_R| of each against the
scene's one directional light (R is 1° wide for cotton: a fiber glints within a few degrees of it), the tilt of the
fiber and of t_f from the yarn tangent (its angle; its components along the strip frame's b, across the strip, and n,
toward the camera; how the two tilts correlate there: how much of the fiber's direction the texture predicts), and the
fiber's tangent less t_f against the texture's own tangent spread (Toksvig, ``strip_shading.tangent_spread``), which the
shading widens the lobes by.

With ``--second-draw`` each ray is met with a second fiber draw too, the instance floor's (fiber seed + 1), and a
second table asks how far a draw's fiber tilts are predictable at all, and where: per group and per class of the
fiber bend's κ·o at the point (``strip_shading.fiber_bend``: the outside of a bend tighter than 1.25 radii, the
outside of a gentler one, nearly straight, the inside), the correlation of the two draws' tilts (b, n), of t_f's
with each draw's (their mean), and the tilts' rms. Where the draws agree and t_f does not, the fibers' direction is
set by the yarn's geometry in a way the texture and the fiber bend do not model.

    .venv/bin/python benchmarks/probe_glints.py --pack out/bench/cotton1_standard_66.h5 \\
        --compare-dir out/compare66b [--scene simulated_patch_directional] [--worst 0.05] [--sample 3000] \\
        [--second-draw]
"""

from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np
from scipy.spatial import cKDTree

from data_formats.conventions import LUMINANCE
from data_formats.images import read_exr
from data_formats.scene import EnvironmentLight, load_scene, read_curves
from knitbake.compare.image_metrics import yarn_filter
from knitbake.compare.report import yarn_diameter_px
from knitbake.fibers.fiber_sweep import sweep_fibers
from knitbake.trace.reference import _only_curves
from knitrun.render import pipeline
from knitrun.render.camera import scene_camera, tan_half_fov
from knitrun.render.strip_shading import fiber_bend, tangent_spread
from knitrun.render.texture_sampling import mip_level, sample_mip
from knitrun.shading.fiber_bcsdf import P_ALPHA_R

BEND_CLASSES = (("outside, R < 1.25 r", -np.inf, -0.8), ("outside", -0.8, -0.4), ("nearly straight", -0.4, 0.1),
                ("inside", 0.1, np.inf))  # κ·o of the fiber bend at the point: −κ·o = r/R on a bend's outside, v = 0
LIT = 0.02  # lit pixels: the filtered reference above this share of its largest value (``probe_regions.LIT``)
NEAR_DEG = (2.0, 5.0)  # specular mismatches counted as glinting


def missed_pixels(reference, strips, d: float, fraction: float) -> np.ndarray:
    """(H, W) bool: of the reference's lit pixels at the yarn scale, the ``fraction`` where the strips' error is
    largest, those where the strips are darker (module docstring)."""
    ref = yarn_filter(reference, d) @ LUMINANCE
    drawn = yarn_filter(strips, d) @ LUMINANCE
    lit = np.flatnonzero(ref.ravel() > LIT * ref.max())
    error = np.abs(drawn.ravel() - ref.ravel())[lit]
    worst = lit[np.argsort(error, kind="stable")[::-1][:max(1, int(round(fraction * lit.size)))]]
    out = np.zeros(ref.size, bool)
    out[worst[drawn.ravel()[worst] < ref.ravel()[worst]]] = True
    return out.reshape(ref.shape)


def reference_fibers(scene, seed: int):
    """The reference's regular and flyaway fibers of the scene's (single) yarn entry as segments (start, end,
    radius), drawn as ``build_reference`` draws them with fiber seed ``seed``."""
    if len(scene.yarns) != 1:
        raise SystemExit("probe_glints: a scene of one yarn entry")
    entry = scene.yarns[0]
    curves = read_curves(entry.curves, scene.units)
    drawn = _only_curves(curves, np.isin(curves.yarn_type, entry.yarn_type_indices))
    fibers = sweep_fibers(drawn, scene.render.frame, {i: entry.spec for i in entry.yarn_type_indices},
                          {i: entry.radius for i in entry.yarn_type_indices}, seed=seed)
    ends = np.ones(fibers.points.shape[0], bool)
    ends[fibers.offsets[1:] - 1] = False  # a fiber's last point starts no segment
    start = np.flatnonzero(ends)
    radius = np.repeat(fibers.radius, np.diff(fibers.offsets) - 1)
    return fibers.points[start], fibers.points[start + 1], radius


def first_fiber_tangent(origin, ray, near, reach, tree, a_all, b_all, radius_all):
    """The unit tangent of the fiber segment that the ray (origin, unit ``ray``) crosses first among those whose
    midpoints lie within ``reach`` of the ray's point nearest ``near``; None when it crosses none."""
    candidates = tree.query_ball_point(origin + ((near - origin) @ ray) * ray, reach)
    if not candidates:
        return None
    k = np.asarray(candidates)
    a, u = a_all[k], b_all[k] - a_all[k]
    w0 = a - origin
    uu, ur, uw, rw = (u * u).sum(1), u @ ray, (u * w0).sum(1), w0 @ ray
    den = uu - ur * ur
    ok = den > 1e-15
    s = np.clip(np.where(ok, (ur * rw - uw) / np.where(ok, den, 1.0), 0.0), 0.0, 1.0)
    t = s * ur + rw
    miss = np.linalg.norm(origin + t[:, None] * ray - (a + s[:, None] * u), axis=1)
    t = np.where(miss < radius_all[k], t, np.inf)
    first = int(np.argmin(t))
    if not np.isfinite(t[first]):
        return None
    return u[first] / np.linalg.norm(u[first])


def pixel_ray(camera, row: int, col: int):
    """(origin, unit direction) of the ray through the centre of pixel (row, col), pinhole or orthographic
    (``knitrun.render.camera`` module docstring)."""
    fwd, right, up = camera.basis()
    sx, sy = (2 * (col + 0.5) - camera.width) / camera.height, 1 - 2 * (row + 0.5) / camera.height
    if camera.ortho_height > 0:
        return (np.asarray(camera.position, float) + 0.5 * camera.ortho_height * (sx * right + sy * up),
                np.asarray(fwd, float))
    ray = fwd + tan_half_fov(camera) * (sx * right + sy * up)
    return np.asarray(camera.position, float), ray / np.linalg.norm(ray)


def print_agreement(agreement) -> None:
    """The second table of ``--second-draw`` (module docstring): ``agreement`` maps a group's name to rows (κ·o, then
    in degrees the tilts (b, n) of the first draw's fiber, of the second draw's and of t_f)."""
    def corr(x, y):
        return np.corrcoef(x, y)[0, 1] if len(x) > 2 and x.std() > 0 and y.std() > 0 else np.nan

    print("\n| pixels | bend (κ·o) | pixels met by both draws | tilt correlation (b, n): draw–draw | t_f–draw | "
          "tilt rms (b, n): fibers | t_f |")
    print("|---|---|---|---|---|---|---|")
    for name, r in agreement.items():
        for label, low, high in (("all", -np.inf, np.inf), *BEND_CLASSES):
            k = (r[:, 0] >= low) & (r[:, 0] < high)
            if k.sum() < 30:
                continue
            x = r[k]
            draw = [corr(x[:, 1 + a], x[:, 3 + a]) for a in (0, 1)]
            model = [0.5 * (corr(x[:, 1 + a], x[:, 5 + a]) + corr(x[:, 3 + a], x[:, 5 + a])) for a in (0, 1)]
            fibers = np.sqrt(0.5 * (x[:, [1, 2]] ** 2 + x[:, [3, 4]] ** 2).mean(axis=0))
            print(f"| {name} | {label} | {k.sum()} | {draw[0]:.2f}, {draw[1]:.2f} | {model[0]:.2f}, {model[1]:.2f} | "
                  f"{fibers[0]:.1f}°, {fibers[1]:.1f}° | {np.sqrt((x[:, 5] ** 2).mean()):.1f}°, "
                  f"{np.sqrt((x[:, 6] ** 2).mean()):.1f}° |")


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--pack", required=True, help="the asset pack of the scene's yarn")
    parser.add_argument("--compare-dir", type=Path, required=True, help="a bench_compare.py --out folder")
    parser.add_argument("--scene", default="simulated_patch_directional", help="an example scene of one directional "
                        "light and one yarn entry")
    parser.add_argument("--worst", type=float, default=0.05, help="the fraction of lit pixels taken as worst")
    parser.add_argument("--sample", type=int, default=3000, help="lit pixels drawn at random for comparison")
    parser.add_argument("--second-draw", action="store_true", help="meet each ray with the instance floor's fiber "
                        "draw too and say where the draws' tilts agree and t_f's do not (module docstring)")
    args = parser.parse_args(argv)
    scene = load_scene(Path("examples/scenes") / f"{args.scene}.toml")
    lights = [light for light in scene.lights if not isinstance(light, EnvironmentLight)]
    if len(lights) != 1 or len(lights) != len(scene.lights):
        raise SystemExit("probe_glints: a scene of exactly one directional light")
    to_light = np.asarray(lights[0].unit_direction, float)
    folder = args.compare_dir / args.scene
    reference = read_exr(folder / "reference.exr")[..., :3]
    missed = missed_pixels(reference, read_exr(folder / "strip_full.exr")[..., :3], yarn_diameter_px(scene),
                           args.worst).ravel()

    renderer = pipeline.Renderer(scene, {scene.yarns[0].yarn: args.pack})
    look, kernel_look = renderer.looks[0], renderer.kernel_looks[0][0]
    camera = scene_camera(scene)
    lines = pipeline._polylines(scene, renderer.curves, renderer.frame_index(None), renderer.samples_per_segment)
    raster = renderer._raster(lines, camera).points
    points = pipeline._kernel_points(pipeline.parallax_shift(raster, lines, renderer.looks), lines, renderer.looks,
                                     renderer.features.fiber_bend)
    h, w = camera.height, camera.width
    pixel = np.repeat(np.arange(h * w), np.diff(raster["start"]))
    heaviest = np.full(h * w, -1)
    order = np.argsort(raster["weight"], kind="stable")
    heaviest[pixel[order]] = order  # each pixel's heaviest point: the last of its points in ascending weight
    a_all, b_all, radius_all = reference_fibers(scene, scene.render.seed)
    tree = cKDTree(0.5 * (a_all + b_all))
    second = None
    if args.second_draw:
        a2, b2, radius2 = reference_fibers(scene, scene.render.seed + 1)
        second = (cKDTree(0.5 * (a2 + b2)), a2, b2, radius2)
    # a fiber segment the ray crosses near the strip's point has its midpoint within 3 yarn radii plus half its length
    reach = 3.0 * scene.yarns[0].radius + 0.5 * np.linalg.norm(b_all - a_all, axis=1).max()
    alpha_r = kernel_look.params[P_ALPHA_R]
    texel_u = kernel_look.period / look.tangent.cols[0, 0]
    texel_v = 2.0 * kernel_look.radius / look.tangent.rows[0, 0]
    tex, cov = np.empty(3), np.empty(1)

    def mismatch(t, wo):
        return abs(np.degrees(np.arcsin(np.clip(t @ to_light, -1, 1)) + np.arcsin(np.clip(t @ wo, -1, 1))
                              - 2.0 * alpha_r))

    agreement = {}
    drawn = np.flatnonzero(heaviest >= 0)
    groups = {"missed": np.flatnonzero(missed & (heaviest >= 0)),
              "lit, at random": np.random.default_rng(0).choice(drawn, min(args.sample, drawn.size), replace=False)}
    print(f"{args.scene}: d = {yarn_diameter_px(scene):.1f} px, α_R = {np.degrees(alpha_r):.1f}°, "
          f"{len(a_all)} fiber segments\n")
    print("| pixels | met a fiber | within 2° / 5° of specular: fiber | yarn tangent | t_f | median mismatch: "
          "fiber / yarn / t_f | tilt from the yarn, quartiles: fiber | t_f | tilt rms (b, n): fiber | t_f | "
          "correlation of the two (b, n) | fiber − t_f rms (b, n) | texture spread rms |")
    print("|---|---|---|---|---|---|---|---|---|---|---|---|---|")
    for name, pixels in groups.items():
        rows, draws = [], []
        for p in pixels:
            i, j = divmod(int(p), w)
            origin, ray = pixel_ray(camera, i, j)
            q = heaviest[p]
            fiber = first_fiber_tangent(origin, ray, raster["position"][q], reach, tree, a_all, b_all, radius_all)
            if fiber is None:
                continue
            t, wo = points.tangent[q], points.view_dir[q]
            n = wo - (wo @ t) * t
            n /= np.linalg.norm(n)
            b = np.cross(n, t)
            level = mip_level(points.footprint[q], texel_u, texel_v)
            u, v = points.arclength[q] / kernel_look.period, min(max(points.v[q], -1.0), 1.0)
            sample_mip(look.tangent, 0, level, u, v, tex)
            sample_mip(look.coverage, 0, level, u, v, cov)
            along = fiber_bend(points.curvature, points.stretch, q, kernel_look.radius, v, n, b)
            k_dot_o = float(points.curvature[q] @ (kernel_look.radius * (v * b + np.sqrt(max(0.0, 1.0 - v * v)) * n)))
            t_f = along * tex[0] * t + tex[1] * b + tex[2] * n
            t_f = t_f / np.linalg.norm(t_f) if np.linalg.norm(t_f) >= 1e-6 else t  # ``_texture_tangent``'s rule
            fiber = fiber if fiber @ t >= 0.0 else -fiber
            if second is not None:
                other = first_fiber_tangent(origin, ray, raster["position"][q], reach, *second)
                if other is not None:
                    other = other if other @ t >= 0.0 else -other
                    draws.append((k_dot_o, *np.degrees([fiber @ b, fiber @ n, other @ b, other @ n, t_f @ b, t_f @ n])))
            rows.append((mismatch(fiber, -ray), mismatch(t, wo), mismatch(t_f, wo),
                         np.degrees(np.arccos(min(fiber @ t, 1.0))), np.degrees(np.arccos(min(t_f @ t, 1.0))),
                         np.degrees(fiber @ b - t_f @ b), np.degrees(fiber @ n - t_f @ n),
                         np.degrees(np.sqrt(tangent_spread(tex, cov[0]))), np.degrees(fiber @ b), np.degrees(fiber @ n),
                         np.degrees(t_f @ b), np.degrees(t_f @ n)))
        r = np.array(rows)
        near = [" / ".join(f"{np.mean(r[:, k] < x):.3f}" for x in NEAR_DEG) for k in range(3)]
        quart = [" ".join(f"{x:.1f}" for x in np.quantile(r[:, k], [0.25, 0.5, 0.75])) for k in (3, 4)]
        rms = np.sqrt(np.mean(r[:, 5:] ** 2, axis=0))
        corr = [np.corrcoef(r[:, 8 + k], r[:, 10 + k])[0, 1] for k in (0, 1)]
        print(f"| {name} | {len(r)} of {len(pixels)} | {near[0]} | {near[1]} | {near[2]} | "
              f"{' / '.join(f'{np.median(r[:, k]):.1f}°' for k in range(3))} | {quart[0]}° | {quart[1]}° | "
              f"{rms[3]:.1f}°, {rms[4]:.1f}° | {rms[5]:.1f}°, {rms[6]:.1f}° | {corr[0]:.2f}, {corr[1]:.2f} | "
              f"{rms[0]:.1f}°, {rms[1]:.1f}° | {rms[2]:.1f}° |")
        if draws:
            agreement[name] = np.array(draws)
    if agreement:
        print_agreement(agreement)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
