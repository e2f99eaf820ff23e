"""The light two or more yarns side by side send each other, in the reference and in the strip renderer's bounce
(issue 13, the look): the yarn-level bounce's phase and its share on the hairs, away from a knit's shapes.

Straight white cotton1 yarns 0.9 cm long in the frame of ``knit_patch_directional`` (its camera, light and yarn
radius r), laid out by ``--layouts``, each "kind:h:n":

* ``parallel:h:n``: n parallel yarns along x in the fabric plane, their axes h·r apart (h = 2: touching);
* ``crossing:h:n``: one yarn along x and n along y h·r behind it, 6 r apart.

Per layout, the reference traced at ``--spp`` twice (``trace_reference``; ``inter_yarn=False`` the second time:
paths end where they would scatter off another yarn) and the strips drawn with ``full``, ``no_hair_bounce`` and
``no_bounce``. Printed: the inter-yarn light's share of the reference (the two references' difference), the bounce
over it (full less ``no_bounce``) and the bodies' part alone (``no_hair_bounce`` less ``no_bounce``), the yarn-scale
correlation of the bounce with it (``knitbake.compare.image_metrics.yarn_filter``), each yarn's own light (strips
without the bounce over the reference without inter-yarn light) and the full model over the reference.

    .venv/bin/python benchmarks/probe_yarn_pairs.py --pack out/bench/cotton1_standard_66.h5 \\
        [--layouts parallel:2:2,parallel:3:2,parallel:2.2:5,crossing:2:3] [--spp 16] [--out out/probe_yarn_pairs]
"""

from __future__ import annotations

import argparse
import dataclasses
from pathlib import Path

import numpy as np

from data_formats.scene import load_scene
from data_formats.yarn_curves import make_yarn_curves, write_yarn_curves
from knitbake.compare.image_metrics import yarn_filter
from knitbake.compare.report import yarn_diameter_px
from knitbake.trace.reference import trace_reference
from knitrun.render import pipeline
from knitrun.render.ablations import combined

ROOT = Path(__file__).resolve().parent.parent
KINDS = ("parallel", "crossing")
HALF_LENGTH = 0.45  # cm
SAMPLES = 241  # polyline points per yarn
CROSSING_SPACING_RADII = 6.0


def parse_layout(text: str):
    """(kind, h, n) of one "kind:h:n" of ``--layouts``; ValueError naming what is wrong."""
    parts = text.split(":")
    if len(parts) != 3 or parts[0] not in KINDS:
        raise ValueError(f"layout {text!r}: expected kind:h:n with kind one of {', '.join(KINDS)}")
    kind, h, n = parts[0], float(parts[1]), int(parts[2])
    if not (h >= 2.0 and n >= 1):
        raise ValueError(f"layout {text!r}: h must be at least 2 (touching yarns) and n at least 1")
    return kind, h, n


def layout_curves(kind: str, h: float, n: int, radius: float, centre) -> list:
    """The yarns' polylines (module docstring) about ``centre`` (the camera's look-at point), in cm."""
    cx, cy = float(centre[0]), float(centre[1])
    along = np.linspace(-HALF_LENGTH, HALF_LENGTH, SAMPLES)
    zero = np.zeros(SAMPLES)
    if kind == "parallel":
        return [np.stack([cx + along, zero + cy + (k - (n - 1) / 2) * h * radius, zero], axis=1) for k in range(n)]
    curves = [np.stack([cx + along, zero + cy, zero], axis=1)]
    for k in range(n):
        x = cx + (k - (n - 1) / 2) * CROSSING_SPACING_RADII * radius
        curves.append(np.stack([zero + x, cy + along, zero - h * radius], axis=1))
    return curves


def layout_scene(kind: str, h: float, n: int, folder: Path):
    """``knit_patch_directional`` with its yarns swapped for the layout's, white."""
    base = load_scene(ROOT / "examples" / "scenes" / "knit_patch_directional.toml")
    entry = base.yarns[0]
    curves = layout_curves(kind, h, n, entry.radius, base.camera.look_at)
    offsets = np.cumsum([0] + [len(c) for c in curves])
    path = folder / f"{kind}_{h:g}_{n}.h5"
    write_yarn_curves(path, make_yarn_curves(np.concatenate(curves), offsets, yarn_types=["cotton1"],
                                             curve_type="PL", units="cm"))
    return dataclasses.replace(base, yarns=(dataclasses.replace(entry, curves=path, color=(1.0, 1.0, 1.0)),))


def main():
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--pack", required=True, help="the asset pack of cotton1")
    parser.add_argument("--layouts", default="parallel:2:2,parallel:3:2,parallel:2.2:5,crossing:2:3",
                        help="comma-separated kind:h:n (module docstring)")
    parser.add_argument("--spp", type=int, default=16, help="samples per pixel of the references")
    parser.add_argument("--out", default="out/probe_yarn_pairs", help="folder for the layouts' curve files")
    args = parser.parse_args()
    try:
        layouts = [parse_layout(t) for t in args.layouts.split(",")]
    except ValueError as error:
        parser.error(f"--layouts: {error}")
    if args.spp < 1:
        parser.error("--spp: at least 1")
    folder = Path(args.out)
    folder.mkdir(parents=True, exist_ok=True)
    print("| layout | inter-yarn share of the reference | bounce / inter-yarn (bodies alone) | yarn-scale correlation "
          "| own light: strips / reference | full / reference |")
    print("|---|---|---|---|---|---|")
    for kind, h, n in layouts:
        scene = layout_scene(kind, h, n, folder)
        seed, depth = scene.render.seed, scene.render.max_depth

        def traced(inter_yarn, scene=scene, seed=seed, depth=depth):
            image = trace_reference(scene, args.spp, seed, depth, inter_yarn=inter_yarn)[0]
            return np.asarray(image, np.float64)[..., :3]

        def drawn(model, scene=scene):
            image = pipeline.Renderer(scene, {"cotton1": args.pack}, combined(model)).render().image
            return np.asarray(image, np.float64)[..., :3]

        full, own = traced(True), traced(False)
        strips, bodies, bounced = drawn("no_bounce"), drawn("no_hair_bounce"), drawn("full")
        between, bounce = full - own, bounced - strips
        d = yarn_diameter_px(scene)
        a, b = yarn_filter(between, d).mean(-1).ravel(), yarn_filter(bounce, d).mean(-1).ravel()
        corr = float(np.corrcoef(a, b)[0, 1]) if a.std() > 0 and b.std() > 0 else float("nan")
        print(f"| {kind}:{h:g}:{n} | {between.mean() / full.mean():.3f} | {bounce.mean() / between.mean():.2f} "
              f"({(bodies - strips).mean() / between.mean():.2f}) | {corr:.2f} | {strips.mean() / own.mean():.3f} | "
              f"{bounced.mean() / full.mean():.3f} |", flush=True)


if __name__ == "__main__":
    main()
