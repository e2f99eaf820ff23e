"""Bake the per-yarn corrections of Huang et al. 2025 §4.3: the DS correction ξ ≈ ξ_M(v, θ_d) ξ_N(v, φ) and the
fiber-level shadowing Ψ^Fiber_G ≈ Ψ_{G,M}(v, θ_i) Ψ_{G,N}(v, φ), each with a rank-1 factorization residual and per-entry
standard errors from independent sample batches.

Set-up (the conventions of ``data_formats/ASSET_PACK.md`` §3): one straight yarn of the spec, regular fibers only,
along t = +z over three periods; the strip normal n = +x (toward the camera at θ_o = 0), b = n × t = −y, v = w/h
with w the coordinate along b and h = spec.radius. A direction with longitudinal angle θ and azimuth φ (from n
toward b) is ω = cos θ cos φ n + cos θ sin φ b + sin θ t. For a grid cell (θ-index k, φ-index m):

* **Shadowing** Ψ^Fiber_G(v; θ_i, φ): the camera looks along −n (θ_o = 0, φ_o = 0); the light comes from θ_i,
  φ_i = −φ. For every camera sample that hits a fiber, visibility of the light from the far side of that fiber
  (``TracerScene.leave_points``, the tracer's own rule) through the other fibers: 1 or 0. Ψ^Fiber_G of a v-bin = mean
  visibility of the hits in it.
* **Correction** ξ(v; θ_d, φ) = Ψ_*/Ψ_DS: the camera looks from θ_o = θ_d, the light comes from θ_i = −θ_d,
  φ_i = −φ (so (θ_o − θ_i)/2 = θ_d). Ψ_* is the path-traced radiance of the hits in the bin (multiple scattering
  inside the yarn, ``yarn_only_radius``), Ψ_DS the dual-scattering estimate of the same hits
  (``knitrun.shading.dual_scattering``) as the renderer evaluates it: lit or not by the explicit fibers, and a shadowed
  hit behind the renderer's n_occluded fibers (``dual_scattering.fiber_counts``), not its own count, so that
  ξ·Ψ_DS^renderer reproduces Ψ_* whatever the error of that count; ξ of a bin = Σ Ψ_* / Σ Ψ_DS. ξ's
  factorization is weighted by (Σ Ψ_DS)² of each bin, i.e. it fits the radiance
  ξ·Ψ_DS that shading produces: a bin where the DS estimate is tiny (an edge bin lit from the far side) has a
  ratio far from the others that an unweighted fit lets distort every other direction of that v. The stage also
  keeps Ψ_* itself, ``correction/radiance``: the mean path-traced radiance of each bin's pixels per unit irradiance
  (the camera's pixels are 2h/rows square), which the ``closure`` stage (``knitbake/stages/closure.py``) makes the
  strip renderer reproduce; this stage's ξ stays the paper's, and that stage stores the closed one beside it.

Each quantity is measured B times with independent seeds; tables hold the batch mean, ``*_stderr`` the standard
error s/√B. The factorization X[k, m] ≈ a[k]·c[m] per (v, channel) is the leading singular pair of X (non-negative),
scaled so that c has mean 1 over m; the residual is ‖X − a cᵀ‖_F / ‖X‖_F. Bins without any hit (beyond the fibers)
get the value 1 and error 0.
"""

from __future__ import annotations

import dataclasses
import math

import numpy as np

from data_formats.conventions import PHI_RANGE, THETA_RANGE, cell_centres
from data_formats.yarn_spec import YarnSpec, dumps_spec
from knitbake.fibers.fiber_set import KIND_REGULAR
from knitbake.fibers.procedural_yarn import generate_fibers
from knitbake.stages.stage_result import StageResult
from knitbake.trace.path_tracer import MAX_DEPTH, TracerScene, camera_rays, render
from knitrun.render.camera import Camera, tan_half_fov
from knitrun.shading.dual_scattering import evaluate_ds, fiber_counts
from knitrun.shading.fiber_bcsdf import params_from_optics, tinted
from knitrun.shading.fiber_frame import fiber_angles


def yarn_direction(theta, phi):
    """World direction (x = n, y = −b, z = t) of longitudinal angle θ and azimuth φ (from n toward b)."""
    return np.array([math.cos(theta) * math.cos(phi), -math.cos(theta) * math.sin(phi), math.sin(theta)])


