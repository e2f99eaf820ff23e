"""The environment's multiple-scattering lights: the SRBF environment integrated over fixed cells of the sphere.

Eq. 17 of Huang et al. 2025 has single scattering only; the renderer adds the dual-scattering terms of the
environment's light (``strip_shading`` docstring, SHADING.md §4) by treating a few directions as distant lights.
Those terms vary strongly with the light's angle to the yarn (θ_i: a fiber lit along its axis scatters little), so
a broad lobe's light must arrive from the directions it covers, not from its centre alone.

Cells: the sphere is split into ``MS_CELLS`` cells, the Voronoi regions of the Fibonacci point set of
``equirect.fibonacci_directions`` (poles on ±y, the world's up axis), fixed in the world. Lobe j (centre ω_j,
sharpness λ_j, RGB weight W_j) carries irradiance E_j = W_j (2π/λ_j)(1 − e^{−2λ_j}) (``im_lookup.sg_integral``); it
is spread over the cells by its SRBF value at ``MS_SAMPLES`` Fibonacci directions (equal solid angle), each sample
given to its nearest cell centre, so Σ_c E_cj = E_j exactly. A lobe narrower than ``NARROW_SAMPLES`` sample spacings
(a sun) goes whole to the cell of its centre. Cell c is one distant light: irradiance E_c = Σ_j E_cj, direction the
normalised luminance-weighted mean of the sample directions its light comes from, and visibility Σ_j w_cj T̃_j at a
point, w_cj = lum(E_cj)/lum(E_c) (the lobes' visibilities from their shadow maps). Cells without light are dropped.

Why cells and not the lobes: the first version merged lobes within 30° of each other and put each group's light at
its centre, so the image depended on how the fit happened to split the sky: on the straight yarn under the built-in
sky the mean brightness went 0.954 / 0.971 / 1.048 / 1.022 / 0.985 of the reference for J = 8 / 12 / 16 / 24 / 32
lobes with irradiance errors of the fit all below 1 %. With 12 cells it is 0.993 / 1.031 / 1.026 / 1.028 / 1.023,
and 12, 24 or 48 cells agree to 1 % (BENCHMARKS.md, "The environment's multiple scattering over cells of the sky").
Twelve cells cost what the 13 groups of the built-in sky's 16 lobes did.
"""

from __future__ import annotations

import functools
import math

import numpy as np

from data_formats.conventions import LUMINANCE
from knitrun.shading.equirect import fibonacci_directions
from knitrun.shading.im_lookup import sg_integral

MS_CELLS = 12
MS_SAMPLES = 16384
NARROW_SAMPLES = 2.0  # a lobe of angular standard deviation 1/√λ below this many sample spacings is one direction


@functools.cache
def _cells(n_cells: int, n_samples: int):
    """(cell centres, samples, owning cell of each sample), built once."""
    centres, samples = fibonacci_directions(n_cells), fibonacci_directions(n_samples)
    return centres, samples, np.argmax(samples @ centres.T, axis=1)


def ms_cells(lobe_dir, lobe_lambda, lobe_w, n_cells: int = MS_CELLS, n_samples: int = MS_SAMPLES):
    """The multiple-scattering lights of an SRBF environment (module docstring): (directions (C, 3), irradiance
    (C, 3), weights (C, J)), C ≤ ``n_cells``; weights[c, j] is lobe j's share of cell c's luminance (rows sum to 1).
    ``lobe_dir`` (J, 3) unit, ``lobe_lambda`` (J,), ``lobe_w`` (J, 3) ≥ 0."""
    lobe_dir = np.asarray(lobe_dir, np.float64).reshape(-1, 3)
    lobe_lambda = np.asarray(lobe_lambda, np.float64).reshape(-1)
    energy = np.asarray(lobe_w, np.float64).reshape(-1, 3) * sg_integral(lobe_lambda)[:, None]
    luminance = energy @ LUMINANCE
    centres, samples, owner = _cells(n_cells, n_samples)
    narrow_lambda = 1.0 / (NARROW_SAMPLES ** 2 * 4.0 * math.pi / n_samples)
    share = np.zeros((n_cells, len(lobe_lambda)))  # fraction of lobe j's light in cell c
    moment = np.zeros((n_cells, 3))  # Σ luminance × direction of the light in each cell
    for j in np.flatnonzero(luminance > 0.0):
        g = np.exp(lobe_lambda[j] * (samples @ lobe_dir[j] - 1.0))
        if lobe_lambda[j] > narrow_lambda or not g.sum() > 0.0:
            c = int(np.argmax(centres @ lobe_dir[j]))
            share[c, j] = 1.0
            moment[c] += luminance[j] * lobe_dir[j]
            continue
        g /= g.sum()
        share[:, j] = np.bincount(owner, g, n_cells)
        for a in range(3):
            moment[:, a] += luminance[j] * np.bincount(owner, g * samples[:, a], n_cells)
    cell_energy = share[:, :, None] * energy[None, :, :]  # (C, J, 3)
    irradiance = cell_energy.sum(axis=1)
    cell_luminance = irradiance @ LUMINANCE
    lit = np.flatnonzero((cell_luminance > 0.0) & (np.linalg.norm(moment, axis=1) > 0.0))
    directions = moment[lit] / np.linalg.norm(moment[lit], axis=1, keepdims=True)
    weights = (cell_energy[lit] @ LUMINANCE) / cell_luminance[lit, None]
    return (directions.reshape(-1, 3), np.ascontiguousarray(irradiance[lit]).reshape(-1, 3),
            weights.reshape(len(lit), len(lobe_lambda)))


def ms_lights(lobe_dir, lobe_lambda, lobe_w, lobe_vis):
    """``ms_cells`` with each cell's visibility at the points of every receiver set: (directions (C, 3),
    irradiance (C, 3), [visibility (C, N) per receiver set of ``lobe_vis``, each (J, N)])."""
    dirs, irr, weights = ms_cells(lobe_dir, lobe_lambda, lobe_w)
    return dirs, irr, [np.ascontiguousarray(weights @ v) for v in lobe_vis]
