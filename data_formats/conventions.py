"""Conventions every format and kernel of the toolchain shares: length units, angle domains and the grid rule.

Each quantity here has this one definition; the formats, the baker and the runtime import it.

* Lengths: a file states its unit, one of ``LENGTH_UNITS``; ``CM_PER_UNIT`` converts (presets use centimetres).
* Angles are radians. A longitudinal angle θ = asin(ω·t) lies in ``THETA_RANGE`` = [−π/2, π/2]; an azimuth
  difference φ = φ_o − φ_i is wrapped into ``PHI_RANGE`` = [−π, π) (``ASSET_PACK.md`` §3).
* Colour: linear RGB with Rec. 709 primaries; luminance Y = ``LUMINANCE``·(R, G, B).
* Grid rule (``ASSET_PACK.md`` §4.2): a sampled axis of n samples over [lo, hi] holds the centres of n equal cells,
  x_k = lo + (k + ½)(hi − lo)/n (``cell_centres``). Tables, textures and the bake's bins all follow it.
"""

from __future__ import annotations

import math

import numpy as np

HALF_PI = 0.5 * math.pi
THETA_RANGE = (-HALF_PI, HALF_PI)
PHI_RANGE = (-math.pi, math.pi)
CM_PER_UNIT = {"mm": 0.1, "cm": 1.0, "m": 100.0}
LENGTH_UNITS = tuple(CM_PER_UNIT)
MAX_COORD = 1e9  # bound of every position and direction in a file we read (in its units): keeps products finite
LUMINANCE = np.array([0.2126, 0.7152, 0.0722])  # Rec. 709 luminance weights of linear RGB


def cell_centres(lo: float, hi: float, n: int) -> np.ndarray:
    """Sample positions of an axis: the centres of n equal cells over [lo, hi] (the module docstring's grid rule)."""
    return lo + (np.arange(n, dtype=np.float64) + 0.5) * ((hi - lo) / n)
