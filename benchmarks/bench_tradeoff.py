"""The speed/accuracy trade of the strip renderer: bake quality × runtime knobs → (time, error against the
reference at the yarn scale), with the Pareto front marked, as a Markdown table and a scatter plot (PNG).

Three sweeps, each against path-traced references (``--reference-dir``: ``<scene>.exr`` as `knitbake reference`
writes them; missing ones are rendered there at ``--spp``):

* ``quality``: the pack's bake quality (one pack per quality, ``--packs``) × MSAA samples × shadow-map size, on the
  example straight yarn and 6 × 6 patch under the directional light.
* ``srbf``: the SRBF count J fitted to the built-in sky, on the same two scenes under the sky (standard pack).
* ``hairs``: ``render.hair_layers``, the flyaway strips composited per sample (1: the nearest alone), on the 6 × 6
  patch under the directional light and under the sky (standard pack).
* ``gn``: the knot simulator's Gauss–Newton iterations per frame. A 6 × 6 stockinette stitch mesh is stretched
  1.4× in x in one frame (the hardest step: no warm start from a nearby frame) and simulated with k iterations;
  the reference is the example scene ``simulated_patch_directional`` (the path-traced patch of the k = 16 curves,
  converged: the points move < 1e-6 cm from k = 8).
  Time = the simulated frame's solve + assembly (median of three runs) + the render.

Error: the yarn-scale rel L1 (``knitbake.compare.image_metrics.yarn_scale_metrics``, images box-filtered to the
projected yarn diameter) and its ratio to the reference's fiber-instance floor (``<scene>_instance.exr`` beside the
reference, traced with seed and fiber seed + 1 when missing); pixel FLIP and the mean radiance ratio are printed
too. Time: the whole ``render`` call, median of two after a warm-up call. A configuration is on the Pareto front
when no other configuration of the same scene is at least as fast with at most its yarn-scale error (and better in
one).

    .venv/bin/python benchmarks/bench_tradeoff.py --packs draft=d.h5,standard=s.h5,final=f.h5 --reference-dir DIR
                                                  [--sweeps quality,srbf,hairs,gn] [--spp 64] [--plot PNG]
"""

import argparse
import dataclasses
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
from PIL import Image, ImageDraw

from data_formats.images import read_exr
from data_formats.scene import load_scene
from data_formats.yarn_curves import read_yarn_curves, write_yarn_curves
from knitbake.compare.image_metrics import compare_images, yarn_scale_metrics
from knitbake.compare.report import yarn_diameter_px
from knitrun.render.pipeline import render
from knitrun.sim.deformations import deformation_frames, parse_deformation
from knitrun.sim.knit_chart import chart_to_mesh, pattern_chart
from knitrun.sim.simulate import simulate

ROOT = Path(__file__).resolve().parent.parent
QUALITY_SCENES = ("straight_yarn_directional", "knit_patch_directional")
SKY_SCENES = ("straight_yarn_sky", "knit_patch_sky")
MSAA = (1, 4, 8)
SHADOW = (512, 2048)
SRBF = (1, 4, 16, 64)
HAIR_SCENES = ("knit_patch_directional", "knit_patch_sky")
HAIRS = (1, 2, 3, 4)
GN = (0, 1, 2, 4, 8)
GN_CONVERGED = 16
GN_SCENE = "simulated_patch_directional"
GN_SCENE_TOML = ROOT / "examples" / "scenes" / f"{GN_SCENE}.toml"  # the converged (k = 16) curves


def timed_render(scene, packs):
    """(median seconds of two renders after a warm-up, image)."""
    render(scene, packs)
    runs, image = [], None
    for _ in range(2):
        t0 = time.perf_counter()
        image = render(scene, packs).image
        runs.append(time.perf_counter() - t0)
    return float(np.median(runs)), image


