"""How the strip model's brightness and yarn-scale error change as a straight yarn tilts toward the camera
(issue 13, the look).

On the simulated patch the strips fall further below the reference the more the yarn points at the camera
(``--bins-from`` below; BENCHMARKS.md, stop 43), and the patches' loops turn toward the camera at every stitch. This
probe isolates that on the simplest scene: ``straight_yarn_directional`` with the
yarn 6 cm long (its projection still crosses the frame at the largest tilt) and turned by ψ about the image's y axis
toward the camera, ω_o · t = sin ψ. ``--light turn`` turns its light with it (the light's relation to the yarn stays
fixed, θ_i = 0, and only the view moves); ``--light fixed`` keeps the scene's light (near the camera, as on the
patches' loops that turn toward the camera: θ_i follows θ_o).

Per tilt: a reference (seed 0) and a second fiber instance (seed 1, fiber seed 1, the instance floor), then the strip
models of ``--models`` (``knitrun.render.ablations.ABLATIONS``); reported per model: the mean radiance ratio and the
yarn-scale rel L1 at d as a ratio to the instance floor (``knitbake.compare.image_metrics.yarn_scale_metrics``).
About 9 s per tilt and model set at 16 spp on 2 cores.

``--bins-from DIR`` instead bins an existing comparison of the simulated patch (``bench_compare.py``'s folder for
``simulated_patch_directional``: ``reference.exr`` and ``strip_<model>.exr``) along the scene's yarn curves: at each
control point's pixel, both images filtered to the yarn scale d, grouped by |ω_o · t| — where on the patch the
strips lose light to the reference.

    .venv/bin/python benchmarks/probe_tilt.py --pack out/bench/cotton1_standard.h5 [--tilts 0,30,50,70] [--spp 16] \\
        [--light turn|fixed] [--models plain_ds,no_tables,full]
    .venv/bin/python benchmarks/probe_tilt.py --bins-from out/compare43/simulated_patch_directional \\
        [--models diagonal_xi,full]
"""

from __future__ import annotations

import argparse
import dataclasses
import math
import tempfile
import time
from pathlib import Path

import numpy as np

from data_formats.images import read_exr
from data_formats.scene import load_scene
from data_formats.yarn_curves import make_yarn_curves, read_yarn_curves, write_yarn_curves
from knitbake.compare.image_metrics import yarn_filter, yarn_scale_metrics
from knitbake.compare.report import yarn_diameter_px
from knitbake.trace.reference import trace_reference
from knitrun.render import pipeline
from knitrun.render.ablations import ABLATIONS
from knitrun.render.camera import project, scene_camera

EXAMPLES = Path(__file__).parent.parent / "examples" / "scenes"
SCENE = EXAMPLES / "straight_yarn_directional.toml"
PATCH = EXAMPLES / "simulated_patch_directional.toml"
TILT_BINS = (0.0, 0.2, 0.4, 0.6, 0.8, 1.0)  # |ω_o · t|, the last bin closed
HALF_LENGTH = 3.0  # cm: 2 · 3 · cos 70° = 2.05 cm, wider than the frame (1.2 cm)


def tilted_scene(base, psi_deg: float, folder: Path, turn_light: bool = True):
    """``base`` with its yarn along (cos ψ, 0, sin ψ) and, if ``turn_light``, its lights turned by the same rotation
    about y."""
    c, s = math.cos(math.radians(psi_deg)), math.sin(math.radians(psi_deg))
    rotate = np.array([[c, 0.0, -s], [0.0, 1.0, 0.0], [s, 0.0, c]])
    points = (rotate @ np.array([[-HALF_LENGTH, 0.0, 0.0], [HALF_LENGTH, 0.0, 0.0]]).T).T
    path = folder / f"tilt{psi_deg:g}.h5"
    write_yarn_curves(path, make_yarn_curves(points[None], [0, 2], yarn_types=["cotton1"], units="cm"))
    lights = tuple(dataclasses.replace(light, direction=tuple(rotate @ np.asarray(light.direction, float)))
                   for light in base.lights) if turn_light else base.lights
    camera = dataclasses.replace(base.camera, position=(0.0, 0.0, 10.0))  # orthographic: in front of every end
    return dataclasses.replace(base, yarns=(dataclasses.replace(base.yarns[0], curves=path),), lights=lights,
                               camera=camera)


