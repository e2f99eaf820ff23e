"""The bake's speed/accuracy trade: wall time and error estimate of every stage at each quality preset.

Bakes one preset yarn at each quality with the stage cache disabled (a warm-up draft bake first pays the Numba
compile/cache load), and prints one row per (quality, stage): seconds, number of tables, the largest error
estimate among its tables and, for the factored tables, the factorization residual; for the environment stage the
I_M lookup error against direct quadrature that the bake measures and stores (relative where I_M > 1% of its
maximum / relative to each λ decade's maximum).

    .venv/bin/python benchmarks/bench_bake.py [--yarn cotton1] [--qualities draft,standard]
"""

import argparse
import tempfile
import time
from pathlib import Path

from data_formats.asset_pack import read_pack, validate
from data_formats.yarn_spec import resolve_yarn
from knitbake.bake import bake
from knitbake.stages.correction import forget_yarn_tracers


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--yarn", default="cotton1")
    parser.add_argument("--qualities", default="draft,standard")
    args = parser.parse_args()
    spec = resolve_yarn(args.yarn)
    with tempfile.TemporaryDirectory() as tmp:
        bake(spec, Path(tmp) / "warm.h5", "draft", use_cache=False,
             overrides={"correction": {"batches": 2, "n_theta": 2, "n_phi": 2}})
        print(f"{'quality':<10}{'stage':<17}{'seconds':>9}{'tables':>8}  {'max error':>10}  residual")
        for quality in args.qualities.split(","):
            forget_yarn_tracers()  # each quality builds its own fiber geometry, as a fresh process
            t0 = time.perf_counter()
            out = Path(tmp) / f"{quality}.h5"
            summary = bake(spec, out, quality, use_cache=False)
            total = time.perf_counter() - t0
            pack = read_pack(out, tables=["correction/xi_residual", "shadowing/psi_residual"])
            residual = {"correction": f'{float(pack.tables["correction/xi_residual"]):.3f}',
                        "shadowing": f'{float(pack.tables["shadowing/psi_residual"]):.3f}'}
            im = pack.info.get("environment/I_M_TT_D")
            if im is not None:
                residual["environment"] = (f"lookup {im.attrs['lookup_rel_error']:.4f} / "
                                           f"{im.attrs['lookup_error_per_decade']:.4f}")
            for stage, row in summary.items():
                res = residual.get(stage, "")
                print(f"{quality:<10}{stage:<17}{row['seconds']:>9.1f}{row['tables']:>8}  "
                      f"{row['error_estimate']:>10.3g}  {res}")
            problems = validate(out)
            print(f"{quality:<10}{'TOTAL':<17}{total:>9.1f}   pack {out.stat().st_size / 2**20:.1f} MiB, "
                  f"validate: {'ok' if not problems else problems}")


if __name__ == "__main__":
    main()
