"""Reference rendering of a scene file: explicit fibers swept along the scene's yarn curves, path traced.

``build_reference(scene)`` turns a ``data_formats.scene.Scene`` into what ``path_tracer.render`` needs:
curves (HDF5 or BCC) → fibers (``fiber_sweep``) → tubes (``tessellate``) → Embree scene, one fiber-BCSDF
parameter row per yarn entry (the spec's optics times the entry's ``color``), directional lights, the environment
(file or the built-in sky) and the background. Units are the scene's.
"""

from __future__ import annotations

import time
from dataclasses import dataclass

import numpy as np

from data_formats.bcc import read_bcc
from data_formats.bcc import sniff as is_bcc
from data_formats.images import read_image
from data_formats.scene import EnvironmentLight, Scene
from data_formats.yarn_curves import read_yarn_curves
from knitbake.trace.env_light import env_from_image
from knitbake.fibers.fiber_set import FiberSet
from knitbake.fibers.fiber_sweep import sweep_fibers
from knitbake.trace.path_tracer import TracerScene
from knitbake.fibers.tessellate import tessellate_fibers
from knitrun.shading.builtin_sky import sky_image
from knitrun.render.camera import Camera
from knitrun.shading.fiber_bcsdf import P_A_D, P_A_R, P_A_TT, params_from_optics

TUBE_SIDES = 6
BUILTIN_ENVIRONMENTS = {"sky": sky_image}


@dataclass
class ReferenceScene:
    tracer: TracerScene
    camera: Camera
    facts: dict  # fibers, segments, triangles, build timings


def _entry_params(entry) -> np.ndarray:
    p = params_from_optics(entry.spec.optics)
    colour = np.asarray(entry.color, float)
    for base in (P_A_R, P_A_TT, P_A_D):
        p[base:base + 3] *= colour
    return p


def _curves(path, units):
    return read_bcc(path, units=units) if is_bcc(path) else read_yarn_curves(path)


def build_reference(scene: Scene, seed: int = 0) -> ReferenceScene:
    """Explicit-fiber tracer scene of ``scene`` at frame ``scene.render.frame``."""
    t0 = time.perf_counter()
    parts, types = [], []
    for k, entry in enumerate(scene.yarns):
        if entry.curves is None:
            raise ValueError(f"yarns[{k}] gives a stitch mesh: simulate it to yarn curves first (knitrun simulate)")
        curves = _curves(entry.curves, scene.units)
        keep = np.isin(curves.yarn_type, entry.yarn_type_indices)
        specs = {i: entry.spec for i in entry.yarn_type_indices}
        radii = {i: entry.radius for i in entry.yarn_type_indices}
        fibers = sweep_fibers(_only_curves(curves, keep), scene.render.frame, specs, radii, seed=seed + 7919 * k)
        parts.append(fibers)
        types.append(np.full(fibers.n_fibers, k, np.int32))
    fibers = _concat(parts)
    t_sweep = time.perf_counter() - t0
    mesh = tessellate_fibers(fibers, sides=TUBE_SIDES)
    t_tess = time.perf_counter() - t0 - t_sweep
    lights = [light for light in scene.lights if not isinstance(light, EnvironmentLight)]
    envs = [light for light in scene.lights if isinstance(light, EnvironmentLight)]
    env = None
    if envs:
        e = envs[0]
        image = BUILTIN_ENVIRONMENTS[e.builtin]() if e.builtin else read_image(e.file)
        env = env_from_image(image, e.scale)
    tracer = TracerScene(mesh, np.concatenate(types), np.stack([_entry_params(e) for e in scene.yarns]),
                         light_dirs=np.array([light.unit_direction for light in lights]).reshape(-1, 3),
                         light_irradiance=np.array([light.irradiance for light in lights]).reshape(-1, 3),
                         env=env, background=np.asarray(scene.background, float))
    cam = scene.camera
    camera = Camera(np.asarray(cam.position, float), np.asarray(cam.look_at, float), np.asarray(cam.up, float),
                    cam.width, cam.height, fov_deg=cam.fov_deg or 40.0, ortho_height=cam.ortho_height or 0.0)
    facts = {"fibers": fibers.n_fibers, "segments": fibers.n_segments, "triangles": int(mesh.triangles.shape[0]),
             "sweep_s": t_sweep, "tessellate_s": t_tess, "embree_build_s": time.perf_counter() - t0 - t_sweep - t_tess}
    return ReferenceScene(tracer, camera, facts)


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
