"""Do the two reference geometries (fibers as Embree curves, fibers as 6-sided tubes) draw the same image? (issue 16)
For each scene: the reference traced both ways with the same seeds (build and render seconds; memory is measured by
``bench_curves.py``), and the curves image's yarn-scale metrics against the tubes image, next to the scene's
instance floor (``bench_floors.py`` output, when given: another fiber instance, at that run's spp).

    .venv/bin/python benchmarks/check_geometry.py --spp 16 [--scenes knit_patch_directional,...] \\
        [--reference-dir out/bench/refs2]
"""

import argparse
from pathlib import Path

from data_formats.images import read_exr
from data_formats.scene import load_scene
from knitbake.compare.image_metrics import yarn_scale_metrics
from knitbake.compare.report import yarn_diameter_px
from knitbake.trace.reference import trace_reference

EXAMPLES = Path(__file__).resolve().parent.parent / "examples" / "scenes"


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--spp", type=int, default=16)
    parser.add_argument("--scenes", default="straight_yarn_directional,knit_patch_directional,knit_patch_sky")
    parser.add_argument("--reference-dir", default=None, help="bench_floors.py output: the instance floors")
    args = parser.parse_args()
    print("| scene | tubes: build + render s | curves: build + render s | mean ratio curves/tubes | "
          "yarn-scale rel L1 | instance floor |")
    print("|---|---|---|---|---|---|")
    for name in args.scenes.split(","):
        scene = load_scene(EXAMPLES / f"{name}.toml")
        images, facts = {}, {}
        for geometry in ("tubes", "curves"):
            images[geometry], facts[geometry] = trace_reference(scene, args.spp, scene.render.seed,
                                                                scene.render.max_depth, geometry=geometry)
        d = yarn_diameter_px(scene)
        m = yarn_scale_metrics(images["curves"], images["tubes"], d)
        floor = "—"
        if args.reference_dir:
            folder = Path(args.reference_dir)
            instance, ref = read_exr(folder / f"{name}_instance.exr"), read_exr(folder / f"{name}.exr")
            floor = f"{yarn_scale_metrics(instance, ref, d)['rel_l1']:.3f}"
        cost = {g: f"{f['sweep_s'] + f['tessellate_s'] + f['embree_build_s']:.1f} + {f['render_s']:.1f}"
                for g, f in facts.items()}
        print(f"| {name} | {cost['tubes']} | {cost['curves']} | {m['mean_ratio']:.4f} | {m['rel_l1']:.3f} | {floor} |",
              flush=True)


if __name__ == "__main__":
    main()
