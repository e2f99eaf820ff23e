"""Bakes of several yarns serial (1 process × all threads) against distributed on an embedded Dask cluster
(``knitbake.scale_out``), and the per-task overhead of the cluster.

Serial: ``bake`` of each yarn in turn in this process, after a warm-up bake (kernels loaded). Distributed:
``bake_library`` on ``dask_client(workers=W)`` (W processes × cores/W Numba threads), timed twice: the first run
includes the workers' kernel loading (what a user waits for), the second is warm. Stage cache off throughout, so
every stage is baked. Overhead: the mean wall time of a no-op task over 200 submitted at once, and of 20 chained.

    .venv/bin/python benchmarks/bench_scale_out.py [--yarns cotton1,silk1,polyester1,rayon1] [--quality draft]
        [--workers 2]
"""

import argparse
import tempfile
import time
from pathlib import Path

from data_formats.yarn_spec import resolve_yarn
from knitbake.bake import bake
from knitbake.scale_out import bake_library, dask_client, local_layout


def _noop(x):
    return x


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--yarns", default="cotton1,silk1,polyester1,rayon1")
    parser.add_argument("--quality", default="draft")
    parser.add_argument("--workers", type=int, default=2)
    args = parser.parse_args()
    specs = [resolve_yarn(name) for name in args.yarns.split(",")]
    with tempfile.TemporaryDirectory() as tmp:
        tmp = Path(tmp)
        bake(specs[0], tmp / "warm.h5", "draft", use_cache=False)
        t0 = time.perf_counter()
        for spec in specs:
            bake(spec, tmp / f"serial-{spec.name}.h5", args.quality, use_cache=False)
        serial = time.perf_counter() - t0
        workers, threads = local_layout(args.workers)
        print(f"serial       {len(specs)} {args.quality} bakes: {serial:.1f} s (1 process, all threads)")
        t0 = time.perf_counter()
        with dask_client(workers=args.workers) as client:
            start = time.perf_counter() - t0
            for run in ("cold", "warm"):
                t1 = time.perf_counter()
                results = bake_library(client, [(s, str(tmp / f"{run}-{s.name}.h5")) for s in specs], args.quality,
                                       use_cache=False)
                failed = [name for name, r in results.items() if isinstance(r, Exception)]
                print(f"distributed  {len(specs)} {args.quality} bakes, {run}: {time.perf_counter() - t1:.1f} s "
                      f"({workers} processes × {threads} thread(s); cluster start {start:.1f} s)"
                      + (f"; FAILED {failed}" if failed else ""))
            t1 = time.perf_counter()
            client.gather(client.map(_noop, range(200), pure=False))
            many = (time.perf_counter() - t1) / 200
            t1 = time.perf_counter()
            x = 0
            for _ in range(20):
                x = client.submit(_noop, x, pure=False)
            x.result()
            chained = (time.perf_counter() - t1) / 20
        print(f"overhead     {many * 1e3:.2f} ms per task (200 at once), {chained * 1e3:.2f} ms per task (20 chained)")


if __name__ == "__main__":
    main()
