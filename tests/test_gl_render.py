"""The GL backend of the strip renderer (``knitrun.render.gl``) against the CPU renderer it ports: the same image at
the yarn scale on lit, shadowed, sky-lit and ablated scenes; its refusals and its one-line errors. The tests need an
OpenGL 4.5 context through EGL (Mesa's llvmpipe is enough; no GPU); without one they are skipped with the reason."""

import dataclasses
import json
import shutil

import h5py
import numpy as np
import pytest
from click.testing import CliRunner

from data_formats.errors import FormatError
from data_formats.images import tonemap
from data_formats.scene import load_scene
from data_formats.yarn_curves import make_yarn_curves, write_yarn_curves
from knitbake.compare.image_metrics import yarn_scale_metrics
from knitrun.render.ablations import ABLATIONS, Features
from knitrun.render import pipeline
from knitrun.render.camera import scene_camera
from knitrun.render.gl import gl_renderer
from tests.helpers import BACKLIT, FRONT, OVERHEAD_SUN, SIDE, SKY, SUN, straight, write_scene

# orthographic, yarns along the image axes: the strips' edges then cross the same samples in both renderers (the
# driver's 4× positions have the CPU pattern's x and y values), so the images agree to rounding
ORTHO = """[camera]
position = [0.0, 0.0, 1.0]
look_at = [0.0, 0.0, 0.0]
ortho_height = 0.5
width = 64
height = 48"""
ALONG_Y = np.array([[0, 1, 0], [1, 0, 0], [0, 0, 1.0]])

try:
    gl_renderer.gl_context()
except gl_renderer.GLUnavailable as e:
    pytest.skip(f"no OpenGL context: {e}", allow_module_level=True)


def _both(path, pack, features=Features()):
    """(GL image, CPU image) of the scene at ``path`` over a black background (the comparison is of the yarns, not
    diluted by empty pixels), the CPU one drawn from the GL renderer's own set-up."""
    scene = dataclasses.replace(load_scene(path), background=(0.0, 0.0, 0.0))
    renderer = gl_renderer.GLRenderer(scene, {"cotton1": str(pack)}, features)
    return renderer.render().image, renderer.cpu.render().image


def _yarn_l1(a, b, diameter_px=8.0):
    return yarn_scale_metrics(a, b, diameter_px)["rel_l1"]


@pytest.mark.parametrize("lights", ["sun", "sun and sky"])
def test_a_lit_straight_yarn_is_the_cpu_image(tmp_path, pack, lights):
    """One yarn, so no yarn-level shadow: the shading itself (DS, ξ, Ψ^Fiber; under the sky I_M with the R rule,
    the multiple-scattering clusters and the inter-reflection) agrees to single-precision rounding."""
    path = write_scene(tmp_path, [straight()], camera=ORTHO, lights=SUN if lights == "sun" else SUN + "\n" + SKY)
    gl, cpu = _both(path, pack)
    assert gl.shape == cpu.shape and gl.dtype == np.float32 and np.all(np.isfinite(gl))
    assert cpu.mean() > 0.003 and (cpu.mean(axis=2) > 0.01).mean() > 0.05  # the yarn covers some pixels
    assert abs(gl.mean() / cpu.mean() - 1) < 2e-3
    assert np.abs(gl - cpu).mean() < 5e-3 * cpu.mean()  # per pixel: the same geometry, shaded at the same sample


@pytest.mark.parametrize("ablation", ["plain_ds", "xi", "factored", "no_tables", "no_detail", "diagonal_xi",
                                      "whole_xi"])
def test_ablations_follow_the_cpu_renderer(tmp_path, pack, ablation):
    gl, cpu = _both(write_scene(tmp_path, [straight()], camera=ORTHO, lights=SUN + "\n" + SKY), pack,
                    ABLATIONS[ablation])
    assert abs(gl.mean() / cpu.mean() - 1) < 2e-3
    assert np.abs(gl - cpu).mean() < 5e-3 * cpu.mean()


def test_the_view_closed_xi_is_read_and_moves_the_image(tmp_path, pack):
    """The default (ξ closed at every view) and ``diagonal_xi`` compare different images: the pack's
    ``correction/xi_view`` is uploaded, and the image it gives is not the diagonal ξ's."""
    path = write_scene(tmp_path, [straight()], camera=ORTHO, lights=SUN + "\n" + SKY)
    scene = dataclasses.replace(load_scene(path), background=(0.0, 0.0, 0.0))
    renderer = gl_renderer.GLRenderer(scene, {"cotton1": str(pack)})
    assert renderer.cpu.looks[0].xi_view.shape[0] > 0
    view, diagonal = renderer.render().image, _both(path, pack, ABLATIONS["diagonal_xi"])[0]
    assert np.abs(view - diagonal).mean() > 1e-2 * diagonal.mean()


def test_the_split_xi_is_read_and_moves_the_image(tmp_path, pack):
    """The default (ξ closed apart on single and multiple scattering) and ``whole_xi`` draw different images: the
    pack's ``correction/xi_view_ss`` is uploaded beside ``_ms`` (that each term reads the right one is held by the
    per-pixel agreement with the CPU renderer, whose split is tested in ``tests/test_closure.py`` and
    ``tests/test_render.py``; ``diagonal_xi`` reads the diagonal's pair, ``whole_xi`` the one ξ)."""
    path = write_scene(tmp_path, [straight()], camera=ORTHO, lights=SUN + "\n" + SKY)
    scene = dataclasses.replace(load_scene(path), background=(0.0, 0.0, 0.0))
    split = gl_renderer.GLRenderer(scene, {"cotton1": str(pack)})
    assert split.cpu.looks[0].xi_single_view.shape[0] > 0
    whole = gl_renderer.GLRenderer(scene, {"cotton1": str(pack)}, ABLATIONS["whole_xi"])
    assert whole.cpu.looks[0].xi_single_view.shape[0] == 0
    split_image, whole_image = split.render().image, whole.render().image
    assert np.abs(split_image - whole_image).mean() > 1e-2 * whole_image.mean()


def test_a_pinhole_view_agrees_at_the_yarn_scale(tmp_path, pack):
    """Under perspective the strips' edges cross the driver's samples, not the CPU's: the images agree at the yarn
    scale (here, a yarn along the image's x axis, to 1e-4)."""
    gl, cpu = _both(write_scene(tmp_path, [straight()], camera=FRONT, lights=SUN), pack)
    assert abs(gl.mean() / cpu.mean() - 1) < 2e-3
    assert _yarn_l1(gl, cpu) < 2e-3


