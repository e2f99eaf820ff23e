"""Regular-fiber and flyaway textures of one yarn period by orthographic ray casting (Huang et al. 2025 §4.2–4.4, §5.1;
asset pack ``/textures``, ASSET_PACK.md §3 and §8).

Conventions
-----------
* Yarn space of ``procedural_yarn`` (lengths in the spec's unit, cm for every preset): the yarn axis is +z. The
  camera is orthographic and looks along −x, so the strip frame of ASSET_PACK.md §3 is t = +z (yarn tangent),
  n = +x (toward the camera), b = n × t = −y. A vector (x, y, z) of yarn space has strip components
  (·t, ·b, ·n) = (z, −y, x) (``to_strip``).
* Strip coordinates: u = z / period, v = w / h with w = p·b = −y, so a point of the strip is (x, y, z) =
  (·, −v h, u P). Texel (i, j) of an H × W level covers v ∈ −1 + [i, i + 1]·2/H (row i), u ∈ [j, j + 1]/W
  (column j); its S × S sub-sample rays sit at the centres of an S × S grid of sub-cells (``texel_rays``).
  Every texture covers z ∈ [0, P] and is cast against fibers of z ∈ [−P, 2P] (regular fibers are P-periodic,
  ``generate_fibers``), so fibers and occluders of the neighbouring periods are present at the seam.
* Fibers are traced as Embree's round linear curves (``knitbake.trace.embree_curves``): each fiber polyline swept by
  a sphere of the fiber radius r (cones, here cylinders, between spheres at the points), its exact shape with no
  polygon, so a fiber's projected width is exactly 2r. Vertices and rays are float32 inside Embree (hit distances
  and normals come back as float64 of float32 precision); everything computed from them is float64.
* h (``half_width``): the yarn radius ``spec.radius`` for the regular textures; for the flyaway textures the
  farthest point of any drawn flyaway's swept spheres from the yarn axis (max over its points of hypot(x, y) + r,
  ≥ the yarn radius).
* ``normal``: the outward unit normal of the first fiber hit, Embree's geometric normal of the swept-sphere surface
  (radial from the segment's axis on a cylinder, from the point on a joint's or an end's sphere). Camera rays start
  outside every fiber, so it faces the camera (normal · ray direction < 0). ``tangent``: the unit direction of the
  hit segment (from its two float32 vertices), signed so that its t-component is ≥ 0. Both are
  coverage-premultiplied: a texel holds the mean over its sub-samples with misses counted as 0 (length ≤ coverage).
* ``coverage``: fraction of sub-samples that hit a regular fiber.
* ``ao``: ambient visibility of the visible fiber points: from each hit, ``ao_rays`` rays cosine-distributed about
  its normal, starting at the hit moved off the surface along the normal by ``AO_OFFSET`` × the scene extent E
  (the largest |coordinate| + r of its vertices): 2^−18 E is 64 float32 ulps of the largest coordinate, far above
  the error of Embree's hit points (float32 vertices and rays; measured ≤ 1.6e-4 r ≈ 4 ulps on cotton1, where the
  offset is 0.004 r), so no ray starts inside its own fiber (Embree reports the exit of a curve from inside).
  Counted visible when they leave without hitting any regular fiber of the same yarn (no distance limit; flyaways
  do not occlude). A texel holds the mean over its covered sub-samples, 1 where none is covered. The random numbers
  of a sub-sample depend only on (seed, its texel column in the period), so a bake of a shifted window sees the
  same rays.
* ``flyaway`` (3, H, W, 4): RGB the coverage-premultiplied flyaway tangent (as ``tangent``), A the fraction of
  sub-samples that see a flyaway nearer than every regular fiber (depth test at bake time: a flyaway hidden by
  the regular fibers of the same yarn is removed).
* Mip levels down to 1 × 1 (width and height must be powers of two); level k + 1 is the 2 × 2 box reduction of
  level k (2 × 1 once one dimension is 1): plain mean for normal, tangent, coverage and flyaway; for ao the
  coverage-weighted mean, computed exactly from the pooled ray counts.

Regular seam
------------
The regular fibers are P-periodic and the margins hold the neighbouring periods, so the texture is the view of an
endless yarn: u = 1 continues into u = 0. The curves are the fibers' exact swept spheres, with no polygon turning
along a tube, so what is left is float32 rounding inside Embree: a fiber point and its copy one period on round
differently (their z differ by P; half an ulp of 2P is 3e-8 for cotton1, 4e-5 r), as do the ray origins, and
Embree's hit arithmetic is float32. Only a sub-sample within a few ulps of a silhouette, or of the crossing of two
fibers, could see another fiber across the seam (none does on cotton1 at 256 × 64, S = 4); elsewhere normals and
tangents differ by rounding (and where a ray passes from a segment to the next at a joint) and AO only by the odd
grazing AO ray (the same random numbers, from points a few ulps apart). ``regular_seam_error`` measures this;
``tests/test_texture_bake.py::test_regular_textures_are_seamless`` holds cotton1 at 64 × 16, S = 2 to at most one
sub-sample changing fiber and four AO rays flipping, plus rounding, and the error at the standard quality's
256 × 64, S = 4 is measured in BENCHMARKS.md, section "Texture seam".

Flyaway seam design (three variants that tile in any order)
-----------------------------------------------------------
Flyaways are generated for one long yarn (``generate_fibers``, one seed). Each flyaway has the z-range [a, b] of
its swept spheres (min z − r, max z + r over its points). A **band** of half-width δ (``band`` mip-0 columns,
δ = band·P/W) surrounds every period boundary mP. A flyaway is a *boundary* flyaway if its z-range meets some band;
its *first* band is the leftmost one it meets. Variant k (k = 0, 1, 2) draws

* the flyaways lying inside (kP + δ, (k + 1)P − δ), moved by −kP (private to variant k), and
* every boundary flyaway whose first band is the one at z = 0, copied to every shift mP (m integer) where the copy
  meets [0, P] (shared, identical in all three variants).

Seam: inside the bands, i.e. in the first and last ``band`` columns of mip 0, every variant draws exactly the same
geometry (private flyaways stay out of the bands), and the shared flyaways are drawn periodically, so the seam
k → j looks exactly like the seam k → k, which is the continuous periodic drawing: texture k's right edge continues
into any texture j's left edge. ``flyaway_seam_error`` measures the band disagreement (0 by construction).
Statistics: the private sets and the shared set are disjoint classes of one Poisson process, hence independent,
and since the first band of a boundary flyaway is unique, every point of the strip sees the flyaway density of the
infinite yarn (boundary flyaways are correlated between the two ends of a tile, which is what the seam requires).
Flyaways as long as a period (cotton1 loops follow a host fiber for one migration cycle, 0.8 P) are mostly boundary
flyaways, so the three variants share most loops and differ mostly in hairs; ``flyaway_variants`` reports counts.

Which draw (the coverage profile)
---------------------------------
Three periods of flyaways, one shared set among them, are a small sample: the mean flyaway coverage across the strip
(per texture row, i.e. per distance from the axis) varies between draws of cotton1's flyaways by ±26 % (sd) beyond the
yarn body (0.44–1.72× the yarn's own over 64 draws), and the strip renderer draws the pack's three variants along every
yarn, so a draw's excess is a systematic error of every image (stop 51: the back-lit straight yarn's hairs 1.34× the
mean of eight references; the draw the stage used to take, the regular fibers' own stream, has 1.35× the yarn's coverage
beyond the body). So the stage draws ``FLYAWAY_DRAWS`` sets of flyaways (the same regular fibers, ``generate_fibers(...,
flyaway_seed=j)``) and keeps the one whose variants' mean coverage profile (``coverage_profile``, cast at
``PROFILE_COLUMNS`` columns per period) is nearest to the yarn's expected profile, that of ``PROFILE_PERIODS`` periods
of one long yarn drawn as the reference path tracer draws it (``expected_flyaway_profile``, edges of the window left
out): nearest in the rel L1 of the coverage summed over bands of distance from the axis (``PROFILE_BANDS``, each side;
``profile_error``). Measured on cotton1 (standard, scratch, stop 51): the kept draw (10 of 64) is within 0.066 of the
expected bands, its coverage beyond the body 1.04× the expected and over the whole strip 0.99×; seven bands instead of
four kept a draw 0.87× beyond the body, and rows compared one by one stay above 0.21 (single loops). The kept draw is
still one set of real flyaways (hairs stay hairs); what the choice fixes is their mean coverage, not the individual
fibers. The attributes record the draw (``flyaway_draw`` of ``flyaway_draws``), its profile's rel L1 against the
expected one (``coverage_profile_rel_l1``) and the expected profile's own sampling error
(``coverage_profile_target_rel_l1``: half the rel L1 between its two halves).
"""

