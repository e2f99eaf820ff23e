"""What the strip renderer's shading kernels receive (``strip_shading.shade_regular`` and ``shade_flyaway``): a few
named tuples of arrays, one per kind of input, instead of dozens of positional arrays. Numba passes a named tuple to a
kernel whole and types it by its fields, so each field keeps one dtype and number of dimensions. The tuples are flat
(no tuple inside a tuple): Numba's ``prange`` lowering splits argument tuples into their fields and cannot rebuild
a nested one, so a yarn's textures travel as ``MipStack`` arguments of their own. An input a scene lacks is a
structure of no rows (``no_lights``, ``no_lobes``, ``no_rows``, ``texture_sampling.no_texture``), never None: Numba
types None apart and would compile a kernel once per combination of absent inputs (``strip_shading``, "One
signature").

=================  =======================================================================================
structure          fields (units: scene lengths, radians, linear RGB; N = shading points)
=================  =======================================================================================
``Points``         ``view_dir`` (N, 3) unit toward the camera, ``tangent`` (N, 3) unit yarn tangent,
                   ``arclength`` (N,) rest arc length shifted by the view phase, ``v`` (N,) across the strip
                   in [−1, 1], ``footprint`` (N,) pixel size at the point, ``curve`` (N,) int64 curve index,
                   ``curvature`` (N, 3) and ``stretch`` (N,) of the point's polyline segment
                   (``pipeline.segment_bend``, for ``strip_shading.fiber_bend``; zeros and ones for hairs)
``Corrections``    ``xi_full``, ``psi_full`` (N_v, N_θ, N_φ, 3) or (0, 1, 1, 3) for "use the factors";
                   ``xi_m``, ``xi_n``, ``psi_gm``, ``psi_gn`` (N_v, N, 3) factors (ASSET_PACK.md §6–7);
                   ``xi_view`` (N_v, N_θi, N_θo, N_φ, 3), ξ closed at every view, or (0, 1, 1, 1, 3): when it
                   has cells it replaces the other ξ tables; ``xi_single`` (v, θ_d, φ) and ``xi_single_view``
                   (v, θ_i, θ_o, φ), the ξ of single scattering where ξ is closed apart on single and multiple
                   scattering (the tables above then hold multiple scattering's), or empty: one ξ for both
``Look``           one yarn entry: ``params`` fiber BCSDF vector, ``ds`` dual-scattering tables (5, N_θ, 3),
                   ``period`` texture period, ``radius`` regular strip half-width, ``flyaway_half_width``,
                   fiber counts ``n_occluded``, ``n_cross`` (a beam crossing another yarn: all of its
                   transmittance T_Y) and ``n_cross_rest`` (the part not passing between the fibers), ``gap``
                   τ_Y (the part that does, ``yarn_look.gap_transmittance``), Zinke's density factors ``d_f``,
                   ``d_b``
``MipStack``       a texture (``knitrun.render.texture_sampling``): tangent, coverage, flyaway (3 variants)
``Lights``         distant lights: ``direction`` (L, 3) unit toward the light, ``irradiance`` (L, 3),
                   ``visibility`` (L, N) yarn-level, per point (also the multiple-scattering clusters of the
                   SRBF lobes, ``pipeline.ms_lights``), ``beyond`` (L, N) the fraction at most one yarn blocks
                   (``Features.two_blockers``, the default), or (L, 0) where not counted (1 everywhere: the
                   ablation ``one_blocker``; the clusters)
``Lobes``          SRBF lobes: ``direction`` (J, 3), ``sharpness`` λ (J,), ``weight`` W (J, 3),
                   ``visibility`` (J, N)
``IMSlices``       the I_M^{TT,D} table at each lobe's λ and its other axes (``knitrun.shading.im_lookup``)
=================  =======================================================================================
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np


class Points(NamedTuple):
    view_dir: np.ndarray
    tangent: np.ndarray
    arclength: np.ndarray
    v: np.ndarray
    footprint: np.ndarray
    curve: np.ndarray
    curvature: np.ndarray
    stretch: np.ndarray


class Corrections(NamedTuple):
    xi_full: np.ndarray
    xi_m: np.ndarray
    xi_n: np.ndarray
    psi_full: np.ndarray
    psi_gm: np.ndarray
    psi_gn: np.ndarray
    xi_view: np.ndarray
    xi_single: np.ndarray  # ξ of single scattering (N_v, N_θ, N_φ, 3), or (0, 1, 1, 3): the one ξ for both
    xi_single_view: np.ndarray  # the same closed at every view (N_v, N_θ, N_θ, N_φ, 3), or (0, 1, 1, 1, 3)


class Look(NamedTuple):
    params: np.ndarray
    ds: np.ndarray
    period: float
    radius: float
    flyaway_half_width: float
    n_occluded: float
    n_cross: float
    n_cross_rest: float  # n_cross with τ_Y split out: τ_Y + (1 − τ_Y) ā_f^{n_cross_rest} = T_Y
    gap: float  # τ_Y: light past a blocking yarn unscattered, between its fibers (``yarn_look.gap_transmittance``)
    d_f: float  # Zinke's forward-scattering density factor (``dual_scattering.D_F``; 0: single scattering alone)
    d_b: float  # his back-scattering density factor (``dual_scattering.D_B``; 0: single scattering alone)


class Lights(NamedTuple):
    direction: np.ndarray
    irradiance: np.ndarray
    visibility: np.ndarray
    beyond: np.ndarray


class Lobes(NamedTuple):
    direction: np.ndarray
    sharpness: np.ndarray
    weight: np.ndarray
    visibility: np.ndarray
    albedo: np.ndarray  # (4,): the ρ ``visibility`` was inter-reflected with, then ρ_Y per channel (zeros: none)


def no_lights(n_points: int) -> Lights:
    """No distant light (an environment-only scene, or no multiple-scattering cluster)."""
    return Lights(np.zeros((0, 3)), np.zeros((0, 3)), np.zeros((0, n_points)), np.zeros((0, 0)))


def no_lobes(n_points: int) -> Lobes:
    """No SRBF lobe (a scene without an environment)."""
    return Lobes(np.zeros((0, 3)), np.zeros(0), np.zeros((0, 3)), np.zeros((0, n_points)), np.zeros(4))


def no_rows() -> np.ndarray:
    """(0, 3) float64: an optional per-point or per-channel input that is absent (the yarn-level bounce of
    ``shade_regular``, the body's glow of ``shade_flyaway``)."""
    return np.zeros((0, 3))
