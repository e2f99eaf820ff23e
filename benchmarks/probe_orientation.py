"""How the strip model's brightness depends on a yarn's orientation to the light (issue 13, the look).

A straight cotton1 yarn lies in the image plane at angle α to the x axis (α = −60°, −30°, 0°, 30°, 60°, 90°), seen
head-on by an orthographic camera (θ_o = 0) and lit by the directional light of ``knit_patch_directional`` (toward
(0.4, 0.6, 1.0)), so θ_i runs from −15° to 36° and the light's azimuth about the yarn changes sign. Each scene is path
traced with the flyaways switched off (the regular fibers the strip model draws; ``check_brightness_gap.py``'s
reference) and rendered by the strip renderer with each pack and ablation named, without its flyaway layer;
printed: per α, the reference's mean luminance in the central 160 × 160 pixels and each model's over it there, and the
RMS of the ratios' logarithms over the six. ``--light`` puts the light elsewhere (``knit_patch_grazing``'s:
0.2,1.0,0.3, where θ_i reaches 70°).

A knit shows its yarns at every orientation, so a model right at one orientation only (the example straight yarn
is α = 0) is wrong on a fabric: this is the quick check for that (about 30 s per pack on 2 cores).

    .venv/bin/python benchmarks/probe_orientation.py --pack out/bench/cotton1_standard.h5 \\
        [--ablations full,factored,plain_ds] [--light 0.2,1.0,0.3] [--spp 32] [--out out/probe_orientation]
"""

from __future__ import annotations

import argparse
import math
import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).parent))
from check_brightness_gap import _trace_without_flyaways  # noqa: E402

from data_formats.conventions import LUMINANCE  # noqa: E402
from data_formats.images import read_exr, write_exr  # noqa: E402
from data_formats.scene import load_scene  # noqa: E402
from data_formats.yarn_curves import make_yarn_curves, write_yarn_curves  # noqa: E402
from knitrun.render.ablations import regular_fibers  # noqa: E402
from knitrun.render.pipeline import render  # noqa: E402

ANGLES = (-60, -30, 0, 30, 60, 90)
LIGHT = np.array([0.4, 0.6, 1.0])
SIZE = 256
CROP = slice(48, 208)


def _scene(folder: Path, alpha: int, spp: int, light: np.ndarray) -> Path:
    d = np.array([math.cos(math.radians(alpha)), math.sin(math.radians(alpha)), 0.0])
    points = np.linspace(-0.6, 0.6, 25)[:, None] * d
    write_yarn_curves(folder / f"yarn_{alpha}.h5", make_yarn_curves(points[None], np.array([0, 25], np.int64),
                                                                  yarn_types=["cotton1"], units="cm"))
    path = folder / f"yarn_{alpha}.toml"
    path.write_text(f"""format = "knit-scene"
version = "1.0"
units = "cm"
background = [0.0, 0.0, 0.0]
[[yarns]]
curves = "yarn_{alpha}.h5"
yarn = "cotton1"
radius = 0.03
[camera]
position = [0.0, 0.0, 2.0]
look_at = [0.0, 0.0, 0.0]
up = [0.0, 1.0, 0.0]
ortho_height = 0.5
width = {SIZE}
height = {SIZE}
[[lights]]
type = "directional"
direction = {light.tolist()}
irradiance = [3.0, 3.0, 3.0]
[render]
spp = {spp}
""")
    return path


def main():
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--pack", action="append", required=True, help="cotton1 asset pack (repeatable)")
    parser.add_argument("--ablations", default="full", help="comma-separated ablations (knitrun render --ablation)")
    parser.add_argument("--spp", type=int, default=32, help="spp of the flyaway-free references")
    parser.add_argument("--light", default=",".join(str(c) for c in LIGHT),
                        help="direction toward the light, x,y,z (default knit_patch_directional's; "
                             "knit_patch_grazing's is 0.2,1.0,0.3)")
    parser.add_argument("--out", default="out/probe_orientation", help="folder for scenes and references (reused)")
    args = parser.parse_args()
    direction = np.array([float(c) for c in args.light.split(",")])
    if direction.shape != (3,) or not np.all(np.isfinite(direction)) or not np.linalg.norm(direction) > 0:
        parser.error(f"--light {args.light!r}: give three finite numbers, not all zero")
    light = direction / np.linalg.norm(direction)
    folder = Path(args.out) / "light_{:+.3f}_{:+.3f}_{:+.3f}".format(*light)
    folder.mkdir(parents=True, exist_ok=True)
    references, scenes = {}, {}
    for alpha in ANGLES:
        scenes[alpha] = load_scene(_scene(folder, alpha, args.spp, direction))
        exr = folder / f"reference_{alpha}_{args.spp}spp.exr"
        if not exr.is_file():
            write_exr(exr, _trace_without_flyaways(scenes[alpha], args.spp).astype(np.float32))
        references[alpha] = read_exr(exr) @ LUMINANCE
    header = " | ".join(f"α = {a}° (θ_i {math.degrees(math.asin(light @ [math.cos(math.radians(a)), math.sin(math.radians(a)), 0])):+.0f}°)"  # noqa: E501
                        for a in ANGLES)
    print(f"| pack | model | {header} | RMS log |")
    print("|---|---|" + "---|" * (len(ANGLES) + 1))
    print("| reference | mean luminance | " + " | ".join(f"{references[a][CROP, CROP].mean():.4f}" for a in ANGLES)
          + " | |")
    for pack in args.pack:
        for ablation in args.ablations.split(","):
            ratios = []
            for alpha in ANGLES:
                image = render(scenes[alpha], {"cotton1": pack}, regular_fibers(ablation)).image @ LUMINANCE
                ratios.append(float(image[CROP, CROP].sum() / references[alpha][CROP, CROP].sum()))
            rms = math.sqrt(float(np.mean(np.log(ratios) ** 2)))
            print(f"| {Path(pack).name} | {ablation} | " + " | ".join(f"{r:.3f}" for r in ratios) + f" | {rms:.3f} |")


if __name__ == "__main__":
    main()
