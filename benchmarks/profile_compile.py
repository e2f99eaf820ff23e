"""Where a cold first frame's compile time goes (issue 15, item 4): render an example scene in this process with an
empty kernel cache (``KNIT_CACHE_DIR`` on a fresh folder) and print the passes' times and the 25 longest Numba
compilations (Numba's compile events; nested: a kernel's time includes the callees it compiles), then how many
compilations there were and every function compiled for more than one set of argument types, with those types
(Numba specialises on read-only and literal arguments as well as on dtypes: each extra set is a whole compile).

    .venv/bin/python benchmarks/profile_compile.py --pack out/bench/cotton1_standard.h5 \\
        [--scene examples/scenes/knit_patch_directional.toml] [--compile-ahead]
"""

import os
import sys
import tempfile

if __name__ == "__main__":  # before the toolchain picks its cache folder
    os.environ["KNIT_CACHE_DIR"] = tempfile.mkdtemp(prefix="knit_cold_")
    os.environ.pop("NUMBA_CACHE_DIR", None)

import argparse  # noqa: E402
import time  # noqa: E402

from numba.core import event  # noqa: E402

from data_formats.scene import load_scene  # noqa: E402
from knitrun.render.pipeline import render  # noqa: E402


class CompileTimes(event.Listener):
    """Seconds of every ``numba:compile`` event by the compiled function's module and qualified name, and the
    argument types of each compilation."""

    def __init__(self):
        self.started, self.seconds, self.signatures = {}, {}, {}

    def on_start(self, ev):
        self.started[id(ev.data["dispatcher"])] = time.perf_counter()

    def on_end(self, ev):
        dispatcher = ev.data["dispatcher"]
        name = f"{dispatcher.py_func.__module__}.{dispatcher.py_func.__qualname__}"
        self.seconds[name] = self.seconds.get(name, 0.0) + time.perf_counter() - self.started.pop(id(dispatcher))
        self.signatures.setdefault(name, []).append(str(ev.data.get("args")))


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--pack", required=True)
    parser.add_argument("--scene", default="examples/scenes/knit_patch_directional.toml")
    parser.add_argument("--compile-ahead", action="store_true",
                        help="with the compile-ahead helper, as knitrun render runs (its compilations, in its own "
                             "process, are not listed)")
    args = parser.parse_args()
    times = CompileTimes()
    event.register("numba:compile", times)
    start = time.perf_counter()
    result = render(load_scene(args.scene), {"cotton1": args.pack}, compile_ahead=args.compile_ahead)
    helper = ", compile-ahead helper" if args.compile_ahead else ""
    print(f"{args.scene}, empty cache{helper}: {time.perf_counter() - start:.1f} s; passes: " +
          ", ".join(f"{k} {v:.1f} s" for k, v in result.timings.items()))
    for name, seconds in sorted(times.seconds.items(), key=lambda kv: -kv[1])[:25]:
        print(f"{seconds:6.2f} s  {name}")
    count = sum(len(s) for s in times.signatures.values())
    print(f"{count} compilations of {len(times.signatures)} functions; compiled for more than one set of argument "
          "types (Numba's own overloads, numba.*, left out):")
    for name, signatures in sorted(times.signatures.items()):
        if len(signatures) > 1 and not name.startswith("numba."):
            print(f"  {name} x{len(signatures)}: " + " | ".join(signatures))


if __name__ == "__main__":
    sys.exit(main())
