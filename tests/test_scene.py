"""Tests of data_formats.scene: the knit-scene TOML file (load, dump, sniff, describe, validate)."""

import copy
import json
import math
from pathlib import Path

import numpy as np
import pytest
import tomli_w

from data_formats import scene as sc
from data_formats.bcc import write_bcc
from data_formats.errors import FormatError
from data_formats.yarn_curves import make_yarn_curves, read_yarn_curves, write_yarn_curves
from data_formats.yarn_spec import load_preset, save_spec
from knitrun.sim.crane_stockinette import write_example_patch

EXAMPLES = Path(__file__).resolve().parent.parent / "examples" / "scenes"


def curves(types=("cotton1", "silk1"), units="cm", frames=2):
    pts = np.random.default_rng(1).normal(size=(frames, 8, 3))
    return make_yarn_curves(pts, [0, 4, 8], yarn_type=[0, len(types) - 1], yarn_types=list(types), units=units)


def base_scene():
    return {
        "format": "knit-scene", "version": "1.0", "units": "cm", "name": "t",
        "yarns": [{"curves": "c.h5", "yarn_type": "cotton1", "yarn": "cotton1", "radius": 0.05, "pack": "p.h5"},
                  {"curves": "c.h5", "yarn_type": 1, "yarn": "specs/my.toml", "color": [0.5, 0.5, 1.0]}],
        "camera": {"position": [0, 0, 5], "look_at": [0, 0, 0], "fov_deg": 30.0, "width": 64, "height": 48},
        "lights": [{"type": "directional", "direction": [0, 1, 1], "irradiance": [2, 2, 2]},
                   {"type": "environment", "file": "env/sky.hdr", "scale": [0.5, 0.5, 0.5]}],
        "render": {"spp": 8, "frame": 1},
    }


@pytest.fixture
def folder(tmp_path):
    write_yarn_curves(tmp_path / "c.h5", curves())
    (tmp_path / "specs").mkdir()
    save_spec(tmp_path / "specs" / "my.toml", load_preset("silk1"))
    (tmp_path / "env").mkdir()
    (tmp_path / "env" / "sky.hdr").write_bytes(b"#?RADIANCE\n")
    return tmp_path


def write(folder, data, name="s.toml"):
    path = folder / name
    path.write_text(tomli_w.dumps(data), encoding="utf-8")
    return path


def test_load_resolves_paths_defaults_and_yarn_types(folder):
    s = sc.load_scene(write(folder, base_scene()))
    a, b = s.yarns
    assert a.curves == b.curves == (folder / "c.h5").resolve()
    assert (a.yarn_type_indices, b.yarn_type_indices) == ((0,), (1,))
    assert a.spec.name == "cotton1" and a.radius == 0.05 and a.pack == (folder / "p.h5").resolve()
    assert b.yarn == str((folder / "specs" / "my.toml").resolve()) and b.spec.name == "silk1"
    assert b.radius == pytest.approx(load_preset("silk1").radius) and a.color == (1.0, 1.0, 1.0)
    assert s.camera.up == (0.0, 1.0, 0.0) and s.camera.ortho_height is None
    assert s.lights[0].unit_direction == pytest.approx((0, math.sqrt(0.5), math.sqrt(0.5)))
    assert s.lights[1].file == (folder / "env" / "sky.hdr").resolve() and s.lights[1].builtin is None
    assert (s.render.spp, s.render.frame, s.render.msaa, s.render.srbf_count) == (8, 1, 4, 16)
    assert s.background == (0.0, 0.0, 0.0)


def test_radius_default_converts_spec_units(folder):
    data = base_scene()
    data["units"] = "mm"
    write_yarn_curves(folder / "c.h5", curves(units="mm"))
    s = sc.load_scene(write(folder, data))
    assert s.yarns[1].radius == pytest.approx(10 * load_preset("silk1").radius)


def test_round_trip_to_another_folder(folder):
    s = sc.load_scene(write(folder, base_scene()))
    (folder / "out" / "deep").mkdir(parents=True)
    target = folder / "out" / "deep" / "copy.toml"
    sc.save_scene(target, s)
    text = target.read_text()
    assert 'curves = "../../c.h5"' in text and 'yarn = "../../specs/my.toml"' in text
    assert sc.load_scene(target) == s
    assert sc.dumps_scene(sc.load_scene(target), target.parent) == text  # dump is a fixed point


