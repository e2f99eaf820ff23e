"""Explicit fibers of whole yarns: the straight procedural yarn swept along yarn curves (for the reference renderer).

Conventions
-----------
* Yarn space (``procedural_yarn``): axis +z, fiber offsets (x, y) from the axis, all in the spec's units.
* **Scaling.** A curve drawn with yarn radius r uses the yarn scaled *uniformly* by k = r / spec.radius — x, y and z
  — so the fibers, their radius, the ply and fiber pitches and the flyaways all scale together (a thicker yarn of
  the same kind is twisted proportionally longer). The fibers come from ``generate_fibers(spec, length = L / k)``,
  L the curve's rest length; k is a pure ratio, so the curve's length unit is the output unit.
* **Attachment.** Yarn-space z·k is the rest arc length σ along the curve (``curve_eval.dense_curve``), never the
  current arc length: a curve stretched between frames carries every fiber point to the same rest coordinate, and
  the twist of the fibers is a function of σ only — fibers do not swim.
* **Frame** (the yarn frame of ``data_formats.curve_eval``, shared with the strip renderer, which aligns its
  textures' phase to it). (x, y) are laid along (N, B) of a rotation-minimising frame, B = T × N, transported along the
  dense curve by the double reflection method (Wang et al. 2008, "Computation of rotation minimizing frames", ACM TOG
  27(1)) with central-difference tangents. Between samples the tangent and normal are interpolated linearly and
  re-orthonormalised. A straight curve along +z starting at the origin therefore reproduces the generator's
  fibers exactly.
* **Start normal.** At frame 0 the curve's start normal is ``initial_normal(T_0)`` (x̂, or ŷ when T_0 is within
  ~25° of ±x̂, made orthogonal to T_0). At a later frame it is the frame-0 normal carried by the smallest rotation
  that takes the frame-0 start tangent to the current one (a half turn about the frame-0 normal when they are
  opposite), so a curve that turns as a whole turns its fibers with it instead of rolling them about its axis.
* **Closed curves.** The transported frame comes back rotated by the holonomy Δ ∈ (−π, π] about the start tangent;
  the frame at σ is turned by −Δ·σ/L, so it closes exactly. The fibers are generated over an integer number
  n = max(1, round(L / (k·α_yarn))) of ply-twist periods and stretched axially by L / (n·k·α_yarn)
  (``axial_stretch``, within 1 ± 1/(2n) once L ≥ k·α_yarn / 2; a shorter loop is compressed), so the periodic
  regular fibers close up: the last point of regular fiber f is, to float precision, the first point of regular
  fiber ``seam_successor[f]`` (the generator's successor map applied n times). Fibers stay open polylines that meet
  at the seam (σ = 0): a tube tessellation caps both ends there. Flyaways crossing the seam wrap around.
* **Open curves.** A yarn is cut at its ends: every fiber stops at the end cross-sections σ = 0 and σ = L, as the
  strip renderer's yarn does. Regular fibers end there already; a flyaway that crosses an end plane is cut there
  (``clip_axially``: the parts of its polyline with 0 ≤ z ≤ L/k, the cut points interpolated on the plane; a hair that
  leaves and comes back becomes two fibers).
* **Seeds.** Curve c uses ``curve_seed(seed, c)``; the output is deterministic for a seed.
* Output: one ``FiberSet`` in curve coordinates, curve by curve; ``z_start = z_end = 0`` (there is no yarn axis);
  ``info["curves"][c]`` gives the fiber range ``fibers = (first, stop)``, ``seed``, ``scale`` k, ``rest_length``,
  ``axial_stretch``, and for closed curves ``periods``, ``holonomy`` (rad) and ``seam_successor``.
"""

from __future__ import annotations

import math

import numpy as np

from data_formats.curve_eval import curve_frames, dense_curve, start_normal, tangents
from data_formats.errors import FormatError
from data_formats.yarn_curves import YarnCurves
from data_formats.yarn_spec import YarnSpec
from knitbake.fibers.fiber_set import KIND_REGULAR, FiberSet
from knitbake.fibers.procedural_yarn import generate_fibers


def curve_seed(seed: int, c: int) -> int:
    """Seed of curve c's fibers: a 63-bit hash of (seed, c) by numpy's SeedSequence."""
    return int(np.random.SeedSequence((int(seed), int(c))).generate_state(1, np.uint64)[0] >> np.uint64(1))