def reference_for(name, scene_path, reference_dir: Path, spp: int):
    """(reference image, yarn diameter in px, the instance floor's yarn-scale rel L1) of a scene; the reference and
    its instance floor are path traced with `knitbake reference` into ``reference_dir`` where missing."""
    scene = load_scene(scene_path)
    images = {}
    for suffix, extra in (("", []), ("_instance", ["--seed", str(scene.render.seed + 1),
                                                   "--fiber-seed", str(scene.render.seed + 1)])):
        path = reference_dir / f"{name}{suffix}.exr"
        if not path.is_file():
            reference_dir.mkdir(parents=True, exist_ok=True)
            subprocess.run([str(Path(sys.executable).parent / "knitbake"), "reference", str(scene_path), "-o",
                            str(path), "--spp", str(spp), *extra], check=True)
        images[suffix] = read_exr(path)
    diameter = yarn_diameter_px(scene)
    return images[""], diameter, yarn_scale_metrics(images["_instance"], images[""], diameter)["rel_l1"]


def sweep_quality(packs, reference_dir, spp):
    rows = []
    for name in QUALITY_SCENES:
        path = ROOT / "examples" / "scenes" / f"{name}.toml"
        base, reference = load_scene(path), reference_for(name, path, reference_dir, spp)
        rows.append(floor_row(name, reference))
        for quality, pack in packs.items():
            for msaa in MSAA:
                for shadow in SHADOW:
                    scene = dataclasses.replace(base, render=dataclasses.replace(base.render, msaa=msaa,
                                                                                 shadow_map_size=shadow))
                    seconds, image = timed_render(scene, {"cotton1": pack})
                    rows.append({"scene": name, "quality": quality, "knob": f"MSAA {msaa}, shadow {shadow}²",
                                 "msaa": msaa, "ms": 1e3 * seconds, **metrics(image, *reference)})
    return rows


def sweep_setting(pack, reference_dir, spp, scenes, field, values, knob, label):
    """One ``render`` setting over ``values`` on ``scenes`` (standard pack): rows named ``knob.format(value)``, the plot
    labels ``label.format(value)``."""
    rows = []
    for name in scenes:
        path = ROOT / "examples" / "scenes" / f"{name}.toml"
        base, reference = load_scene(path), reference_for(name, path, reference_dir, spp)
        rows.append(floor_row(name, reference))
        for value in values:
            scene = dataclasses.replace(base, render=dataclasses.replace(base.render, **{field: value}))
            seconds, image = timed_render(scene, {"cotton1": pack})
            rows.append({"scene": name, "quality": "standard", "knob": knob.format(value),
                         "label": label.format(value), "ms": 1e3 * seconds, **metrics(image, *reference)})
    return rows


def sweep_gn(pack, reference_dir, spp, work: Path):
    """Simulate with k iterations, write one scene per k into ``work`` (the example scene with the k-iteration
    curves), render each against the reference of the example scene, whose curves are the converged k = 16 ones."""
    work.mkdir(parents=True, exist_ok=True)
    base = load_scene(GN_SCENE_TOML)
    converged = read_yarn_curves(base.yarns[0].curves)
    mesh = chart_to_mesh(pattern_chart("stockinette", 6, 6), where="pattern stockinette")
    frames = deformation_frames(mesh.vertices, [parse_deformation("stretch-x=1.4")], 1)
    scenes, sim_ms, energy = {}, {}, {}
    for k in (GN_CONVERGED, *GN):
        times = []
        for _ in range(3):
            curves, report = simulate(mesh, frames, iterations=k)
            times.append(report["ms_per_frame_median"])
        sim_ms[k], energy[k] = float(np.median(times)), report["final_energy"]
        if k == GN_CONVERGED and not np.allclose(curves.points, converged.points, rtol=0, atol=1e-5):
            raise SystemExit(f"{base.yarns[0].curves} is not the {GN_CONVERGED}-iteration simulation of this "
                             "simulator: regenerate it with the commands in its scene file")
        write_yarn_curves(work / f"gn{k}.h5", curves)
        yarn = dataclasses.replace(base.yarns[0], curves=work / f"gn{k}.h5")
        scenes[k] = dataclasses.replace(base, yarns=(yarn,))
    reference = reference_for(GN_SCENE, GN_SCENE_TOML, reference_dir, spp)
    rows = [floor_row(GN_SCENE, reference)]
    for k in GN:
        seconds, image = timed_render(scenes[k], {"cotton1": pack})
        rows.append({"scene": GN_SCENE, "quality": "standard", "knob": f"{k} GN iterations (energy {energy[k]:.6g})",
                     "label": str(k), "ms": 1e3 * seconds + sim_ms[k], **metrics(image, *reference)})
    return rows


