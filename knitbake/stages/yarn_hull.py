"""The yarn tube's optics at yarn level: its hull albedo ρ_Y and its transmittance T_Y (asset pack
``/interreflection/albedo`` and ``/interreflection/transmittance``, ASSET_PACK.md §10).

The strip renderer's shadow maps treat a yarn as an opaque tube of the yarn radius R. Light a tube blocks is not
lost: part passes between its fibers, the rest is scattered (cotton fibers: albedo 0.95) and leaves the tube in
every direction. Two numbers say how much, both measured by path tracing the bake's straight yarn (regular fibers,
three periods, ``correction.yarn_tracer``) through the correction bake's orthographic strip camera
(``correction.strip_camera``: rows across v ∈ [−1, 1], one period along the yarn, so every pixel is a ray into the
tube; a ray that crosses it without a hit sees the environment):

* ρ_Y, the **hull albedo**: the mean radiance leaving the tube when it sits in a uniform white environment of
  radiance 1: what a tube returns of the light around it, in every direction (the renderer's yarn-level
  inter-reflection, ``knitrun.render.interreflection``). For a non-absorbing fiber ρ_Y = 1 (the white furnace).
* T_Y, the **transmittance**: the same image when only the hemisphere behind the yarn (directions away from the
  camera, d·ω_o < 0) has radiance 1 and the camera's side 0. By reciprocity it is the fraction of a beam from the
  camera's direction that leaves the tube on the far side, between the fibers or scattered through them: what a
  yarn lets through to a yarn it shadows (the renderer's fiber count for light crossing a yarn,
  ``dual_scattering.transmittance_count``). The hemisphere is an equirectangular map of ``HEMISPHERE_MAP`` texels
  (its edge, directions grazing the image plane, is resolved to ~3°). ρ_Y = T_Y + R_Y, R_Y the same image under
  the camera's hemisphere (``hull_radiance``; ``tests/test_interreflection.py``).

Views are θ_o at ``n_views`` cell centres of (−π/2, π/2) (azimuth 0; the ply pattern repeats around the yarn as
along it), weighted by solid angle (cos θ_o) times the tube's projected width (cos θ_o):

    X = Σ_views w(θ_o) · mean over the strip image of L(θ_o)  /  Σ_views w(θ_o),    w(θ_o) = cos² θ_o

**Against the colour** (``albedo_by_colour``, ``transmittance_by_colour``, ASSET_PACK.md §10): a scene colour c
multiplies the fibers' lobe albedos A_R, A_TT, A_D per channel (``fiber_bcsdf.tinted``, ``correction.yarn_tracer``),
and a path of n scattering events carries c^n, so ρ_Y and T_Y are polynomials in c, not c times the white yarn's
(cotton1, standard: a yarn red in one channel, c = 0.25, has ρ_Y = 0.228 there, not 0.25 × 0.741 = 0.185: the light
between the fibers keeps its colour). Both are baked with the lobe albedos of every channel scaled by k at the
``colour_scale`` axis' cell centres (``n_colours`` of them, 16 m + 1: 17 puts them at k = 0, 1/16, …, 1; linear
interpolation between 9 samples errs by up to 4 %, between 17 by up to 1.3 %, at k = 31/32), with the same fibers
and paths at every k, so the curve in k is smooth. At k = 0 no path scatters and both are the light that crosses the
tube between the fibers.

Paths are traced to ``max_depth`` scattering events (Russian roulette beyond), so both hold every order of
scattering inside the yarn; an estimate above 1 (noise) is clipped to 1. ``batches`` independent batches (fiber
geometry and paths reseeded) give the standard errors of the means.
"""

from __future__ import annotations

import dataclasses
import math

import numpy as np

from data_formats.asset_pack import AXES
from data_formats.conventions import cell_centres
from data_formats.yarn_spec import YarnSpec
from knitbake.stages.correction import strip_camera, yarn_direction, yarn_tracer
from knitbake.stages.stage_result import StageResult
from knitbake.trace.env_light import env_from_image, uniform_env
from knitbake.trace.path_tracer import MAX_DEPTH, render
from knitrun.shading.equirect import texel_directions

TABLE = "interreflection/albedo"
TRANSMITTANCE_TABLE = "interreflection/transmittance"
BY_COLOUR = {TABLE: "interreflection/albedo_by_colour", TRANSMITTANCE_TABLE: "interreflection/transmittance_by_colour"}
HEMISPHERE_MAP = (64, 128)  # rows, columns of the equirectangular map that lights one hemisphere


def hemisphere_env(toward_camera: np.ndarray, far: bool):
    """An environment of radiance 1 on the hemisphere behind the yarn (``far``: d·ω_o < 0) or on the camera's
    side (d·ω_o > 0), 0 on the other (``HEMISPHERE_MAP`` texels, each lit by its centre direction)."""
    side = texel_directions(*HEMISPHERE_MAP) @ np.asarray(toward_camera, np.float64)
    lit = (side < 0.0) if far else (side > 0.0)
    return env_from_image(np.repeat(lit.astype(np.float64)[..., None], 3, axis=2))


