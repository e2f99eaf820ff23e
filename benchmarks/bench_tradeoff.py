"""The speed/accuracy trade of the strip renderer: bake quality × runtime knobs → (time, error against the
reference), with the Pareto front marked, as a Markdown table and a scatter plot (PNG).

Knobs swept: the pack's bake quality (one pack per quality, ``--packs``), MSAA samples and the shadow-map size.
Scenes: the example straight yarn and 6 × 6 patch under the directional light, against references rendered earlier
(``--reference-dir``: ``<scene>.exr`` as written by `knitbake reference`). The SRBF count matters only under an
environment light and the Gauss–Newton iterations only for a simulated stitch mesh; neither applies to these scenes.
Time: the whole ``render`` call, median of two after a warm-up call. A configuration is on the Pareto front when
no other configuration of the same scene is at least as fast with at most its FLIP (and better in one).

    .venv/bin/python benchmarks/bench_tradeoff.py --packs draft=d.h5,standard=s.h5 --reference-dir DIR
                                                  [--plot tradeoff.png]
"""

import argparse
import dataclasses
import time
from pathlib import Path

import numpy as np
from PIL import Image, ImageDraw

from data_formats.images import read_exr
from data_formats.scene import load_scene
from knitrun.image_metrics import compare_images
from knitrun.render import render

SCENES = ("straight_yarn_directional", "knit_patch_directional")
MSAA = (1, 4, 8)
SHADOW = (512, 2048)


def measure(scene, pack, reference):
    render(scene, {"cotton1": pack})
    runs = []
    for _ in range(2):
        t0 = time.perf_counter()
        image = render(scene, {"cotton1": pack}).image
        runs.append(time.perf_counter() - t0)
    return float(np.median(runs)), compare_images(image, reference)


def pareto(rows):
    """Mark rows (dicts with 'ms', 'flip') that no other row dominates (no worse in both, better in one)."""
    for r in rows:
        r["pareto"] = not any(o["ms"] <= r["ms"] and o["flip"] <= r["flip"] and (o["ms"], o["flip"]) != (r["ms"], r["flip"])
                              for o in rows)


def plot(path, by_scene):
    """Scatter of FLIP against ms per scene (one panel each), Pareto front joined; PIL only."""
    w, h, pad = 480, 320, 48
    canvas = Image.new("RGB", (w * len(by_scene), h), "white")
    draw = ImageDraw.Draw(canvas)
    colours = {"draft": (220, 90, 40), "standard": (40, 90, 220), "final": (40, 160, 60)}
    for k, (name, rows) in enumerate(by_scene.items()):
        x0 = k * w
        ms = np.array([r["ms"] for r in rows])
        fl = np.array([r["flip"] for r in rows])
        lo_x, hi_x = ms.min() * 0.9, ms.max() * 1.1
        lo_y, hi_y = fl.min() * 0.97, fl.max() * 1.03

        def xy(m, f):
            return (x0 + pad + (m - lo_x) / (hi_x - lo_x) * (w - 2 * pad),
                    h - pad - (f - lo_y) / (hi_y - lo_y) * (h - 2 * pad))

        draw.rectangle([x0 + pad, pad, x0 + w - pad, h - pad], outline="black")
        draw.text((x0 + pad, 8), f"{name}: FLIP vs ms", fill="black")
        draw.text((x0 + pad, h - pad + 6), f"{lo_x:.0f} ms", fill="black")
        draw.text((x0 + w - pad - 60, h - pad + 6), f"{hi_x:.0f} ms", fill="black")
        draw.text((x0 + 2, pad), f"{hi_y:.3f}", fill="black")
        draw.text((x0 + 2, h - pad - 10), f"{lo_y:.3f}", fill="black")
        front = sorted((r for r in rows if r["pareto"]), key=lambda r: r["ms"])
        draw.line([xy(r["ms"], r["flip"]) for r in front], fill=(120, 120, 120), width=2)
        for r in rows:
            cx, cy = xy(r["ms"], r["flip"])
            size = 2 + r["msaa"]
            draw.ellipse([cx - size, cy - size, cx + size, cy + size], outline=colours.get(r["quality"], "black"),
                         width=2 if r["shadow"] == 2048 else 1)
        draw.text((x0 + pad + 4, pad + 4), "orange draft, blue standard, green final; size: MSAA; thick: 2048 px shadow map",
                  fill="black")
    canvas.save(path)


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--packs", required=True, help="quality=pack.h5,... e.g. draft=d.h5,standard=s.h5")
    parser.add_argument("--reference-dir", required=True)
    parser.add_argument("--plot", default="docs/tradeoff.png")
    args = parser.parse_args()
    packs = dict(item.split("=", 1) for item in args.packs.split(","))
    root = Path(__file__).resolve().parent.parent / "examples" / "scenes"
    by_scene = {}
    for name in SCENES:
        base = load_scene(root / f"{name}.toml")
        reference = read_exr(Path(args.reference_dir) / f"{name}.exr")
        rows = []
        for quality, pack in packs.items():
            for msaa in MSAA:
                for shadow in SHADOW:
                    scene = dataclasses.replace(base, render=dataclasses.replace(base.render, msaa=msaa,
                                                                                 shadow_map_size=shadow))
                    seconds, metrics = measure(scene, pack, reference)
                    rows.append({"quality": quality, "msaa": msaa, "shadow": shadow, "ms": 1e3 * seconds,
                                 "flip": metrics["flip"], "rmse": metrics["rmse"]})
        pareto(rows)
        by_scene[name] = rows
    print("| scene | bake | MSAA | shadow map | ms | FLIP | RMSE | Pareto |")
    print("|---|---|---|---|---|---|---|---|")
    for name, rows in by_scene.items():
        for r in sorted(rows, key=lambda r: r["ms"]):
            print(f"| {name} | {r['quality']} | {r['msaa']} | {r['shadow']}² | {r['ms']:.0f} | {r['flip']:.4f} | "
                  f"{r['rmse']:.4f} | {'**yes**' if r['pareto'] else ''} |")
    plot(args.plot, by_scene)
    print(f"\nplot: {args.plot}")


if __name__ == "__main__":
    main()
