"""A pytest plugin: how much of a test run is Numba compiling, by kernel and by test (the default run's budget).

Sums the seconds of Numba's ``numba:compile`` events in the test process (a Dask worker's or a CLI subprocess's
compilations are not seen), counting an outermost compilation only: a kernel's time includes the callees it compiles
for the first time, and the total is not counted twice. At the end of the run the terminal summary lists the total,
the 25 kernels that took longest (with their number of signatures: each set of argument types is a whole compile)
and the 15 tests during which most compiling happened (the first test to need a kernel pays for it); then, for every
kernel compiled for three signatures or more, each signature's seconds, the arguments it had as None (the branches
Numba pruned: the variants a scene's kinds of light and a model's switches make) and the test that compiled it. Run on
an empty kernel cache to see a clean machine's cost:

    KNIT_CACHE_DIR=$(mktemp -d) PYTHONPATH=benchmarks .venv/bin/python -m pytest -q -p compile_time_plugin
"""

from __future__ import annotations

import inspect
import time
from collections import Counter, defaultdict

from numba.core import event, types


class _OutermostCompiles(event.Listener):
    def __init__(self):
        self.depth, self.started = 0, 0.0
        self.seconds, self.count, self.per_test = defaultdict(float), Counter(), defaultdict(float)
        self.signatures = defaultdict(list)  # kernel → [(seconds, test, the arguments typed None)]
        self.test = "(collection)"

    def on_start(self, ev):
        if self.depth == 0:
            self.started = time.perf_counter()
        self.depth += 1

    def on_end(self, ev):
        self.depth -= 1
        if self.depth:
            return
        seconds = time.perf_counter() - self.started
        function = ev.data["dispatcher"].py_func
        name = f"{function.__module__}.{function.__qualname__}"
        self.seconds[name] += seconds
        self.count[name] += 1
        self.per_test[self.test] += seconds
        names = list(inspect.signature(function).parameters)
        none = [n for n, a in zip(names, ev.data.get("args") or ()) if isinstance(a, (types.NoneType, types.Omitted))]
        self.signatures[name].append((seconds, self.test, none))


_COMPILES = _OutermostCompiles()
event.register("numba:compile", _COMPILES)


def pytest_runtest_setup(item):
    _COMPILES.test = item.nodeid


def pytest_terminal_summary(terminalreporter):
    write = terminalreporter.write_line
    total = sum(_COMPILES.seconds.values())
    terminalreporter.section("Numba compile time (compile_time_plugin)")
    write(f"{total:.1f} s compiling: {sum(_COMPILES.count.values())} compilations of {len(_COMPILES.count)} kernels")
    for name, seconds in sorted(_COMPILES.seconds.items(), key=lambda kv: -kv[1])[:25]:
        write(f"{seconds:8.2f} s  {_COMPILES.count[name]:3d}x  {name}")
    write("during the tests:")
    for test, seconds in sorted(_COMPILES.per_test.items(), key=lambda kv: -kv[1])[:15]:
        write(f"{seconds:8.2f} s  {test}")
    for name, compiles in sorted(_COMPILES.signatures.items(), key=lambda kv: -_COMPILES.seconds[kv[0]]):
        if len(compiles) < 3:
            continue
        write(f"signatures of {name}:")
        for seconds, test, none in compiles:
            write(f"{seconds:8.2f} s  None: {', '.join(none) or '-'}  ({test})")
