"""Shading model: the fiber BCSDF, dual scattering, the I_M lookup, table lookups, environment maps (equirectangular conventions, the built-in sky, the SRBF fit)."""
