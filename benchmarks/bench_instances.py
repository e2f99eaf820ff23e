"""More fiber instances of each example scene's reference, for the ensemble part of the ruler (``knitrun compare
--instance``, ``benchmarks/bench_compare.py --instances``).

One path-traced reference is one draw of the yarn's fibers; its mean radiance alone varies from draw to draw by several
per cent (the back-lit straight yarn: 5.4 % over eight draws, its flyaways), as much as a model's error may. This traces
``--count`` further draws per scene, fiber seed and sampling seed S + 2 … S + 1 + count (S the scene's seed; S and S + 1
are the reference and its instance floor, ``knitbake.compare.report.FLOORS``), at the reference's spp (its JSON summary
in DIR; else the scene's; or ``--spp``), into ``DIR/<scene>_fiber<seed>.exr`` with their JSON summaries, and prints each
draw's mean radiance over the reference's and the spread of the means. A draw already in DIR is kept when its summary
says the same spp (or has none), and traced again (with a line saying so) when it says another.

    .venv/bin/python benchmarks/bench_instances.py --out out/bench/refs2 [--count 6] [--scenes a,b] [--spp N]
"""

import argparse
import time
from pathlib import Path

import numpy as np

from data_formats.images import read_exr
from data_formats.scene import load_scene
from knitbake.trace.reference import read_summary, trace_reference, write_reference

ROOT = Path(__file__).resolve().parent.parent
SCENES = ("straight_yarn_directional", "straight_yarn_sky", "straight_yarn_backlit", "knit_patch_directional",
          "knit_patch_sky", "knit_patch_grazing", "simulated_patch_directional")


def instance_path(folder, scene_name: str, seed: int) -> Path:
    """Where draw ``seed`` of a scene's fibers is kept: ``folder/<scene>_fiber<seed>.exr``."""
    return Path(folder) / f"{scene_name}_fiber{seed}.exr"


def instance_files(folder, scene_name: str) -> list[Path]:
    """Every draw of a scene's fibers kept in ``folder`` (``instance_path``), by seed."""
    found = Path(folder).glob(f"{scene_name}_fiber*.exr")
    return sorted(found, key=lambda f: int(f.stem.rsplit("fiber", 1)[1]))


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--out", required=True, help="folder of the references (bench_floors.py --out)")
    parser.add_argument("--count", type=int, default=6)
    parser.add_argument("--scenes", default=",".join(SCENES))
    parser.add_argument("--spp", type=int, default=None,
                        help="samples per pixel (default: the reference's in --out, else the scene's)")
    args = parser.parse_args()
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    print("| scene | spp | draws | mean of each draw over the reference's | spread (sd) | seconds |")
    print("|---|---|---|---|---|---|")
    for name in args.scenes.split(","):
        scene = load_scene(ROOT / "examples" / "scenes" / f"{name}.toml")
        ref = out / f"{name}.exr"
        summary = read_summary(ref) if ref.is_file() else None
        spp, seed = args.spp or (summary or {}).get("spp") or scene.render.spp, scene.render.seed
        t0 = time.perf_counter()
        means = []
        for k in range(seed + 2, seed + 2 + args.count):
            path = instance_path(out, name, k)
            kept = (read_summary(path) or {}).get("spp", spp) if path.is_file() else spp
            if kept != spp:  # a draw of another spp is not this ruler's
                print(f"{path}: traced at {kept} spp, not {spp}: traced again", flush=True)
                path.unlink()
            if not path.is_file():
                image, facts = trace_reference(scene, spp, k, scene.render.max_depth, fiber_seed=k)
                write_reference(path, image, {"scene": name, **facts})
            means.append(float(read_exr(path).mean()))
        base = float(read_exr(ref).mean()) if ref.is_file() else float(np.mean(means))
        ratios = np.array(means) / base
        spread = f"{ratios.std(ddof=1):.3f}" if len(ratios) > 1 else "—"  # one draw has no spread
        print(f"| {name} | {spp} | {args.count} | {', '.join(f'{r:.3f}' for r in ratios)} | {spread} | "
              f"{time.perf_counter() - t0:.0f} |", flush=True)


if __name__ == "__main__":
    main()