def colour_scales(n_colours: int) -> np.ndarray:
    """The k of the ``colour_scale`` axis' ``n_colours`` cell centres (ASSET_PACK.md §4.2)."""
    return cell_centres(*AXES["colour_scale"].range, n_colours)


def hull_radiance(spec: YarnSpec, environment, n_views=6, rows=16, spp=4, batches=3, max_depth=MAX_DEPTH, seed=0,
                  colour_scale=1.0, progress=None, progress_offset=0, progress_total=None):
    """(batches, 3): per batch, the view-weighted mean radiance of the strip images (module docstring) with the
    environment ``environment(ω_o)`` of each view (ω_o toward the camera), the fibers' lobe albedos scaled by
    ``colour_scale``."""
    thetas = cell_centres(-0.5 * math.pi, 0.5 * math.pi, n_views)
    weight = np.cos(thetas) ** 2
    weight /= weight.sum()
    samples = np.empty((batches, 3))
    for b in range(batches):
        tracer = dataclasses.replace(yarn_tracer(spec, seed + b, colour_scale), background=None)
        views = np.empty((n_views, 3))
        for k, theta in enumerate(thetas):
            tracer = dataclasses.replace(tracer, env=environment(yarn_direction(float(theta), 0.0)))
            image, _ = render(tracer, strip_camera(spec, float(theta), rows), spp, seed=seed + 1000 * b + k,
                              max_depth=max_depth)
            views[k] = image.reshape(-1, 3).mean(axis=0)
            if progress:
                progress(progress_offset + b * n_views + k + 1, progress_total or batches * n_views)
        samples[b] = weight @ views
    return samples


def bake_yarn_hull(spec: YarnSpec, n_views=6, rows=16, spp=4, batches=3, max_depth=MAX_DEPTH, seed=0, n_colours=17,
                   progress=None):
    """ρ_Y and T_Y (RGB) of ``spec`` (module docstring); returns (tables, errors) with ``TABLE`` and
    ``TRANSMITTANCE_TABLE``, their curves against the colour (``BY_COLOUR``, ``n_colours`` samples of k, 16 m + 1 so
    that k = 0 and 1 are among them; 0: no curves) and their standard errors."""
    if batches < 2:
        raise ValueError(f"interreflection: batches = {batches}, expected >= 2 (the standard error needs two)")
    if n_colours < 0 or (n_colours % 16 != 1 and n_colours != 0):
        raise ValueError(f"interreflection: n_colours = {n_colours}, expected 0 (no curve against the colour) or "
                         f"16 m + 1 (samples at k = 0, …, 1: the white yarn's tables are the last)")
    runs = colour_scales(n_colours) if n_colours else np.ones(1)
    per_run = 2 * batches * n_views
    uniform = uniform_env(1.0)
    settings = {"n_views": n_views, "rows": rows, "spp": spp, "batches": batches, "max_depth": max_depth,
                "seed": seed, "progress": progress, "progress_total": len(runs) * per_run}
    curves = {TABLE: [], TRANSMITTANCE_TABLE: []}
    for r, k in enumerate(runs):
        curves[TABLE].append(hull_radiance(spec, lambda _: uniform, colour_scale=float(k),
                                           progress_offset=r * per_run, **settings))
        curves[TRANSMITTANCE_TABLE].append(hull_radiance(spec, lambda wo: hemisphere_env(wo, far=True),
                                                         colour_scale=float(k),
                                                         progress_offset=r * per_run + batches * n_views, **settings))
    tables, errors = {}, {}
    for name, runs_samples in curves.items():
        # both are ≤ 1 (a yarn creates no light); the estimate of a lossless yarn scatters about 1 by its noise, so
        # it is clipped to the bound, and its standard error still says by how much it may be off
        samples = np.stack(runs_samples)  # (runs, batches, 3)
        value = np.clip(samples.mean(axis=1), 0.0, 1.0)
        error = samples.std(axis=1, ddof=1) / math.sqrt(batches)
        tables[name], errors[name] = value[-1], error[-1]
        if n_colours:
            tables[BY_COLOUR[name]], errors[BY_COLOUR[name]] = value, error
    return tables, errors


def bake_yarn_hull_stage(spec, settings, seed, progress=None) -> StageResult:
    """Stage ``interreflection`` of ``knitbake.bake``: settings n_views, rows, spp, batches, n_colours."""
    tables, errors = bake_yarn_hull(spec, seed=seed, progress=progress, **settings)
    kind = (f"standard error of the mean over {settings['batches']} independent batches (fiber geometry and paths "
            f"reseeded)")
    return StageResult(tables, errors, {name: {"error_kind": kind} for name in tables},
                       {"batches": settings["batches"], "views": settings["n_views"],
                        "paths_per_pixel": settings["spp"],
                        "colour_scales": len(tables.get(BY_COLOUR[TABLE], ()))})
