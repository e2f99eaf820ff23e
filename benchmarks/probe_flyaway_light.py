"""What the flyaways add to each example scene, in the reference and in the strip renderer (issue 13, the look), and
where: over the yarn's body, at its edge, or beside it.

The reference is traced a second time with its regular fibers alone (``trace_reference(..., flyaways=False)``: the
loop and hair fibers of the same draw dropped, the same seeds); the full reference less it is the light the
flyaways add, counting the light they scatter and the body's light they hide. The strip renderer's counterpart is
the full model less the ablation ``closed`` (the full model without its flyaway layers). Pixels fall into three
regions by the front regular strips' MSAA coverage (``strip_raster.rasterize_visibility`` at the yarn radius): over
the body (covered), at its edge (partly), beside it (not). Printed per scene, over the background and as shares of
the image without flyaways (luminance-free: the mean of RGB): the flyaways' light in all and per region for the
reference and the strips; and the strips without flyaways against the reference without them (mean ratio and
yarn-scale rel L1), which says whether a scene's error lies in the regular fibers or in the hairs. A second table
splits the same shares by how bright the yarns are there: the regular-only reference filtered to the yarn's projected
diameter, its pixels with light (over 1 % of its largest) cut into four quarters from darkest to brightest, and the
rest ("no yarn"). It says whether the hairs' light is wrong on the lit or the shadowed side of a knit.

The full references are read from ``--reference-dir`` (``<scene>.exr``, as ``bench_floors.py`` writes them; the
scene's spp and seed); the regular-only ones are traced at the same spp and seed and kept in ``--out``
(``<scene>_regular.exr``, read again when present). 10–60 s per scene on 2 cores, the first time.

    .venv/bin/python benchmarks/probe_flyaway_light.py --pack out/bench/cotton1_standard_51.h5 \\
        --reference-dir out/bench/refs2 --out out/bench/regular_refs [--scenes a,b]
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np

from data_formats.images import read_exr, write_exr
from data_formats.scene import load_scene
from knitbake.compare.image_metrics import yarn_filter, yarn_scale_metrics
from knitbake.compare.report import yarn_diameter_px
from knitbake.trace.reference import trace_reference
from knitrun.render import pipeline
from knitrun.render.ablations import combined
from knitrun.render.camera import scene_camera
from knitrun.render.strip_raster import rasterize_visibility

sys.path.insert(0, str(Path(__file__).resolve().parent))
from probe_split import ROOT, SCENES, checked_models_and_scenes  # noqa: E402

REGIONS = ("over the body", "at its edge", "beside it")
QUARTERS = ("no yarn", "darkest quarter", "2nd", "3rd", "brightest quarter")


def body_coverage(scene) -> np.ndarray:
    """(H, W) fraction of each pixel's MSAA samples that a regular strip of the scene's frame covers."""
    lines = pipeline._polylines(scene, [pipeline._scene_curves(e, scene.units, []) for e in scene.yarns],
                                scene.render.frame, 4)
    radius = np.array([scene.yarns[k].radius for k in lines.entry])
    vis = rasterize_visibility(lines.points, lines.offsets, False, lines.rest, radius, lines.entry,
                               scene_camera(scene), scene.render.msaa)
    return vis.coverage.mean(axis=-1)


def brightness_classes(regular_light: np.ndarray, diameter_px: float) -> list[np.ndarray]:
    """Masks of ``QUARTERS``: pixels by the brightness of the regular-only light (H, W) filtered to the yarn's
    diameter; the quarters split the pixels over 1 % of its largest at its quartiles."""
    smooth = yarn_filter(regular_light[..., None], diameter_px)[..., 0]
    lit = smooth > 0.01 * smooth.max()
    edges = np.quantile(smooth[lit], [0.25, 0.5, 0.75])
    index = np.digitize(smooth, edges)
    return [~lit] + [lit & (index == i) for i in range(4)]


def main():
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--pack", required=True, help="the asset pack of cotton1")
    parser.add_argument("--reference-dir", required=True, help="the full references, <scene>.exr")
    parser.add_argument("--out", required=True, help="folder for the regular-only references")
    parser.add_argument("--scenes", default=",".join(SCENES), help="comma-separated example scene names")
    args = parser.parse_args()
    args.models = "closed,full"
    _, names = checked_models_and_scenes(parser, args)
    missing = [n for n in names if not (Path(args.reference_dir) / f"{n}.exr").is_file()]
    if missing:
        parser.error(f"--reference-dir: no {missing[0]}.exr")
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    print("| scene | flyaways add: reference | strips | " + " | ".join(f"{r}: ref / strips" for r in REGIONS) +
          " | strips / reference without flyaways: mean | yarn-scale rel L1 |")
    print("|---|---|---|" + "---|" * len(REGIONS) + "---|---|")
    by_brightness = []
    for name in names:
        scene = load_scene(ROOT / "examples" / "scenes" / f"{name}.toml")
        regular_path = out / f"{name}_regular.exr"
        if not regular_path.is_file():
            image, _ = trace_reference(scene, scene.render.spp, scene.render.seed, scene.render.max_depth,
                                       flyaways=False)
            write_exr(regular_path, image)
        background = np.asarray(scene.background, np.float64)

        def light(image, background=background):
            return (np.asarray(image, np.float64)[..., :3] - background).mean(axis=-1)

        reference, regular = read_exr(Path(args.reference_dir) / f"{name}.exr"), read_exr(regular_path)
        drawn = {model: pipeline.Renderer(scene, {"cotton1": args.pack}, combined(model)).render().image
                 for model in ("closed", "full")}
        ref_add, ref_base = light(reference) - light(regular), light(regular).sum()
        strip_add, strip_base = light(drawn["full"]) - light(drawn["closed"]), light(drawn["closed"]).sum()
        cover = body_coverage(scene)
        regions = (cover == 1.0, (cover > 0.0) & (cover < 1.0), cover == 0.0)
        cells = " | ".join(f"{100 * ref_add[m].sum() / ref_base:+.1f} / {100 * strip_add[m].sum() / strip_base:+.1f} %"
                           for m in regions)
        alone = yarn_scale_metrics(drawn["closed"], regular, yarn_diameter_px(scene))
        print(f"| {name} | {100 * ref_add.sum() / ref_base:+.1f} % | {100 * strip_add.sum() / strip_base:+.1f} % | "
              f"{cells} | {alone['mean_ratio']:.3f} | {alone['rel_l1']:.3f} |", flush=True)
        by_brightness.append(f"| {name} | " + " | ".join(
            f"{100 * ref_add[m].sum() / ref_base:+.1f} / {100 * strip_add[m].sum() / strip_base:+.1f} %"
            for m in brightness_classes(light(regular), yarn_diameter_px(scene))) + " |")
    print("\nThe same, by the regular fibers' brightness at the yarn scale (reference / strips):\n")
    print("| scene | " + " | ".join(QUARTERS) + " |")
    print("|---|" + "---|" * len(QUARTERS))
    print("\n".join(by_brightness))


if __name__ == "__main__":
    main()
