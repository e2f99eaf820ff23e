"""Bakes of several yarns, and the frames of a reference animation, serial (1 process × all threads) against
distributed on an embedded Dask cluster (``knitbake.scale_out``), and the per-task overhead of the cluster.

Serial: ``bake`` of each yarn in turn in this process, after a warm-up bake (kernels loaded). Distributed:
``bake_library`` on ``dask_client(workers=W)`` (W processes × cores/W Numba threads), timed twice: the first run
includes the workers' kernel loading (what a user waits for), the second is warm. Stage cache off throughout, so
every stage is baked. Overhead: the mean wall time of a no-op task over 200 submitted at once, and of 20 chained.
``--reference``: instead, a 4-frame stretch of a 6×6 stockinette (``knitrun pattern`` + ``knitrun simulate``),
256×256 at 16 spp, serial (``trace_reference`` per frame) against one task per frame (``submit_reference``).

    .venv/bin/python benchmarks/bench_scale_out.py [--yarns cotton1,silk1,polyester1,rayon1] [--quality draft]
        [--workers 2] [--reference]
"""

import argparse
import dataclasses
import subprocess
import sys
import tempfile
import time
from pathlib import Path

from data_formats.scene import load_scene
from data_formats.yarn_spec import resolve_yarn
from knitbake.bake import bake
from knitbake.scale_out import bake_library, dask_client, local_layout, submit_reference
from knitbake.trace.reference import trace_reference

SCENE = """format = "knit-scene"
version = "1.0"
units = "cm"
[[yarns]]
curves = "anim.h5"
yarn = "cotton1"
[camera]
position = [0.9, 0.9, 3.0]
look_at = [0.9, 0.9, 0.0]
ortho_height = 2.4
width = 256
height = 256
[[lights]]
type = "directional"
direction = [0.4, 0.6, 1.0]
irradiance = [3.0, 3.0, 3.0]
"""


def _noop(x):
    return x


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--yarns", default="cotton1,silk1,polyester1,rayon1")
    parser.add_argument("--quality", default="draft")
    parser.add_argument("--workers", type=int, default=2)
    parser.add_argument("--reference", action="store_true", help="time a 4-frame reference instead of bakes")
    args = parser.parse_args()
    if args.reference:
        return reference(args.workers)
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


def reference(n_workers, frames=4, spp=16):
    knitrun = str(Path(sys.executable).with_name("knitrun"))
    with tempfile.TemporaryDirectory() as tmp:
        tmp = Path(tmp)
        subprocess.run([knitrun, "pattern", "stockinette", "--rows", "6", "--cols", "6", "-o", str(tmp / "m.h5")],
                       check=True, capture_output=True)
        subprocess.run([knitrun, "simulate", str(tmp / "m.h5"), "--deform", "stretch-x=1.3", "--frames",
                        str(frames), "-o", str(tmp / "anim.h5")], check=True, capture_output=True)
        (tmp / "anim.toml").write_text(SCENE)
        scene = load_scene(tmp / "anim.toml")
        at = [dataclasses.replace(scene, render=dataclasses.replace(scene.render, frame=f)) for f in range(frames)]
        trace_reference(dataclasses.replace(at[0], camera=dataclasses.replace(scene.camera, width=8, height=8)), 1)
        t0 = time.perf_counter()
        serial = [trace_reference(s, spp)[0] for s in at]
        print(f"serial       {frames}-frame reference, 256x256, {spp} spp: {time.perf_counter() - t0:.1f} s")
        workers, threads = local_layout(n_workers)
        with dask_client(workers=n_workers) as client:
            for run in ("cold", "warm"):
                t0 = time.perf_counter()
                images = client.gather([submit_reference(client, s, spp) for s in at])
                same = all((a == b[0]).all() for a, b in zip(serial, images))
                print(f"distributed  {frames}-frame reference, {run}: {time.perf_counter() - t0:.1f} s ({workers} "
                      f"processes × {threads} thread(s)); identical to serial: {same}")


if __name__ == "__main__":
    main()
