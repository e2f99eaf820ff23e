"""Numba settings shared by every kernel of the toolchain.

* Compiled kernels are cached on disk (``cache=True``) so compile cost is paid once per machine. The cache lives in
  ``$NUMBA_CACHE_DIR`` if set, else in the cache's ``numba/<sources>`` (``data_formats.cache_folders``, by default
  ``~/.cache/knit``: writable even when the package is installed read-only), ``<sources>`` a hash of every Python
  source of the toolchain: Numba checks only the timestamp of a kernel's own file, so a kernel whose callee in
  another module changed would load its stale machine code (seen: an edited normaliser in ``fiber_bcsdf`` left
  ``strip_shading`` on the old one). Other sources give another folder; old folders can be deleted at any time.
  Numba's settings that change the machine code it generates (``CODEGEN_SETTINGS``) are not in its cache key
  either: a run under ``NUMBA_ENABLE_PROFILING=1`` (for a profiler) cached kernels that then shaded 1.8× slower in
  every later run. When any of them is set, the folder's name carries a hash of their values too.
  This module must be imported before any kernel is defined; ``data_formats/__init__`` (the bottom layer, which
  every package imports first) does, and it also sets Numba's setting when a script imported numba first (Numba
  reads its environment once, at import).
* Kernels never turn on all of fastmath (that drops NaN/Inf checks); ``FASTMATH`` is the flag set that keeps them.
"""

import hashlib
import os
import sys
from pathlib import Path

from data_formats.cache_folders import cache_root

PACKAGES = ("data_formats", "knitbake", "knitrun", "cli")  # the toolchain's packages, beside this one's


def sources_hash(root=None) -> str:
    """A short hash of the content of every ``.py`` file of ``PACKAGES`` under ``root`` (default: this checkout or
    installation), in path order."""
    root = Path(__file__).resolve().parent.parent if root is None else Path(root)
    digest = hashlib.blake2b(digest_size=8)
    for package in PACKAGES:
        for path in sorted((root / package).rglob("*.py")):
            digest.update(str(path.relative_to(root)).encode())
            digest.update(path.read_bytes())
    return digest.hexdigest()


# environment settings that change Numba's generated code (and that its cache key ignores)
CODEGEN_SETTINGS = ("NUMBA_ENABLE_PROFILING", "NUMBA_OPT", "NUMBA_DEBUGINFO", "NUMBA_BOUNDSCHECK", "NUMBA_CPU_NAME",
                    "NUMBA_CPU_FEATURES", "NUMBA_LOOP_VECTORIZE", "NUMBA_SLP_VECTORIZE", "NUMBA_FASTMATH")


def cache_folder_name(environ=os.environ) -> str:
    """``sources_hash()``, followed by a hash of the ``CODEGEN_SETTINGS`` set in ``environ`` if any is."""
    settings = [f"{name}={environ[name]}" for name in CODEGEN_SETTINGS if name in environ]
    if not settings:
        return sources_hash()
    return sources_hash() + "-" + hashlib.blake2b("\n".join(settings).encode(), digest_size=4).hexdigest()


if "NUMBA_CACHE_DIR" not in os.environ:
    _cache = cache_root() / "numba" / cache_folder_name()
    try:
        _cache.mkdir(parents=True, exist_ok=True)
        os.environ["NUMBA_CACHE_DIR"] = str(_cache)
    except OSError:  # read-only home: numba falls back to its own default next to the sources
        pass
if "numba" in sys.modules:  # imported before us (a script's own ``import numba``): it read its settings already
    from numba.core import config

    config.CACHE_DIR = os.environ.get("NUMBA_CACHE_DIR", config.CACHE_DIR)

# Reassociation and contraction only: no 'nnan'/'ninf', so NaN and Inf checks still work.
FASTMATH = {"reassoc", "contract", "arcp"}