_GEOMETRY_MEMO: dict = {}
CAMERA_CLEARANCE = 3.0  # yarn radii between the axis and the nearest ray origin of ``strip_camera``


def yarn_tracer(spec: YarnSpec, seed: int, colour_scale: float = 1.0) -> TracerScene:
    """Regular fibers of three periods, z ∈ [−P, 2P], as an unlit tracer scene (memoised per spec and seed, so
    the correction and shadowing stages of one bake build each batch's geometry once); ``colour_scale`` k: the
    fibers' lobe albedos A_R, A_TT, A_D times k, the yarn in the grey k (as the reference tracer draws a colour)."""
    key = (dumps_spec(spec), seed)
    if key not in _GEOMETRY_MEMO:
        if len(_GEOMETRY_MEMO) >= 8:
            _GEOMETRY_MEMO.clear()
        _GEOMETRY_MEMO[key] = _build_yarn_tracer(spec, seed)
    tracer = _GEOMETRY_MEMO[key]
    if colour_scale == 1.0:
        return tracer
    return dataclasses.replace(tracer, params=np.stack([tinted(p, np.full(3, colour_scale)) for p in tracer.params]))


def forget_yarn_tracers() -> None:
    """Drop the memoised tracer scenes of ``yarn_tracer`` (a benchmark timing each bake as a fresh process would)."""
    _GEOMETRY_MEMO.clear()


def _build_yarn_tracer(spec: YarnSpec, seed: int) -> TracerScene:
    period = spec.geometry.ply_pitch
    fibers = generate_fibers(spec, length=3 * period, z_start=-period, seed=seed, flyaways=False)
    fibers = fibers.select(fibers.kind == KIND_REGULAR)
    return TracerScene(None, np.zeros(fibers.n_fibers, np.int32), params_from_optics(spec.optics)[None],
                       fibers=fibers)


def strip_camera(spec: YarnSpec, theta_o: float, rows: int) -> Camera:
    """Orthographic camera from direction θ_o (φ_o = 0) framing v ∈ [−1, 1] in ``rows`` rows and ≥ one period.

    An orthographic ray starts on the image plane, so the plane must clear the yarn: its point farthest along the
    yarn, half the image width W out, lies d cos θ_o − (W/2)|sin θ_o| in front of the axis for a camera d away, and
    d is chosen to leave ``CAMERA_CLEARANCE`` yarn radii there at every θ_o (a fixed d of 4 radii, as once used,
    started the rays of oblique views inside or behind the yarn: from |θ_o| ≈ 28° on for cotton1)."""
    h = spec.radius
    period = spec.geometry.ply_pitch
    wo = yarn_direction(theta_o, 0.0)
    centre = np.array([0.0, 0.0, period / 2])
    width = max(1, math.ceil(rows * period * math.cos(theta_o) / (2 * h)))
    half_width = width * h / rows  # pixels are 2h / rows square
    distance = (CAMERA_CLEARANCE * h + half_width * abs(math.sin(theta_o))) / math.cos(theta_o)
    # image up = +y = −b, so image row r has v = −(1 − 2 (r + ½)/rows)
    return Camera(centre + distance * wo, centre, np.array([0.0, 1.0, 0.0]), width, rows, ortho_height=2 * h)


def row_v(rows: int) -> np.ndarray:
    """v of each image row of ``strip_camera``: the cell centres of [−1, 1], row 0 at v = −1 (image up is −b)."""
    return cell_centres(-1.0, 1.0, rows)


