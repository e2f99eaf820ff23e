"""Simulation pipeline: continuous yarns in knitting order, shared boundary points, up-sampling, fixed rest arc
length, the seed-000 Fig. 9 comparison with naive interpolation, the built-in deformations and OBJ frames, the
``knitrun pattern`` / ``knitrun simulate`` commands."""

import dataclasses
import functools
import json
from pathlib import Path

import numpy as np
import pytest
from click.testing import CliRunner

from cli.knitbake_cli import main as knitbake
from cli.knitrun_cli import main as knitrun
from data_formats.bcc import read_bcc
from data_formats.errors import FormatError
from data_formats.stitch_mesh import read_obj_stitch_mesh, read_stitch_mesh, write_obj_stitch_mesh
from data_formats.yarn_curves import control_polygon_arclength, read_yarn_curves
from knitrun.sim.contact import contact_statistic
from knitrun.sim.deformations import deform, deformation_frames, frame_amounts, parse_deformation, read_obj_frames
from knitrun.sim.knit_chart import PATTERNS, chart_to_mesh, pattern_chart
from knitrun.sim.simulate import (control_segment_lengths, course_knot_spacing, prepare, simulate, solve_frame,
                                  yarn_points)
from knitrun.sim.stitch_templates import ROLE_IN, ROLE_OUT, piece_ranges
from knitrun.sim.yarn_assembly import face_point_offsets


@functools.lru_cache(maxsize=None)
def eyelet_model():
    return prepare(chart_to_mesh(pattern_chart("eyelet", 7, 8)))


def with_vertices(mesh, vertices):
    """``mesh`` with other vertex positions (same topology)."""
    return dataclasses.replace(mesh, vertices=np.asarray(vertices, np.float64))


def run(*args):
    return CliRunner().invoke(knitrun, [str(a) for a in args], catch_exceptions=False)


def assert_one_line_error(result, *fragments):
    assert result.exit_code == 1, result.output
    lines = result.stderr.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("knitrun: error:"), result.stderr
    for fragment in fragments:
        assert fragment in lines[0]


# --- yarn assembly --------------------------------------------------------------------------------------------------

def test_yarns_are_continuous_and_take_every_face_point_once():
    model = eyelet_model()
    mesh, layout, points = model.mesh, model.layout, model.rest_points
    assert len(layout.offsets) - 1 == len(mesh.yarn_type) + 1  # one yarn and the cast-on run under course 0
    assert not layout.cast_on[0] and layout.cast_on[1:].all()
    used = np.zeros(len(points), bool)
    used[layout.index] = True
    assert len(np.unique(layout.index)) == len(layout.index)  # no row twice
    unused = np.flatnonzero(~used)  # shared boundary points: the same point is in the yarn from the other face
    taken = {tuple(p) for p in points[layout.index].tolist()}
    assert all(tuple(points[i].tolist()) in taken for i in unused)
    for c in range(len(layout.offsets) - 1):
        curve = points[layout.index[layout.offsets[c]:layout.offsets[c + 1]]]
        steps = np.linalg.norm(np.diff(curve, axis=0), axis=1)
        assert steps.max() < model.length_scale and steps.min() > 0  # no jumps, no repeated points


def test_neighbours_share_boundary_points_bit_for_bit_when_deformed():
    model = eyelet_model()
    mesh = model.mesh
    rng = np.random.default_rng(2)
    points = solve_frame(model, mesh.vertices + rng.normal(0, 0.05, mesh.vertices.shape)).points
    offsets = face_point_offsets(mesh.stitch_type)

    def piece_end(f, role, last):
        (start, stop), = [(a, b) for r, a, b in piece_ranges(mesh.stitch_type[f]) if r == role]
        return points[offsets[f] + (stop - 1 if last else start)]

    pairs = 0
    for f in np.flatnonzero(mesh.course_right >= 0):
        g = mesh.course_right[f]
        assert np.array_equal(piece_end(f, ROLE_OUT, True), piece_end(g, ROLE_IN, False))  # right = neighbour's left
        pairs += 1
    assert pairs > 40


def test_upsampling_interpolates_the_control_points():
    model = eyelet_model()
    render = yarn_points(model, model.rest_points)
    samples = model.plan.samples
    for c in range(len(model.layout.offsets) - 1):
        ctrl = model.rest_points[model.layout.index[model.layout.offsets[c]:model.layout.offsets[c + 1]]]
        curve = render[model.plan.offsets[c]:model.plan.offsets[c + 1]]
        assert len(curve) == (len(ctrl) - 1) * samples + 1  # 4 rendering points per control segment
        np.testing.assert_array_equal(curve[::samples], ctrl)  # Catmull-Rom passes through its control points


