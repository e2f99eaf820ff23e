"""File formats of the knit toolchain: yarn specs, yarn curves (HDF5 and BCC), asset packs; readers, writers,
validators. Imports nothing else of ours (the dependency rule of DESIGN.md §2)."""

from . import numba_setup  # noqa: F401  (sets the Numba kernel cache folder before any kernel compiles)
from .errors import FormatError

__all__ = ["FormatError"]