def metrics(image, reference, diameter, floor):
    """Yarn-scale rel L1 (``err``), its ratio to the instance floor, pixel FLIP and the mean radiance ratio."""
    yarn = yarn_scale_metrics(image, reference, diameter)
    return {"err": yarn["rel_l1"], "to_floor": yarn["rel_l1"] / floor, "flip": compare_images(image, reference)["flip"],
            "mean_ratio": yarn["mean_ratio"]}


def floor_row(name, reference):
    """The instance floor as a row of the table (not a configuration: no time, never on the front)."""
    return {"scene": name, "floor": True, "err": reference[2], "to_floor": 1.0}


def pareto(rows):
    """Mark rows (dicts with 'ms', 'err') that no other row dominates (no worse in both, better in one)."""
    for r in rows:
        r["pareto"] = not any(o["ms"] <= r["ms"] and o["err"] <= r["err"] and (o["ms"], o["err"]) != (r["ms"], r["err"])
                              for o in rows)


def plot(path, by_scene, floors):
    """Scatter of the yarn-scale error against ms per scene (one panel each, two rows), Pareto front joined, the
    instance floor as a dashed line; PIL only."""
    w, h, pad = 480, 320, 48
    cols = (len(by_scene) + 1) // 2
    canvas = Image.new("RGB", (w * cols, h * 2), "white")
    draw = ImageDraw.Draw(canvas)
    colours = {"draft": (220, 90, 40), "standard": (40, 90, 220), "final": (40, 160, 60)}
    for k, (name, rows) in enumerate(by_scene.items()):
        x0, y0 = (k % cols) * w, (k // cols) * h
        ms = np.array([r["ms"] for r in rows])
        floor = next((r["err"] for r in floors.get(name, [])), None)
        fl = np.array([r["err"] for r in rows] + ([floor] if floor is not None else []))
        lo_x, hi_x = ms.min() * 0.9, ms.max() * 1.1
        lo_y, hi_y = min(0.0, fl.min()), fl.max() * 1.05

        def xy(m, f):
            return (x0 + pad + (m - lo_x) / (hi_x - lo_x) * (w - 2 * pad),
                    y0 + h - pad - (f - lo_y) / (hi_y - lo_y) * (h - 2 * pad))

        draw.rectangle([x0 + pad, y0 + pad, x0 + w - pad, y0 + h - pad], outline="black")
        draw.text((x0 + pad, y0 + 8), f"{name}: yarn-scale rel L1 vs ms", fill="black")
        if floor is not None:
            fy = xy(lo_x, floor)[1]
            for x in range(x0 + pad, x0 + w - pad, 12):
                draw.line([(x, fy), (x + 6, fy)], fill=(150, 150, 150))
            draw.text((x0 + w - pad - 90, fy - 12), "instance floor", fill=(120, 120, 120))
        draw.text((x0 + pad, y0 + h - pad + 6), f"{lo_x:.0f} ms", fill="black")
        draw.text((x0 + w - pad - 60, y0 + h - pad + 6), f"{hi_x:.0f} ms", fill="black")
        draw.text((x0 + 2, y0 + pad), f"{hi_y:.3f}", fill="black")
        draw.text((x0 + 2, y0 + h - pad - 10), f"{lo_y:.3f}", fill="black")
        front = sorted((r for r in rows if r["pareto"]), key=lambda r: r["ms"])
        if len(front) > 1:
            draw.line([xy(r["ms"], r["err"]) for r in front], fill=(120, 120, 120), width=2)
        marks = []
        for r in rows:
            cx, cy = xy(r["ms"], r["err"])
            size = 2 + r.get("msaa", 2)
            marks.append([cx - size, cy - size, cx + size, cy + size])
            draw.ellipse(marks[-1], outline=colours.get(r["quality"], "black"),
                         width=2 if "2048" in r["knob"] or "label" in r else 1)
        placed = []  # labels after every mark: a label that would cover a mark or a label moves down a line
        for k_row, r in sorted(enumerate(rows), key=lambda item: (item[1]["ms"], item[1]["err"])):
            if "label" not in r:
                continue
            cx, cy = xy(r["ms"], r["err"])
            box = list(draw.textbbox((cx + 6, cy - 6), r["label"]))
            others = placed + marks[:k_row] + marks[k_row + 1:]
            while any(box[0] < b[2] and b[0] < box[2] and box[1] < b[3] and b[1] < box[3] for b in others):
                box[1], box[3] = box[1] + 12, box[3] + 12
            placed.append(box)
            draw.text((box[0], box[1] - draw.textbbox((0, 0), r["label"])[1]), r["label"], fill="black")
        legend = ("orange draft, blue standard, green final; size: MSAA; thick: 2048 x 2048 shadow map"
                  if name in QUALITY_SCENES else "labels: SRBF count J" if name in SKY_SCENES
                  else "labels: Gauss-Newton iterations (time includes the solve)")
        if name in HAIR_SCENES:
            legend += "; hK: K hair layers"
        draw.text((x0 + pad, y0 + 24), legend, fill="black")
    canvas.save(path)


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--packs", required=True, help="quality=pack.h5,... e.g. draft=d.h5,standard=s.h5 (the "
                                                       "SRBF and GN sweeps use the standard pack)")
    parser.add_argument("--reference-dir", required=True)
    parser.add_argument("--sweeps", default="quality,srbf,hairs,gn")
    parser.add_argument("--spp", type=int, default=64, help="samples per pixel of references rendered here")
    parser.add_argument("--work-dir", default="out/bench/tradeoff", help="the GN sweep's curves and scenes")
    parser.add_argument("--plot", help="scatter plot PNG (default docs/tradeoff.png when every sweep runs; none "
                                       "for a subset, so a partial run does not replace the documented plot)")
    args = parser.parse_args()
    packs = dict(item.split("=", 1) for item in args.packs.split(","))
    sweeps = args.sweeps.split(",")
    every = {"quality", "srbf", "hairs", "gn"}
    unknown = sorted(set(sweeps) - every)
    if unknown:
        parser.error(f"--sweeps: unknown sweep {unknown[0]!r} (quality, srbf, hairs, gn)")
    if args.plot is None and set(sweeps) == every:
        args.plot = "docs/tradeoff.png"
    reference_dir = Path(args.reference_dir)
    rows = []
    if "quality" in sweeps:
        rows += sweep_quality(packs, reference_dir, args.spp)
    if "srbf" in sweeps:
        rows += sweep_setting(packs["standard"], reference_dir, args.spp, SKY_SCENES, "srbf_count", SRBF, "J = {}",
                              "{}")
    if "hairs" in sweeps:
        rows += sweep_setting(packs["standard"], reference_dir, args.spp, HAIR_SCENES, "hair_layers", HAIRS,
                              "{} hair layers", "h{}")
    if "gn" in sweeps:
        rows += sweep_gn(packs["standard"], reference_dir, args.spp, Path(args.work_dir))
    by_scene, floors = {}, {}
    for r in rows:
        (floors if r.get("floor") else by_scene).setdefault(r["scene"], []).append(r)
    for scene_rows in by_scene.values():
        pareto(scene_rows)
    print("| scene | bake | knob | ms | yarn-scale rel L1 | ratio to instance floor | mean ratio | pixel FLIP | "
          "Pareto |")
    print("|---|---|---|---|---|---|---|---|---|")
    for name, scene_rows in by_scene.items():
        floor = floors[name][0]["err"]
        print(f"| {name} | — | *instance floor* | — | {floor:.3f} | 1.00 | — | — | |")
        for r in sorted(scene_rows, key=lambda r: r["ms"]):
            print(f"| {name} | {r['quality']} | {r['knob']} | {r['ms']:.0f} | {r['err']:.3f} | {r['to_floor']:.2f} | "
                  f"{r['mean_ratio']:.3f} | {r['flip']:.4f} | {'**yes**' if r['pareto'] else ''} |")
    if args.plot:
        plot(args.plot, by_scene, floors)
        print(f"\nplot: {args.plot}")


if __name__ == "__main__":
    main()
