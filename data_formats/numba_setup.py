"""Numba settings shared by every kernel of the toolchain.

* Compiled kernels are cached on disk (``cache=True``) so compile cost is paid once per machine. The cache lives in
  ``$NUMBA_CACHE_DIR`` if set, else in ``~/.cache/knit/numba`` (a writable folder even when the package is
  installed read-only). This module must be imported before numba compiles anything; ``data_formats/__init__``
  (the bottom layer, which every package imports first) does.
* Kernels never turn on all of fastmath (that drops NaN/Inf checks); ``FASTMATH`` is the flag set that keeps them.
"""

import os
from pathlib import Path

if "NUMBA_CACHE_DIR" not in os.environ:
    _cache = Path(os.environ.get("XDG_CACHE_HOME", Path.home() / ".cache")) / "knit" / "numba"
    try:
        _cache.mkdir(parents=True, exist_ok=True)
        os.environ["NUMBA_CACHE_DIR"] = str(_cache)
    except OSError:  # read-only home: numba falls back to its own default next to the sources
        pass

# Reassociation and contraction only: no 'nnan'/'ninf', so NaN and Inf checks still work.
FASTMATH = {"reassoc", "contract", "arcp"}
