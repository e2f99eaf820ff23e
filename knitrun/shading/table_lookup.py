"""Table lookups by the asset pack's grid and interpolation rules (``data_formats/ASSET_PACK.md`` §4.2–4.3).

This is the one implementation of the rule in ``knitrun``; every table lookup (dual scattering, correction,
shadowing, I_M) goes through ``axis_cell``.

Grid (§4.2): a sampled axis of N samples over [lo, hi] holds the cell centres x_k = lo + (k + ½)(hi − lo)/N.

Interpolation (§4.3), for a query x:

    t = (x − lo)/(hi − lo) · N − ½
    clamp:   t = clamp(t, 0, N − 1);  i0 = ⌊t⌋;  i1 = min(i0 + 1, N − 1);  f = t − i0
    repeat:  t = t − N⌊t/N⌋;          i0 = ⌊t⌋;  i1 = (i0 + 1) mod N;     f = t − i0
    value = (1 − f)·T[i0] + f·T[i1]

so a query beyond the outermost centres takes the end sample (clamp), N = 1 gives T[0], and a query exactly at a
centre returns that sample. θ axes (``theta_i``, ``theta_d``) span [−π/2, π/2] and clamp; φ spans [−π, π] and
repeats.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit, prange

from data_formats.conventions import THETA_RANGE

WRAPS = ("clamp", "repeat")


@njit(cache=True)
def axis_cell(x, lo, hi, n, repeat):
    """(i0, i1, f) of §4.3 for one sampled axis of n samples over [lo, hi]; ``repeat`` False means clamp."""
    t = (x - lo) / (hi - lo) * n - 0.5
    if repeat:
        t = t - n * math.floor(t / n)
        i0 = int(math.floor(t))
        if i0 >= n:  # t − N⌊t/N⌋ rounds up to exactly N for t just below a multiple of N
            i0 -= n
            t -= n
        return i0, (i0 + 1) % n, t - i0
    t = min(max(t, 0.0), n - 1.0)
    i0 = int(math.floor(t))
    return i0, min(i0 + 1, n - 1), t - i0


@njit(parallel=True, cache=True)
def _cells(x, lo, hi, n, repeat):
    i0 = np.empty(x.shape[0], np.int64)
    i1 = np.empty(x.shape[0], np.int64)
    f = np.empty(x.shape[0])
    for k in prange(x.shape[0]):
        i0[k], i1[k], f[k] = axis_cell(x[k], lo, hi, n, repeat)
    return i0, i1, f


def lookup_axis(table, x, lo: float, hi: float, wrap: str = "clamp") -> np.ndarray:
    """Interpolate ``table`` along its first axis (n samples over [lo, hi]) at the queries ``x`` (any shape).
    Returns shape x.shape + table.shape[1:] (the trailing axes, e.g. the RGB channel, are carried along)."""
    if wrap not in WRAPS:
        raise ValueError(f"wrap is {wrap!r}, expected one of {WRAPS}")
    table = np.asarray(table, dtype=np.float64)
    x = np.asarray(x, dtype=np.float64)
    if table.ndim < 1 or table.shape[0] < 1:
        raise ValueError(f"table of shape {table.shape} has no samples along its first axis")
    if not np.all(np.isfinite(x)):
        raise ValueError("lookup positions must be finite")
    i0, i1, f = _cells(np.ascontiguousarray(x.ravel()), float(lo), float(hi), table.shape[0], wrap == "repeat")
    f = f.reshape(f.shape + (1,) * (table.ndim - 1))
    return ((1.0 - f) * table[i0] + f * table[i1]).reshape(x.shape + table.shape[1:])


def lookup_theta(table, theta) -> np.ndarray:
    """Interpolate a θ table (first axis: cell centres over [−π/2, π/2], clamp) at ``theta`` (radians)."""
    return lookup_axis(table, theta, *THETA_RANGE, "clamp")
