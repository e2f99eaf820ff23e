"""knitrun: the runtime (shading model, table lookups, knot simulator, strip renderer). Never imports knitbake."""

from . import numba_setup  # noqa: F401  (sets the kernel cache folder before any kernel compiles)
