"""Shading model: the fiber BCSDF and the angles about a fiber, dual scattering, table lookups, the I_M lookup,
environment maps (equirectangular conventions, the built-in sky, the SRBF fit)."""
