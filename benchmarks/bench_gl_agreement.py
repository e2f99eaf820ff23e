"""The GL backend against the CPU renderer on the example scenes (issue 20): mean radiance ratio GL / CPU and the
yarn-scale relative L1 between the two images, also as a ratio to the scene's fiber-instance floor (the reference
against its other fiber instance, ``benchmarks/bench_floors.py``); frame ms of each renderer after a warm-up frame
(the GL one with its set-up kept, the CPU one likewise). Targets: mean within 2 %, L1 at most a quarter of the floor.
Then the GL image against the reference itself, as ``bench_compare.py`` measures the CPU renderer: its mean radiance
over the reference's and its yarn-scale rel L1 over the instance floor (the scene's ``layers`` of regular strips and
``hair_layers`` of flyaway strips on both backends since knit's stop 73).

    .venv/bin/python benchmarks/bench_gl_agreement.py --pack out/bench/cotton1_standard.h5 \\
        --reference-dir out/bench/refs2 [--scenes a,b] [--ablation papers_xi | axis_shadows+no_parallax]
"""

import argparse
import time
from pathlib import Path

from data_formats.images import read_exr
from data_formats.scene import load_scene
from knitbake.compare.image_metrics import yarn_scale_metrics
from knitbake.compare.report import yarn_diameter_px
from knitrun.render.ablations import combined
from knitrun.render.gl.gl_renderer import GLRenderer, gl_context

SCENES = ("straight_yarn_directional", "straight_yarn_sky", "straight_yarn_backlit", "knit_patch_directional",
          "knit_patch_sky", "knit_patch_grazing", "simulated_patch_directional")
EXAMPLES = Path(__file__).resolve().parent.parent / "examples" / "scenes"


def timed(draw):
    draw()
    start = time.perf_counter()
    image = draw().image
    return image, (time.perf_counter() - start) * 1e3


def main():
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--pack", required=True, help="cotton1 asset pack")
    parser.add_argument("--reference-dir", required=True, help="folder of <scene>.exr and <scene>_instance.exr")
    parser.add_argument("--scenes", default=",".join(SCENES))
    parser.add_argument("--ablation", default="full", help="an ablation or a combination a+b (ablations.combined)")
    args = parser.parse_args()
    try:
        features = combined(args.ablation)
    except ValueError as e:
        parser.error(f"--ablation: {e}")
    print(f"GL: {gl_context().info['GL_RENDERER']}; ablation {args.ablation}\n")
    print("| scene | mean GL / CPU | yarn-scale rel L1 | / instance floor | GL ms | CPU ms | GL / reference: mean | "
          "rel L1 / instance floor |")
    print("|---|---|---|---|---|---|---|---|")
    for name in args.scenes.split(","):
        scene = load_scene(EXAMPLES / f"{name}.toml")
        with GLRenderer(scene, {"cotton1": args.pack}, features) as renderer:
            gl, gl_ms = timed(renderer.render)
            cpu, cpu_ms = timed(renderer.cpu.render)
        diameter = yarn_diameter_px(scene)
        ref = Path(args.reference_dir)
        reference = read_exr(ref / f"{name}.exr")
        floor = yarn_scale_metrics(read_exr(ref / f"{name}_instance.exr"), reference, diameter)["rel_l1"]
        l1 = yarn_scale_metrics(gl, cpu, diameter)["rel_l1"]
        truth = yarn_scale_metrics(gl, reference, diameter)
        print(f"| {name} | {gl.mean() / cpu.mean():.4f} | {l1:.4f} | {l1 / floor:.3f}× | {gl_ms:.0f} | {cpu_ms:.0f} | "
              f"{truth['mean_ratio']:.3f} | {truth['rel_l1'] / floor:.2f}× |", flush=True)


if __name__ == "__main__":
    main()