def test_a_bent_yarn_is_split_into_triangles_as_the_cpu_splits_it(tmp_path, pack):
    """A tight arc makes every strip quad a trapezoid, whose attributes depend on the diagonal it is split along.
    The regular strips alone (the hair layer's own sampling differences blur it: with it, 0.0081 against 0.0265):
    split as the CPU splits, this arc measures 0.0052 at the yarn scale; along the other diagonal (a+ b−) 0.0116
    (stop 51, the test pack's flyaways of stop 51; before, with them, 0.0125 along the other diagonal)."""
    camera = ORTHO.replace("width = 64", "width = 160").replace("height = 48", "height = 120")
    a = np.linspace(0.0, 1.5 * np.pi, 25)
    arc = np.stack([0.15 * np.cos(a), 0.15 * np.sin(a), np.zeros_like(a)], axis=1)
    gl, cpu = _both(write_scene(tmp_path, [arc], camera=camera, lights=SUN), pack, Features(flyaways=False))
    assert abs(gl.mean() / cpu.mean() - 1) < 3e-3
    assert _yarn_l1(gl, cpu) < 8e-3


def test_the_fiber_bend_agrees_and_moves_the_image(tmp_path, pack):
    """``Features.fiber_bend`` on the arc above: the GL fragments read the bend and stretch of their segment from the
    polyline texture as ``pipeline.segment_bend`` gives them, so the backends agree as they do without it
    (0.0049 at the yarn scale, measured; 0.0054 without the bend), and the bend moves the image 17× as much (0.085)."""
    camera = ORTHO.replace("width = 64", "width = 160").replace("height = 48", "height = 120")
    a = np.linspace(0.0, 1.5 * np.pi, 25)
    arc = np.stack([0.15 * np.cos(a), 0.15 * np.sin(a), np.zeros_like(a)], axis=1)
    path = write_scene(tmp_path, [arc], camera=camera, lights=SUN)
    gl, cpu = _both(path, pack, Features(flyaways=False))
    gl_plain, cpu_plain = _both(path, pack, Features(flyaways=False, fiber_bend=False))
    assert abs(gl.mean() / cpu.mean() - 1) < 3e-3
    assert _yarn_l1(gl, cpu) < 8e-3
    assert _yarn_l1(gl_plain, cpu_plain) < 8e-3
    assert _yarn_l1(cpu, cpu_plain) > 10 * _yarn_l1(gl, cpu)


def test_shadows_agree_at_the_yarn_scale(tmp_path, pack):
    """A yarn in front of another under a slanted sun and the sky, a third across them: the shadow maps are
    rasterised by the driver from the light's view (edges at its samples), so again the yarn scale. The regular
    layer with the paper's ξ, whose difference lies along one row of shadow edge; with the closed ξ the same row's
    differences share one sign and the mean moves −0.72 % (yarn scale 0.0075), with the flyaway layer too −1.3 %
    (0.0136): measured, not yet explained (BENCHMARKS.md "Issue 13: hairs in their own yarn's shadow, and the
    closed ξ with flyaways as the default")."""
    yarns = [straight(z=0.0), straight(z=-0.1) + [0, -0.04, 0], straight(z=0.05) @ ALONG_Y.T]
    gl, cpu = _both(write_scene(tmp_path, yarns, camera=ORTHO, lights=SUN + "\n" + SKY), pack,
                    ABLATIONS["interreflection"])
    assert abs(gl.mean() / cpu.mean() - 1) < 5e-3
    assert _yarn_l1(gl, cpu) < 6e-3


def test_shadows_on_the_tube_surface_agree_and_move_the_image(tmp_path, pack):
    """``Features.surface_shadows``: two touching yarns under a light 16° above their plane from B's side (the CPU
    test's scene, ``tests/test_render.py``), where the strip plane puts A's middle in B's shadow and the tube's
    surface does not: the backends agree at the yarn scale, and the lookups on the surface light A's middle third
    (the rows the CPU test reads; until stop 56 the whole image's mean, which B, unchanged, dilutes: 1.20× with ξ
    closed apart, 1.2 required)."""
    r, camera = 0.03, ORTHO.replace("ortho_height = 0.5", "ortho_height = 0.3")
    grazing = SUN.replace("direction = [0.3, 0.6, 1.0]", "direction = [0.0, 1.0, 0.29]")
    path = write_scene(tmp_path, [straight(), straight() + [0.0, 2 * r, 0.0]], camera=camera, lights=grazing,
                       name="touching")
    axis = Features(flyaways=False, view_xi=False, parallax=False, yarn_bounce=False, surface_shadows=False)
    gl, cpu = _both(path, pack, dataclasses.replace(axis, surface_shadows=True))
    assert abs(gl.mean() / cpu.mean() - 1) < 2e-3
    assert _yarn_l1(gl, cpu) < 2e-3
    plane = _both(path, pack, axis)[0]
    px = 0.3 / 48  # ortho_height / height: rows of A's middle third
    row_a, cols = slice(24 - int(r / 3 / px), 24 + int(r / 3 / px) + 1), slice(16, 48)
    assert gl[row_a, cols].mean() > 1.5 * plane[row_a, cols].mean()


def test_a_lone_yarn_lit_along_its_length_is_not_shadowed_by_its_own_strip(tmp_path, pack):
    """The CPU test's lone yarn lit from behind 56° toward its axis (``tests/test_render.py``): the GL lookups on
    the tube's surface keep their margin from the yarn's own strip as the CPU's do (``own_strip_depth`` in
    ``shadow.glsl``), so the image is the axis plane's, and the CPU's."""
    along = SUN.replace("direction = [0.3, 0.6, 1.0]", "direction = [1.0, 0.3, -0.6]")
    path = write_scene(tmp_path, [straight()], camera=FRONT, lights=along, name="along")
    gl, cpu = _both(path, pack, Features(flyaways=False))
    plane = _both(path, pack, Features(flyaways=False, surface_shadows=False))[0]
    assert gl.max() > 0.0
    assert _yarn_l1(gl, plane) < 1e-5
    assert _yarn_l1(gl, cpu) < 2e-3


def test_a_lone_yarns_hairs_are_not_shadowed_by_its_own_strip(tmp_path, pack):
    """The CPU test's lone yarn lit from behind and from one side (``tests/test_render.py``), its hairs drawn: the
    flyaway pass's lookups keep their margin from the yarn's own strip as the CPU's do, so the backends agree per
    pixel (measured: 0.46 % of the peak at worst, 0.12 % in the mean; without the margin in ``flyaway.frag`` 2.4 % and
    0.33 %)."""
    side = SUN.replace("direction = [0.3, 0.6, 1.0]", "direction = [0.2, 0.8, -0.5]")
    path = write_scene(tmp_path, [straight()], camera=ORTHO, lights=side, name="side")
    gl, cpu = _both(path, pack)
    assert cpu.max() > 0.0
    assert np.abs(gl - cpu).max() < 1e-2 * cpu.max() and np.abs(gl - cpu).mean() < 2e-3 * cpu.mean()


