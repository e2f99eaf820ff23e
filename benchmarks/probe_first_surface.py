"""The light by the surface the camera sees first, hairs or regular fibers, reference against strips (issue 13).

``probe_regions.py --regular-dir`` measures what the hairs *add*: the full reference less the one traced without
flyaways. That net figure mixes the hairs' own light with what they take from the yarns (the body they hide, the
light they keep off other yarns) and cannot say which of the two a model gets wrong. This probe splits the light
where it leaves toward the camera instead, the same way on both sides:

* the reference traced with ``seen="regular"`` (``knitbake.trace.reference.build_reference``): the light of the
  paths whose camera ray first hits a regular fiber, the flyaways present (they block, scatter and shadow); the full
  reference (the same seeds) less it is the light leaving the flyaways, what they scatter and what they pass on of
  the yarn behind them;
* the strips with ``Features(hair_light=False)`` (``knitrun.render.ablations``: the hairs opaque and black), the
  regular fibers' light between the hairs; the full strips less it, the hairs' light, their transmission included.

Per scene and box (``probe_regions.PATCH_BOXES`` on the knit patches, the whole image everywhere) it prints the
shares of the reference's light on the hairs and on the regular fibers, each strip share over the reference's, and
the whole box's ratio; light is the mean of RGB, as ``probe_regions.py``. The traces use the scene's seeds and the
ruler's spp (``probe_split.SCENES``) unless ``--spp``; ``--out DIR`` keeps the images per scene.

``--without-hairs`` also traces the reference without its flyaways (``flyaways=False``: the same regular fibers)
and renders the model without its flyaway layer, and adds a table: the regular fibers' light seen between the hairs
over their light with no hairs at all, in the reference and in the strips. The hairs hide about as much of the
bodies in both (stop 60: 0.805 and 0.815 of the grazing interior's bodies' light, scratch ray casting); what is left
is how much darker the hairs make the bodies they do not hide.

    .venv/bin/python benchmarks/probe_first_surface.py --pack out/bench/cotton1_standard_56.h5 \\
        [--scenes knit_patch_grazing,knit_patch_directional] [--model full] [--spp N] [--without-hairs] [--out DIR]
"""

from __future__ import annotations

import argparse
import dataclasses
import sys
import time
from pathlib import Path

import numpy as np

from data_formats.images import write_exr
from data_formats.scene import load_scene
from knitbake.trace.reference import trace_reference
from knitrun.render import pipeline
from knitrun.render.ablations import combined

sys.path.insert(0, str(Path(__file__).resolve().parent))
from probe_regions import PATCH_BOXES, boxes_and_all, parse_box  # noqa: E402
from probe_split import SCENES  # noqa: E402

ROOT = Path(__file__).resolve().parent.parent


def split_table(ref_all, ref_regular, strip_all, strip_regular, boxes) -> list[str]:
    """Lines of one scene's table (module docstring) from the four (H, W) light images."""
    lines = ["| box | reference: on hairs | on regular fibers | strips / reference: hairs | regular fibers | whole |",
             "|---|---|---|---|---|---|"]
    for name, (y0, y1, x0, x1) in boxes_and_all(ref_all.shape, boxes):
        box = (slice(y0, y1), slice(x0, x1))
        ref, ref_reg = float(ref_all[box].sum()), float(ref_regular[box].sum())
        strip, strip_reg = float(strip_all[box].sum()), float(strip_regular[box].sum())
        ref_hair, strip_hair = ref - ref_reg, strip - strip_reg
        if ref <= 0.0 or ref_reg <= 0.0 or ref_hair <= 0.0:
            lines.append(f"| {name} | no light of both kinds in the box | | | | |")
            continue
        lines.append(f"| {name} | {ref_hair / ref:.3f} | {ref_reg / ref:.3f} | {strip_hair / ref_hair:.2f} | "
                     f"{strip_reg / ref_reg:.2f} | {strip / ref:.3f} |")
    return lines


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--pack", required=True, help="the asset pack of cotton1")
    parser.add_argument("--scenes", default="knit_patch_grazing,knit_patch_directional",
                        help=f"comma-separated example scene names ({', '.join(SCENES)})")
    parser.add_argument("--model", default="full", help="the strip model (an ablation or a+b combination)")
    parser.add_argument("--spp", type=int, default=None, help="samples per pixel (default: the ruler's per scene)")
    parser.add_argument("--without-hairs", action="store_true",
                        help="also trace and render without flyaways: how much the hairs darken the bodies")
    parser.add_argument("--out", type=Path, default=None, help="keep the images here")
    args = parser.parse_args(argv)
    scenes = [s for s in args.scenes.split(",") if s]
    unknown = [s for s in scenes if s not in SCENES]
    if unknown:
        parser.error(f"unknown scene {unknown[0]!r} (one of {', '.join(SCENES)})")
    try:
        features = combined(args.model)
    except ValueError as err:
        parser.error(str(err))
    if not features.flyaways:
        parser.error(f"model {args.model!r} draws no flyaways: nothing to split")
    for name in scenes:
        scene = load_scene(ROOT / "examples" / "scenes" / f"{name}.toml")
        spp, seed = args.spp or SCENES[name], scene.render.seed
        t0 = time.perf_counter()
        ref_all, _ = trace_reference(scene, spp, seed=seed, max_depth=scene.render.max_depth)
        ref_regular, _ = trace_reference(scene, spp, seed=seed, max_depth=scene.render.max_depth, seen="regular")
        traced_s = time.perf_counter() - t0
        packs = {str(k): args.pack for k in range(len(scene.yarns))}  # every entry of the example scenes: cotton1
        strip_all = pipeline.render(scene, packs, features).image
        strip_regular = pipeline.render(scene, packs, dataclasses.replace(features, hair_light=False)).image
        images = {"reference": ref_all, "reference_regular": ref_regular, "strip": strip_all,
                  "strip_regular": strip_regular}
        if args.without_hairs:
            images["reference_bare"] = trace_reference(scene, spp, seed=seed, max_depth=scene.render.max_depth,
                                                       flyaways=False)[0]
            images["strip_bare"] = pipeline.render(scene, packs, dataclasses.replace(features, flyaways=False)).image
        if args.out is not None:
            (args.out / name).mkdir(parents=True, exist_ok=True)
            for key, image in images.items():
                write_exr(args.out / name / f"{key}.exr", np.asarray(image, np.float32))
        light = {key: np.asarray(image, np.float64)[..., :3].mean(axis=-1) for key, image in images.items()}
        boxes = [parse_box(b) for b in PATCH_BOXES] if light["reference"].shape == (512, 512) else []
        print(f"\n{name} ({spp} spp, traced in {traced_s:.0f} s; model {args.model})\n")
        print("\n".join(split_table(light["reference"], light["reference_regular"], light["strip"],
                                    light["strip_regular"], boxes)))
        if args.without_hairs:
            print("\n| box | regular fibers between the hairs / without hairs: reference | strips |\n|---|---|---|")
            for box, (y0, y1, x0, x1) in boxes_and_all(light["reference"].shape, boxes):
                at = (slice(y0, y1), slice(x0, x1))
                ratio = [float(light[a][at].sum()) / max(float(light[b][at].sum()), 1e-300)
                         for a, b in (("reference_regular", "reference_bare"), ("strip_regular", "strip_bare"))]
                print(f"| {box} | {ratio[0]:.3f} | {ratio[1]:.3f} |")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
