"""Angles of directions about a fiber (``data_formats/ASSET_PACK.md`` §3): the one definition of θ and φ that the
BCSDF, the renderer's shading and the bake share, as Numba functions (callable from kernels and from Python).

Conventions: t is the unit fiber (or yarn) tangent and ω a unit direction pointing away from the fiber, ω_i toward
the light and ω_o toward the viewer; angles in radians.

* Longitudinal angle θ = asin(ω·t) ∈ [−π/2, π/2] (``longitudinal_angle``); the argument is clamped to [−1, 1]
  (``clamped_asin``) so that rounding of a unit vector never leaves asin's domain.
* Azimuth difference φ = φ_o − φ_i (``azimuth_difference``): in a right-handed fiber frame (x = t, y, z) the azimuth
  of ω is atan2(ω_z, ω_y), so φ is the angle from ω_i's projection onto the normal plane to ω_o's, counter-clockwise
  about t, in [−π, π]; φ = 0 is light from the viewer's side, φ = ±π light from behind the fiber.
* ``wrap_angle`` maps any angle into [−π, π).
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit, prange


@njit(cache=True)
def dot(a, b):
    """a·b of two 3-vectors."""
    return a[0] * b[0] + a[1] * b[1] + a[2] * b[2]


@njit(cache=True)
def clamped_asin(x):
    """asin(x) with x clamped to [−1, 1]."""
    return math.asin(min(max(x, -1.0), 1.0))


@njit(cache=True)
def longitudinal_angle(t, w):
    """θ = asin(ω·t) of unit direction ``w`` against unit tangent ``t``."""
    return clamped_asin(dot(w, t))


@njit(cache=True)
def wrap_angle(x):
    """Angle ``x`` (radians) mapped into [−π, π)."""
    return (x + math.pi) % (2.0 * math.pi) - math.pi


@njit(cache=True)
def azimuth_difference(t, wo, wi):
    """φ = φ_o − φ_i of unit directions ``wo``, ``wi`` about the unit tangent ``t`` (module docstring)."""
    co, ci = dot(wo, t), dot(wi, t)
    o0, o1, o2 = wo[0] - co * t[0], wo[1] - co * t[1], wo[2] - co * t[2]
    i0, i1, i2 = wi[0] - ci * t[0], wi[1] - ci * t[1], wi[2] - ci * t[2]
    cx, cy, cz = i1 * o2 - i2 * o1, i2 * o0 - i0 * o2, i0 * o1 - i1 * o0
    return math.atan2(cx * t[0] + cy * t[1] + cz * t[2], i0 * o0 + i1 * o1 + i2 * o2)


@njit(parallel=True, cache=True)
def fiber_angles(t, wo, wi):
    """(θ_i, θ_o, φ) per row of unit tangents ``t`` and unit directions ``wo``, ``wi`` (each (N, 3))."""
    n = t.shape[0]
    theta_i, theta_o, phi = np.empty(n), np.empty(n), np.empty(n)
    for k in prange(n):
        theta_i[k] = longitudinal_angle(t[k], wi[k])
        theta_o[k] = longitudinal_angle(t[k], wo[k])
        phi[k] = azimuth_difference(t[k], wo[k], wi[k])
    return theta_i, theta_o, phi
