"""Sequences and cold starts of the strip renderer (issue 15, items 3 and 4).

1. **Cold first frame**: ``knitrun render`` of an example scene in a fresh process with ``KNIT_CACHE_DIR`` pointing
   at an empty folder (no compiled kernels, no SRBF fit), the process's wall time and the frame's passes; then the
   same command again (warm: kernels and fit from the cache).
2. **A 30-frame sequence** of the simulated 6 × 6 stockinette patch (stretched to 1.4× and released, the knot
   simulator's frames) at the example scene's 512 × 384, MSAA 4, with one ``Renderer``: ms per frame.

    .venv/bin/python benchmarks/bench_sequence.py --pack out/bench/cotton1_standard.h5 [--frames 30]
"""

import argparse
import json
import os
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

EXAMPLES = Path(__file__).resolve().parent.parent / "examples" / "scenes"
KNITRUN = str(Path(sys.executable).parent / "knitrun")


def timed(cmd, env):
    start = time.perf_counter()
    out = subprocess.run(cmd, env=env, check=True, capture_output=True, text=True).stdout
    return time.perf_counter() - start, json.loads(out)


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--pack", required=True)
    parser.add_argument("--frames", type=int, default=30)
    parser.add_argument("--scenes", default="knit_patch_directional,knit_patch_sky")
    args = parser.parse_args()
    work = Path(tempfile.mkdtemp(prefix="knit_bench_sequence_"))
    for name in args.scenes.split(","):
        env = dict(os.environ, KNIT_CACHE_DIR=str(work / f"cache_{name}"))
        env.pop("NUMBA_CACHE_DIR", None)
        cmd = [KNITRUN, "render", str(EXAMPLES / f"{name}.toml"), "--pack", f"cotton1={args.pack}", "-o",
               str(work / f"{name}.png"), "--json"]
        for label in ("cold (empty cache)", "warm (cache filled)"):
            wall, summary = timed(cmd, env)
            passes = ", ".join(f"{k} {v:.0f}" for k, v in summary["ms_per_pass"].items())
            print(f"{name}, {label}: process {wall:.1f} s, frame {summary['ms_total']:.0f} ms ({passes})",
                  flush=True)
    subprocess.run([KNITRUN, "pattern", "stockinette", "--rows", "6", "--cols", "6", "-o", str(work / "m.h5")],
                   check=True, capture_output=True)
    subprocess.run([KNITRUN, "simulate", str(work / "m.h5"), "--deform", "stretch-x=1.4", "--frames",
                    str(args.frames), "-o", str(work / "anim.h5")], check=True, capture_output=True)
    scene = (EXAMPLES / "simulated_patch_directional.toml").read_text().replace("simulated_patch_6x6.h5",
                                                                                str(work / "anim.h5"))
    (work / "anim.toml").write_text(scene)
    (work / "out").mkdir()
    _, summary = timed([KNITRUN, "render", str(work / "anim.toml"), "--frames", f"0:{args.frames}", "--pack",
                        f"cotton1={args.pack}", "-o", str(work / "out" / "f_###.png"), "--json"], dict(os.environ))
    ms = summary["ms_per_frame"]
    passes = {k: statistics.median(r["ms_per_pass"][k] for r in summary["per_frame"][1:])
              for k in summary["per_frame"][0]["ms_per_pass"]}
    print(f"sequence of {len(ms)} frames (512x384, MSAA 4): setup {summary['setup_ms']}, first frame {ms[0]:.0f} ms, "
          f"then median {statistics.median(ms[1:]):.0f} ms (min {min(ms[1:]):.0f}, max {max(ms[1:]):.0f}); "
          "median passes: " + ", ".join(f"{k} {v:.0f}" for k, v in passes.items()) + " ms (frame ms include the "
          "PNG write)")


if __name__ == "__main__":
    main()
