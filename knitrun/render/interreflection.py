"""Yarn-level inter-reflection: light that a neighbouring yarn blocks comes back from it (beyond Huang et al. 2025).

The yarn-level shadow maps (``knitrun.render.shadow_map``) give the fraction V of a light that reaches a receiver
past the other yarns, treating them as opaque tubes. A cotton fiber scatters 95 % of what it meets, so a blocking
yarn sends most of that light on: between its fibers, and scattered, in every direction, toward the receiver too.
The pack's hull albedo ρ_Y (``/interreflection/albedo``, ``knitbake.stages.yarn_hull``: the mean radiance leaving
a yarn tube in a uniform environment of radiance 1) says how much.

Model (a self-similar, infinite-bounce approximation, derived here): every
yarn around the receiver is in the receiver's situation, seeing the light L over a fraction V and neighbours of
radiance L_n over 1 − V; a neighbour returns ρ_Y of what reaches it, L_n = ρ_Y (V L + (1 − V) L_n), so the
receiver's incoming radiance is V L + (1 − V) L_n = L · V / (1 − ρ_Y (1 − V)) — the visibility V is replaced by

    V' = V / (1 − ρ_Y (1 − V))             (V' = V for ρ_Y = 0; V' = 1 for ρ_Y = 1: the white furnace)

It is applied per SRBF lobe of an environment (the light the neighbours pass on is counted as coming from the lobe's
direction, which forward-scattering fibers make plausible) and, through the lobes, to the environment's
multiple-scattering lights. It is not applied to directional lights: there V is 0 or 1 but for the penumbra, and the
blocked light reaches the receiver from the lit side of the blocker, a different light path this term does not
model; the part of it the blocker lets through enters the dual-scattering estimate instead, through the fiber count
for light crossing a yarn (``dual_scattering.transmittance_count``, from the pack's transmittance T_Y). ρ_Y is the
yarn's in the scene colour (``yarn_look.hull_colour``). The shadow pass inter-reflects each lobe's visibility with
its luminance ρ (one value per lobe and point, which the multiple-scattering lights mix, ``ms_lights``); the shading
kernels take each channel's V'_c = V / (1 − ρ_c (1 − V)) from it (``channel_visibility``: V recovered from V' and ρ),
and scale a multiple-scattering light's term by V'_c / V' of its mixed visibility. Light that bounces between yarns
takes their colour once per bounce: white cotton's ρ_Y is (0.785, 0.741, 0.641), and with its luminance on every
channel the knit patch under the sky came out 0.958 / 1.005 / 1.112 of the reference per channel (BENCHMARKS.md,
stop 61).
"""

from __future__ import annotations

import numpy as np
from numba import njit, prange


def interreflected_visibility(visibility, albedo, out=None):
    """V' = V / (1 − ρ (1 − V)) (module docstring) for visibility V ∈ [0, 1] and hull albedo ρ ∈ [0, 1]
    (broadcasting; both clipped to [0, 1]); V' ∈ [V, 1]; into ``out`` if given (C-contiguous, the broadcast shape; it
    may be ``visibility`` itself). One pass over the elements on the machine's threads: the renderer applies it to
    every lobe's visibility of every shading point (16 × ~1.2M values a frame under the sky; numpy's chain of
    temporaries took 0.2 s, and copying the per-point albedo down the lobes before the pass another 0.17 s a set of
    points, BENCHMARKS.md stop 72: a row the same down every leading axis is read as one row)."""
    v, rho = np.asarray(visibility, np.float64), np.asarray(albedo, np.float64)
    shape = np.broadcast_shapes(v.shape, rho.shape)
    if out is None:
        out = np.empty(shape)
    elif out.shape != shape or out.dtype != np.float64 or not (out.flags.c_contiguous and out.flags.writeable):
        raise ValueError(f"out: expected a writable C-contiguous float64 array of shape {shape}")
    n = shape[-1] if shape else 1
    if out.size:
        _interreflect(_rows(v, shape), _rows(rho, shape), out.reshape(-1, n))
    return out


def _rows(a, shape):
    """``a`` broadcast to ``shape`` as (rows, n), n = shape[-1], one C-contiguous writable run: a single row where ``a``
    is the same down every leading axis (the renderer's per-point albedo under every lobe), else every row of
    ``shape`` (``a`` itself where it already is one, else a copy; a read-only or broadcast view would make Numba
    compile ``_interreflect`` once more)."""
    n = shape[-1] if shape else 1
    if a.size == n and (a.ndim == 0 or a.shape[-1] == n):
        row = a.reshape(1, n)
        return row if row.flags.c_contiguous and row.flags.writeable else np.array(row)
    if a.shape == shape and a.flags.c_contiguous and a.flags.writeable:
        return a.reshape(-1, n)
    return np.array(np.broadcast_to(a, shape)).reshape(-1, n)


@njit(cache=True, inline='always')
def channel_visibility(inter, rho, rho_channel):
    """V'_c = V / (1 − ρ_c (1 − V)) of the visibility V whose V' = V / (1 − ρ (1 − V)) is ``inter`` (ρ the
    luminance ``rho``, ρ_c ``rho_channel``; module docstring): V = V' (1 − ρ) / (1 − ρ V'). ``inter`` itself where
    ρ ≥ 1 (V' is then 1 whatever V was) or ρ_c = ρ."""
    vp, r, rc = min(max(inter, 0.0), 1.0), min(max(rho, 0.0), 1.0), min(max(rho_channel, 0.0), 1.0)
    if r >= 1.0 or rc == r:
        return vp
    v = min(vp * (1.0 - r) / (1.0 - r * vp), 1.0)
    denominator = 1.0 - rc * (1.0 - v)
    return min(v / denominator, 1.0) if denominator > 0.0 else 1.0


@njit(parallel=True, cache=True)
def _interreflect(v, rho, out):
    """out (R, N) from ``v`` and ``rho``, each (R, N) or (1, N): a single row serves every row (``_rows``)."""
    rows, n = out.shape
    v_rows, rho_rows = v.shape[0] > 1, rho.shape[0] > 1
    for index in prange(rows * n):
        i, k = index // n, index % n
        vk = min(max(v[i if v_rows else 0, k], 0.0), 1.0)
        r = min(max(rho[i if rho_rows else 0, k], 0.0), 1.0)
        denominator = 1.0 - r * (1.0 - vk)
        out[i, k] = vk / denominator if denominator > 0.0 else 1.0