def test_the_axial_parallax_agrees_and_moves_the_image(tmp_path, pack):
    """``Features.parallax`` on a straight yarn tilted 27° toward an orthographic camera, where each point is read
    r √(1 − v²) tan θ_o further along its curve: the GL walk along the polyline agrees with the CPU's as the image
    without it does (1.8e-4 at the yarn scale, measured; the parallax moves it by 0.047)."""
    tilted = straight() + np.stack([np.zeros(9), np.zeros(9), np.linspace(-0.15, 0.15, 9)], axis=1)
    path = write_scene(tmp_path, [tilted], camera=ORTHO, lights=SUN, name="tilted")
    gl, cpu = _both(path, pack, Features(flyaways=False))
    assert abs(gl.mean() / cpu.mean() - 1) < 2e-3
    assert _yarn_l1(gl, cpu) < 1e-3
    plain = _both(path, pack, Features(flyaways=False, parallax=False))[0]
    assert _yarn_l1(gl, plain) > 20 * _yarn_l1(gl, cpu)


def test_the_parallax_newton_steps_agree_on_a_tight_bend(tmp_path, pack, monkeypatch):
    """A yarn bent over a radius of 0.08 cm rising toward the camera, where the straight tube's shift misses the
    surface the ray meets (``pipeline.parallax_shift``'s Newton steps): the GL image is the CPU's (measured: 0.006 at
    the yarn scale, 0.008 without the parallax), and the CPU with one step alone is 0.10 away (measured), so the
    shader takes the same ``PARALLAX_PASSES`` steps."""
    t = np.linspace(0.0, np.pi, 25)
    arc = np.stack([0.08 * np.cos(t), 0.01 * np.sin(t), 0.08 * np.sin(t)], axis=1)
    path = write_scene(tmp_path, [arc], camera=ORTHO.replace("ortho_height = 0.5", "ortho_height = 0.25"),
                       lights=SUN, name="tight")
    scene = dataclasses.replace(load_scene(path), background=(0.0, 0.0, 0.0))
    renderer = gl_renderer.GLRenderer(scene, {"cotton1": str(pack)}, Features(flyaways=False))
    gl, cpu = renderer.render().image, renderer.cpu.render().image
    assert abs(gl.mean() / cpu.mean() - 1) < 5e-3
    assert _yarn_l1(gl, cpu) < 0.015
    monkeypatch.setattr(pipeline, "PARALLAX_PASSES", 1)
    assert _yarn_l1(gl, renderer.cpu.render().image) > 4 * _yarn_l1(gl, cpu)


def test_the_yarn_bounce_agrees_and_moves_the_image(tmp_path, pack):
    """``Features.yarn_bounce`` on two crossing yarns under the sun: the bounce at the polyline points is the CPU's
    (``pipeline.frame_bounce``, from the CPU twin's shadow maps), read by the fragments as the CPU's points read it,
    so the backends agree as they do without it; and the bounce brightens the image."""
    crossing = [straight(z=0.0), straight(z=0.07) @ ALONG_Y.T]
    path = write_scene(tmp_path, crossing, camera=ORTHO, lights=SUN, name="crossing")
    gl, cpu = _both(path, pack, Features(flyaways=False))
    assert abs(gl.mean() / cpu.mean() - 1) < 5e-3
    assert _yarn_l1(gl, cpu) < 6e-3
    plain = _both(path, pack, Features(flyaways=False, yarn_bounce=False))[0]
    assert gl.mean() > 1.01 * plain.mean()


def test_two_blocking_yarns_agree_and_darken_the_yarn_behind_both(tmp_path, pack):
    """``Features.two_blockers`` (the default) on three yarns stacked under a sun from above, seen from the side: the
    lights' second yarn layer is peeled by the driver (``depth.frag``) as ``strip_raster.rasterize_behind`` peels it,
    and what lies behind two yarns takes τ_Y² where one blocker let τ_Y through. The backends agree with it as without
    it, and it moves the image by far more than they differ, on the bottom yarn alone. (The sun is tilted so that the
    top yarn's shadow covers the bottom yarn's surface but not its axis: a hair there lies behind one yarn, the
    surface behind two. Until stop 75 the CPU's hairs over a body took that body's surface lookups, and this test
    switched that off.)"""
    stack = [straight(z=z) for z in (0.24, 0.12, 0.0)]
    sun = OVERHEAD_SUN.replace("[0.0, 0.0, 1.0]", "[0.0, 0.15, 1.0]")
    path = write_scene(tmp_path, stack, camera=SIDE, lights=sun, name="stack")
    gl, cpu = _both(path, pack)
    one, one_cpu = _both(path, pack, Features(two_blockers=False))
    assert abs(gl.mean() / cpu.mean() - 1) < 5e-3
    assert _yarn_l1(gl, cpu) < 6e-3 and _yarn_l1(one, one_cpu) < 6e-3
    assert _yarn_l1(gl, one) > 10 * _yarn_l1(gl, cpu)
    change = np.abs(gl - one).max(axis=(1, 2))
    assert change[: int(0.6 * len(change))].max() < 0.05 * change.max()  # the upper yarns' rows do not move
    assert gl.mean() < 0.97 * one.mean()


def test_the_bounce_reads_the_light_maps_the_driver_drew(tmp_path, pack, monkeypatch):
    """The yarn-level bounce looks the lights up in this frame's light atlas read back (``_read_light_maps``), not in
    maps the CPU draws again: two lights (two tiles of the atlas), each read back equal to the CPU's
    ``build_shadow_map`` on the texels both cover, both layers, and covering the same texels but for a few on the
    strips' edges; the bounce then as the CPU twin's."""
    from knitrun.render.shadow_map import build_shadow_map

    read = []
    original = gl_renderer.GLRenderer._read_light_maps
    monkeypatch.setattr(gl_renderer.GLRenderer, "_read_light_maps",
                        lambda self, *args: read.append(original(self, *args)) or read[-1])
    stack = [straight(z=z) for z in (0.24, 0.12, 0.0)] + [straight(z=0.12) @ ALONG_Y.T]
    second = OVERHEAD_SUN.replace("[0.0, 0.0, 1.0]", "[0.5, 0.3, 1.0]").replace("2.0, 2.0, 2.0", "1.0, 1.0, 1.0")
    path = write_scene(tmp_path, stack, camera=SIDE, lights=OVERHEAD_SUN + "\n" + second, name="stack")
    scene = dataclasses.replace(load_scene(path), background=(0.0, 0.0, 0.0))
    renderer = gl_renderer.GLRenderer(scene, {"cotton1": str(pack)})
    gl = renderer.render()
    cpu = renderer.cpu.render()
    lines = pipeline._polylines(scene, renderer.cpu.curves, 0, renderer.cpu.samples_per_segment)
    radius = np.array([renderer.cpu.looks[k].radius for k in lines.entry])
    size = scene.render.shadow_map_size
    assert len(read) == 1 and len(read[0]) == 2
    for sm, d in zip(read[0], renderer.light_dir):
        twin = build_shadow_map(lines.points, lines.offsets, False, lines.rest, radius, d, size,
                                lines.points.min(axis=0), lines.points.max(axis=0), layers=2)
        # GL's rows run upward: the read-back map's view has the light camera's up negated, its rows flipped
        assert np.allclose(sm.view, twin.view * [[1.0], [-1.0], [1.0]]) and np.allclose(sm.origin, twin.origin)
        for ours, theirs in ((sm.depth[::-1], twin.depth), (sm.behind[::-1], twin.behind)):
            both = np.isfinite(ours) & np.isfinite(theirs)
            assert both.sum() > 1000
            assert np.abs(ours[both] - theirs[both]).max() < 1e-5
            assert (np.isfinite(ours) != np.isfinite(theirs)).sum() < 0.01 * both.sum()
    ours, theirs = gl.facts["yarn_bounce"], cpu.facts["yarn_bounce"]
    assert ours["covered_sphere"] == theirs["covered_sphere"] > 0.05
    assert ours["radiance"] == pytest.approx(theirs["radiance"], rel=2e-3) and min(ours["radiance"]) > 1e-3


