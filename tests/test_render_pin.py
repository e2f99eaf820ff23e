"""The strip renderer's image is pinned: small renders of two crossing yarns (the session's tiny cotton1 pack) under
the sun with the flyaway layer and the paper's ξ, under the built-in sky with 16 SRBF lobes (the full model: the
closed ξ and the flyaway layer), and under the sun with the paper's factored tables, compared with the images
stored in ``tests/data/render_pins.npz``.

Speed work (issue 15) must not move the image. The tolerance admits what a faster but equivalent evaluation changes
(a tabulated normaliser, reordered sums): per pixel, |Δ| ≤ ``PIXEL_TOLERANCE`` × the pinned image's largest value,
and the mean radiance within ``MEAN_TOLERANCE``. A change of the model or of the bake is expected to fail here:
look at the images, then re-pin deliberately with

    KNIT_UPDATE_PINS=1 .venv/bin/python -m pytest tests/test_render_pin.py

and say in the commit why the image moved."""

import os
from pathlib import Path

import numpy as np
import pytest

from data_formats.scene import load_scene
from knitrun.render.ablations import ABLATIONS
from knitrun.render.pipeline import render
from tests.helpers import SKY, SUN, straight, write_scene

PINS = Path(__file__).parent / "data" / "render_pins.npz"
PIXEL_TOLERANCE = 2e-3
MEAN_TOLERANCE = 1e-3
CAMERA = """[camera]
position = [0.05, 0.1, 1.0]
look_at = [0.0, 0.0, 0.0]
fov_deg = 30.0
width = 80
height = 60"""
CASES = {"sun_flyaways": (SUN, 4, "papers_xi"),
         "sky16": (SKY, 16, "full"),
         "sun_factored": (SUN, 4, "factored")}


def _crossing():
    """Two yarns crossing at 60°, the second in front and bent, so that shadows, both tables' angles and a range of
    mip levels are exercised."""
    a = straight(n=9, length=0.7)
    t = np.linspace(-0.35, 0.35, 15)
    b = np.stack([0.5 * t, 0.866 * t, 0.06 + 0.2 * t * t], axis=1)
    return [a, b]


@pytest.mark.parametrize("case", sorted(CASES))
def test_the_image_matches_its_pin(tmp_path, pack, case):
    lights, lobes, ablation = CASES[case]
    path = write_scene(tmp_path, _crossing(), camera=CAMERA, lights=lights)
    path.write_text(path.read_text().replace("srbf_count = 4", f"srbf_count = {lobes}"))
    image = render(load_scene(path), {"cotton1": str(pack)}, features=ABLATIONS[ablation]).image.astype(np.float64)
    if os.environ.get("KNIT_UPDATE_PINS"):
        pins = dict(np.load(PINS)) if PINS.is_file() else {}
        pins[case] = image.astype(np.float32)
        PINS.parent.mkdir(exist_ok=True)
        np.savez_compressed(PINS, **pins)
        pytest.skip(f"re-pinned {case}")
    pinned = np.load(PINS)[case].astype(np.float64)
    assert image.shape == pinned.shape
    worst = np.abs(image - pinned).max() / pinned.max()
    mean = image.mean() / pinned.mean() - 1.0
    assert worst <= PIXEL_TOLERANCE and abs(mean) <= MEAN_TOLERANCE, \
        f"{case}: worst pixel moved {worst:.2e} of the peak, mean radiance {mean:+.2e}"
    assert image.std() > 0.05 * image.mean()  # a picture, not a flat field
