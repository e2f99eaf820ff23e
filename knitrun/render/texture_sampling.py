"""Sampling the asset pack's mip-mapped strip textures (``data_formats/ASSET_PACK.md`` §8) inside Numba kernels.

Texel (i, j) of a level with H rows and W columns has its centre at u_j = (j + ½)/W, v_i = −1 + (i + ½)·2/H; u
repeats, v clamps to the edge. ``sample_mip`` is trilinear: bilinear in each of the two levels that bracket the
real-valued ``level`` (clamped to the stored chain), blended linearly, as a GPU does with GL_LINEAR_MIPMAP_LINEAR
and GL_TEXTURE_MAX_LEVEL at the last stored level.

A ``MipStack`` flattens one texture's chain (or, for the three flyaway variants, three chains) into a single
(total texels, C) float32 array with per-level offsets; it is a named tuple, so a kernel receives it whole.
"""

from __future__ import annotations

import math
from typing import NamedTuple

import numpy as np
from numba import njit


class MipStack(NamedTuple):
    """``data`` (total, C) float32; ``offset``, ``rows``, ``cols`` (V, L) int64: where level l of variant k starts
    in ``data`` and its size (V = 1 for an ordinary texture, 3 for the flyaway variants)."""

    data: np.ndarray
    offset: np.ndarray
    rows: np.ndarray
    cols: np.ndarray


def empty_mip_stack(channels: int, variants: int = 1) -> MipStack:
    """A one-texel stack of zeros: the stand-in a kernel receives for a texture the scene does not draw."""
    return mip_stack([[np.zeros((1, 1, channels))] for _ in range(variants)])


def no_texture(channels: int) -> MipStack:
    """A stack of no level: "no such texture" for a kernel that reads an optional texture only where
    ``has_levels`` says it has one (the same Numba type as any stack of ``channels``, so no second signature)."""
    return MipStack(np.zeros((0, channels), np.float32), np.zeros((1, 0), np.int64), np.zeros((1, 0), np.int64),
                    np.zeros((1, 0), np.int64))


@njit(cache=True)
def has_levels(mip):
    """Whether ``mip`` holds a texture (``no_texture``'s stack holds none)."""
    return mip.cols.shape[1] > 0


def mip_stack(chains) -> MipStack:
    """A ``MipStack`` from a list of variants, each a list of levels (H, W) or (H, W, C), level 0 first."""
    blocks, offset, rows, cols = [], [], [], []
    start = 0
    for chain in chains:
        o, r, c = [], [], []
        for level in chain:
            level = np.asarray(level, np.float32)
            level = level[..., None] if level.ndim == 2 else level
            o.append(start)
            r.append(level.shape[0])
            c.append(level.shape[1])
            blocks.append(level.reshape(-1, level.shape[2]))
            start += level.shape[0] * level.shape[1]
        offset.append(o)
        rows.append(r)
        cols.append(c)
    if len({len(o) for o in offset}) != 1 or len({b.shape[1] for b in blocks}) != 1:
        raise ValueError("every variant of a mip stack needs the same number of levels and channels")
    return MipStack(np.ascontiguousarray(np.concatenate(blocks)), np.array(offset, np.int64),
                    np.array(rows, np.int64), np.array(cols, np.int64))


@njit(cache=True)
def _bilinear(data, start, rows, cols, u, v, weight, out):
    x = u * cols - 0.5
    x = x - cols * math.floor(x / cols)
    j0 = min(int(math.floor(x)), cols - 1)
    j1 = (j0 + 1) % cols
    fx = x - j0
    y = min(max((v + 1.0) * 0.5 * rows - 0.5, 0.0), rows - 1.0)
    i0 = int(math.floor(y))
    i1 = min(i0 + 1, rows - 1)
    fy = y - i0
    for ch in range(out.shape[0]):
        top = (1.0 - fx) * data[start + i0 * cols + j0, ch] + fx * data[start + i0 * cols + j1, ch]
        bottom = (1.0 - fx) * data[start + i1 * cols + j0, ch] + fx * data[start + i1 * cols + j1, ch]
        out[ch] += weight * ((1.0 - fy) * top + fy * bottom)


@njit(cache=True, inline='always')
def sample_mip(mip, variant, level, u, v, out):
    """out[:C] = trilinear sample of ``variant`` of the ``MipStack`` ``mip`` at (u, v) and real mip ``level``
    (0 = finest; clamped to the chain). u is any real (repeat), v in [−1, 1] (clamp)."""
    data, offset, rows, cols = mip
    n_levels = offset.shape[1]
    level = min(max(level, 0.0), n_levels - 1.0)
    l0 = int(math.floor(level))
    l1 = min(l0 + 1, n_levels - 1)
    f = level - l0
    out[:] = 0.0
    _bilinear(data, offset[variant, l0], rows[variant, l0], cols[variant, l0], u, v, 1.0 - f, out)
    if f > 0.0:
        _bilinear(data, offset[variant, l1], rows[variant, l1], cols[variant, l1], u, v, f, out)


@njit(cache=True)
def mip_level(footprint, texel_u, texel_v):
    """Mip level for a pixel footprint (scene units) over texels of level 0 (scene units along u and across v): the
    coarser of the two axes, log2(footprint / texel), never below 0."""
    ratio = max(footprint / texel_u, footprint / texel_v)
    return math.log2(ratio) if ratio > 1.0 else 0.0