def factor_rank1(x: np.ndarray, weight: np.ndarray | None = None, iterations: int = 30):
    """x (N_v, K, M, 3) → a (N_v, K, 3), c (N_v, M, 3) with x ≈ a c per (v, channel), c of mean 1 over M; plus the
    relative residual ‖x − a cᵀ‖_F/‖x‖_F per v and overall (unweighted, ASSET_PACK.md §6).

    Without ``weight``: the leading singular pair (non-negative). With ``weight`` (same shape, ≥ 0): the weighted
    least-squares rank-1 fit min Σ w (x − a c)², by alternating exact updates a_k = Σ_m w x c / Σ_m w c² (and
    likewise c) from the singular pair, ``iterations`` times, a and c kept ≥ 0."""
    n_v, n_k, n_m, _ = x.shape
    a = np.ones((n_v, n_k, 3))
    c = np.ones((n_v, n_m, 3))
    approx = np.empty_like(x)
    for i in range(n_v):
        for ch in range(3):
            u, s, vt = np.linalg.svd(x[i, :, :, ch])
            av, cv = np.abs(u[:, 0]) * s[0], np.abs(vt[0])
            if weight is not None and np.any(weight[i, :, :, ch] > 0):
                w, xi = weight[i, :, :, ch], x[i, :, :, ch]
                for _ in range(iterations):
                    av = np.maximum((w * xi) @ cv / np.maximum(w @ (cv * cv), 1e-300), 0.0)
                    cv = np.maximum(av @ (w * xi) / np.maximum((av * av) @ w, 1e-300), 0.0)
            scale = cv.mean()
            if scale > 0:
                a[i, :, ch], c[i, :, ch] = av * scale, cv / scale
            approx[i, :, :, ch] = np.outer(a[i, :, ch], c[i, :, ch])
    err = ((x - approx) ** 2).sum(axis=(1, 2, 3))
    norm = (x ** 2).sum(axis=(1, 2, 3))
    by_v = np.sqrt(err / np.maximum(norm, 1e-300))
    total = math.sqrt(err.sum() / max(norm.sum(), 1e-300))
    return a, c, by_v, total


def v_bin_sums(values, weights, rows_v, n_v):
    """Per-v-bin sums of ``values`` (rows, cols, ...) and counts of ``weights`` (rows, cols) > 0."""
    idx = np.clip(((rows_v + 1) / 2 * n_v).astype(int), 0, n_v - 1)
    sums = np.zeros((n_v,) + values.shape[2:])
    counts = np.zeros(n_v)
    for r, b in enumerate(idx):
        sums[b] += values[r].sum(axis=0)
        counts[b] += weights[r].sum()
    return sums, counts


def _factored_tables(samples, prefix, names, weights=None):
    """Batch samples (B, N_v, K, M, 3) → the full table (batch mean), its factors, per-entry stderr of each, and
    the residuals; ``weights``
    (same shape) makes each factorization the weighted fit of ``factor_rank1``."""
    if weights is None:
        weights = [None] * len(samples)
    factors = [factor_rank1(s, w) for s, w in zip(samples, weights)]
    a = np.stack([f[0] for f in factors])
    c = np.stack([f[1] for f in factors])
    b = samples.shape[0]
    mean_factors = factor_rank1(samples.mean(axis=0), None if weights[0] is None else np.mean(weights, axis=0))
    full = names[2].split("_")[0]  # "xi" or "psi": the unfactorized table
    tables = {f"{prefix}/{full}": samples.mean(axis=0),
              f"{prefix}/{names[0]}": mean_factors[0], f"{prefix}/{names[1]}": mean_factors[1],
              f"{prefix}/{names[2]}": np.float64(mean_factors[3]), f"{prefix}/{names[2]}_by_v": mean_factors[2]}
    errors = {f"{prefix}/{full}": samples.std(axis=0, ddof=1) / math.sqrt(b),
              f"{prefix}/{names[0]}": a.std(axis=0, ddof=1) / math.sqrt(b),
              f"{prefix}/{names[1]}": c.std(axis=0, ddof=1) / math.sqrt(b),
              f"{prefix}/{names[2]}": float(np.std([f[3] for f in factors], ddof=1) / math.sqrt(b)),
              f"{prefix}/{names[2]}_by_v": np.stack([f[2] for f in factors]).std(axis=0, ddof=1) / math.sqrt(b)}
    return tables, errors


def bake_shadowing(spec: YarnSpec, n_v=8, n_theta=8, n_phi=8, rows=32, spp=4, batches=4, seed=0, progress=None):
    """Ψ^Fiber_{G,M}, Ψ^Fiber_{G,N} and residuals (see module docstring); returns (tables, errors)."""
    thetas = cell_centres(*THETA_RANGE, n_theta)
    phis = cell_centres(*PHI_RANGE, n_phi)
    samples = np.ones((batches, n_v, n_theta, n_phi, 3))
    rows = max(rows, n_v)
    total, done = batches * n_theta * n_phi, 0
    for b in range(batches):
        tracer = yarn_tracer(spec, seed + b)
        cam = strip_camera(spec, 0.0, rows)
        for k, th in enumerate(thetas):
            for m, ph in enumerate(phis):
                light = yarn_direction(th, -ph)
                vis, hit = _visibility_image(tracer, cam, light, spp, seed + 1000 * b + 37 * k + m)
                sums, counts = v_bin_sums(vis[..., None], hit, row_v(rows), n_v)
                ok = counts > 0
                samples[b, ok, k, m, :] = (sums[ok] / counts[ok][:, None])
                done += 1
                if progress:
                    progress(done, total)
    return _factored_tables(samples, "shadowing", ("psi_GM", "psi_GN", "psi_residual"))