def test_orthographic_builtin_sky_and_bcc_round_trip(folder):
    write_bcc(folder / "c.bcc", curves(frames=1))
    data = base_scene()
    data["yarns"] = [{"curves": "c.bcc", "yarn": "rayon1"}]
    data["camera"] = {"position": [1, 2, 3], "look_at": [0, 0, 0], "up": [0, 0, 1], "ortho_height": 2.5,
                      "width": 10, "height": 10}
    data["lights"] = [{"type": "environment", "builtin": "sky"}]
    data["render"] = {}
    s = sc.load_scene(write(folder, data))
    assert s.camera.fov_deg is None and s.camera.ortho_height == 2.5
    assert s.lights[0].builtin == "sky" and s.lights[0].scale == (1.0, 1.0, 1.0)
    assert s.yarns[0].yarn_type_indices == (0,)
    sc.save_scene(folder / "again.toml", s)
    assert sc.load_scene(folder / "again.toml") == s
    assert sc.describe(folder / "again.toml")["projection"] == "orthographic"


def test_examples_load_validate_and_describe_as_json():
    paths = sorted(EXAMPLES.glob("*.toml"))
    assert len(paths) >= 3
    for path in paths:
        assert sc.sniff(path) and sc.validate(path) == []
        d = sc.describe(path)
        assert d["kind"] == "scene" and json.loads(json.dumps(d, allow_nan=False)) == d


def test_example_knit_patch_is_what_its_scene_file_says(tmp_path):
    """The example patch's curves are what the call in its scene file's header writes today (as the simulated patch's
    are its commands' output: tests/test_simulate.py)."""
    header = (EXAMPLES / "knit_patch_directional.toml").read_text()
    assert "write_example_patch('examples/scenes/knit_patch_6x6.h5', 6, 6)" in header
    write_example_patch(tmp_path / "patch.h5", 6, 6)
    written, example = read_yarn_curves(tmp_path / "patch.h5"), read_yarn_curves(EXAMPLES / "knit_patch_6x6.h5")
    assert written.points.shape == example.points.shape
    np.testing.assert_array_equal(written.offsets, example.offsets)
    np.testing.assert_allclose(written.points, example.points, rtol=0, atol=1e-6)


def test_sniff_is_content_based_and_never_raises(folder):
    assert sc.sniff(write(folder, base_scene(), "scene.txt"))
    assert not sc.sniff(folder / "specs" / "my.toml")
    assert not sc.sniff(folder / "c.h5")
    assert not sc.sniff(folder / "missing.toml")
    assert not sc.sniff(folder)


def edit(path, value):
    """A change to base_scene: set the item at ``path`` (keys and indices) to ``value`` (DELETE removes it)."""
    def apply(data):
        *head, last = path
        node = data
        for key in head:
            node = node[key]
        if value is DELETE:
            del node[last]
        else:
            node[last] = value
    return apply


