"""Reference rendering of a scene file: explicit fibers swept along the scene's yarn curves, path traced.

``build_reference(scene)`` turns a ``data_formats.scene.Scene`` into what ``path_tracer.render`` needs:
curves (HDF5 or BCC) → fibers (``fiber_sweep``) → Embree scene of the fibers as round linear curves (``geometry =
"curves"``, the default) or of tubes (``"tubes"``: ``tessellate``, the former path, kept to validate), one fiber-BCSDF
parameter row per yarn entry (the spec's optics times the entry's ``color``), directional lights, the environment
(file or the built-in sky) and the background. Units are the scene's.

``trace_reference`` builds and renders; ``write_reference`` writes what ``knitbake reference`` leaves on disk: the
linear EXR, a tone-mapped PNG beside it and the JSON summary (``summary_path``: the EXR's name with ``.json``),
whose keys are those of ``trace_reference``'s facts plus the paths. ``read_summary`` reads it back (``knitrun
compare --reference`` takes the reference's cost from it, ``reference_seconds``).
"""

from __future__ import annotations

import hashlib
import json
import time
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from scipy.spatial import cKDTree

from data_formats.atomic import atomic_path
from data_formats.cache_folders import cache_root
from data_formats.curve_eval import dense_curve
from data_formats.errors import FormatError
from data_formats.images import write_exr, write_png
from data_formats.numba_setup import sources_hash
from data_formats.scene import EnvironmentLight, Scene, read_curves
from knitbake.fibers.fiber_set import KIND_REGULAR, FiberSet
from knitbake.fibers.fiber_sweep import sweep_fibers
from knitbake.fibers.tessellate import tessellate_fibers
from knitbake.trace.embree_curves import CurveScene
from knitbake.trace.env_light import env_from_image
from knitbake.trace.path_tracer import MAX_DEPTH, TracerScene, render_samples
from knitrun.render.camera import Camera, scene_camera
from knitrun.render.yarn_bounce import REACH_RADII
from knitrun.shading.builtin_sky import environment_image
from knitrun.shading.fiber_bcsdf import params_from_optics, tinted

TUBE_SIDES = 6
GEOMETRIES = ("curves", "tubes")
SEEN = ("all", "regular", "flyaways")  # ``build_reference``'s ``seen``: the fibers whose light the image holds


@dataclass
class ReferenceScene:
    tracer: TracerScene
    camera: Camera
    facts: dict  # fibers, segments, triangles, build timings
    own_yarn: tuple | None  # (yarn of each fiber, σ of each fiber point, reach): ``build_reference``'s ``own_yarn``
    first_seen: np.ndarray | None = None  # (types,) bool: ``path_tracer.render_samples``' ``first_seen``, or None