def primary_hits(tracer, cam, seed, sample):
    """Camera sample ``sample`` of every pixel — exactly the primary rays ``path_tracer.render`` traces for this
    seed, so the path-traced and DS images share their hits (common random numbers: the ratio ξ loses the
    coverage noise). Returns (hit mask (H, W), hit points (n, 3), prims (n,), flat pixel indices (n,))."""
    fwd, right, up = cam.basis()
    h, w = cam.height, cam.width
    org, dirs = np.empty((h * w, 3)), np.empty((h * w, 3))
    camera_rays(np.asarray(cam.position, float), fwd, right, up, w, h, tan_half_fov(cam),
                 float(cam.ortho_height), seed, sample, 1, org, dirs)
    hits = tracer.intersect(org, dirs)
    idx = np.flatnonzero(hits.hit)
    return hits.hit.reshape(h, w), org[idx] + hits.t[idx, None] * dirs[idx], hits.prim[idx].astype(np.int64), idx


def _visibility_image(tracer, cam, light, spp, seed):
    """Per pixel: summed visibility of the light over the pixel's fiber hits, and the number of hits (spp samples).
    Shadow rays leave each hit fiber by the tracer's own rule (``leave_points``)."""
    vis = np.zeros((cam.height, cam.width))
    hits_n = np.zeros((cam.height, cam.width))
    for sample in range(spp):
        mask, points, prims, idx = primary_hits(tracer, cam, seed, sample)
        dirs = np.tile(light, (prims.size, 1))
        start = tracer.leave_points(prims, points, dirs)
        v = np.zeros(mask.size)
        v[idx] = ~tracer.occluded(start, dirs, np.inf)
        vis += v.reshape(mask.shape)
        hits_n += mask
    return vis, hits_n


def fibers_toward(tracer, prims, points, light, max_fibers=256):
    """Number of fibers a ray from each hit (leaving its own fiber) toward ``light`` crosses before escaping."""
    dirs = np.tile(light, (prims.size, 1))
    start = tracer.leave_points(prims, points, dirs)
    count = np.zeros(prims.size, np.int64)
    live = np.arange(prims.size)
    for _ in range(max_fibers):
        if live.size == 0:
            break
        hits = tracer.intersect(start[live], dirs[live])
        live, start_live = live[hits.hit], start[live][hits.hit]
        count[live] += 1
        p = start_live + hits.t[hits.hit, None] * dirs[live]
        start[live] = tracer.leave_points(hits.prim[hits.hit], p, dirs[live])
    return count


def fiber_frames(tracer, prims):
    """Unit fiber tangents at hit segments (``TracerScene.fiber_tangents``)."""
    return tracer.fiber_tangents(prims)


def _ds_image(tracer, cam, light, spp, seed, ds_tables, params, n_occluded=None):
    """Per pixel: mean DS radiance per unit irradiance (``knitrun.shading.dual_scattering.evaluate_ds``) of the pixel's
    fiber hits (misses add 0), fiber angles in each hit fiber's frame. ``n_occluded`` None: Zinke's estimate, each
    hit behind its own count of fibers toward the light (D = 1 iff none). A number: as the renderer evaluates it, a
    hit is lit directly (D = 1) iff the explicit fibers leave it a clear path to the light, else D = 0 with
    ``n_occluded`` fibers toward the light; DS is linear in D at fixed n, so a bin's mean is then the renderer's DS
    at D = the bin's lit fraction."""
    fwd = cam.basis()[0]
    img = np.zeros((cam.height * cam.width, 3))
    for sample in range(spp):
        _, points, prims, idx = primary_hits(tracer, cam, seed, sample)
        t = fiber_frames(tracer, prims)
        theta_i, theta_o, phi = fiber_angles(t, np.tile(-fwd, (len(t), 1)), np.tile(light, (len(t), 1)))
        if n_occluded is None:
            n_front = fibers_toward(tracer, prims, points, light)
        else:
            n_front = np.where(fibers_toward(tracer, prims, points, light, max_fibers=1) == 0, 0.0, n_occluded)
        img[idx] += evaluate_ds(ds_tables, theta_i, theta_o, phi, n_front, params=params,
                                direct_fraction=(n_front == 0).astype(float))
    return (img / spp).reshape(cam.height, cam.width, 3)