def _knit_like_yarns(rng):
    """``BounceYarns`` of five wavy curves of two yarn entries (one with a Lambertian tube's phase, one with a random
    positive table, so a swapped axis or a wrong wrap shows) crossing over and under each other, and two lights."""
    from knitrun.render.strip_raster import vertex_tangents
    from knitrun.render.yarn_bounce import PHASE_PHI, PHASE_THETA, BounceLights, BounceYarns, lambert_phase

    s = np.linspace(0.0, 1.0, 41)
    curves = [np.stack([s, np.full_like(s, y), 0.03 * np.sin(2 * np.pi * 3 * s + y * 20)], axis=1)
              for y in (0.0, 0.06, 0.12)]
    curves += [np.stack([np.full_like(s, x), 0.3 * s - 0.09, 0.03 * np.cos(2 * np.pi * 2 * s)], axis=1)
               for x in (0.3, 0.36)]
    points = np.concatenate(curves)
    offsets = np.cumsum([0] + [len(c) for c in curves]).astype(np.int64)
    rest = np.concatenate([np.concatenate([[0.0], np.cumsum(np.linalg.norm(np.diff(c, axis=0), axis=1))])
                           for c in curves])
    view = np.array([0.2, -0.4, 2.0]) - points
    view /= np.linalg.norm(view, axis=1, keepdims=True)
    phase = np.stack([lambert_phase(np.array([0.5, 0.3, 0.2]), np.array([0.2, 0.1, 0.05])),
                      rng.uniform(0.0, 0.1, (PHASE_THETA, PHASE_THETA, PHASE_PHI, 3))])
    yarns = BounceYarns(points, vertex_tangents(points, offsets),
                        np.repeat(np.arange(len(curves)), np.diff(offsets)), offsets, rest,
                        np.array([0.03, 0.03, 0.03, 0.025, 0.025]), rng.uniform(0.3, 0.9, (len(points), 3)), view,
                        phase, np.array([0, 0, 1, 1, 0], np.int64))
    direction = np.array([[0.3, 0.2, 1.0], [-0.6, 0.1, 0.5]])
    lights = BounceLights(direction / np.linalg.norm(direction, axis=1, keepdims=True),
                          np.array([[2.0, 1.8, 1.5], [0.5, 0.6, 0.7]]), rng.uniform(0.0, 1.0, (2, len(points))))
    return yarns, lights


def test_the_bounce_sums_on_the_gpu_are_the_numba_kernels():
    """``gl_bounce.gpu_vertex_bounce`` (the compute shader ``bounce.comp``) gives ``yarn_bounce.vertex_bounce``'s B,
    f and I on crossing curves of two yarn entries under two lights, to single precision: 2e-3 of each largest value
    (measured 1.0e-3 for B, where the random table's steep cells magnify the single-precision angles of nearly
    aligned directions; 1.7e-4 on the pack's phase of ``bench_render.py``'s patch), with a bounce on nearly every
    point. Edits of the shader fail it: the receiver's θ axes swapped (B off by 0.37 of its largest), the sender's
    azimuth reversed (0.12), φ clamped instead of wrapped (0.020)."""
    from knitrun.render.gl.gl_bounce import gpu_vertex_bounce
    from knitrun.render.yarn_bounce import vertex_bounce

    yarns, lights = _knit_like_yarns(np.random.default_rng(7))
    program = gl_renderer._programs(gl_renderer.gl_context())[3]  # the bounce's compute shader
    ours = gpu_vertex_bounce(program, yarns, lights)
    theirs = vertex_bounce(yarns, lights)
    assert (theirs[1] > 0).mean() > 0.9 and theirs[0].max() > 0
    for a, b in zip(ours, theirs):
        assert a.shape == b.shape and np.all(np.isfinite(a))
        assert np.abs(a - b).max() < 2e-3 * np.abs(b).max()
    no_light = lights._replace(direction=np.zeros((0, 3)), irradiance=np.zeros((0, 3)),
                               direct=np.zeros((0, len(yarns.points))))
    assert all(np.all(x == 0) for x in gpu_vertex_bounce(program, yarns, no_light))


def test_the_bounce_runs_on_the_gpu_or_the_cpu_to_the_same_image(tmp_path, pack):
    """``GLRenderer(bounce_on=…)``: the frame with the bounce's sums on the GPU equals the frame with them in the
    Numba kernel to single precision; "auto" takes the CPU on a software rasteriser (llvmpipe, where the kernel is
    the faster) and the GPU on any other; another word is a one-line error."""
    crossing = [straight(z=0.0), straight(z=0.07) @ ALONG_Y.T, straight(z=-0.07) @ ALONG_Y.T]
    path = write_scene(tmp_path, crossing, camera=ORTHO, lights=SUN, name="crossing")
    scene = dataclasses.replace(load_scene(path), background=(0.0, 0.0, 0.0))
    frames = {}
    for where in ("gpu", "cpu"):
        renderer = gl_renderer.GLRenderer(scene, {"cotton1": str(pack)}, Features(flyaways=False), bounce_on=where)
        assert renderer.setup_facts["bounce_on"] == where
        frames[where] = renderer.render()
    gpu, cpu = frames["gpu"], frames["cpu"]
    assert gpu.facts["yarn_bounce"]["covered_sphere"] == pytest.approx(cpu.facts["yarn_bounce"]["covered_sphere"],
                                                                       abs=1e-4)
    assert gpu.facts["yarn_bounce"]["radiance"] == pytest.approx(cpu.facts["yarn_bounce"]["radiance"], rel=1e-4)
    assert np.abs(gpu.image - cpu.image).max() < 1e-4 * cpu.image.max()
    plain = gl_renderer.GLRenderer(scene, {"cotton1": str(pack)}, Features(flyaways=False, yarn_bounce=False))
    assert np.abs(gpu.image - plain.render().image).max() > 100 * np.abs(gpu.image - cpu.image).max()
    auto = gl_renderer.GLRenderer(scene, {"cotton1": str(pack)}, Features(flyaways=False))
    software = gl_renderer.software_renderer(auto.ctx.info["GL_RENDERER"])
    assert auto.setup_facts["bounce_on"] == ("cpu" if software else "gpu")
    assert gl_renderer.software_renderer("llvmpipe (LLVM 15.0.6, 256 bits)")
    assert not gl_renderer.software_renderer("NVIDIA H200/PCIe/SSE2")
    with pytest.raises(FormatError, match="bounce_on 'tpu': expected one of auto, gpu, cpu"):
        gl_renderer.GLRenderer(scene, {"cotton1": str(pack)}, bounce_on="tpu")