def test_reused_buffers_give_the_same_frame():
    model = eyelet_model()
    v = deformation_frames(model.mesh.vertices, ["shear=0.4"])[0]
    fresh = solve_frame(model, v)
    buffers = solve_frame(model, model.mesh.vertices)
    assert solve_frame(model, v, out=buffers) is buffers
    for name in ("points", "theta", "energy"):
        np.testing.assert_array_equal(getattr(buffers, name), getattr(fresh, name))
    render = yarn_points(model, model.rest_points)
    assert yarn_points(model, fresh.points, out=render) is render
    np.testing.assert_array_equal(render, yarn_points(model, fresh.points))


def test_rest_arclength_is_fixed_over_a_stretch_and_release():
    mesh = chart_to_mesh(pattern_chart("seed", 4, 5))
    frames = deformation_frames(mesh.vertices, ["stretch-x=1.6", "shear=0.2"], 5)
    curves, report = simulate(mesh, frames)
    rest = control_polygon_arclength(curves.points[0], curves.offsets)  # frame 0 is the rest state
    np.testing.assert_allclose(curves.rest_arclength, rest, rtol=1e-12)
    stretched = control_polygon_arclength(curves.points[2], curves.offsets)
    assert (stretched[curves.offsets[1:] - 1] > rest[curves.offsets[1:] - 1]).all()  # the yarn did get longer
    np.testing.assert_allclose(curves.points[-1], curves.points[0], atol=1e-12)  # released
    assert report["frame_energy"][2] > 1 and report["final_energy"] < 1e-20
    assert len(report["ms_per_frame"]) == 5 and report["ms_per_frame_median"] > 0


# --- Huang et al. 2025 Fig. 9: knots stay uniform, yarn length error below naive interpolation ----------------

def fig9_metrics(model, vertices, **mode):
    """(RMS relative control-segment length error, spacing ratios of consecutive knots along the courses)."""
    points = solve_frame(model, vertices, **mode).points
    ratio = control_segment_lengths(model, points) / control_segment_lengths(model, model.rest_points)
    return np.sqrt(np.mean((ratio - 1) ** 2)), \
        course_knot_spacing(model, points) / course_knot_spacing(model, model.rest_points)


@pytest.mark.parametrize("spec, factor", [("stretch-x=1.5", 1.5), ("stretch-x=2.0", 2.0), ("stretch-y=1.5", 1.0)])
def test_uniform_stretch_keeps_knots_uniform_and_yarn_lengths_closer_than_naive(spec, factor):
    model = prepare(chart_to_mesh(pattern_chart("stockinette", 6, 6)))
    v = deformation_frames(model.mesh.vertices, [spec])[0]
    ours, spacing = fig9_metrics(model, v)
    naive, _ = fig9_metrics(model, v, naive=True)
    np.testing.assert_allclose(spacing, factor, rtol=1e-12)  # every knot-to-knot distance scales alike
    assert ours < 0.9 * naive


def test_cylinder_bending_is_nearly_free():
    model = prepare(chart_to_mesh(pattern_chart("rib2x2", 6, 8)))  # rectangular faces stay planar on a cylinder
    bent = deformation_frames(model.mesh.vertices, ["cylinder=0.5"])[0]
    stretched = deformation_frames(model.mesh.vertices, ["stretch-x=1.2"])[0]
    assert solve_frame(model, bent).energy[:, -1].sum() < 0.02 * solve_frame(model, stretched).energy[:, -1].sum()


@pytest.mark.parametrize("name", sorted(PATTERNS))
def test_every_pattern_simulates_to_finite_continuous_yarns(name):
    mesh = chart_to_mesh(pattern_chart(name, 6, 7))
    curves, report = simulate(mesh, deformation_frames(mesh.vertices, ["stretch-y=1.3", "shear=-0.4"]))
    assert np.isfinite(curves.points).all() and np.isfinite(report["final_energy"])
    assert report["energy_history"][-1] <= report["energy_history"][0]


# --- deformations ---------------------------------------------------------------------------------------------------