def place(yarn_pts: np.ndarray, xyz: np.ndarray, sigma: np.ndarray, t: np.ndarray, n: np.ndarray,
          closed: bool) -> np.ndarray:
    """World points of yarn-space points (x, y, σ) on the dense curve (xyz, sigma) with frames (t, n)."""
    s = np.mod(yarn_pts[:, 2], sigma[-1]) if closed else yarn_pts[:, 2]
    i = np.clip(np.searchsorted(sigma, s, side="right") - 1, 0, len(sigma) - 2)
    ds = sigma[i + 1] - sigma[i]
    f = np.where(ds > 0, (s - sigma[i]) / np.where(ds > 0, ds, 1.0), 0.0)[:, None]
    centre = xyz[i] + f * (xyz[i + 1] - xyz[i])  # f leaves [0, 1] only by rounding at an open end (fibers cut there)
    fc = np.clip(f, 0.0, 1.0)
    tt = t[i] + fc * (t[i + 1] - t[i])
    tn = np.linalg.norm(tt, axis=1, keepdims=True)
    tt = np.where(tn > 1e-12, tt / np.maximum(tn, 1e-300), t[i])
    nn = n[i] + fc * (n[i + 1] - n[i])
    nn -= np.sum(nn * tt, axis=1, keepdims=True) * tt
    nn /= np.linalg.norm(nn, axis=1, keepdims=True)
    return centre + yarn_pts[:, :1] * nn + yarn_pts[:, 1:2] * np.cross(tt, nn)


def _plane_point(p, q, z):
    """The point of segment p → q at height z (p and q on either side of it)."""
    return p + (z - p[2]) / (q[2] - p[2]) * (q - p)


def _inside_runs(p, z_lo, z_hi):
    """The runs of polyline p (n, 3) inside the slab z_lo ≤ z ≤ z_hi, each an (m ≥ 2, 3) array with its ends cut on
    the slab's planes."""
    z = p[:, 2]
    inside = (z >= z_lo) & (z <= z_hi)
    runs, cur = [], []
    for j in range(len(p)):
        if inside[j]:
            if not cur and j > 0:  # entering: the cut on the plane the previous point lies beyond
                cut = _plane_point(p[j - 1], p[j], z_lo if z[j - 1] < z_lo else z_hi)
                if not np.array_equal(cut, p[j]):
                    cur.append(cut)
            cur.append(p[j])
            continue
        if cur:  # leaving
            cut = _plane_point(p[j - 1], p[j], z_lo if z[j] < z_lo else z_hi)
            if not np.array_equal(cut, cur[-1]):
                cur.append(cut)
            runs.append(cur)
            cur = []
        elif j > 0 and (z[j - 1] < z_lo) != (z[j] < z_lo):  # both outside, on either side: across the slab
            a, b = sorted((z_lo, z_hi), key=lambda zz: abs(zz - z[j - 1]))
            runs.append([_plane_point(p[j - 1], p[j], a), _plane_point(p[j - 1], p[j], b)])
    if cur:
        runs.append(cur)
    return [np.array(r) for r in runs if len(r) >= 2]


def clip_axially(fs: FiberSet, z_lo: float, z_hi: float) -> FiberSet:
    """``fs`` with every flyaway cut to the slab z_lo ≤ z ≤ z_hi of yarn space (regular fibers unchanged): the cut
    ends of a yarn (module docstring, "Open curves"). Fiber order is kept; a flyaway that leaves the slab and comes
    back becomes one fiber per run inside, one outside it disappears."""
    pts, counts, radius, kind, ply = [], [], [], [], []
    for i in range(fs.n_fibers):
        p = fs.fiber(i)
        if fs.kind[i] == KIND_REGULAR or np.all((p[:, 2] >= z_lo) & (p[:, 2] <= z_hi)):
            runs = [p]
        else:
            runs = _inside_runs(p, z_lo, z_hi)
        for r in runs:
            pts.append(r)
            counts.append(len(r))
            radius.append(fs.radius[i])
            kind.append(fs.kind[i])
            ply.append(fs.ply[i])
    offsets = np.zeros(len(counts) + 1, dtype=np.int64)
    np.cumsum(counts, out=offsets[1:])
    return FiberSet(np.concatenate(pts) if pts else np.zeros((0, 3)), offsets, np.array(radius, np.float64),
                    np.array(kind, fs.kind.dtype), np.array(ply, fs.ply.dtype), fs.z_start, fs.z_end, dict(fs.info))