from __future__ import annotations

import math

import numpy as np

from data_formats.yarn_spec import YarnSpec
from knitbake.fibers.fiber_set import KIND_REGULAR, FiberSet
from knitbake.fibers.procedural_yarn import generate_fibers
from knitbake.stages.stage_result import StageResult
from knitbake.trace.embree_curves import CurveScene, any_hits, closest_hits

AO_OFFSET = 2.0 ** -18  # AO rays start this fraction of the scene extent off the surface: 64 float32 ulps
FLYAWAY_BAND_TEXELS = 2  # default half-width of the shared band around each period boundary, in mip-0 columns
VARIANTS = 3
FLYAWAY_DRAWS = 64  # sets of flyaways drawn, the one nearest the expected coverage profile kept (module docstring)
# edges (yarn radii from the axis) of the bands, each side of the axis, a coverage profile is compared in: the body,
# its edge, the fuzz beside it and the far hairs (rows one by one would weigh single loops, not the level)
PROFILE_BANDS = (0.9, 1.3, 1.75)
PROFILE_PERIODS = 24  # periods of one long yarn whose flyaway coverage profile is the expected one
PROFILE_COLUMNS = 32  # columns per period the coverage profiles are cast at (2 × 2 sub-samples, the texture's rows)
_AO_RAYS_PER_BLOCK = 1 << 20  # occlusion rays per batch (memory bound)
_REGULAR = ("normal", "tangent", "ao", "coverage")
_QUANTISATION_KIND = ("deterministic orthographic ray casting, {s}x{s} regular sub-samples per mip-0 texel; "
                      "error_estimate = 1/(2 n), n the sub-samples per texel of this level: half the step of a "
                      "sub-sample count (not a bound on geometric aliasing)")