DELETE = object()
BAD = [
    (edit(["camera"], DELETE), ["camera is missing"]),
    (edit(["camera", "fov_deg"], 200.0), ["camera.fov_deg = 200.0", "out of range", "(0, 180)"]),
    (edit(["camera", "fov_deg"], 0.0), ["camera.fov_deg = 0.0", "(0, 180)"]),
    (edit(["camera", "ortho_height"], 1.0), ["camera", "exactly one of fov_deg or ortho_height"]),
    (edit(["camera", "up"], [0, 0, -3]), ["camera.up", "parallel"]),
    (edit(["camera", "width"], 0), ["camera.width = 0", "[1, 16384]"]),
    (edit(["camera", "position"], [0, float("nan"), 5]), ["camera.position[1] = nan", "not finite"]),
    (edit(["yarns", 0, "radius"], float("nan")), ["yarns[0].radius = nan", "not finite"]),
    (edit(["yarns", 0, "radius"], -1.0), ["yarns[0].radius = -1.0", "(0, 1e+06]"]),
    (edit(["yarns", 0, "curves"], "nope.h5"), ["yarns[0].curves = 'nope.h5'", "file not found"]),
    (edit(["yarns", 1, "yarn"], "specs/none.toml"), ["yarns[1].yarn = 'specs/none.toml'", "file not found"]),
    (edit(["yarns", 1, "yarn"], "wool9"), ["yarns[1].yarn = 'wool9'", "neither a preset"]),
    (edit(["yarns", 0, "yarn_type"], "wool"), ["yarns[0].yarn_type = 'wool'", "cotton1, silk1"]),
    (edit(["yarns", 0, "yarn_type"], 5), ["yarns[0].yarn_type = 5", "[0, 1]"]),
    (edit(["yarns", 0, "yarn_type"], 1), ["yarns[1] and yarns[0] both draw yarn type 1"]),
    (edit(["yarns", 1], DELETE), ["yarn types ['silk1']", "drawn by no [[yarns]] entry"]),
    (edit(["yarns", 0, "color"], [2, 0, 0]), ["yarns[0].color[0] = 2", "[0, 1]"]),
    (edit(["yarns", 0, "stitch_mesh"], "c.h5"), ["yarns[0]", "exactly one of curves or stitch_mesh"]),
    (edit(["yarns", 0, "yarn"], DELETE), ["yarns[0].yarn is missing"]),
    (edit(["yarns"], []), ["yarns", "non-empty array"]),
    (edit(["lights", 0, "type"], "spot"), ["lights[0].type = 'spot'", "directional, environment"]),
    (edit(["lights", 0, "direction"], [0, 0, 0]), ["lights[0].direction", "is zero"]),
    (edit(["lights", 0, "irradiance"], [1, -1, 1]), ["lights[0].irradiance[1] = -1", "out of range"]),
    (edit(["lights", 1, "builtin"], "sky"), ["lights[1]", "exactly one of file or builtin"]),
    (edit(["lights", 1, "file"], "env/none.hdr"), ["lights[1].file = 'env/none.hdr'", "file not found"]),
    (edit(["lights", 0], {"type": "environment", "builtin": "sky"}), ["more than one environment light"]),
    (edit(["render", "msaa"], 3), ["render.msaa = 3", "1, 2, 4, 8, 16"]),
    (edit(["render", "shadow_map_size"], 1000), ["render.shadow_map_size = 1000", "power of two"]),
    (edit(["render", "spp"], 0), ["render.spp = 0", "[1, 1000000]"]),
    (edit(["render", "frame"], 2), ["render.frame = 2", "2 frames", "[0, 1]"]),
    (edit(["render", "sample_count"], 2), ["render: unknown key 'sample_count'"]),
    (edit(["units"], "inch"), ["units = 'inch'", "mm, cm, m"]),
    (edit(["format"], "knit-yarn-spec"), ["format = 'knit-yarn-spec'", "'knit-scene'"]),
    (edit(["version"], "2.0"), ["version = '2.0'"]),
    (edit(["camera", "fov"], 30.0), ["camera: unknown key 'fov'"]),
]


@pytest.mark.parametrize("change, fragments", BAD, ids=[" ".join(f[1][:1]) for f in BAD])
def test_bad_scene_is_one_line_error_naming_field(folder, change, fragments):
    data = copy.deepcopy(base_scene())
    change(data)
    path = write(folder, data)
    with pytest.raises(FormatError) as info:
        sc.load_scene(path)
    message = str(info.value)
    assert "\n" not in message and message.startswith(str(path))
    for fragment in fragments:
        assert fragment in message, message
    assert sc.validate(path) == [message]


def test_units_mismatch_and_newer_minor_version(folder):
    write_yarn_curves(folder / "c.h5", curves(units="m"))
    with pytest.raises(FormatError, match=r"yarns\[0\]\.curves = 'c.h5' is in units 'm', expected the scene's"):
        sc.load_scene(write(folder, base_scene()))
    write_yarn_curves(folder / "c.h5", curves())
    data = base_scene()
    data.update(version="1.3", future_key=1)
    data["camera"]["future_key"] = 2
    assert sc.load_scene(write(folder, data)).camera.fov_deg == 30.0


def test_not_toml_and_unreadable(folder):
    (folder / "bad.toml").write_text("format = [", encoding="utf-8")
    assert "not valid TOML" in sc.validate(folder / "bad.toml")[0]
    assert "no such file, expected a scene file" in sc.validate(folder / "missing.toml")[0]


def test_validate_reports_missing_pack_and_broken_curve_file(folder):
    path = write(folder, base_scene())
    problems = sc.validate(path)
    assert len(problems) == 1 and "yarns[0].pack: file not found" in problems[0]
    (folder / "p.h5").write_bytes(b"")
    assert sc.validate(path) == []
    import h5py
    with h5py.File(folder / "c.h5", "r+") as f:
        f["rest_arclength"][1] = -5.0
    problems = sc.validate(path)
    assert len(problems) == 1 and "yarns[0].curves: " in problems[0] and "rest_arclength" in problems[0]
