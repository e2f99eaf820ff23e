"""Strip renderer vs the reference path tracer on the seven example scenes (a straight yarn under a directional light,
under the built-in sky and back-lit; a 6 × 6 knit patch under a directional light, under the sky and under a grazing
light; the simulated, stretched patch of the trade-off sweep), next to the reference's own floors: per model the mean
radiance ratio, the yarn-scale rel L1 and its ratio to the fiber-instance floor, pixel FLIP and time, and the speed
ratio to the reference. One `knitrun compare` report folder per scene under ``--out``.

    .venv/bin/python benchmarks/bench_compare.py --pack cotton1.h5 [--spp 64] [--out out/compare]
                                                 [--reference-dir DIR] [--scenes a,b] [--models a,b+c]

``--models`` names the models to draw (default: every ablation, ``knitrun.render.ablations.ABLATION_ORDER``), each
an ablation or a combination "a+b" of them (``ablations.combined``).

``--reference-dir`` reuses references rendered earlier: ``DIR/<scene>.exr`` and its floors ``<scene>_instance.exr``,
``<scene>_mc.exr`` (``benchmarks/bench_floors.py --out DIR`` writes all three, with the JSON summaries that give
the reference's cost); otherwise the reference and its floors are path traced at ``--spp``. Further fiber instances
there, ``DIR/<scene>_fiber<seed>.exr`` (``benchmarks/bench_instances.py --out DIR``), are used with
``--instances`` (all of them, or ``--instances N``: the first N by seed): a second table gives each model against the
ensemble of the reference, its instance floor and those draws (``knitbake.compare.report``, "the ensemble").
"""

import argparse
import sys
from pathlib import Path

from knitbake.compare.report import FLOOR_LABELS, compare_scene
from knitrun.render.ablations import ABLATION_LABELS, ABLATION_ORDER

sys.path.insert(0, str(Path(__file__).resolve().parent))
from bench_instances import instance_files  # noqa: E402
from probe_split import checked_models_and_scenes  # noqa: E402

SCENES = ("straight_yarn_directional", "straight_yarn_sky", "straight_yarn_backlit", "knit_patch_directional",
          "knit_patch_sky", "knit_patch_grazing", "simulated_patch_directional")
FLOOR_FILES = {"instance": "_instance", "monte_carlo": "_mc"}


def _fmt(x, spec):
    return "—" if x is None else format(x, spec)


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--pack", required=True, help="cotton1 asset pack")
    parser.add_argument("--spp", type=int, default=64)
    parser.add_argument("--out", default="out/compare")
    parser.add_argument("--reference-dir", default=None)
    parser.add_argument("--scenes", default=",".join(SCENES), help="comma-separated example scene names")
    parser.add_argument("--models", default=",".join(ABLATION_ORDER),
                        help="comma-separated ablations or combinations a+b (default: every ablation)")
    parser.add_argument("--instances", nargs="?", type=int, const=-1, default=0,
                        help="compare against the ensemble of the further fiber instances in --reference-dir too "
                             "(all of them, or the first N)")
    args = parser.parse_args()
    models, _ = checked_models_and_scenes(parser, args)
    if args.instances and not args.reference_dir:
        parser.error("--instances reads the further instances from --reference-dir")
    ensembles = []
    root = Path(__file__).resolve().parent.parent / "examples" / "scenes"
    print("| scene | model | mean ratio | yarn-scale rel L1 (d) | (2d) | ratio to instance floor (d) | yarn FLIP | "
          "pixel FLIP | strip ms | speed-up |")
    print("|---|---|---|---|---|---|---|---|---|---|")
    for name in args.scenes.split(","):
        ref, floors, more = None, {}, []
        if args.reference_dir:
            folder = Path(args.reference_dir)
            if (folder / f"{name}.exr").is_file():
                ref = folder / f"{name}.exr"
                floors = {k: folder / f"{name}{s}.exr" for k, s in FLOOR_FILES.items()
                          if (folder / f"{name}{s}.exr").is_file()}
                more = instance_files(folder, name)
                more = more[:args.instances] if args.instances > 0 else more if args.instances else []
        summary = compare_scene(root / f"{name}.toml", Path(args.out) / name, reference=ref,
                                spp=None if ref else args.spp, packs={"cotton1": args.pack}, floor_references=floors,
                                ablations=models, instances=more or None)
        if "ensemble" in summary:
            ensembles.append((name, summary))
        inst = summary["floors"].get("instance")
        rows = [(FLOOR_LABELS[k], r, None) for k, r in summary["floors"].items()] + \
            [(ABLATION_LABELS.get(k, k), r, r["to_instance_floor"]) for k, r in summary["ablations"].items()]
        for label, row, to_floor in rows:
            y = row["yarn"]
            ratio = to_floor["rel_l1"] if to_floor else (y["rel_l1"] / inst["yarn"]["rel_l1"] if inst else None)
            speed = f"{row['speedup']:.0f}×" if row.get("speedup") else "—"
            ms = f"{row['ms']:.0f}" if "ms" in row else "—"
            print(f"| {name} | {label} | {y['mean_ratio']:.3f} | {y['rel_l1']:.3f} | {y['rel_l1_2x']:.3f} | "
                  f"{_fmt(ratio, '.2f')} | {y['flip']:.4f} | {row['flip']:.4f} | {ms} | {speed} |", flush=True)
    if ensembles:
        print("\n| scene | instances | their means' sd | ensemble floor (rel L1, leave one out) | model | mean ratio "
              "(ensemble) | yarn-scale rel L1 | ratio to ensemble floor |")
        print("|---|---|---|---|---|---|---|---|")
        for name, summary in ensembles:
            e = summary["ensemble"]
            for k, row in summary["ablations"].items():
                r = row["ensemble"]
                print(f"| {name} | {e['instances']} | {e['mean_sd']:.3f} | {e['rel_l1']:.3f} | "
                      f"{ABLATION_LABELS.get(k, k)} | {r['mean_ratio']:.3f} ± {r['mean_ratio'] * e['mean_se']:.3f} | "
                      f"{r['rel_l1']:.3f} | {_fmt(r['to_floor'], '.2f')} |")


if __name__ == "__main__":
    main()