def build_reference(scene: Scene, seed: int = 0, geometry: str = "curves", own_yarn: bool = False,
                    flyaways: bool = True, seen: str = "all") -> ReferenceScene:
    """Explicit-fiber tracer scene of ``scene`` at frame ``scene.render.frame``; ``seed`` draws the fibers;
    ``geometry``: ``GEOMETRIES``. ``flyaways`` False: the regular fibers alone, the loop and hair fibers drawn and
    dropped (the regular ones are those of the full draw; a diagnostic: the full reference less this one is the light
    the flyaways add). ``own_yarn``: also what the tracer's "no light between yarns" diagnostic reads
    (``path_tracer`` module docstring): the yarn (the scene's curves, numbered over its entries) of each fiber, the
    rest arc length σ of each fiber point (that of the nearest point of its curve's dense polyline) and the reach,
    the strip renderer's (``yarn_bounce.REACH_RADII`` yarn radii, the largest entry's). ``seen`` (``SEEN``): "all", or
    the diagnostic "light by the surface seen first" (``path_tracer`` module docstring): "regular" keeps the light of
    the paths whose camera ray first hits a regular fiber (the flyaways still block, scatter and shadow), "flyaways"
    that of the paths that first hit a loop or hair fiber; both see the background where camera rays miss, so "all"
    less "regular" is the light leaving the flyaways. The flyaways of entry k then trace as fiber type
    k + len(scene.yarns), with entry k's parameters."""
    if geometry not in GEOMETRIES:
        raise FormatError(f"geometry {geometry!r}: expected one of {', '.join(GEOMETRIES)}")
    if seen not in SEEN:
        raise FormatError(f"seen {seen!r}: expected one of {', '.join(SEEN)}")
    if seen != "all" and (geometry != "curves" or not flyaways):
        raise ValueError("build_reference: seen needs the fibers as curves, with their flyaways")
    if own_yarn and not flyaways:  # the yarn of each fiber comes from the full draw's fiber ranges
        raise ValueError("build_reference: own_yarn and flyaways=False do not combine (one diagnostic at a time)")
    t0 = time.perf_counter()
    parts, types, yarns, sigmas, next_yarn = [], [], [], [], 0
    for k, entry in enumerate(scene.yarns):
        if entry.curves is None:
            raise FormatError(f"yarns[{k}] gives a stitch mesh: simulate it to yarn curves first (knitrun simulate)")
        curves = read_curves(entry.curves, scene.units)
        keep = np.isin(curves.yarn_type, entry.yarn_type_indices)
        specs = {i: entry.spec for i in entry.yarn_type_indices}
        radii = {i: entry.radius for i in entry.yarn_type_indices}
        drawn = _only_curves(curves, keep)
        fibers = sweep_fibers(drawn, scene.render.frame, specs, radii, seed=seed + 7919 * k)
        if not flyaways:
            fibers = fibers.select(fibers.kind == KIND_REGULAR)
        parts.append(fibers)
        flyaway = (fibers.kind != KIND_REGULAR) & (seen != "all")
        types.append(np.where(flyaway, k + len(scene.yarns), k).astype(np.int32))
        if own_yarn:
            yarn, sigma = _yarn_and_sigma(drawn, scene.render.frame, fibers, next_yarn)
            yarns.append(yarn)
            sigmas.append(sigma)
            next_yarn += len(fibers.info["curves"])
    fibers = _concat(parts)
    t_sweep = time.perf_counter() - t0
    mesh = tessellate_fibers(fibers, sides=TUBE_SIDES) if geometry == "tubes" else None
    t_tess = time.perf_counter() - t0 - t_sweep
    lights = [light for light in scene.lights if not isinstance(light, EnvironmentLight)]
    envs = [light for light in scene.lights if isinstance(light, EnvironmentLight)]
    env = None
    if envs:
        e = envs[0]
        image = environment_image(e)
        env = env_from_image(image, e.scale)
    params = np.stack([tinted(params_from_optics(e.spec.optics), e.color) for e in scene.yarns])
    first_seen = None
    if seen != "all":
        params = np.concatenate([params, params])
        first_seen = np.repeat([seen == "regular", seen == "flyaways"], len(scene.yarns))
    n_fibers, n_segments = fibers.n_fibers, fibers.n_segments
    curve_scene = None
    if mesh is None:  # the fibers' float64 points are dropped before Embree builds: the build sets the peak
        curve_scene = CurveScene(fibers, commit=False)
        del fibers, parts
        curve_scene.commit()
    tracer = TracerScene(mesh, np.concatenate(types), params, curves=curve_scene,
                         light_dirs=np.array([light.unit_direction for light in lights]).reshape(-1, 3),
                         light_irradiance=np.array([light.irradiance for light in lights]).reshape(-1, 3),
                         env=env, background=np.asarray(scene.background, float))
    camera = scene_camera(scene)
    facts = {"geometry": geometry, "fibers": n_fibers, "segments": n_segments,
             "triangles": 0 if mesh is None else int(mesh.triangles.shape[0]),
             "sweep_s": t_sweep, "tessellate_s": t_tess, "embree_build_s": time.perf_counter() - t0 - t_sweep - t_tess}
    own = None
    if own_yarn:
        own = (np.concatenate(yarns), np.concatenate(sigmas), REACH_RADII * max(e.radius for e in scene.yarns))
    return ReferenceScene(tracer, camera, facts, own, first_seen)


def _yarn_and_sigma(curves, frame, fibers, first_yarn):
    """(yarn of each fiber: first_yarn + its curve, σ of each fiber point: the rest arc length of the nearest point
    of its curve's dense polyline, ``curve_eval.dense_curve``)."""
    yarn = np.zeros(fibers.n_fibers, np.int32)
    sigma = np.zeros(len(fibers.points))
    for c, facts in enumerate(fibers.info["curves"]):
        first, stop = facts["fibers"]
        yarn[first:stop] = first_yarn + c
        xyz, arc = dense_curve(curves, c, frame)
        lo, hi = fibers.offsets[first], fibers.offsets[stop]
        sigma[lo:hi] = arc[cKDTree(xyz).query(fibers.points[lo:hi])[1]]
    return yarn, sigma


