"""Did the strip renderer's images move between two runs of ``bench_compare.py``? (issue 15: speed work must not
change the image.) For every scene folder present in both: the full model's image, largest |Δ| over the peak and
the change of the mean; and over every model, the largest relative change of the yarn-scale mean radiance ratio and
rel L1.

    .venv/bin/python benchmarks/check_image_moved.py --before out/compare3,out/compare3p --after out/compare4
"""

import argparse
import json
from pathlib import Path

import numpy as np

from data_formats.images import read_exr


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--before", required=True, help="comma-separated bench_compare output folders")
    parser.add_argument("--after", required=True)
    args = parser.parse_args()
    worst = {"mean_ratio": 0.0, "rel_l1": 0.0}
    for root in args.before.split(","):
        for old in sorted(p for p in Path(root).iterdir() if (p / "report.json").is_file()):
            new = Path(args.after) / old.name
            if not (new / "report.json").is_file():
                continue
            a, b = (json.loads((d / "report.json").read_text())["ablations"] for d in (old, new))
            for model in a.keys() & b.keys():
                for metric in worst:
                    change = abs(b[model]["yarn"][metric] / a[model]["yarn"][metric] - 1.0)
                    worst[metric] = max(worst[metric], change)
            before, after = (read_exr(d / "strip_full.exr").astype(np.float64) for d in (old, new))
            print(f"{old.name}: full model, largest |Δ| / peak {np.abs(after - before).max() / before.max():.1e}, "
                  f"mean {after.mean() / before.mean() - 1.0:+.1e}")
    print("largest relative change over every model and scene: " +
          ", ".join(f"{k} {v:.1e}" for k, v in worst.items()))


if __name__ == "__main__":
    main()