_AO_KIND = ("Monte Carlo ambient visibility, {k} cosine-weighted rays per covered sub-sample ({s}x{s} per mip-0 "
            "texel); error_estimate = max over covered texels of the binomial standard-error bound "
            "sqrt(p(1-p)/N), N the rays pooled in the texel, p = (visible + 1/2)/(N + 1)")


def to_strip(vec: np.ndarray) -> np.ndarray:
    """Strip components (·t, ·b, ·n) = (z, −y, x) of yarn-space vectors (..., 3)."""
    return np.stack([vec[..., 2], -vec[..., 1], vec[..., 0]], axis=-1)


def texel_rays(width: int, height: int, samples: int, period: float, half_width: float, x0: float,
               column_offset: int = 0) -> tuple[np.ndarray, np.ndarray]:
    """Orthographic sub-sample rays of an H × W texture of the strip with half-width ``half_width``: origins
    (H·S·W·S, 3) at x = ``x0`` in the order (row, sub-row, column, sub-column), all directions (−1, 0, 0).
    Column j of the texture covers u ∈ [j + column_offset, j + column_offset + 1]/W (z = u·period)."""
    v = -1.0 + (np.arange(height * samples) + 0.5) * (2.0 / (height * samples))
    u = (column_offset * samples + np.arange(width * samples) + 0.5) / (width * samples)
    org = np.empty((v.size, u.size, 3))
    org[..., 0] = x0
    org[..., 1] = -v[:, None] * half_width
    org[..., 2] = u[None, :] * period
    org = org.reshape(-1, 3)
    dirs = np.zeros_like(org)
    dirs[:, 0] = -1.0
    return org, dirs


def regular_fibers(spec: YarnSpec, seed: int = 0) -> FiberSet:
    """The regular fibers of z ∈ [−P, 2P] (P = ply pitch): the texture period [0, P] and one period either side."""
    period = spec.geometry.ply_pitch
    return generate_fibers(spec, length=3 * period, z_start=-period, seed=seed, flyaways=False)


def regular_scene(spec: YarnSpec, seed: int = 0) -> CurveScene:
    """Embree curves of ``regular_fibers``: the camera-ray target and the AO / depth-test occluders."""
    return CurveScene(regular_fibers(spec, seed))


def _texel_sum(grid: np.ndarray, height: int, width: int, samples: int) -> np.ndarray:
    """Sum over each texel's S × S sub-samples of per-sub-sample values (H·S·W·S, ...) → (H, W, ...)."""
    return grid.reshape(height, samples, width, samples, *grid.shape[1:]).sum(axis=(1, 3))


def _segment_directions(scene: CurveScene, segment: np.ndarray) -> np.ndarray:
    """Unit direction (yarn space) of each curve segment in ``segment``, from its two vertices, signed with z ≥ 0."""
    v = scene.segment_start[segment].astype(np.int64)
    d = scene.vertices[v + 1, :3].astype(np.float64) - scene.vertices[v, :3]
    d /= np.linalg.norm(d, axis=1, keepdims=True)
    return np.where(d[:, 2:3] < 0, -d, d)


def surface_offset(scene: CurveScene) -> float:
    """How far AO rays start off the surface: ``AO_OFFSET`` × the scene extent (largest |coordinate| + radius of its
    vertices), 64 float32 ulps of the largest coordinate (module docstring, ``ao``)."""
    v = scene.vertices.astype(np.float64)
    return AO_OFFSET * float(np.abs(v[:, :3]).max() + v[:, 3].max())


def _cosine_directions(normals: np.ndarray, xi: np.ndarray) -> np.ndarray:
    """Cosine-distributed unit directions about unit ``normals`` (N, 3) from uniform numbers ``xi`` (N, K, 2) →
    (N, K, 3); orthonormal basis of Duff et al. 2017."""
    nx, ny, nz = normals[:, 0:1], normals[:, 1:2], normals[:, 2:3]
    sign = np.where(nz >= 0, 1.0, -1.0)
    a = -1.0 / (sign + nz)
    b = nx * ny * a
    e1 = np.stack([1.0 + sign * nx * nx * a, sign * b, -sign * nx], axis=-1)  # (N, 1, 3)
    e2 = np.stack([b, sign + ny * ny * a, -ny], axis=-1)
    r = np.sqrt(xi[..., 0:1])
    phi = 2.0 * np.pi * xi[..., 1:2]
    return r * np.cos(phi) * e1 + r * np.sin(phi) * e2 + np.sqrt(1.0 - xi[..., 0:1]) * normals[:, None, :]