def probe(pack, psi_deg, spp, models, folder, turn_light):
    scene = tilted_scene(load_scene(SCENE), psi_deg, folder, turn_light)
    t0 = time.perf_counter()
    reference, _ = trace_reference(scene, spp, seed=0)
    instance, _ = trace_reference(scene, spp, seed=1, fiber_seed=1)
    trace_s = time.perf_counter() - t0
    d = yarn_diameter_px(scene)
    reference, instance = reference.astype(np.float64)[..., :3], instance.astype(np.float64)[..., :3]
    floor = yarn_scale_metrics(instance, reference, d)
    cells = [f"{psi_deg:g}°", f"{math.sin(math.radians(psi_deg)):.2f}", f"{floor['mean_ratio']:.3f}",
             f"{floor['rel_l1']:.3f}"]
    for model in models:
        strip = pipeline.Renderer(scene, {"cotton1": str(pack)}, ABLATIONS[model]).render().image
        m = yarn_scale_metrics(np.asarray(strip, np.float64)[..., :3], reference, d)
        cells.append(f"{m['mean_ratio']:.3f} / {m['rel_l1'] / floor['rel_l1']:.2f}×")
    return "| " + " | ".join(cells + [f"{trace_s:.0f}"]) + " |"


def curve_tilts(scene):
    """(row, col, |ω_o · t|) of every control point of the scene's curve-file yarns, at the scene's frame; None when
    no yarn is drawn from a curve file."""
    camera = scene_camera(scene)
    rows, cols, tilts = [], [], []
    for entry in scene.yarns:
        if entry.curves is None:
            continue
        curves = read_yarn_curves(entry.curves)
        points = curves.points[scene.render.frame if curves.points.shape[0] > 1 else 0]
        x, y, _ = project(camera, points)
        cols.append(np.clip(np.round(x).astype(int), 0, scene.camera.width - 1))
        rows.append(np.clip(np.round(y).astype(int), 0, scene.camera.height - 1))
        for a, b in zip(curves.offsets[:-1], curves.offsets[1:]):
            t = np.gradient(points[a:b], axis=0)
            t /= np.maximum(np.linalg.norm(t, axis=1), 1e-300)[:, None]
            view = camera.position - points[a:b]
            view /= np.maximum(np.linalg.norm(view, axis=1), 1e-300)[:, None]
            tilts.append(np.abs(np.einsum("ij,ij->i", t, view)))
    if not tilts:
        return None
    return np.concatenate(rows), np.concatenate(cols), np.concatenate(tilts)


def patch_bins(folder: Path, models) -> str:
    """Mean of the yarn-scale filtered reference and strip images at the simulated patch's control points, by
    |ω_o · t| (the last bin closed)."""
    scene = load_scene(PATCH)
    d = yarn_diameter_px(scene)
    row, col, tilt = curve_tilts(scene)
    sampled = {name: yarn_filter(read_exr(folder / f"{name}.exr")[..., :3], d).mean(-1)[row, col]
               for name in ("reference", *(f"strip_{m}" for m in models))}
    lines = ["| |ω_o · t| | points | reference | " + " | ".join(f"{m}: mean / ratio" for m in models) + " |",
             "|---" * (3 + len(models)) + "|"]
    for lo, hi in zip(TILT_BINS[:-1], TILT_BINS[1:]):
        at = (tilt >= lo) & ((tilt < hi) | (hi == TILT_BINS[-1]))
        ref = sampled["reference"][at].mean()
        cells = [f"{sampled[f'strip_{m}'][at].mean():.4f} / {sampled[f'strip_{m}'][at].mean() / ref:.2f}"
                 for m in models]
        lines.append(f"| {lo:.1f}–{hi:.1f} | {int(at.sum())} | {ref:.4f} | " + " | ".join(cells) + " |")
    return "\n".join(lines)


def main():
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--pack", help="the asset pack of cotton1 (the tilt sweep)")
    parser.add_argument("--bins-from", type=Path, help="bin this comparison folder of the simulated patch instead")
    parser.add_argument("--tilts", default="0,30,50,70", help="tilts ψ toward the camera in degrees")
    parser.add_argument("--spp", type=int, default=16)
    parser.add_argument("--light", choices=("turn", "fixed"), default="turn",
                        help="turn the light with the yarn (θ_i = 0), or keep the scene's (θ_i follows θ_o)")
    parser.add_argument("--models", default="plain_ds,no_tables,full", help="names of knitrun.render.ablations")
    args = parser.parse_args()
    models = args.models.split(",")
    unknown = sorted(set(models) - set(ABLATIONS))
    if unknown:
        parser.error(f"--models: unknown model {unknown[0]!r} ({', '.join(ABLATIONS)})")
    if args.bins_from is not None:
        print(patch_bins(args.bins_from, models))
        return
    if args.pack is None:
        parser.error("--pack is required for the tilt sweep")
    print("| tilt ψ | ω_o · t | instance mean ratio | instance rel L1 (d) | "
          + " | ".join(f"{m}: mean ratio / ×floor" for m in models) + " | trace s |")
    print("|---" * (5 + len(models)) + "|")
    with tempfile.TemporaryDirectory() as folder:
        for psi in (float(t) for t in args.tilts.split(",")):
            print(probe(args.pack, psi, args.spp, models, Path(folder), args.light == "turn"), flush=True)


if __name__ == "__main__":
    main()
