"""``knitrun view``: its camera and light controls, its one-line refusal without a display, and a screenshot taken
under a virtual display (Xvfb; skipped with the reason where ``xvfb-run`` or OpenGL is missing)."""

import math
import shutil
import subprocess
import sys

import numpy as np
import pytest
from click.testing import CliRunner

from data_formats.scene import load_scene
from knitrun.render.camera import Camera
from knitrun.render.gl import viewer
from tests.helpers import FRONT, SUN, straight, write_scene


def test_orbit_turns_about_the_look_at_point_and_zooms():
    cam = Camera(np.array([0.0, 0.0, 2.0]), np.zeros(3), np.array([0.0, 1.0, 0.0]), 64, 48)
    turned = viewer.orbit(cam, math.pi / 2, 0.0)
    assert np.allclose(turned.position, [2.0, 0.0, 0.0], atol=1e-12)  # a quarter turn about +y
    tilted = viewer.orbit(cam, 0.0, 0.3)
    assert math.isclose(np.linalg.norm(tilted.position), 2.0) and tilted.position[1] > 0
    assert np.allclose(viewer.orbit(cam, 0.0, 0.0, 0.5).position, [0.0, 0.0, 1.0])
    over = viewer.orbit(cam, 0.0, 3.0)  # pitch stops short of the up axis, never flips over it
    assert math.degrees(math.asin(over.position[1] / 2.0)) == pytest.approx(89.0)
    ortho = Camera(np.array([0.0, 0.0, 2.0]), np.zeros(3), np.array([0.0, 1.0, 0.0]), 64, 48, ortho_height=0.5)
    assert viewer.orbit(ortho, 0.0, 0.0, 2.0).ortho_height == 1.0
    d = viewer.turn_light(np.array([0.0, 0.0, 1.0]), np.array([0.0, 1.0, 0.0]), math.pi / 2, 0.0)
    assert np.allclose(d, [1.0, 0.0, 0.0], atol=1e-12) and math.isclose(np.linalg.norm(d), 1.0)


def test_without_a_display_the_viewer_says_so_in_one_line(tmp_path, monkeypatch):
    from cli.knitrun_cli import main

    monkeypatch.delenv("DISPLAY", raising=False)
    monkeypatch.delenv("WAYLAND_DISPLAY", raising=False)
    path = write_scene(tmp_path, [straight()], camera=FRONT, lights=SUN)
    with pytest.raises(viewer.DisplayUnavailable, match="needs a display") as e:
        viewer.view(load_scene(path))
    assert "\n" not in str(e.value) and "xvfb-run" in str(e.value)
    result = CliRunner().invoke(main, ["view", str(path), "--screenshot", str(tmp_path / "v.png")])
    assert result.exit_code != 0 and "needs a display" in result.output and not (tmp_path / "v.png").exists()


@pytest.mark.skipif(shutil.which("xvfb-run") is None, reason="no xvfb-run (Debian: apt install xvfb)")
def test_a_screenshot_under_a_virtual_display_shows_the_gl_image(tmp_path, pack):
    from knitrun.render.gl import gl_renderer

    try:
        gl_renderer.gl_context()
    except gl_renderer.GLUnavailable as e:
        pytest.skip(f"no OpenGL context: {e}")
    path = write_scene(tmp_path, [straight(), straight(z=-0.1) + [0, 0.05, 0]], camera=FRONT, lights=SUN)
    shot = tmp_path / "view.png"
    command = [shutil.which("xvfb-run"), "-a", "-s", "-screen 0 640x480x24", sys.executable, "-c",
               "from cli.knitrun_cli import main; main()", "view", str(path), "--pack", f"cotton1={pack}",
               "--screenshot", str(shot)]
    done = subprocess.run(command, capture_output=True, text=True, timeout=300)
    assert done.returncode == 0, done.stderr[-2000:]
    from PIL import Image

    from data_formats.images import tonemap

    shown = np.asarray(Image.open(shot)).astype(float)
    scene = load_scene(path)
    assert shown.shape == (scene.camera.height, scene.camera.width, 3)
    expected = tonemap(gl_renderer.GLRenderer(scene, {"cotton1": str(pack)}).render().image).astype(float)
    assert shown.std() > 5  # not a blank window
    assert np.abs(shown - expected).mean() < 1.0  # the window shows the GL backend's frame (8-bit rounding aside)
