"""The reference's own floors per example scene and samples per pixel: how far the path-traced reference is from
another fiber instance of itself (the fiber-instance floor) and from another sampling of the same fibers (the
Monte Carlo floor), at the yarn scale (``knitbake.compare.image_metrics.yarn_scale_metrics``).

For each scene and each spp in ``--spp``: reference A (seed S, fiber seed S), B (seed S + 1, fiber seed S + 1) and
C (seed S + 1, fiber seed S), S the scene's seed, as ``knitrun compare`` traces them
(``knitbake.compare.report.FLOORS``); prints the floors (rel L1 at the yarn diameter d and at 2d, FLIP per pixel, B's
mean radiance ratio) and the smallest spp whose Monte Carlo floor is at most half the instance floor at d, the instance
floor taken at the largest spp (a low-spp B carries its own noise). With ``--out`` the three references of the largest
spp are written there as ``<scene>.exr``, ``<scene>_instance.exr`` and ``<scene>_mc.exr`` (with their JSON summaries)
for ``benchmarks/bench_compare.py --reference-dir``.

    .venv/bin/python benchmarks/bench_floors.py [--spp 4,16,64] [--scenes a,b] [--out out/bench/refs]
"""

import argparse
import time
from pathlib import Path

from data_formats.scene import load_scene
from knitbake.compare.image_metrics import compare_images, yarn_scale_metrics
from knitbake.compare.report import FLOORS, yarn_diameter_px
from knitbake.trace.reference import trace_reference, write_reference

ROOT = Path(__file__).resolve().parent.parent
SCENES = ("straight_yarn_directional", "straight_yarn_sky", "straight_yarn_backlit", "knit_patch_directional",
          "knit_patch_sky", "knit_patch_grazing", "simulated_patch_directional")
FILE_SUFFIX = {"instance": "_instance", "monte_carlo": "_mc"}


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--spp", default="4,16,64")
    parser.add_argument("--scenes", default=",".join(SCENES))
    parser.add_argument("--out", default=None, help="write the largest spp's three references here")
    args = parser.parse_args()
    spps = sorted(int(s) for s in args.spp.split(","))
    print("| scene | yarn px | spp | instance rel L1 (d) | (2d) | MC rel L1 (d) | (2d) | MC / instance (d) | "
          "instance FLIP | MC FLIP | B mean ratio | seconds (A+B+C) |")
    print("|---|---|---|---|---|---|---|---|---|---|---|---|")
    for name in args.scenes.split(","):
        scene = load_scene(ROOT / "examples" / "scenes" / f"{name}.toml")
        d, seed = yarn_diameter_px(scene), scene.render.seed
        rows = []
        for spp in spps:
            t0 = time.perf_counter()
            ref, facts = trace_reference(scene, spp, seed, scene.render.max_depth)
            floors = {}
            for floor, ((d_sample, d_fiber), _) in FLOORS.items():
                image, floor_facts = trace_reference(scene, spp, seed + d_sample, scene.render.max_depth,
                                                     fiber_seed=seed + d_fiber)
                floors[floor] = (image, floor_facts, yarn_scale_metrics(image, ref, d),
                                 compare_images(image, ref)["flip"])
            seconds = time.perf_counter() - t0
            inst, mc = floors["instance"][2], floors["monte_carlo"][2]
            rows.append((spp, inst, mc))
            print(f"| {name} | {d:.1f} | {spp} | {inst['rel_l1']:.3f} | {inst['rel_l1_2x']:.3f} | {mc['rel_l1']:.3f} | "
                  f"{mc['rel_l1_2x']:.3f} | {mc['rel_l1'] / inst['rel_l1']:.2f} | {floors['instance'][3]:.4f} | "
                  f"{floors['monte_carlo'][3]:.4f} | {inst['mean_ratio']:.3f} | {seconds:.0f} |", flush=True)
            if args.out and spp == spps[-1]:
                out = Path(args.out)
                out.mkdir(parents=True, exist_ok=True)
                write_reference(out / f"{name}.exr", ref, {"scene": name, **facts})
                for floor, (image, floor_facts, _, _) in floors.items():
                    write_reference(out / f"{name}{FILE_SUFFIX[floor]}.exr", image, {"scene": name, **floor_facts})
        best = rows[-1][1]["rel_l1"]
        enough = [spp for spp, _, mc in rows if mc["rel_l1"] <= 0.5 * best]
        print(f"<!-- {name}: Monte Carlo floor ≤ half the instance floor ({best:.3f} at {spps[-1]} spp) from "
              f"{enough[0] if enough else 'none of these'} spp -->", flush=True)


if __name__ == "__main__":
    main()