def sample_batches(spp: int, batch_spp: int | None) -> list[tuple[int, int]]:
    """(first sample, count) of each batch of a reference of ``spp`` samples in batches of ``batch_spp`` (None or
    ≥ spp: one batch): the image is the sum of the batches' sums in this order, divided by spp."""
    step = spp if not batch_spp or batch_spp >= spp else int(batch_spp)
    return [(first, min(step, spp - first)) for first in range(0, spp, step)]


def trace_reference(scene: Scene, spp: int, seed: int = 0, max_depth: int = MAX_DEPTH, progress=None, on_built=None,
                    fiber_seed: int | None = None, geometry: str = "curves", batch_spp: int | None = None,
                    inter_yarn: bool = True, flyaways: bool = True, seen: str = "all"):
    """Build ``scene``'s fibers and path-trace them: (image (H, W, 3) float32 linear RGB, facts). ``seed`` drives the
    path sampling and, unless ``fiber_seed`` is given, the fibers too: another fiber seed draws another instance of
    the same yarns (the fiber-instance floor of a comparison), another sampling seed another estimate of the same
    image (its Monte Carlo floor). ``batch_spp`` sums the samples in batches (``sample_batches``): the image a
    distributed reference with the same batches gives bit for bit (``knitbake.scale_out``); None, one batch.
    ``on_built(facts)`` is called once the tracer scene exists (before rendering), ``progress(done, total)`` per
    pass of samples. facts: width, height, frame, spp, batch_spp, seed, fiber_seed, max_depth, render_s, rays,
    rays_per_s, the build facts of ``build_reference`` (geometry, fibers, segments, triangles, sweep_s,
    tessellate_s, embree_build_s) and mean_rgb. ``inter_yarn`` False: no light between yarns, a diagnostic
    (``path_tracer`` module docstring: paths end where they would scatter off another yarn than the one seen; the
    full image less this one is the light the yarns send each other); facts then say ``inter_yarn: false``.
    ``flyaways`` False: the regular fibers alone (``build_reference``); facts then say ``flyaways: false``. ``seen``
    "regular" or "flyaways": the light of the paths that first hit those fibers (``build_reference``); facts then
    say ``seen``."""
    fiber_seed = seed if fiber_seed is None else fiber_seed
    built = build_reference(scene, seed=fiber_seed, geometry=geometry, own_yarn=not inter_yarn, flyaways=flyaways,
                            seen=seen)
    if on_built is not None:
        on_built(built.facts)
    total, seconds, rays = None, 0.0, 0
    for first, count in sample_batches(spp, batch_spp):
        part, stats = render_samples(built.tracer, built.camera, first, count, seed=seed, max_depth=max_depth,
                                     progress=None if progress is None else
                                     (lambda done, _, first=first: progress(first + done, spp)),
                                     own_yarn=built.own_yarn, first_seen=built.first_seen)
        total = part if total is None else total + part
        seconds, rays = seconds + stats.seconds, rays + stats.rays
    image = total / spp
    facts = {"width": built.camera.width, "height": built.camera.height, "frame": scene.render.frame, "spp": spp,
             "batch_spp": batch_spp, "seed": seed, "fiber_seed": fiber_seed, "max_depth": max_depth,
             "render_s": seconds, "rays": rays,
             "rays_per_s": rays / seconds if seconds > 0 else 0.0, **built.facts,
             **({} if inter_yarn else {"inter_yarn": False}), **({} if flyaways else {"flyaways": False}),
             **({} if seen == "all" else {"seen": seen}),
             "mean_rgb": image.reshape(-1, 3).mean(axis=0).tolist()}
    return image, facts


def batch_key(scene: Scene, first: int, count: int, seed: int, fiber_seed: int, max_depth: int,
              geometry: str) -> str:
    """Content key of one sample batch: the scene (its parsed fields and the bytes of its curve files), the batch,
    seeds, depth, geometry and the hash of every source file (``data_formats.numba_setup.sources_hash``), so any
    change of input or code is a miss."""
    digest = hashlib.blake2b(digest_size=16)
    digest.update(repr((scene, first, count, seed, fiber_seed, max_depth, geometry, sources_hash())).encode())
    for entry in scene.yarns:
        if entry.curves is not None:
            digest.update(Path(entry.curves).read_bytes())
    return digest.hexdigest()


