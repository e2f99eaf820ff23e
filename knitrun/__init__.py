"""knitrun: the runtime. The shading model (``shading``), the knot simulator (``sim``: stitch mesh → yarn curves) and
the strip renderer (``render``: yarn curves + asset packs → image). Never imports knitbake."""

import data_formats  # noqa: F401  (its numba_setup sets the kernel cache folder before any kernel compiles)