def bake_correction(spec: YarnSpec, ds_tables: dict, n_v=8, n_theta=4, n_phi=4, rows=32, spp=8, batches=4,
                    max_depth=MAX_DEPTH, seed=0, progress=None):
    """ξ_M, ξ_N and residuals (see module docstring); ``ds_tables``: the baked ``dual_scattering/*`` arrays.
    Returns (tables, errors)."""
    thetas = cell_centres(*THETA_RANGE, n_theta)
    phis = cell_centres(*PHI_RANGE, n_phi)
    params = params_from_optics(spec.optics)
    n_occluded = fiber_counts(spec.geometry, spec.radius)[1]
    samples = np.ones((batches, n_v, n_theta, n_phi, 3))
    weights = np.zeros((batches, n_v, n_theta, n_phi, 3))
    radiance = np.zeros((batches, n_v, n_theta, n_phi, 3))
    rows = max(rows, n_v)
    total, done = batches * n_theta * n_phi, 0
    for b in range(batches):
        geometry = yarn_tracer(spec, seed + b)
        for k, th_d in enumerate(thetas):
            cam = strip_camera(spec, th_d, rows)
            for m, ph in enumerate(phis):
                light = yarn_direction(-th_d, -ph)
                lit = geometry.with_lights(light[None], np.ones((1, 3)))
                s = seed + 1000 * b + 37 * k + m
                traced, _ = render(lit, cam, spp, seed=s, max_depth=max_depth)
                ds = _ds_image(geometry, cam, light, spp, s, ds_tables, params, n_occluded)
                num, pixels = v_bin_sums(traced, np.ones(traced.shape[:2]), row_v(rows), n_v)
                den, _ = v_bin_sums(ds, np.ones(ds.shape[:2]), row_v(rows), n_v)
                radiance[b, :, k, m] = num / np.maximum(pixels, 1)[:, None]
                ok = np.all(den > 1e-12 * max(den.max(), 1e-300), axis=1)
                samples[b, ok, k, m] = num[ok] / den[ok]
                weights[b, :, k, m] = den ** 2
                done += 1
                if progress:
                    progress(done, total)
    tables, errors = _factored_tables(samples, "correction", ("xi_M", "xi_N", "xi_residual"), weights)
    tables["correction/radiance"] = radiance.mean(axis=0)
    errors["correction/radiance"] = radiance.std(axis=0, ddof=1) / math.sqrt(batches)
    return tables, errors


def bake_shadowing_stage(spec, settings, seed, progress=None) -> StageResult:
    """Stage ``shadowing`` of ``knitbake.bake``: settings n_v, n_theta, n_phi, rows, spp, batches."""
    tables, errors = bake_shadowing(spec, seed=seed, progress=progress, **settings)
    kind = (f"standard error of the mean over {settings['batches']} independent batches (fiber geometry and "
            f"pixel jitter reseeded)")
    return StageResult(tables, errors, {name: {"error_kind": kind} for name in tables},
                       {"batches": settings["batches"], "directions": settings["n_theta"] * settings["n_phi"],
                        "camera_samples_per_pixel": settings["spp"]})


def bake_correction_stage(spec, settings, seed, progress=None) -> StageResult:
    """Stage ``correction`` of ``knitbake.bake``: settings n_v, n_theta, n_phi, rows, spp, batches, and ``ds`` —
    the dual-scattering quadrature settings, the same as the pack's own dual_scattering stage, since ξ divides by
    the DS estimate the runtime computes from those tables."""
    from knitbake.stages.ds_precompute import precompute_dual_scattering

    ds = {k: v[0] for k, v in precompute_dual_scattering(params_from_optics(spec.optics), **settings["ds"]).items()}
    tables, errors = bake_correction(spec, ds, seed=seed, progress=progress,
                                     **{k: v for k, v in settings.items() if k != "ds"})
    kind = (f"standard error of the mean over {settings['batches']} independent batches (fiber geometry, paths and "
            f"pixel jitter reseeded)")
    return StageResult(tables, errors, {name: {"error_kind": kind} for name in tables},
                       {"batches": settings["batches"], "paths_per_pixel": settings["spp"],
                        "directions": settings["n_theta"] * settings["n_phi"]})