def test_built_in_deformations():
    mesh = chart_to_mesh(pattern_chart("stockinette", 4, 6))
    v = mesh.vertices
    c = 0.5 * (v.min(axis=0) + v.max(axis=0))
    np.testing.assert_allclose(np.ptp(deform(v, "stretch-x", 2.0, 1.0, c)[:, 0]), 2 * np.ptp(v[:, 0]))
    np.testing.assert_allclose(np.ptp(deform(v, "stretch-y", 0.5, 0.5, c)[:, 1]), 0.75 * np.ptp(v[:, 1]))
    sheared = deform(v, "shear", 0.5, 1.0, c)
    np.testing.assert_allclose(sheared[:, 0] - v[:, 0], 0.5 * (v[:, 1] - c[1]))
    bent = deform(v, "cylinder", 0.4, 1.0, c)
    axis = np.array([c[0], c[2] - 0.4])
    np.testing.assert_allclose(np.hypot(bent[:, 0] - axis[0], bent[:, 2] - axis[1]), 0.4)  # on the cylinder
    course = v[:, 1] == 0  # the bottom boundary line: each edge becomes the chord of an arc of its own length
    chords = np.linalg.norm(np.diff(bent[course], axis=0), axis=1)
    np.testing.assert_allclose(chords, 2 * 0.4 * np.sin(np.diff(v[course, 0]) / (2 * 0.4)), rtol=1e-12)
    np.testing.assert_array_equal(deform(v, "cylinder", 0.4, 0.0, c), v)  # amount 0: rest, no division by zero


def test_stretch_and_release_amounts_and_spec_errors():
    np.testing.assert_allclose(frame_amounts(1), [1.0])
    np.testing.assert_allclose(frame_amounts(5), [0, np.sqrt(0.5), 1, np.sqrt(0.5), 0], atol=1e-15)
    assert parse_deformation("stretch-x=2") == ("stretch-x", 2.0)
    for bad, fragment in (("twist=1", "unknown name"), ("shear=abc", "not a number"), ("cylinder=0", "> 0"),
                          ("stretch-y=nan", "finite")):
        with pytest.raises(FormatError, match=fragment):
            parse_deformation(bad)


def test_obj_frames_in_natural_order_and_topology_checked(tmp_path):
    mesh = chart_to_mesh("k/k\nkkkk\n")
    frames = deformation_frames(mesh.vertices, ["stretch-x=1.5"], 3)
    for t, v in enumerate(frames):
        write_obj_stitch_mesh(tmp_path / f"frame{[2, 10, 1][t]}.obj", with_vertices(mesh, v))
    read = read_obj_frames(tmp_path, mesh)
    np.testing.assert_allclose(read, frames[[2, 0, 1]])  # frame1, frame2, frame10
    other = chart_to_mesh("kkk\nkkk\n")
    with pytest.raises(FormatError, match="vertices, expected the mesh's"):
        read_obj_frames(tmp_path, other)
    empty = tmp_path / "empty"
    empty.mkdir()
    with pytest.raises(FormatError, match="no \\*.obj files"):
        read_obj_frames(empty, mesh)


# --- command line ---------------------------------------------------------------------------------------------------

def test_cli_help_shows_examples():
    for command in ("pattern", "simulate"):
        result = run(command, "--help")
        assert result.exit_code == 0 and "Example" in result.output and f"knitrun {command}" in result.output


def test_cli_pattern_and_simulate(tmp_path):
    h5, obj = tmp_path / "eyelet.h5", tmp_path / "chart.obj"
    result = run("pattern", "eyelet", "--rows", 6, "--cols", 6, "-o", h5, "--json")
    assert result.exit_code == 0 and json.loads(result.stdout)["faces"] == 36
    assert {0, 2, 3} <= set(read_stitch_mesh(h5).stitch_type.tolist())  # knit, yarn-over, k2tog
    chart = tmp_path / "chart.txt"
    chart.write_text("kp/\nkkkk\n")
    assert run("pattern", chart, "-o", obj).exit_code == 0
    assert len(read_obj_stitch_mesh(obj).stitch_type) == 7  # labels sidecar written and read back
    yarns = tmp_path / "yarns.h5"
    result = run("simulate", h5, "--deform", "stretch-x=1.5", "--deform", "shear=0.2", "--frames", 3, "-o", yarns,
                 "--iterations", 2, "--w-length", 50, "--beta", 0.8, "--json")
    report = json.loads(result.stdout)
    assert result.exit_code == 0 and report["frames"] == 3 and len(report["energy_history"]) == 3
    curves = read_yarn_curves(yarns)
    assert curves.points.shape == (3, report["render_points"], 3) and curves.units == "cm"
    assert curves.radius == report["yarn_radius"]  # the file keeps the radius the yarns were built for
    contact = report["contact"]
    assert contact["frames_evaluated"] == [0, 1, 2] and contact["worst"]["radius"] == report["yarn_radius"]
    assert 0 < contact["worst"]["p5"] <= contact["worst"]["p50"] <= contact["worst"]["p95"]
    assert contact["worst"]["p5"] == min(contact_statistic(curves, curves.radius, t)["p5"] for t in range(3))
    inspected = CliRunner().invoke(knitbake, ["inspect", str(yarns), "--json"], catch_exceptions=False)
    assert json.loads(inspected.stdout)["contact"]["last"] == contact["last"]
    bcc = tmp_path / "bent.bcc"
    result = run("simulate", obj, "--deform", "cylinder=1.0", "-o", bcc)
    assert result.exit_code == 0 and "ms/frame" in result.output and "final energy" in result.output
    assert np.isfinite(read_bcc(bcc).points).all()
    frames = tmp_path / "frames"
    frames.mkdir()
    mesh = read_obj_stitch_mesh(obj)
    for t in range(2):
        write_obj_stitch_mesh(frames / f"f{t}.obj", with_vertices(mesh, mesh.vertices * (1 + 0.1 * t)))
    assert run("simulate", obj, "--obj-dir", frames, "-o", yarns).exit_code == 0
    assert read_yarn_curves(yarns).points.shape[0] == 2


