"""Knot simulator: knit charts, stitch templates, the per-face knot solver, yarn assembly, deformations, ``simulate``;
and the closed-form stockinette curves."""
