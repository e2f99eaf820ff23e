"""What drives the knot simulator: per-frame vertex positions of a stitch mesh, from built-in deformations of its rest
shape or from a folder of OBJ frames with the mesh's topology.

Built-in deformations (``DEFORMATIONS``), written ``NAME=VALUE``, all about the centre c of the rest vertices'
bounding box, with an animation amount a ∈ [0, 1] (a = 0: rest, a = 1: the full deformation):

* ``stretch-x=S`` / ``stretch-y=S``: uniaxial stretch along the course (x) / wale (y),
  x ← c_x + (1 + a(S − 1))(x − c_x).
  S < 1 compresses, S = 0 collapses every face, S < 0 inverts them; any finite S is accepted.
* ``shear=G``: simple shear along the course, x ← x + a·G·(y − c_y).
* ``cylinder=R``: the patch bent around an axis parallel to y lying R (> 0) behind it (−z), the front of the fabric
  outside (a sleeve): curvature κ = a/R, a point at (x − c_x, z) goes to angle φ = κ(x − c_x) on the circle of radius
  1/κ + z. Isometric in the plane: course lengths are kept. Evaluated with sinc so κ → 0 is exact.

Several deformations compose in the order given. Frames (stretch-and-release): with N = 1 the single frame is the full
deformation (a = 1); with N ≥ 2 frame t has a = sin(π t / (N − 1)): rest, stretched at the middle, released at the
end (an odd N hits a = 1 exactly).

OBJ frames: every ``*.obj`` file of a folder, in natural name order (``f2`` before ``f10``), each with the mesh's
vertex count and exactly its faces (fixed topology); only ``v`` and ``f`` lines matter (``STITCH_MESH.md``).
"""

from __future__ import annotations

import math
import re
from pathlib import Path

import numpy as np

from data_formats.errors import FormatError
from data_formats.stitch_mesh import parse_obj

DEFORMATIONS = ("stretch-x", "stretch-y", "shear", "cylinder")


def parse_deformation(spec):
    """(name, value) of a ``NAME=VALUE`` spec; ``FormatError`` naming the spec if it is not one of ``DEFORMATIONS``
    with a finite number (and a positive radius for ``cylinder``)."""
    name, _, text = str(spec).partition("=")
    name = name.strip()
    if name not in DEFORMATIONS:
        raise FormatError(f"deformation {spec!r}: unknown name {name!r}, expected NAME=VALUE with NAME one of "
                          f"{', '.join(DEFORMATIONS)} (e.g. stretch-x=2.0)")
    try:
        value = float(text)
    except ValueError:
        raise FormatError(f"deformation {spec!r}: value {text!r} is not a number, expected e.g. {name}=2.0") from None
    if not math.isfinite(value) or (name == "cylinder" and value <= 0):
        raise FormatError(f"deformation {spec!r}: value {value}, expected a finite number"
                          + (" > 0 (the cylinder radius)" if name == "cylinder" else ""))
    return name, value


def frame_amounts(n_frames):
    """Animation amount a of each of ``n_frames`` frames (module docstring)."""
    if n_frames < 1:
        raise FormatError(f"frames = {n_frames}, expected at least 1")
    if n_frames == 1:
        return np.ones(1)
    return np.sin(np.pi * np.arange(n_frames) / (n_frames - 1))


def deform(vertices, name, value, amount, center):
    """``vertices`` (V, 3) under deformation ``name`` = ``value`` at amount ``amount``, about ``center`` (3,)."""
    out = np.array(vertices, np.float64)
    x = out[:, 0] - center[0]
    if name in ("stretch-x", "stretch-y"):
        axis = 0 if name == "stretch-x" else 1
        out[:, axis] = center[axis] + (1.0 + amount * (value - 1.0)) * (out[:, axis] - center[axis])
    elif name == "shear":
        out[:, 0] += amount * value * (out[:, 1] - center[1])
    elif name == "cylinder":
        phi = (amount / value) * x
        z = out[:, 2] - center[2]
        # sin(φ)/κ = x·sinc(φ/π) and (cos φ − 1)/κ = −x·sin(φ/2)·sinc(φ/2π): exact as κ → 0
        out[:, 0] = center[0] + x * np.sinc(phi / np.pi) + z * np.sin(phi)
        out[:, 2] = center[2] - x * np.sin(phi / 2) * np.sinc(phi / (2 * np.pi)) + z * np.cos(phi)
    else:
        raise FormatError(f"deformation {name!r}: unknown, expected one of {', '.join(DEFORMATIONS)}")
    return out


def deformation_frames(rest_vertices, specs, n_frames=1):
    """(T, V, 3) vertex positions: the ``specs`` (``NAME=VALUE`` strings or (name, value) pairs) applied in order to
    ``rest_vertices`` at each frame's amount (``frame_amounts``)."""
    steps = [parse_deformation(s) if isinstance(s, str) else s for s in specs]
    rest = np.asarray(rest_vertices, np.float64)
    center = 0.5 * (rest.min(axis=0) + rest.max(axis=0))
    frames = np.empty((n_frames,) + rest.shape)
    for t, amount in enumerate(frame_amounts(n_frames)):
        v = rest
        for name, value in steps:
            v = deform(v, name, value, amount, center)
        frames[t] = v
    return frames


def _natural_key(path):
    return [int(part) if part.isdigit() else part for part in re.split(r"(\d+)", path.name)]


def read_obj_frames(folder, mesh):
    """(T, V, 3) vertex positions of the ``*.obj`` files in ``folder`` (natural name order); ``FormatError`` naming
    the file if one cannot be read, has non-finite coordinates, or its vertex count or faces differ from ``mesh``."""
    folder = Path(folder)
    if not folder.is_dir():
        raise FormatError(f"{folder}: not a folder, expected a folder of OBJ frames")
    paths = sorted(folder.glob("*.obj"), key=_natural_key)
    if not paths:
        raise FormatError(f"{folder}: no *.obj files, expected one OBJ per frame")
    frames = np.empty((len(paths),) + mesh.vertices.shape)
    for t, path in enumerate(paths):
        vertices, offsets, face_vertices, _ = parse_obj(path, str(path))
        if vertices.shape != mesh.vertices.shape:
            raise FormatError(f"{path}: {len(vertices)} vertices, expected the mesh's {len(mesh.vertices)} (frames "
                              f"must keep the mesh's topology)")
        if not (np.array_equal(offsets, mesh.face_offsets) and np.array_equal(face_vertices, mesh.face_vertices)):
            faces = [face_vertices[a:b] for a, b in zip(offsets[:-1], offsets[1:])]
            mine = [mesh.face_vertices[a:b] for a, b in zip(mesh.face_offsets[:-1], mesh.face_offsets[1:])]
            differ = [f for f, (x, y) in enumerate(zip(faces, mine)) if not np.array_equal(x, y)]
            f = differ[0] if differ else min(len(faces), len(mine))
            raise FormatError(f"{path}: face {f} differs from the mesh's (frames must keep the mesh's faces and "
                              f"vertex order)")
        frames[t] = vertices
    return frames