def test_frames_an_empty_scene_and_the_renderer_interface(tmp_path, pack):
    path = write_scene(tmp_path, [straight()], camera=FRONT, lights=SUN)
    renderer = gl_renderer.GLRenderer(load_scene(path), {"cotton1": str(pack)})
    assert renderer.frame_count == 1 and renderer.warnings == []
    assert {"load", "gl_setup"} <= set(renderer.setup_timings)
    result = renderer.render(0)
    assert {"load", "shadow", "shade", "resolve"} == set(result.timings)
    with pytest.raises(FormatError, match="frame 1 is out of range"):
        renderer.render(1)
    empty = write_scene(tmp_path, [np.zeros((2, 3))], camera=FRONT, lights=SUN, name="empty")  # a point: nothing drawn
    scene = load_scene(empty)
    image = gl_renderer.GLRenderer(scene, {"cotton1": str(pack)}).render().image
    assert np.allclose(image, np.asarray(scene.background, np.float32))


def test_the_flyaway_layer_follows_the_cpu_renderer(tmp_path, pack):
    """The nearest flyaway strips against the regular depth (``render.hair_layers`` = 1), shaded and composited as the
    CPU renderer does (on an axis-aligned orthographic view: the same samples)."""
    path = write_scene(tmp_path, [straight(), straight(z=-0.1) + [0, 0.03, 0]], camera=ORTHO, lights=SUN + "\n" + SKY,
                       render="hair_layers = 1\nlayers = 1")
    gl, cpu = _both(path, pack, Features(flyaways=True))
    bare, _ = _both(path, pack, Features(flyaways=False))
    assert np.abs(gl - bare).mean() > 0.02 * bare.mean()  # the layer is drawn
    assert abs(gl.mean() / cpu.mean() - 1) < 2e-3
    assert np.abs(gl - cpu).mean() < 5e-3 * cpu.mean()


def test_the_flyaway_layers_behind_the_nearest_are_peeled_as_the_cpu_draws_them(tmp_path, pack):
    """``render.hair_layers`` K: the K nearest flyaway strips of each sample, peeled one layer a pass (each beyond the
    previous layer's depth, ``flyaway.frag``'s sample mask) and composited the farthest first, as the CPU's
    ``rasterize_before`` and resolve do. Three yarns whose flyaway strips overlap in depth: each further layer adds
    light on both backends, and the backends agree on what it adds. A layer's strip is shaded at its first sample on
    the strip here, at its first sample in that layer on the CPU: where a pixel's samples split a strip between two
    layers (the edge of a nearer strip) the two differ (measured: the images 0.3 % apart in the mean at K = 2 and 3
    on the standard pack, against 0.03 % at K = 1). Strips at one depth fall into successive layers (ordered by
    curve): three side-by-side yarns, whose hairs each further layer adds as on the CPU. One layer of regular strips:
    the one behind differs per pixel in the same way (``test_the_regular_strips_behind_the_front_ones_…``)."""
    side_by_side = [straight() + [0.0, dy, 0.0] for dy in (-0.045, 0.0, 0.045)]
    for k in (1, 3):
        path = write_scene(tmp_path, side_by_side, camera=ORTHO, lights=SUN, render=f"hair_layers = {k}",
                           name=f"side{k}")
        gl, cpu = _both(path, pack)
        if k == 1:
            one = gl, cpu
    assert abs((gl - one[0]).mean() / (cpu - one[1]).mean() - 1) < 0.05 and (cpu - one[1]).mean() > 1e-3 * cpu.mean()
    curves = [straight(), straight(z=-0.1) + [0, 0.03, 0], straight(z=-0.2) + [0, 0.06, 0]]
    images = {}
    for k in (1, 2, 3):
        path = write_scene(tmp_path, curves, camera=ORTHO, lights=SUN, render=f"hair_layers = {k}\nlayers = 1",
                           name=f"k{k}")
        images[k] = _both(path, pack)
    for k in (2, 3):
        gl, cpu = images[k]
        assert abs(gl.mean() / cpu.mean() - 1) < 6e-3
        assert np.abs(gl - cpu).mean() < 1.2e-2 * cpu.mean()
        added_gl, added_cpu = gl - images[k - 1][0], cpu - images[k - 1][1]
        assert added_cpu.mean() > 1e-3 * cpu.mean() and added_gl.mean() > 1e-3 * gl.mean()
        assert abs(added_gl.mean() / added_cpu.mean() - 1) < 0.15


def test_a_frame_drawn_into_a_framebuffer_is_the_tone_mapped_image(tmp_path, pack):
    """``render(into=…)`` (the viewer's window): the composite pass tone-maps the frame into the framebuffer, nothing
    read back, to within one 8-bit level of ``tonemap`` of the image ``render`` returns, at +1 stop of exposure (the
    shader applies it: some pixels clip); a non-finite pixel raises as the read-back does."""
    path = write_scene(tmp_path, [straight(), straight(z=-0.1) + [0, 0.05, 0]], camera=ORTHO, lights=SUN)
    renderer = gl_renderer.GLRenderer(load_scene(path), {"cotton1": str(pack)})
    ctx, camera = renderer.ctx, scene_camera(renderer.scene)
    target = ctx.texture((camera.width, camera.height), 4, dtype="f1")
    fbo = ctx.framebuffer(color_attachments=[target])
    drawn = renderer.render(into=fbo, exposure=1.0)
    assert drawn.image is None and "resolve" in drawn.timings
    shown = np.frombuffer(fbo.read(components=3), np.uint8).reshape(camera.height, camera.width, 3)[::-1]
    expected = tonemap(renderer.render().image, 1.0)
    assert expected.std() > 5 and (expected == 255).any()  # a picture, some of it clipped by the exposure
    assert np.abs(shown.astype(int) - expected).max() <= 1
    bad = np.full((camera.height, camera.width, 3), 0.5, np.float32)
    bad[3, 4, 1] = np.nan
    with pytest.raises(RuntimeError, match="non-finite"):
        renderer._display_array(bad, fbo, 0.0)
    fbo.release()
    target.release()


