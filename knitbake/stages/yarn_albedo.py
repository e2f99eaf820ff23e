"""The yarn's hull albedo ρ_Y: how much of the light that a yarn blocks it sends on, for the renderer's yarn-level
inter-reflection (asset pack ``/interreflection/albedo``, ASSET_PACK.md §10).

The strip renderer's shadow maps treat a yarn as an opaque tube of the yarn radius R. Light a tube blocks is not
lost: part passes between its fibers, the rest is scattered (cotton fibers: albedo 0.95) and leaves the tube in
every direction, toward the neighbours too. ρ_Y measures what such a tube returns under uniform light: the mean
radiance leaving the tube, over the rays that enter it, when the yarn (regular fibers, three periods, the bake's
straight yarn ``correction.yarn_tracer``) sits in a uniform white environment of radiance 1:

    ρ_Y = Σ_views w(θ_o) · mean over the strip image of L(θ_o)  /  Σ_views w(θ_o),    w(θ_o) = cos² θ_o

The image is the correction bake's orthographic strip camera (``correction.strip_camera``: rows across v ∈ [−1, 1],
one period along the yarn), so every pixel is a ray into the tube; a ray that crosses without a hit sees the
environment (1). Views are θ_o at ``n_views`` cell centres of (−π/2, π/2) (azimuth 0; the ply pattern repeats
around the yarn as along it), weighted by solid angle (cos θ_o) times the tube's projected width (cos θ_o). Paths
are traced to ``max_depth`` scattering events (Russian roulette beyond), so ρ_Y holds every order of scattering
inside the yarn: for a non-absorbing fiber it is 1 (the white furnace, ``tests/test_interreflection.py``); an
estimate above 1 (noise) is clipped to 1.

``batches`` independent batches (fiber geometry and paths reseeded) give the standard error of the mean.
"""

from __future__ import annotations

import dataclasses
import math

import numpy as np

from data_formats.conventions import cell_centres
from data_formats.yarn_spec import YarnSpec
from knitbake.stages.correction import strip_camera, yarn_tracer
from knitbake.stages.stage_result import StageResult
from knitbake.trace.env_light import uniform_env
from knitbake.trace.path_tracer import render

TABLE = "interreflection/albedo"


def bake_yarn_albedo(spec: YarnSpec, n_views=6, rows=16, spp=4, batches=3, max_depth=32, seed=0, progress=None):
    """ρ_Y (RGB) of ``spec`` (module docstring); returns (tables, errors) with ``TABLE`` and its standard error."""
    if batches < 2:
        raise ValueError(f"interreflection: batches = {batches}, expected >= 2 (the standard error needs two)")
    thetas = cell_centres(-0.5 * math.pi, 0.5 * math.pi, n_views)
    weight = np.cos(thetas) ** 2
    weight /= weight.sum()
    samples = np.empty((batches, 3))
    environment = uniform_env(1.0)
    for b in range(batches):
        tracer = dataclasses.replace(yarn_tracer(spec, seed + b), env=environment, background=None)
        views = np.empty((n_views, 3))
        for k, theta in enumerate(thetas):
            image, _ = render(tracer, strip_camera(spec, float(theta), rows), spp, seed=seed + 1000 * b + k,
                              max_depth=max_depth)
            views[k] = image.reshape(-1, 3).mean(axis=0)
            if progress:
                progress(b * n_views + k + 1, batches * n_views)
        samples[b] = weight @ views
    # ρ_Y ≤ 1 (a yarn creates no light); the estimate of a lossless yarn scatters about 1 by its noise, so it is
    # clipped to the bound, and its standard error still says by how much it may be off
    mean = np.clip(samples.mean(axis=0), 0.0, 1.0)
    return {TABLE: mean}, {TABLE: samples.std(axis=0, ddof=1) / math.sqrt(batches)}


def bake_yarn_albedo_stage(spec, settings, seed, progress=None) -> StageResult:
    """Stage ``interreflection`` of ``knitbake.bake``: settings n_views, rows, spp, batches."""
    tables, errors = bake_yarn_albedo(spec, seed=seed, progress=progress, **settings)
    kind = (f"standard error of the mean over {settings['batches']} independent batches (fiber geometry and paths "
            f"reseeded)")
    return StageResult(tables, errors, {TABLE: {"error_kind": kind}},
                       {"batches": settings["batches"], "views": settings["n_views"],
                        "paths_per_pixel": settings["spp"]})
