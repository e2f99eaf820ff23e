"""Fixtures shared by the test modules (plain shared data and builders are in ``helpers.py``), and how a test
process shares the cores.

``make test`` runs the tests in two pytest-xdist worker processes (``-n 2 --dist loadfile``: a module's tests stay in
one worker, so a module's fixtures are built once; ``--no-loadscope-reorder``: modules are handed out in the order of
``pytest_collection_modifyitems``). Each worker then computes on its share of the cores, Numba's
kernels and the BLAS under numpy and scipy alike (``pytest_configure``): two workers running two threads each on two
cores made the relaxation's least-squares solves 4× slower (OpenBLAS threads spinning while the other worker's ran)
and the whole run only 14 % faster than one process (BENCHMARKS.md, "The default test run on two workers"). A test
may still ask for more threads (``numba.set_num_threads`` up to ``NUMBA_NUM_THREADS``), as the thread-count
determinism tests do.
"""

import dataclasses
import os
from pathlib import Path

import numba
import pytest
from threadpoolctl import threadpool_limits

from data_formats.yarn_spec import load_preset
from knitbake.bake import bake
from tests.helpers import TINY


def _bakes(module_path) -> bool:
    """Whether a test module names knitbake (the package: the bake, the path tracer, the references; or its command
    line): its first such test compiles the bake's kernels unless another process has cached them."""
    return "knitbake" in Path(module_path).read_text(encoding="utf-8")


def pytest_collection_modifyitems(config, items):
    """Module order: the first module that bakes or uses the session pack, then every module that does not, then the
    other baking ones (each group in collection order). ``make test`` hands modules to its two workers in this order
    (``--no-loadscope-reorder``, each worker taking the next as it finishes one), so one worker compiles the bake's
    kernels while the other runs the modules that need none of them, instead of both compiling them side by side;
    the baking modules after it read them from the kernel cache (module docstring)."""
    modules = {}
    for item in items:
        modules.setdefault(str(item.path), []).append(item)
    baking = [m for m, its in modules.items() if _bakes(m) or any("pack" in it.fixturenames for it in its)]
    order = baking[:1] + [m for m in modules if m not in baking] + baking[1:]
    items[:] = [item for m in order for item in modules[m]]


def pytest_configure(config):
    workers = int(os.environ.get("PYTEST_XDIST_WORKER_COUNT", "1"))
    if workers > 1:  # an xdist worker: its share of the cores (module docstring)
        share = max(1, len(os.sched_getaffinity(0)) // workers)
        numba.set_num_threads(min(share, numba.config.NUMBA_NUM_THREADS))
        threadpool_limits(share)


@pytest.fixture(scope="session")
def pack(tmp_path_factory):
    """A tiny asset pack of cotton1 (15 fibers per ply, every stage at ``TINY`` settings, seed 1, no stage cache)
    for the renderer's tests; read-only."""
    spec = load_preset("cotton1")
    spec = dataclasses.replace(spec, geometry=dataclasses.replace(spec.geometry, fibers_per_ply=15))
    out = tmp_path_factory.mktemp("pack") / "cotton1.h5"
    bake(spec, out, overrides=TINY, seed=1, use_cache=False)
    return out
