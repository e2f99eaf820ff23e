"""The camera model shared by the strip renderer and the path tracer (``knitbake.trace.path_tracer``).

Conventions:

* ``Camera`` is a pinhole with vertical field of view ``fov_deg`` (degrees), or orthographic when ``ortho_height``
  > 0 (the height of the view, in scene units; its width is ``ortho_height · width / height``).
* Basis (``basis``): fwd = normalize(look_at − position); right = normalize(fwd × up); up' = right × fwd. View-space
  coordinates of a point p are x = (p − position)·right, y = (p − position)·up', z = (p − position)·fwd (z > 0 in
  front of the camera).
* Image: ``width`` × ``height`` pixels; pixel (row i, column j) covers screen x ∈ [j, j + 1), y ∈ [i, i + 1); row 0
  is the top of the image (screen y grows downward, along −up'). The normalized coordinates of screen point (X, Y)
  are sx = (2X − W) / H (so sx ∈ [−W/H, W/H]) and sy = 1 − 2Y / H ∈ [−1, 1].
* Pinhole: the ray through (sx, sy) leaves ``position`` along fwd + tan(fov/2)·(sx·right + sy·up'), so
  sx = x / (z·tan(fov/2)). Orthographic: the ray leaves position + ortho_height/2·(sx·right + sy·up') along fwd, so
  sx = 2x / ortho_height.
"""

import math
from dataclasses import dataclass

import numpy as np

from data_formats.errors import FormatError


@dataclass
class Camera:
    """Pinhole (``fov_deg`` vertical field of view) or orthographic (``ortho_height`` > 0) camera."""

    position: np.ndarray
    look_at: np.ndarray
    up: np.ndarray
    width: int
    height: int
    fov_deg: float = 40.0
    ortho_height: float = 0.0

    def basis(self):
        """Unit (fwd, right, up') of the module docstring; ValueError if ``up`` is parallel to the view."""
        fwd = np.asarray(self.look_at, float) - np.asarray(self.position, float)
        fwd /= np.linalg.norm(fwd)
        right = np.cross(fwd, self.up)
        if np.linalg.norm(right) < 1e-12:
            raise FormatError("camera up is parallel to the viewing direction")
        right /= np.linalg.norm(right)
        return fwd, right, np.cross(right, fwd)


def view_matrix(camera: Camera):
    """(3, 3) rows (right, up', fwd): view coordinates of p are ``view_matrix(camera) @ (p − camera.position)``."""
    fwd, right, up = camera.basis()
    return np.stack([right, up, fwd])


def tan_half_fov(camera: Camera):
    """tan(fov/2) of a pinhole camera (the value is unused by an orthographic one)."""
    return math.tan(math.radians(camera.fov_deg) / 2)


def pixel_size(camera: Camera, distance: float | None = None) -> float:
    """Side of one pixel in scene units at view depth ``distance`` (default: the depth of ``look_at``); an
    orthographic camera's pixels have one size at every depth."""
    if camera.ortho_height > 0:
        return camera.ortho_height / camera.height
    if distance is None:
        distance = float(np.linalg.norm(np.subtract(camera.look_at, camera.position)))
    return 2.0 * distance * tan_half_fov(camera) / camera.height


def project(camera: Camera, points):
    """Screen position of world ``points`` (..., 3): returns (X, Y, z) arrays of shape (...), X and Y in pixels
    (module docstring: X = column, Y = row, pixel centres at +0.5), z the view depth along fwd in scene units.
    Points with z ≤ 0 behind a pinhole camera get non-finite or mirrored X, Y: test z first."""
    p = np.asarray(points, float) - np.asarray(camera.position, float)
    view = p @ view_matrix(camera).T
    x, y, z = view[..., 0], view[..., 1], view[..., 2]
    w, h = float(camera.width), float(camera.height)
    if camera.ortho_height > 0:
        sx, sy = 2 * x / camera.ortho_height, 2 * y / camera.ortho_height
    else:
        with np.errstate(divide="ignore", invalid="ignore"):
            scale = 1.0 / (z * tan_half_fov(camera))
        sx, sy = x * scale, y * scale
    return (sx * h + w) / 2, (1 - sy) * h / 2, z


def scene_camera(scene) -> Camera:
    """The ``Camera`` of a scene file's ``[camera]`` (``data_formats.scene``: exactly one of ``fov_deg`` and
    ``ortho_height`` is set); the strip renderer and the reference path tracer both see the scene through it."""
    c = scene.camera
    return Camera(np.array(c.position, float), np.array(c.look_at, float), np.array(c.up, float), c.width, c.height,
                  fov_deg=c.fov_deg if c.fov_deg is not None else 40.0, ortho_height=c.ortho_height or 0.0)