def test_cli_errors_are_one_line(tmp_path):
    h5 = tmp_path / "m.h5"
    assert run("pattern", "stockinette", "--rows", 3, "--cols", 3, "-o", h5).exit_code == 0
    assert_one_line_error(run("pattern", "nope", "-o", h5), "nope", "eyelet")
    assert_one_line_error(run("pattern", "seed", "-o", tmp_path / "m.txt"), ".obj")
    assert_one_line_error(run("simulate", h5, "--deform", "bend=2", "-o", tmp_path / "y.h5"), "unknown name")
    assert_one_line_error(run("simulate", h5, "-o", tmp_path / "y.txt"), ".bcc")
    assert_one_line_error(run("simulate", h5, "--obj-dir", tmp_path, "--frames", 2, "-o", tmp_path / "y.h5"),
                          "--obj-dir")
    assert_one_line_error(run("simulate", tmp_path / "missing.h5", "-o", tmp_path / "y.h5"), "no such file")
    frames = tmp_path / "frames"
    frames.mkdir()
    (frames / "f0.obj").write_text("v 0 0 nan\nv 1 0 0\nv 0 1 0\nf 1 2 3\n")
    assert_one_line_error(run("simulate", h5, "--obj-dir", frames, "-o", tmp_path / "y.h5"), "not finite")
    assert not (tmp_path / "y.h5").exists()


def test_a_radius_off_the_templates_sizing_is_named():
    """The templates are sized for r = stitch width / 8: within 5 % no warning; a 40 % thicker yarn is simulated
    but named (overlap), with the scale that would fit it; a thinner one leaves gaps."""
    mesh = chart_to_mesh(pattern_chart("stockinette", 3, 3))  # 0.25 cm stitches
    assert simulate(mesh, mesh.vertices[None])[1]["warnings"] == []
    assert simulate(mesh, mesh.vertices[None], radius=0.0297)[1]["warnings"] == []  # cotton1: 5 % thinner
    (thick,) = simulate(mesh, mesh.vertices[None], radius=0.04375)[1]["warnings"]
    assert "overlap" in thick and "1.4" in thick and "\n" not in thick
    (thin,) = simulate(mesh, mesh.vertices[None], radius=0.02)[1]["warnings"]
    assert "leave gaps" in thin


def test_example_simulated_patch_is_what_its_scene_file_says(tmp_path, monkeypatch):
    """The example scene's curves are the output of the commands its header gives, run by this simulator: a change to
    the simulator or its templates must regenerate the file (it went stale once, after the relaxed templates)."""
    examples = Path(__file__).resolve().parent.parent / "examples" / "scenes"
    header = (examples / "simulated_patch_directional.toml").read_text().splitlines()
    commands = [line.lstrip("# ").split()[1:] for line in header if line.startswith("#   knitrun ")]
    assert [c[0] for c in commands] == ["pattern", "simulate"]
    monkeypatch.chdir(tmp_path)  # the commands name their files relative to where they run
    for command in commands:
        result = run(*command)
        assert result.exit_code == 0, result.output
    written = read_yarn_curves(tmp_path / commands[1][-1])
    example = read_yarn_curves(examples / "simulated_patch_6x6.h5")
    assert written.points.shape == example.points.shape
    np.testing.assert_allclose(written.points, example.points, rtol=0, atol=1e-5)
