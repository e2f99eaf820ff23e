"""Equirectangular (latitude–longitude) environment images: the one definition of their direction mapping.

World +y is up. A unit direction d has polar angle θ = acos(d_y) ∈ [0, π] (0 = zenith, +y) and azimuth
φ = atan2(d_x, d_z) ∈ (−π, π] (0 = +z, π/2 = +x). Pixel (row, column) of an H×W image covers
θ ∈ [row·π/H, (row + 1)·π/H] and φ ∈ [−π + column·2π/W, −π + (column + 1)·2π/W]: row 0 touches the zenith and
column 0 starts at φ = −π (the −z direction). Lookups are nearest-texel.
"""

import math

import numpy as np
from numba import njit


@njit(cache=True)
def direction(theta, phi, out):
    """Unit direction for polar angle θ (from +y) and azimuth φ (from +z toward +x) into ``out``."""
    s = math.sin(theta)
    out[0] = s * math.sin(phi)
    out[1] = math.cos(theta)
    out[2] = s * math.cos(phi)


@njit(cache=True)
def angles(d):
    """(θ, φ) of a unit direction."""
    return math.acos(min(max(d[1], -1.0), 1.0)), math.atan2(d[0], d[2])


@njit(cache=True)
def pixel(height, width, d):
    """(row, column) of the texel holding direction d."""
    theta, phi = angles(d)
    r = min(int(theta / math.pi * height), height - 1)
    c = min(int((phi + math.pi) / (2.0 * math.pi) * width), width - 1)
    return r, c


def texel_directions(height: int, width: int) -> np.ndarray:
    """(H, W, 3) unit directions of the texel centres."""
    theta = (np.arange(height) + 0.5) * np.pi / height
    phi = -np.pi + (np.arange(width) + 0.5) * 2 * np.pi / width
    t, p = np.meshgrid(theta, phi, indexing="ij")
    return np.stack([np.sin(t) * np.sin(p), np.cos(t), np.sin(t) * np.cos(p)], axis=-1)


def fibonacci_directions(n: int) -> np.ndarray:
    """(n, 3) near-uniform unit directions, the Fibonacci lattice with poles on ±y: point k has d_y = 1 − 2(k + ½)/n
    and azimuth φ_k = π(3 − √5)(k + ½) (the golden angle times k + ½, from +z toward +x as above). Deterministic;
    the cells of nearest points have nearly equal solid angle."""
    k = np.arange(n) + 0.5
    y = 1.0 - 2.0 * k / max(n, 1)
    r = np.sqrt(np.maximum(0.0, 1.0 - y * y))
    phi = math.pi * (3.0 - math.sqrt(5.0)) * k
    return np.stack([r * np.sin(phi), y, r * np.cos(phi)], axis=1)
