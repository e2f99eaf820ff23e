"""knitrun: the runtime (shading model, table lookups, knot simulator, strip renderer). Never imports knitbake."""

import data_formats  # noqa: F401  (its numba_setup sets the kernel cache folder before any kernel compiles)