def _ao_visible_counts(scene: CurveScene, origins, normals, hit_grid, width, samples, ao_rays, seed, column_offset,
                       progress) -> np.ndarray:
    """Visible AO rays per sub-sample (H·S, W·S) int: ``ao_rays`` cosine rays about ``normals`` from ``origins``
    (one per hit sub-sample, in grid order), in blocks of columns; the uniform numbers of texture column j come
    from the stream (seed, (j + column_offset) mod W)."""
    n_rows = hit_grid.shape[0]
    visible = np.zeros(hit_grid.shape, np.int64)
    index = np.full(hit_grid.shape, -1, np.int64)
    index[hit_grid] = np.arange(origins.shape[0])
    block = max(1, _AO_RAYS_PER_BLOCK // (n_rows * samples * ao_rays))
    for j0 in range(0, width, block):
        j1 = min(width, j0 + block)
        cols = slice(j0 * samples, j1 * samples)
        xi = np.concatenate([np.random.default_rng([seed, (j + column_offset) % width])
                             .random((n_rows, samples, ao_rays, 2)) for j in range(j0, j1)], axis=1)
        sel = index[:, cols][hit_grid[:, cols]]
        if sel.size:
            dirs = _cosine_directions(normals[sel], xi[hit_grid[:, cols]])
            org = np.broadcast_to(origins[sel][:, None, :], dirs.shape)
            blocked = any_hits(scene, org.reshape(-1, 3), dirs.reshape(-1, 3), np.inf)
            block_view = visible[:, cols]  # a view: writes go to ``visible``
            block_view[hit_grid[:, cols]] = ao_rays - blocked.reshape(-1, ao_rays).sum(axis=1)
        if progress is not None:
            progress(j1, width)
    return visible


def _halve(a: np.ndarray, axis: int, reduce) -> np.ndarray:
    """Pairwise reduction (``reduce`` = np.mean or np.sum) along ``axis``; unchanged where that dimension is 1."""
    n = a.shape[axis]
    if n == 1:
        return a
    return reduce(a.reshape(*a.shape[:axis], n // 2, 2, *a.shape[axis + 1:]), axis=axis + 1)


def mip_levels(level0: np.ndarray, row_axis: int = 0, reduce=np.mean) -> list[np.ndarray]:
    """Level 0 and its 2 × 2 box reductions (over axes ``row_axis``, ``row_axis`` + 1) down to 1 × 1."""
    levels = [level0]
    while levels[-1].shape[row_axis] > 1 or levels[-1].shape[row_axis + 1] > 1:
        levels.append(_halve(_halve(levels[-1], row_axis, reduce), row_axis + 1, reduce))
    return levels


def _check_size(width: int, height: int, samples: int, ao_rays: int = 1) -> None:
    for name, n in (("width", width), ("height", height)):
        if isinstance(n, bool) or not isinstance(n, (int, np.integer)) or n < 1 or n > 1 << 15 or n & (n - 1):
            raise ValueError(f"texture {name} must be a power of two from 1 to 32768, got {n!r}")
    for name, n in (("samples", samples), ("ao_rays", ao_rays)):
        if isinstance(n, bool) or not isinstance(n, (int, np.integer)) or n < 1:
            raise ValueError(f"{name} must be an integer ≥ 1, got {n!r}")


def _regular_level0(spec, scene, width, height, samples, ao_rays, seed, column_offset=0, progress=None):
    """Mip-0 sums of the regular textures: dict of per-texel covered sub-sample counts ``covered`` (H, W), summed
    strip normals / tangents (H, W, 3) and visible AO rays ``visible`` (H, W)."""
    h = spec.radius
    org, dirs = texel_rays(width, height, samples, spec.geometry.ply_pitch, h, 4.0 * h, column_offset)
    t, segment, normal_all, _ = closest_hits(scene, org, dirs)
    hit = segment >= 0
    normal_yarn = normal_all[hit]
    ao_origins = org[hit] + t[hit, None] * dirs[hit] + surface_offset(scene) * normal_yarn
    normal = np.zeros(org.shape)
    tangent = np.zeros(org.shape)
    normal[hit] = to_strip(normal_yarn)
    tangent[hit] = to_strip(_segment_directions(scene, segment[hit]))
    hit_grid = hit.reshape(height * samples, width * samples)
    visible = _ao_visible_counts(scene, ao_origins, normal_yarn, hit_grid, width, samples, ao_rays, seed,
                                 column_offset, progress)
    return {"covered": _texel_sum(hit.astype(np.int64), height, width, samples),
            "normal": _texel_sum(normal, height, width, samples),
            "tangent": _texel_sum(tangent, height, width, samples),
            "visible": _texel_sum(visible.reshape(-1), height, width, samples)}


def _regular_maps(sums: dict, samples: int, ao_rays: int) -> dict:
    """Mip-0 textures (float64) from the sums of ``_regular_level0``."""
    n = samples * samples
    covered = sums["covered"]
    ao = np.where(covered > 0, sums["visible"] / np.maximum(covered * ao_rays, 1), 1.0)
    return {"normal": sums["normal"] / n, "tangent": sums["tangent"] / n, "ao": ao, "coverage": covered / n}


def bake_regular_textures(spec: YarnSpec, width: int = 256, height: int = 64, samples: int = 4, ao_rays: int = 16,
                          seed: int = 0, progress=None, scene=None) -> dict:
    """Regular-fiber textures ``textures/{normal,tangent,ao,coverage}/mip{k}`` → (float32 array, error estimate,
    attrs) (see module docstring). ``progress(done, total)`` is called per block of AO columns; ``scene``: a
    prebuilt ``regular_scene(spec, seed)``."""
    _check_size(width, height, samples, ao_rays)
    sums = _regular_level0(spec, scene or regular_scene(spec, seed), width, height, samples, ao_rays, seed,
                           progress=progress)
    maps = _regular_maps(sums, samples, ao_rays)
    covered = mip_levels(sums["covered"], reduce=np.sum)
    visible = mip_levels(sums["visible"], reduce=np.sum)
    out = {}
    for name in ("normal", "tangent", "coverage"):
        for k, level in enumerate(mip_levels(maps[name])):
            n_sub = samples * samples * (height // level.shape[0]) * (width // level.shape[1])
            out[f"textures/{name}/mip{k}"] = (level.astype(np.float32), 1.0 / (2 * n_sub), {
                "error_kind": _QUANTISATION_KIND.format(s=samples), "error_statistic": "max",
                "half_width": spec.radius, "samples_per_axis": samples})
    for k, (cov, vis) in enumerate(zip(covered, visible)):
        rays = cov * ao_rays
        ao = np.where(rays > 0, vis / np.maximum(rays, 1), 1.0)
        p = (vis + 0.5) / (rays + 1.0)
        stderr = np.sqrt(p * (1 - p) / np.maximum(rays, 1))
        err = float(stderr[rays > 0].max()) if np.any(rays > 0) else 0.0
        out[f"textures/ao/mip{k}"] = (ao.astype(np.float32), err, {
            "error_kind": _AO_KIND.format(k=ao_rays, s=samples), "error_statistic": "max",
            "half_width": spec.radius, "samples_per_axis": samples, "ao_rays": ao_rays})
    return {name: out[name] for base in _REGULAR for name in out if name.startswith(f"textures/{base}/")}


def regular_seam_error(spec: YarnSpec, textures: dict, seed: int = 0, scene=None) -> dict:
    """Seam check of the regular textures: re-bake mip 0 over the window shifted by half a period (W/2 columns),
    whose middle holds the seam u = 1 → 0 of ``textures`` on continuous fibers, and compare it with the baked mip 0
    rolled by W/2. Returns {texture: {"mean": mean |difference|, "max": max |difference|}} for normal, tangent, ao,
    coverage. The curves are the fibers themselves, so only float32 rounding inside Embree limits it (module
    docstring, "Regular seam"): a fiber point and its copy one period on round differently, as do the ray origins,
    so a sub-sample within a few ulps of a silhouette or of a crossing of two fibers may see another fiber (its AO
    then differs by its Monte Carlo error), a ray may pass to the neighbouring segment at a joint (tangent), and an
    AO ray grazing a fiber may flip; elsewhere normals and tangents differ by rounding."""
    ao0 = textures["textures/ao/mip0"]
    height, width = ao0[0].shape
    samples, ao_rays = ao0[2]["samples_per_axis"], ao0[2]["ao_rays"]
    sums = _regular_level0(spec, scene or regular_scene(spec, seed), width, height, samples, ao_rays, seed,
                           width // 2)
    shifted = _regular_maps(sums, samples, ao_rays)
    out = {}
    for name in _REGULAR:
        diff = np.abs(np.roll(textures[f"textures/{name}/mip0"][0], -(width // 2), axis=1) - shifted[name])
        out[name] = {"mean": float(diff.mean()), "max": float(diff.max())}
    return out


def _z_extent(fibers: FiberSet) -> tuple[np.ndarray, np.ndarray]:
    """(lo, hi) z of each fiber's swept spheres: min z − r and max z + r over its points, the exact z-extent of the
    curves Embree draws."""
    if fibers.n_fibers == 0:
        return np.zeros(0), np.zeros(0)
    z = fibers.points[:, 2]
    return (np.minimum.reduceat(z, fibers.offsets[:-1]) - fibers.radius,
            np.maximum.reduceat(z, fibers.offsets[:-1]) + fibers.radius)


def _shifted(fibers: FiberSet, idx: np.ndarray, shift: np.ndarray, period: float) -> FiberSet:
    """Fibers ``idx`` of ``fibers`` (repeats allowed), each moved by ``shift`` along z, as a FiberSet of [0, P]."""
    counts = np.diff(fibers.offsets)[idx]
    offsets = np.zeros(idx.size + 1, np.int64)
    np.cumsum(counts, out=offsets[1:])
    point = np.repeat(fibers.offsets[idx] - offsets[:-1], counts) + np.arange(offsets[-1])
    pts = fibers.points[point].copy()
    pts[:, 2] += np.repeat(shift, counts)
    return FiberSet(pts, offsets, fibers.radius[idx].copy(), fibers.kind[idx].copy(), fibers.ply[idx].copy(), 0.0,
                    period)


def flyaway_periods(spec: YarnSpec) -> int:
    """n: ``flyaway_variants`` draws the flyaways of n + 1 periods of yarn, n covering the variants and the longest
    loop (one migration cycle)."""
    g = spec.geometry
    cycle = g.fiber_pitch / g.migration_frequency if g.migration_frequency > 0 else g.fiber_pitch  # loop length
    return max(VARIANTS, math.ceil(cycle / g.ply_pitch) + 2)


def flyaway_variants(spec: YarnSpec, seed: int = 0, band: float = 0.0,
                     flyaway_seed: int | None = None) -> tuple[list[FiberSet], dict]:
    """The flyaway fibers of the three variants in period coordinates (z ∈ [0, P] is the texture; fibers reaching
    past it are kept whole) and counts: ``shared`` boundary flyaways, ``copies`` of them drawn per variant,
    ``private`` flyaways per variant. ``band``: half-width δ of the band around each period boundary (length);
    ``flyaway_seed``: which draw of the flyaways (``generate_fibers``). See the module docstring for the
    construction."""
    g = spec.geometry
    period = g.ply_pitch
    if not 0 <= band < period / 2:
        raise ValueError(f"band = {band!r} must be in [0, period/2) = [0, {period / 2:g})")
    n = flyaway_periods(spec)
    long = generate_fibers(spec, length=(n + 1) * period, z_start=-period, seed=seed, flyaway_seed=flyaway_seed)
    fly = long.select(long.kind != KIND_REGULAR)
    lo, hi = _z_extent(fly)
    if fly.n_fibers and np.max(hi - lo) > (n - 1) * period:
        raise ValueError(f"a flyaway spans {np.max(hi - lo):g} along the yarn, longer than the generation window "
                         f"allows ({(n - 1) * period:g})")
    first_band = np.floor((lo - band) / period) + 1  # index m of the leftmost band [mP − δ, mP + δ] right of lo
    shared = np.flatnonzero((first_band == 0) & (hi > -band))
    s_min = np.floor(-hi[shared] / period).astype(np.int64) + 1  # copies m·P meeting [0, P]
    s_max = np.ceil((period - lo[shared]) / period).astype(np.int64) - 1
    n_copies = np.maximum(s_max - s_min + 1, 0)
    copy_idx = np.repeat(shared, n_copies)
    copy_shift = (np.repeat(s_min, n_copies) + np.arange(n_copies.sum())
                  - np.repeat(np.cumsum(n_copies) - n_copies, n_copies)) * period
    variants, private = [], []
    for k in range(VARIANTS):
        own = np.flatnonzero((lo >= k * period + band) & (hi <= (k + 1) * period - band))
        private.append(int(own.size))
        idx = np.concatenate([own, copy_idx])
        variants.append(_shifted(fly, idx, np.concatenate([np.full(own.size, -k * period), copy_shift]), period))
    return variants, {"shared": int(shared.size), "copies": int(copy_idx.size), "private": private}


def flyaway_texture(occluders: CurveScene, fibers: FiberSet | None, period: float, half_width: float, width: int,
                    height: int, samples: int, column_offset: int = 0) -> np.ndarray:
    """Mip 0 (H, W, 4) of one flyaway texture of the flyaway fibers ``fibers`` (None or empty: no flyaways) with the
    depth test against the regular fibers ``occluders``: RGB the coverage-premultiplied strip tangent of the nearest
    flyaway, A the fraction of sub-samples where it is nearer than every regular fiber."""
    org, dirs = texel_rays(width, height, samples, period, half_width, 4.0 * half_width, column_offset)
    rgba = np.zeros((org.shape[0], 4))
    if fibers is not None and fibers.n_fibers:
        scene = CurveScene(fibers)
        t, segment, _, _ = closest_hits(scene, org, dirs)
        seen = (segment >= 0) & (t < closest_hits(occluders, org, dirs)[0])
        rgba[seen, :3] = to_strip(_segment_directions(scene, segment[seen]))
        rgba[seen, 3] = 1.0
        scene.close()
    return _texel_sum(rgba, height, width, samples) / (samples * samples)


def _reach(fibers: FiberSet) -> float:
    """The farthest point of ``fibers``' swept spheres from the yarn axis (0 for no fiber)."""
    if not fibers.n_fibers:
        return 0.0
    return float(np.max(np.hypot(fibers.points[:, 0], fibers.points[:, 1]) + np.repeat(fibers.radius,
                                                                                        np.diff(fibers.offsets))))


def coverage_profile(occluders: CurveScene, fibers: FiberSet | None, z0: float, length: float, half_width: float,
                     height: int, columns: int) -> np.ndarray:
    """(height,): the mean flyaway coverage of each texture row (the strip of half-width ``half_width``, row i at
    v ∈ −1 + [i, i + 1]·2/height) over z ∈ [z0, z0 + length], cast as the flyaway texture is (``flyaway_texture``:
    the depth test against ``occluders``) at ``columns`` columns and 2 × 2 sub-samples per texel."""
    org, dirs = texel_rays(columns, height, 2, length, half_width, 4.0 * half_width)
    org[:, 2] += z0
    seen = np.zeros(org.shape[0])
    if fibers is not None and fibers.n_fibers:
        scene = CurveScene(fibers)
        t, segment, _, _ = closest_hits(scene, org, dirs)
        seen = ((segment >= 0) & (t < closest_hits(occluders, org, dirs)[0])).astype(np.float64)
        scene.close()
    return _texel_sum(seen[:, None], height, columns, 2)[..., 0].mean(axis=1) / 4.0


def profile_error(profile, target, half_width: float, radius: float) -> float:
    """Rel L1 of the coverage profile ``profile`` against ``target`` (both (H,) over a strip of ``half_width``),
    summed over the bands ``PROFILE_BANDS`` (yarn ``radius``) each side of the axis first (module docstring)."""
    rows = len(target)
    v = (-1.0 + (np.arange(rows) + 0.5) * 2.0 / rows) * half_width / radius
    edges = np.array((0.0,) + PROFILE_BANDS + (np.inf,))
    band = np.digitize(np.abs(v), edges) - 1 + (v > 0) * (len(edges) - 1)
    a, b = (np.bincount(band, np.asarray(x, np.float64), minlength=2 * (len(edges) - 1)) for x in (profile, target))
    return float(np.abs(a - b).sum() / b.sum()) if b.sum() > 0 else 0.0


def expected_flyaway_profile(spec: YarnSpec, seed: int, height: int,
                             periods: int = PROFILE_PERIODS) -> tuple[np.ndarray, float, float]:
    """(profile (height,), its sampling error, the half-width it is cast at): the flyaway coverage profile of one
    long yarn (``coverage_profile`` over ``periods`` periods; the flyaways drawn over one more period either side,
    so the window's edges see the density of the infinite yarn), drawn as the reference path tracer draws its fibers
    (``generate_fibers`` with its default stream). The half-width is the farthest flyaway's reach (at least the yarn
    radius); the error, half the ``profile_error`` between the profiles of the two halves of the window."""
    period = spec.geometry.ply_pitch
    long = generate_fibers(spec, length=(periods + 2) * period, z_start=-period, seed=seed)
    fly = long.select(long.kind != KIND_REGULAR)
    half_width = max(spec.radius, _reach(fly))
    scene = CurveScene(long.select(long.kind == KIND_REGULAR))
    half = periods // 2
    parts = [coverage_profile(scene, fly, z0, half * period, half_width, height, half * PROFILE_COLUMNS)
             for z0 in (0.0, half * period)]
    scene.close()
    profile = 0.5 * (parts[0] + parts[1])
    return profile, 0.5 * profile_error(parts[0], parts[1], half_width, spec.radius), half_width


def nearest_flyaway_draw(spec: YarnSpec, seed: int, band: float, height: int, occluders: CurveScene,
                         draws: int = FLYAWAY_DRAWS) -> tuple[int, float, float]:
    """(draw j, ``profile_error`` of its variants' mean coverage profile against the expected one, the expected
    profile's own error): among ``draws`` draws of the flyaways (``flyaway_variants(..., flyaway_seed=j)``), the one
    nearest the yarn's expected profile (``expected_flyaway_profile``; module docstring, "Which draw")."""
    period = spec.geometry.ply_pitch
    target, target_error, half_width = expected_flyaway_profile(spec, seed, height)
    best = (0, math.inf)
    for j in range(draws):
        variants, _ = flyaway_variants(spec, seed, band, flyaway_seed=j)
        mean = np.mean([coverage_profile(occluders, f, 0.0, period, half_width, height, PROFILE_COLUMNS)
                        for f in variants], axis=0)
        error = profile_error(mean, target, half_width, spec.radius)
        if error < best[1]:
            best = (j, error)
    return best[0], best[1], target_error


def bake_flyaway_textures(spec: YarnSpec, width: int = 256, height: int = 64, samples: int = 4, seed: int = 0,
                          band: int = FLYAWAY_BAND_TEXELS, progress=None, scene=None) -> tuple[dict, dict]:
    """The three seamless flyaway textures ``textures/flyaway/mip{k}`` → (float32 (3, H, W, 4), error estimate,
    attrs), of the draw of flyaways nearest the yarn's coverage profile (``nearest_flyaway_draw``; the attributes
    record it), and the counts of ``flyaway_variants``; empty for a yarn without flyaways. ``band``: half-width of the
    shared band around the seam in mip-0 columns (at most W/4). ``progress(done, total)`` is called per variant;
    ``scene``: a prebuilt ``regular_scene(spec, seed)``."""
    _check_size(width, height, samples)
    if not spec.has_flyaways:
        return {}, {}
    period = spec.geometry.ply_pitch
    band = min(band, width // 4)
    regular = scene or regular_scene(spec, seed)
    draw, draw_error, target_error = nearest_flyaway_draw(spec, seed, band * period / width, height, regular)
    variants, counts = flyaway_variants(spec, seed, band * period / width, flyaway_seed=draw)
    half_width = max([spec.radius] + [_reach(f) for f in variants])
    level0 = []
    for k, fibers in enumerate(variants):
        level0.append(flyaway_texture(regular, fibers, period, half_width, width, height, samples))
        if progress is not None:
            progress(k + 1, VARIANTS)
    out = {}
    for k, level in enumerate(mip_levels(np.stack(level0), row_axis=1)):
        n_sub = samples * samples * (height // level.shape[1]) * (width // level.shape[2])
        out[f"textures/flyaway/mip{k}"] = (level.astype(np.float32), 1.0 / (2 * n_sub), {
            "error_kind": _QUANTISATION_KIND.format(s=samples), "error_statistic": "max", "half_width": half_width,
            "samples_per_axis": samples, "seam_band_texels": band, "flyaway_draw": draw,
            "flyaway_draws": FLYAWAY_DRAWS, "coverage_profile_rel_l1": draw_error,
            "coverage_profile_target_rel_l1": target_error})
    return out, counts


def flyaway_seam_error(textures: dict) -> np.ndarray:
    """(3, 3) seam errors of the flyaway textures: entry (k, j) is the max |difference| between the seam k → j
    and the self seams k → k and j → j over the shared band (``seam_band_texels`` mip-0 columns each side):
    max(|T_j − T_k| over the first band columns, |T_k − T_j| over the last). 0 by construction."""
    arr, _, attrs = textures["textures/flyaway/mip0"]
    c = int(attrs["seam_band_texels"])
    if c == 0:
        return np.zeros((VARIANTS, VARIANTS))
    bands = np.concatenate([arr[:, :, :c], arr[:, :, arr.shape[2] - c:]], axis=2).reshape(VARIANTS, -1)
    return np.abs(bands[:, None] - bands[None, :]).max(axis=2)


def bake_textures(spec: YarnSpec, width: int = 256, height: int = 64, samples: int = 4, ao_rays: int = 16,
                  seed: int = 0, progress=None) -> dict:
    """Every texture of ``spec``: name (``textures/<texture>/mip{k}``, asset_pack.TABLES) → (float32 array,
    error estimate, attrs for ``write_pack``'s table_attrs). Flyaway textures only when the yarn has flyaways.
    ``progress(done, total)`` over the regular AO blocks, then the flyaway variants."""
    scene = regular_scene(spec, seed)
    out = bake_regular_textures(spec, width, height, samples, ao_rays, seed, progress, scene)
    out.update(bake_flyaway_textures(spec, width, height, samples, seed, progress=progress, scene=scene)[0])
    return out


def _stage(out: dict, counts: dict) -> StageResult:
    return StageResult({k: v[0] for k, v in out.items()}, {k: v[1] for k, v in out.items()},
                       {k: v[2] for k, v in out.items()}, counts)


def bake_regular_stage(spec: YarnSpec, settings: dict, seed: int, progress=None):
    """Stage ``textures`` of ``knitbake.bake``: settings width, height, samples, ao_rays."""
    s = settings
    out = bake_regular_textures(spec, s["width"], s["height"], s["samples"], s["ao_rays"], seed, progress)
    return _stage(out, {"texels": s["width"] * s["height"], "samples_per_texel": s["samples"] ** 2,
                        "ao_rays_per_hit": s["ao_rays"]})


def bake_flyaway_stage(spec: YarnSpec, settings: dict, seed: int, progress=None):
    """Stage ``flyaway`` of ``knitbake.bake``: settings width, height, samples."""
    s = settings
    out, counts = bake_flyaway_textures(spec, s["width"], s["height"], s["samples"], seed, progress=progress)
    return _stage(out, {"texels": s["width"] * s["height"], "samples_per_texel": s["samples"] ** 2,
                        "shared_flyaways": counts["shared"], "shared_copies": counts["copies"],
                        "private_flyaways": counts["private"], "flyaway_draws": FLYAWAY_DRAWS})