def reference_batch(scene: Scene, first: int, count: int, seed: int, fiber_seed: int, max_depth: int,
                    geometry: str = "curves", use_cache: bool = True) -> tuple[np.ndarray, dict]:
    """One batch of a distributed reference, built where it runs: (sum of samples first … first + count − 1 as
    ``render_samples`` gives it, facts of the build and the render). The sum is kept in the cache
    (``cache_root()/reference``, key ``batch_key``), so a rerun of an interrupted reference reuses every batch that
    finished; an unreadable entry is a miss, overwritten."""
    path = cache_root() / "reference" / f"{batch_key(scene, first, count, seed, fiber_seed, max_depth, geometry)}.npz"
    if use_cache:
        try:
            with np.load(path) as entry:
                return entry["sum"], {**json.loads(str(entry["facts"])), "cached": True}
        except Exception:  # noqa: BLE001  (missing, truncated or foreign entry: a miss, rewritten below)
            pass
    built = build_reference(scene, seed=fiber_seed, geometry=geometry)
    part, stats = render_samples(built.tracer, built.camera, first, count, seed=seed, max_depth=max_depth)
    facts = {**built.facts, "render_s": stats.seconds, "rays": stats.rays}
    if use_cache:
        try:
            path.parent.mkdir(parents=True, exist_ok=True)
            with atomic_path(path) as tmp, open(tmp, "wb") as f:
                np.savez(f, sum=part, facts=np.array(json.dumps(facts, default=float)))
        except OSError:  # a read-only cache only costs the next run
            pass
    return part, {**facts, "cached": False}


def summary_path(exr) -> Path:
    """The JSON summary beside a reference EXR."""
    return Path(exr).with_suffix(".json")


def write_reference(exr, image, facts: dict, exposure: float = 0.0) -> dict:
    """Write a reference: ``exr`` (linear float32), its PNG preview at ``exposure`` stops and the JSON summary
    (``facts`` plus the paths; each file written atomically). Returns the summary."""
    preview = str(Path(exr).with_suffix(".png"))
    write_exr(exr, image)
    write_png(preview, image, exposure)
    summary = {**facts, "output": str(exr), "preview": preview}
    with atomic_path(summary_path(exr)) as tmp:
        Path(tmp).write_text(json.dumps(summary, indent=2, default=float))
    return summary


def read_summary(exr) -> dict | None:
    """The JSON summary ``write_reference`` wrote beside ``exr``; None when there is none or it is unreadable."""
    try:
        summary = json.loads(summary_path(exr).read_text())
    except (OSError, ValueError):
        return None
    return summary if isinstance(summary, dict) else None


def reference_seconds(summary: dict) -> float | None:
    """The cost of a reference: fiber build (sweep, tessellation, Embree) plus path tracing, in seconds; None when
    the summary does not say."""
    try:
        return float(summary["render_s"]) + sum(float(summary.get(k, 0.0))
                                                for k in ("sweep_s", "tessellate_s", "embree_build_s"))
    except (KeyError, TypeError, ValueError):
        return None


def _only_curves(curves, keep):
    """The curves where ``keep`` is true (same frames and metadata)."""
    if keep.all():
        return curves
    from data_formats.yarn_curves import make_yarn_curves

    idx = np.flatnonzero(keep)
    pts = [curves.points[:, curves.offsets[c]:curves.offsets[c + 1]] for c in idx]
    arc = [curves.rest_arclength[curves.offsets[c]:curves.offsets[c + 1]] for c in idx]
    offsets = np.concatenate([[0], np.cumsum([p.shape[1] for p in pts])])
    return make_yarn_curves(np.concatenate(pts, axis=1), offsets, curves.closed[idx], curves.yarn_type[idx],
                            curves.yarn_types, np.concatenate(arc), curves.curve_type, curves.units,
                            curves.frame_time)


def _concat(parts) -> FiberSet:
    if len(parts) == 1:
        return parts[0]
    offsets = [np.zeros(1, np.int64)]
    base = 0
    for f in parts:
        offsets.append(f.offsets[1:] + base)
        base += f.points.shape[0]
    return FiberSet(np.concatenate([f.points for f in parts]), np.concatenate(offsets),
                    np.concatenate([f.radius for f in parts]), np.concatenate([f.kind for f in parts]),
                    np.concatenate([f.ply for f in parts]))
