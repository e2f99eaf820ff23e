"""The built-in analytic sky: an environment that needs no download (``builtin = "sky"`` in a scene); and the
radiance image of a scene's environment light (``environment_image``), built-in or from a file.

A clear-sky gradient (zenith blue to a bright horizon), a darker ground below the horizon and a sun disk of
angular radius ``SUN_RADIUS_DEG`` around ``SUN_DIRECTION`` (+y up, see ``knitrun.shading.equirect``). Linear RGB
radiance, scaled so the sky alone gives an upward-facing white diffuser an irradiance of about π (radiance ≈ 1) and the
sun adds about as much again. It is a fixed image, not a physical sky model: its job is a reproducible, varied light.
"""

import numpy as np

from data_formats.images import read_image
from knitrun.shading.equirect import texel_directions

SUN_DIRECTION = np.array([0.35, 0.8, 0.49]) / np.linalg.norm([0.35, 0.8, 0.49])
SUN_RADIUS_DEG = 2.5
ZENITH = np.array([0.35, 0.55, 1.0])
HORIZON = np.array([1.0, 0.95, 0.9])
GROUND = np.array([0.25, 0.22, 0.2])
SUN = np.array([1.0, 0.92, 0.8])


def sky_image(height: int = 128, width: int = 256) -> np.ndarray:
    """(H, W, 3) float32 equirectangular radiance of the built-in sky."""
    d = texel_directions(height, width)
    up = d[..., 1:2]
    t = np.clip(up, 0.0, 1.0) ** 0.5
    sky = HORIZON * (1 - t) + ZENITH * t
    img = np.where(up >= 0, sky, GROUND * (1 + 0.5 * np.clip(up, -1, 0)))
    cos_sun = d @ SUN_DIRECTION
    disk = cos_sun >= min(np.cos(np.radians(SUN_RADIUS_DEG)), cos_sun.max())  # at least the nearest texel
    texel_solid_angle = np.sin(np.arccos(np.clip(up[..., 0], -1, 1))) * (np.pi / height) * (2 * np.pi / width)
    sun_radiance = np.pi / texel_solid_angle[disk].sum()  # irradiance π on a surface facing the sun
    return (img + disk[..., None] * SUN * sun_radiance).astype(np.float32)


def environment_image(light) -> np.ndarray:
    """(H, W, 3) equirectangular radiance of a scene's ``EnvironmentLight`` before its ``scale``: the built-in it
    names (``data_formats.scene.BUILTIN_ENVIRONMENTS``) or its image file (EXR or Radiance HDR)."""
    if light.builtin:
        return {"sky": sky_image}[light.builtin]()
    return read_image(light.file)