def _dense_hairs(pack, folder, coverage=0.9):
    """A copy of ``pack`` whose flyaway textures cover ``coverage`` of every texel (the tangent kept, premultiplied):
    hair strips nearly opaque, so that the order their layers are composited in shows."""
    out = folder / "dense_hairs.h5"
    shutil.copyfile(pack, out)
    with h5py.File(out, "r+") as f:
        for level in f["textures/flyaway"].values():
            texels = level[...]
            length = np.linalg.norm(texels[..., :3], axis=-1, keepdims=True)
            unit = np.where(length > 1e-6, texels[..., :3] / np.maximum(length, 1e-6), [1.0, 0.0, 0.0])
            texels[..., :3], texels[..., 3] = coverage * unit, coverage
            level[...] = texels
    return out


def test_the_flyaway_layers_are_composited_the_farthest_first_as_on_the_cpu(tmp_path, pack):
    """``composite.frag`` lays each flyaway layer over the ones behind it, the K-th nearest first, as the CPU's
    ``resolve`` does. On the packs' sparse hairs the order hardly shows (c₁c₂(L₁ − L₂)), so here the hairs cover 90 %
    of their strips: a red yarn in front of a blue one that lies half a strip aside, their hair strips overlapping
    along the whole yarn (the second hair layer moves the CPU image by 2.5 % at the yarn scale). The backends agree to
    1 % in the mean and at the yarn scale (measured 0.09 % and 0.22 %); composited the nearest first, the GL image
    was 12 % brighter and 18 % off at the yarn scale (measured once by reversing ``_composite``'s loop)."""
    dense = _dense_hairs(pack, tmp_path)
    entries = []
    for name, curve, colour in (("front", straight(), "[1.0, 0.15, 0.1]"),
                                ("back", straight(z=-0.1) + [0.0, 0.05, 0.0], "[0.1, 0.3, 1.0]")):
        offsets = np.array([0, len(curve)], np.int64)
        write_yarn_curves(tmp_path / f"{name}.h5", make_yarn_curves(curve[None], offsets, yarn_types=["cotton1"],
                                                                    units="cm"))
        entries.append(f'[[yarns]]\ncurves = "{name}.h5"\nyarn = "cotton1"\ncolor = {colour}')
    path = tmp_path / "two_depths.toml"
    path.write_text('format = "knit-scene"\nversion = "1.0"\nunits = "cm"\n' + "\n".join(entries) +
                    f"\n{ORTHO}\n{SUN}\n[render]\nmsaa = 4\nshadow_map_size = 256\nlayers = 1\nhair_layers = 2\n")
    gl, cpu = _both(path, dense)
    one = tmp_path / "one_layer.toml"
    one.write_text(path.read_text().replace("hair_layers = 2", "hair_layers = 1"))
    one_cpu = _both(one, dense)[1]
    assert _yarn_l1(one_cpu, cpu) > 1e-2  # the second layer of hair strips shows
    assert abs(gl.mean() / cpu.mean() - 1) < 1e-2
    assert _yarn_l1(gl, cpu) < 1e-2


def test_the_regular_strips_behind_the_front_ones_are_peeled_as_the_cpu_draws_them(tmp_path, pack):
    """``render.layers`` = 2 (the default): at each sample a front strip covers, the nearest strip more than its radius
    behind it (``regular.frag``'s ``behind`` pass: a sample mask against the front pass's floors), shown through the
    front strip's partial coverage by SHADING.md §6's resolve, as the CPU's ``rasterize_behind`` and
    ``resolve_behind`` draw it. Three stacked yarns crossing a fourth, seen from above: the layer behind adds light
    on both backends (6 % of the image on the standard pack), the GL's to 5 % of the CPU's (measured 1 %), and the
    images agree to 1 % in the mean and at the yarn scale (measured 0.05 % and 0.36 %; per pixel 0.7 %: at the front
    strips' edges the GL shades a strip behind at its first sample on the strip, the CPU at its first sample behind
    the front)."""
    curves = [straight(), straight(z=-0.06) + [0, 0.02, 0], straight(z=-0.12) + [0, -0.02, 0],
              straight(z=-0.09) @ ALONG_Y.T]
    images = {}
    for layers in (1, 2):
        path = write_scene(tmp_path, curves, camera=ORTHO, lights=SUN, render=f"layers = {layers}", name=f"l{layers}")
        images[layers] = _both(path, pack)
    (gl, cpu), (gl1, cpu1) = images[2], images[1]
    added_gl, added_cpu = gl - gl1, cpu - cpu1
    assert added_cpu.mean() > 5e-3 * cpu.mean() and abs(added_gl.mean() / added_cpu.mean() - 1) < 0.05
    assert abs(gl.mean() / cpu.mean() - 1) < 1e-2 and _yarn_l1(gl, cpu) < 1e-2
    assert _yarn_l1(gl, gl1) > 3 * _yarn_l1(gl, cpu)


def _term_follows_the_cpu(path, pack, without):
    """What the default model adds over ``without`` (Features) on both backends: the CPU's adds at least 1 % of the
    image, the GL's is nowhere negative and agrees with it to 2 % in the mean and 6 % per pixel; the images agree to
    0.5 % per pixel."""
    gl, cpu = _both(path, pack)
    plain, plain_cpu = _both(path, pack, without)
    added_gl, added_cpu = gl - plain, cpu - plain_cpu
    assert added_cpu.mean() > 0.01 * plain_cpu.mean() and added_gl.min() >= -1e-7
    assert abs(added_gl.mean() / added_cpu.mean() - 1) < 2e-2
    assert np.abs(added_gl - added_cpu).mean() < 6e-2 * np.abs(added_cpu).mean()
    assert np.abs(gl - cpu).mean() < 5e-3 * cpu.mean()


def test_the_bodys_glow_on_its_hairs_follows_the_cpu_renderer(tmp_path, pack):
    """``Features.hair_glow`` (the default) on the flyaway layer under the sun: GLSL ``body_glow`` adds what the CPU's
    adds (2 % of this image), to 2 % in the mean and 6 % per pixel (the backends' shadow lookups differ on hairs whose
    own single scattering is dim and hides it without the glow); a 5 % edit of the glow in the shader fails it."""
    _term_follows_the_cpu(write_scene(tmp_path, [straight()], camera=ORTHO, lights=SUN, name="glow"), pack,
                          Features(hair_glow=False))


