"""Where the toolchain caches what it can compute again: ``$KNIT_CACHE_DIR`` if set, else ``$XDG_CACHE_HOME/knit``
(default ``~/.cache/knit``). Each kind of entry has its own sub-folder: ``numba`` (compiled kernels,
``numba_setup``), ``bake`` (bake stages, ``knitbake.bake``), ``srbf`` (environment fits,
``knitrun.shading.srbf_cache``), ``reference`` (sums of reference sample batches run on Dask,
``knitbake.trace.reference.reference_batch``). Every entry can be deleted at any time; pointing ``KNIT_CACHE_DIR``
at an empty folder gives a cold start."""

import os
from pathlib import Path


def cache_root() -> Path:
    root = os.environ.get("KNIT_CACHE_DIR")
    return Path(root) if root else Path(os.environ.get("XDG_CACHE_HOME", Path.home() / ".cache")) / "knit"