def sweep_curve(curves: YarnCurves, c: int, frame: int, spec: YarnSpec, radius: float, seed: int = 0,
                segments_per_period: int | None = None, flyaways: bool = True,
                samples_per_segment: int | None = None) -> FiberSet:
    """Fibers of curve c at ``frame`` with yarn ``spec`` drawn at ``radius`` (curve units); their ``info`` holds the
    curve's facts (``info["curves"][c]`` of ``sweep_fibers`` without the fiber range)."""
    if not (math.isfinite(radius) and radius > 0):
        raise FormatError(f"curve {c}: radius = {radius!r}, expected a positive finite number")
    xyz, sigma = dense_curve(curves, c, frame, samples_per_segment)
    length = float(sigma[-1])
    if not length > 0:
        raise FormatError(f"curve {c}: rest length {length!r}, expected > 0")
    closed = bool(curves.closed[c])
    k = radius / spec.radius
    cseed = curve_seed(seed, c)
    facts = {"seed": cseed, "scale": k, "rest_length": length}
    if closed:
        period = k * spec.geometry.ply_pitch
        periods = max(1, round(length / period))
        gen_length = periods * spec.geometry.ply_pitch
        stretch = length / (periods * period)
        facts.update(periods=periods, axial_stretch=stretch)
    else:
        gen_length, stretch = length / k, 1.0
        facts.update(axial_stretch=1.0)
    try:
        fs = generate_fibers(spec, length=gen_length, z_start=0.0, seed=cseed, segments_per_period=segments_per_period,
                             flyaways=flyaways)
    except FormatError as e:  # the budget: say that the drawn radius is what makes the yarn so long
        raise FormatError(f"curve {c} ({length:.4g} long) drawn at radius {radius:g}, {k:.3g} × the yarn's "
                          f"{spec.radius:g}: {e}") from None
    if not closed:
        fs = clip_axially(fs, 0.0, gen_length)
    yarn_pts = fs.points * np.array([k, k, k * stretch])
    n0 = start_normal(curves, c, frame, tangents(xyz, closed)[0], samples_per_segment)
    t, n, holonomy = curve_frames(xyz, sigma, closed, n0)
    if closed:
        succ = fs.info["successor"]
        perm = np.arange(succ.size)
        for _ in range(facts["periods"]):
            perm = succ[perm]
        facts.update(holonomy=holonomy, seam_successor=perm)
    pts = place(yarn_pts, xyz, sigma, t, n, closed)
    return FiberSet(pts, fs.offsets, fs.radius * k, fs.kind, fs.ply, 0.0, 0.0, facts)


def sweep_fibers(curves: YarnCurves, frame: int, specs: dict[int, YarnSpec], radii: dict[int, float], seed: int = 0,
                 segments_per_period: int | None = None, flyaways: bool = True,
                 samples_per_segment: int | None = None) -> FiberSet:
    """Explicit fibers of every curve of ``curves`` at ``frame`` (see the module docstring).

    ``specs`` and ``radii`` map a yarn-type index (``curves.yarn_type``) to its yarn and drawn radius (curve units).
    ``segments_per_period`` and ``flyaways`` go to ``generate_fibers``; ``samples_per_segment`` to
    ``curve_eval.dense_curve``."""
    if not 0 <= frame < curves.points.shape[0]:
        raise FormatError(f"frame = {frame}, expected 0 <= frame < {curves.points.shape[0]}")
    parts = []
    for c in range(len(curves.offsets) - 1):
        ytype = int(curves.yarn_type[c])
        if ytype not in specs or ytype not in radii:
            raise FormatError(f"curve {c}: no yarn spec or radius for yarn type {ytype} "
                              f"({curves.yarn_types[ytype]!r}); specs cover {sorted(specs)}, radii {sorted(radii)}")
        parts.append(sweep_curve(curves, c, frame, specs[ytype], radii[ytype], seed, segments_per_period, flyaways,
                                 samples_per_segment))
    counts = np.concatenate([np.diff(p.offsets) for p in parts])
    offsets = np.zeros(counts.size + 1, dtype=np.int64)
    np.cumsum(counts, out=offsets[1:])
    first = np.cumsum([0] + [p.n_fibers for p in parts])
    facts = [dict(p.info, fibers=(int(first[c]), int(first[c + 1]))) for c, p in enumerate(parts)]
    return FiberSet(np.concatenate([p.points for p in parts]), offsets, np.concatenate([p.radius for p in parts]),
                    np.concatenate([p.kind for p in parts]), np.concatenate([p.ply for p in parts]), 0.0, 0.0,
                    {"frame": frame, "seed": seed, "curves": facts})
