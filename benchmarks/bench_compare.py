"""Strip renderer vs the reference path tracer on the four example scenes (a straight yarn and a 6 × 6 knit patch,
each under a directional light and under the built-in sky): FLIP, RMSE, relMSE and time per ablation, and the
speed ratio to the reference. One `knitrun compare` report folder per scene under ``--out``.

    .venv/bin/python benchmarks/bench_compare.py --pack cotton1.h5 [--spp 64] [--out out/compare]
                                                 [--reference-dir DIR]

``--reference-dir`` reuses references rendered earlier (``DIR/<scene stem>.exr`` with the JSON summary
`knitbake reference` writes beside it); otherwise each reference is path traced at ``--spp``.
"""

import argparse
from pathlib import Path

from knitbake.compare.report import compare_scene
from knitrun.render.ablations import ABLATION_LABELS

SCENES = ("straight_yarn_directional", "straight_yarn_sky", "knit_patch_directional", "knit_patch_sky")


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--pack", required=True, help="cotton1 asset pack")
    parser.add_argument("--spp", type=int, default=64)
    parser.add_argument("--out", default="out/compare")
    parser.add_argument("--reference-dir", default=None)
    args = parser.parse_args()
    root = Path(__file__).resolve().parent.parent / "examples" / "scenes"
    print("| scene | model | FLIP | RMSE | relMSE | strip ms | reference s | speed-up |")
    print("|---|---|---|---|---|---|---|---|")
    for name in SCENES:
        ref = None
        if args.reference_dir:
            candidate = Path(args.reference_dir) / f"{name}.exr"
            ref = candidate if candidate.is_file() else None
        summary = compare_scene(root / f"{name}.toml", Path(args.out) / name, reference=ref,
                                spp=None if ref else args.spp, packs={"cotton1": args.pack})
        ref_s = summary["reference_seconds"]
        for model, row in summary["ablations"].items():
            speed = f"{row['speedup']:.0f}×" if row["speedup"] else "—"
            print(f"| {name} | {ABLATION_LABELS[model]} | {row['flip']:.4f} | {row['rmse']:.4f} | "
                  f"{row['rel_mse']:.4f} | {row['ms']:.0f} | {ref_s:.0f} | {speed} |" if ref_s else
                  f"| {name} | {ABLATION_LABELS[model]} | {row['flip']:.4f} | {row['rmse']:.4f} | "
                  f"{row['rel_mse']:.4f} | {row['ms']:.0f} | — | — |", flush=True)


if __name__ == "__main__":
    main()