def test_the_neighbours_light_on_the_hairs_follows_the_cpu_renderer(tmp_path, pack):
    """``Features.hair_bounce`` (the default) on three side-by-side yarns with their flyaways under the sun: GLSL
    reads the neighbours' light arriving at the polyline points (``pipeline.frame_bounce``, a second texture) along
    the hair's segment and adds what the CPU's ``strip_shading.hair_bounce`` adds, to 2 % in the mean and 6 % per
    pixel. One flyaway layer: the images' per-pixel check is then the term's; where the yarns' flyaway strips overlap,
    further layers differ per pixel in their own way (``test_the_flyaway_layers_behind_the_nearest_are_peeled_…``)."""
    side_by_side = [straight() + [0.0, dy, 0.0] for dy in (-0.045, 0.0, 0.045)]
    _term_follows_the_cpu(write_scene(tmp_path, side_by_side, camera=ORTHO, lights=SUN, name="hair_bounce",
                                      render="hair_layers = 1"), pack, Features(hair_bounce=False))


def test_the_hairs_behind_the_body_follow_the_cpu_renderer(tmp_path, pack):
    """``Features.hairs_behind`` (the default) on the flyaway layer lit from behind the yarn: the GLSL share of the
    hairs behind the body (read from the regular coverage texture) adds what the CPU's adds, to 2 % in the mean and
    6 % per pixel, and nothing gets darker; scaling the GLSL share by 0.9 fails it."""
    _term_follows_the_cpu(write_scene(tmp_path, [straight()], camera=ORTHO, lights=BACKLIT, name="behind"), pack,
                          Features(hairs_behind=False))


def test_the_hair_canopy_follows_the_cpu_renderer(tmp_path, pack, monkeypatch):
    """``Features.hair_canopy`` (the default): both backends take the canopy at the polyline points from ``pipeline.
    canopy_at_vertices`` (the canopy itself is the CPU tests', ``tests/test_hair_canopy.py``) and read it where they
    take a light's visibility, interpolated along the curves by rest arc length. The tiny pack's hair layer keeps
    too little off to compare (0.15 % of this image), so the points carry a canopy that runs 0.3 → 1 along each
    curve and differs between the yarns: what it takes off the regular and flyaway layers and the bounce agrees
    with the CPU's to 2 % in the mean and 6 % per pixel, and nothing gets brighter. (Its texture once sat on
    moderngl's scratch unit, which every texture created after it rebinds: the GL took 11.6 % off a scene where the
    CPU took 0.43 %.)"""
    def canopy(lines, looks, direction):
        along = (lines.rest - lines.rest.min()) / np.ptp(lines.rest)
        curve = np.repeat(np.arange(len(lines.offsets) - 1), np.diff(lines.offsets))
        return np.where(curve % 2 == 0, 0.3 + 0.7 * along, 1.0 - 0.5 * along)

    monkeypatch.setattr(pipeline, "canopy_at_vertices", canopy)
    path = write_scene(tmp_path, [straight(), straight(z=-0.1) + [0, 0.03, 0], straight(z=0.07) @ ALONG_Y.T],
                       camera=ORTHO, lights=SUN, name="canopy")
    gl, cpu = _both(path, pack)
    plain, plain_cpu = _both(path, pack, Features(hair_canopy=False))
    taken_gl, taken_cpu = plain - gl, plain_cpu - cpu
    assert taken_cpu.mean() > 0.1 * plain_cpu.mean() and taken_gl.min() >= -1e-7
    assert abs(taken_gl.mean() / taken_cpu.mean() - 1) < 2e-2
    assert np.abs(taken_gl - taken_cpu).mean() < 6e-2 * np.abs(taken_cpu).mean()


def test_the_canopy_and_the_bounces_light_are_kept_while_the_frame_and_the_lights_stay(tmp_path, pack, monkeypatch):
    """A viewer's orbit about a still frame reuses the hair canopy and the lights' visibility at the bounce's points
    (with the light atlas's read-back): both depend on the curves and the lights alone. Another camera draws without
    computing either again, and the same image as a renderer that computes them afresh; a turned light computes both
    again."""
    calls, reads = [], []
    original = pipeline.canopy_at_vertices
    monkeypatch.setattr(pipeline, "canopy_at_vertices", lambda *args: calls.append(args[2]) or original(*args))
    read = gl_renderer.GLRenderer._read_light_maps
    monkeypatch.setattr(gl_renderer.GLRenderer, "_read_light_maps",
                        lambda self, *args: reads.append(self.light_dir.copy()) or read(self, *args))
    path = write_scene(tmp_path, [straight(), straight(z=-0.1) + [0, 0.03, 0]], camera=FRONT, lights=SUN, name="c")
    scene = load_scene(path)
    renderer = gl_renderer.GLRenderer(scene, {"cotton1": str(pack)})
    renderer.render()
    assert len(calls) == 1 and len(reads) == 1
    turned = dataclasses.replace(scene_camera(scene), position=np.array([0.2, -0.3, 1.0]))
    kept = renderer.render(camera=turned)
    assert len(calls) == 1 and len(reads) == 1
    fresh = gl_renderer.GLRenderer(scene, {"cotton1": str(pack)}).render(camera=turned)
    assert len(calls) == 2 and len(reads) == 2 and np.array_equal(kept.image, fresh.image)
    assert kept.facts["yarn_bounce"] == fresh.facts["yarn_bounce"] and kept.facts["yarn_bounce"]["radiance"][0] > 0
    renderer.light_dir = renderer.light_dir @ ALONG_Y.T
    renderer.render(camera=turned)
    assert len(calls) == 3 and np.allclose(calls[-1], renderer.light_dir[0])
    assert len(reads) == 3 and np.allclose(reads[-1], renderer.light_dir)


def test_the_frames_polylines_and_vertex_arrays_are_kept_while_the_frame_stays(tmp_path, pack, monkeypatch):
    """The polylines, the segments' vertex arrays and the polyline textures depend on the frame alone: an orbit draws
    without building them again, to the image of a renderer that builds them afresh; another frame builds its own
    (and draws what a fresh renderer draws of it)."""
    built = []
    original = gl_renderer.GLRenderer._frame_geometry
    monkeypatch.setattr(gl_renderer.GLRenderer, "_frame_geometry",
                        lambda self, frame: built.append((self, frame)) or original(self, frame))
    path = write_scene(tmp_path, [straight()], camera=FRONT, lights=SUN, name="f")
    curve = straight()
    frames = np.stack([curve, curve + [0.0, 0.04, 0.0]])  # frame 1: the yarn moved up
    write_yarn_curves(tmp_path / "f.h5", make_yarn_curves(frames, np.array([0, len(curve)], np.int64),
                                                          yarn_types=["cotton1"], units="cm"))
    scene = load_scene(path)
    renderer = gl_renderer.GLRenderer(scene, {"cotton1": str(pack)})
    renderer.render(0)
    turned = dataclasses.replace(scene_camera(scene), position=np.array([0.2, -0.3, 1.0]))
    kept = renderer.render(0, camera=turned)
    assert [frame for who, frame in built if who is renderer] == [0]
    assert np.array_equal(kept.image, gl_renderer.GLRenderer(scene, {"cotton1": str(pack)}).render(0, camera=turned)
                          .image)
    moved = renderer.render(1, camera=turned)
    assert [frame for who, frame in built if who is renderer] == [0, 1]
    assert np.array_equal(moved.image, gl_renderer.GLRenderer(scene, {"cotton1": str(pack)}).render(1, camera=turned)
                          .image)
    assert not np.array_equal(moved.image, kept.image)


