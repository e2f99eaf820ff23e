"""knitbake: the offline baker. Explicit fibers (``fibers``) are ray traced (``trace``) by the bake stages
(``stages``) that ``bake`` orchestrates into one asset pack per yarn type; ``compare`` measures the strip renderer
against the reference path tracer."""

import knitrun  # noqa: F401  (numba cache setup happens there, before any kernel here compiles)
