"""knitbake: the offline baker (procedural fibers, tessellation, Embree scene, path tracer, table bakers)."""

import knitrun  # noqa: F401  (numba cache setup happens there, before any kernel here compiles)