def test_the_kept_targets_carry_nothing_from_one_frame_to_the_next(tmp_path, pack):
    """The passes' targets are kept on the context between frames of one size (``GLRenderer._target``), shared by its
    renderers: a scene drawn on the targets another scene (more yarns, more layers, the sky) drew into first is the
    image it draws on targets made afresh (``release_targets``), bit for bit. Dense hairs (``_dense_hairs``), so that
    every hair layer draws: with the hair layers' colour targets left uncleared between frames (their depth cleared)
    it fails (measured once)."""
    dense = _dense_hairs(pack, tmp_path)
    busy = write_scene(tmp_path, [straight(), straight(z=-0.1) + [0, 0.03, 0], straight(z=0.05) @ ALONG_Y.T],
                       camera=ORTHO, lights=SUN + "\n" + SKY, render="hair_layers = 4", name="busy")
    plain = write_scene(tmp_path, [straight() + [0, -0.08, 0]], camera=ORTHO, lights=SUN, render="layers = 1",
                        name="plain")
    busy_renderer = gl_renderer.GLRenderer(load_scene(busy), {"cotton1": str(dense)})
    renderer = gl_renderer.GLRenderer(load_scene(plain), {"cotton1": str(dense)})
    gl_renderer.release_targets(renderer.ctx)
    fresh = renderer.render().image
    assert np.abs(fresh - fresh[0, 0]).max() > 0.1  # the yarn shows
    busy_renderer.render()
    assert np.array_equal(renderer.render().image, fresh)
    assert len(renderer.ctx._knit_targets[1]) > 10  # the busy scene's targets were there to reuse


def test_a_released_renderer_holds_no_gl_objects(tmp_path, pack, monkeypatch):
    """Every texture, buffer, vertex array, renderbuffer and framebuffer a renderer makes over its set-up and two
    frames (a new frame, then the kept one) is released by ``GLRenderer.release`` (or at the end of ``with``; the
    one-shot ``render`` uses it), but for the context's kept targets (``release_targets``); a released renderer
    refuses to draw in one line. Without ``release`` 23 objects a renderer were left (measured: 19 textures of the
    yarn entry, the sky's cluster weights, the frame's arrays)."""
    ctx, made = gl_renderer.gl_context(), []
    for name in ("texture", "texture3d", "texture_array", "depth_texture", "buffer", "vertex_array",
                 "simple_vertex_array", "renderbuffer", "depth_renderbuffer", "framebuffer"):
        def making(*args, _make=getattr(ctx, name), **kwargs):
            made.append(_make(*args, **kwargs))
            return made[-1]
        monkeypatch.setattr(ctx, name, making)
    path = write_scene(tmp_path, [straight(), straight(z=-0.1) + [0, 0.03, 0]], camera=ORTHO,
                       lights=SUN + "\n" + SKY, name="released")
    with gl_renderer.GLRenderer(load_scene(path), {"cotton1": str(pack)}) as renderer:
        renderer.render()
        renderer.render(frame=0)
        assert any(type(o.mglo).__name__ != "InvalidObject" for o in made)
    gl_renderer.render(load_scene(path), {"cotton1": str(pack)})
    kept = {id(o) for o in ctx._knit_targets[1].values()}
    assert len(made) > 50
    assert [o for o in made if type(o.mglo).__name__ != "InvalidObject" and id(o) not in kept] == []
    with pytest.raises(RuntimeError, match="released") as e:
        renderer.render()
    assert "\n" not in str(e.value)


def test_what_the_backend_cannot_draw_is_refused_in_one_line(tmp_path, pack):
    many = "\n".join(SUN for _ in range(gl_renderer.MAX_LIGHTS + 1))
    with pytest.raises(FormatError, match="directional lights") as e:
        gl_renderer.GLRenderer(load_scene(write_scene(tmp_path, [straight()], camera=FRONT, lights=many, name="m")),
                               {"cotton1": str(pack)})
    assert "\n" not in str(e.value)
    one = load_scene(write_scene(tmp_path, [straight()], camera=FRONT, lights=SUN, name="one"))
    for features, says in [(Features(multiple_scattering=False), "single scattering"),
                           (Features(hair_light=False), "hair_light")]:
        with pytest.raises(FormatError, match=says) as e:
            gl_renderer.GLRenderer(one, {"cotton1": str(pack)}, features)
        assert "\n" not in str(e.value)


def test_a_machine_without_egl_gets_a_one_line_reason(monkeypatch):
    import moderngl

    def no_egl(**kw):
        raise Exception("libEGL.so.1: cannot open shared object file: No such file or directory\nmore detail")

    monkeypatch.setattr(gl_renderer, "_CONTEXT", [])
    monkeypatch.setattr(moderngl, "create_context", no_egl)
    with pytest.raises(gl_renderer.GLUnavailable) as e:
        gl_renderer.gl_context()
    message = str(e.value)
    assert "\n" not in message and "libEGL.so.1" in message and "libegl1" in message


def test_the_command_line_renders_with_the_gl_backend(tmp_path, pack):
    from cli.knitrun_cli import main

    path = write_scene(tmp_path, [straight()], camera=FRONT, lights=SUN)
    out = tmp_path / "gl.png"
    result = CliRunner().invoke(main, ["render", str(path), "--pack", f"cotton1={pack}", "-o", str(out), "--backend",
                                       "gl", "--json"])
    assert result.exit_code == 0, result.output
    summary = json.loads(result.stdout)
    assert summary["backend"] == "gl" and out.is_file() and summary["mean_rgb"][0] > 0
    assert "GL_RENDERER" not in summary and summary["gl_renderer"]
    frames = CliRunner().invoke(main, ["render", str(path), "--pack", f"cotton1={pack}", "-o",
                                       str(tmp_path / "f_#.png"), "--backend", "gl", "--ablation", "papers_xi",
                                       "--frames", "0:1", "--json"])
    assert frames.exit_code == 0, frames.output
    assert (tmp_path / "f_0.png").is_file() and json.loads(frames.stdout)["frames"] == [0, 1]

