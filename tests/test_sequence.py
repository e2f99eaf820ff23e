"""Sequences (``knitrun.render.sequence``, ``pipeline.Renderer``, ``knitrun render --frames``): one renderer draws
every frame of an animated curve file exactly as single renders of those frames do; file patterns, frame ranges
and their errors; the GIF."""

import dataclasses

import numpy as np
import pytest
from click.testing import CliRunner

from cli.knitrun_cli import main as knitrun
from data_formats.errors import FormatError
from data_formats.scene import load_scene
from data_formats.yarn_curves import make_yarn_curves, write_yarn_curves
from knitrun.render.pipeline import Renderer, render
from knitrun.render.sequence import frame_path, parse_frames
from tests.helpers import FRONT, SUN, straight, write_scene


def _animated_scene(tmp_path, frames=3):
    """The helpers' straight-yarn scene with its curves replaced by ``frames`` frames of the yarn moving up."""
    path = write_scene(tmp_path, [straight()], camera=FRONT, lights=SUN)
    base = straight()
    points = np.stack([base + [0.0, 0.03 * f, 0.0] for f in range(frames)])
    write_yarn_curves(tmp_path / "s.h5", make_yarn_curves(points, np.array([0, len(base)]), yarn_types=["cotton1"],
                                                          units="cm"))
    return path


def test_one_renderer_draws_every_frame_like_a_single_render(tmp_path, pack):
    path = _animated_scene(tmp_path)
    scene = load_scene(path)
    renderer = Renderer(scene, {"cotton1": str(pack)})
    assert renderer.frame_count == 3
    images = [renderer.render(f).image for f in range(3)]
    for f in (0, 2):
        single = dataclasses.replace(scene, render=dataclasses.replace(scene.render, frame=f))
        assert np.array_equal(images[f], render(single, {"cotton1": str(pack)}).image)
    assert not np.array_equal(images[0], images[1])  # the yarn moved
    with pytest.raises(ValueError, match="out of range"):
        renderer.render(3)


def test_frame_patterns_and_ranges():
    assert frame_path("out/frame_####.png", 7).name == "frame_0007.png"
    assert frame_path("a#b_##.png", 12).name == "a12b_##.png"
    assert frame_path("still.png", 3).name == "still.png"
    assert parse_frames("2:5", 10) == range(2, 5) and parse_frames("4:", 6) == range(4, 6)
    assert parse_frames("3", 10) == range(3, 4) and parse_frames(":", 4) == range(0, 4)
    for bad in ("5:2", "0:11", "x", "", "1:2:3", "-1:2"):
        with pytest.raises(FormatError, match="--frames"):
            parse_frames(bad, 10)


def test_cli_frames_write_each_png_and_a_gif(tmp_path, pack):
    path = _animated_scene(tmp_path)
    out = tmp_path / "out"
    out.mkdir()
    run = CliRunner().invoke(knitrun, ["render", str(path), "--frames", "0:3", "-o", str(out / "f_##.png"), "--gif",
                                       str(tmp_path / "a.gif"), "--pack", f"cotton1={pack}", "--json"])
    assert run.exit_code == 0, run.output
    assert sorted(p.name for p in out.iterdir()) == ["f_00.png", "f_01.png", "f_02.png"]
    import imageio.v3 as iio

    gif = iio.imread(tmp_path / "a.gif", index=None)
    assert gif.shape[0] == 3 and gif.shape[1:3] == (48, 64)
    no_run = CliRunner().invoke(knitrun, ["render", str(path), "--frames", "0:3", "-o", str(out / "still.png"),
                                          "--pack", f"cotton1={pack}"])
    assert no_run.exit_code != 0 and "needs a run of '#'" in no_run.output
    no_frames = CliRunner().invoke(knitrun, ["render", str(path), "-o", str(out / "x.png"), "--gif",
                                             str(tmp_path / "b.gif"), "--pack", f"cotton1={pack}"])
    assert no_frames.exit_code != 0 and "--gif needs --frames" in no_frames.output
