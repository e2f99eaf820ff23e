"""Yarn-level light transport: the visibility transform's limits and fixed point, the baked hull albedo ρ_Y and
transmittance T_Y against the white furnace, the fiber count T_Y gives, and what the renderer does with a pack that
has no ρ_Y (schema < 2.1) or no T_Y (schema < 2.2)."""

import dataclasses
import math
import shutil

import h5py
import numpy as np
import pytest

from data_formats.asset_pack import read_pack
from data_formats.conventions import LUMINANCE
from data_formats.scene import load_scene
from data_formats.yarn_spec import load_preset
from knitbake.stages.yarn_hull import (BY_COLOUR, TABLE, TRANSMITTANCE_TABLE, bake_yarn_hull, colour_scales,
                                       hemisphere_env, hull_radiance)
from knitrun.render.ablations import Features
from knitrun.render.interreflection import channel_visibility, interreflected_visibility
from knitrun.render.pipeline import Renderer
from knitrun.render.yarn_look import gap_transmittance, hull_colour, load_look
from knitrun.shading.dual_scattering import transmittance_count
from knitrun.shading.table_lookup import lookup_theta
from tests.helpers import FRONT, OVERHEAD_SUN, SIDE, SKY, SUN, straight, write_scene
from tests.test_render import _render


def test_visibility_limits_and_fixed_point():
    v = np.linspace(0.0, 1.0, 11)
    np.testing.assert_allclose(interreflected_visibility(v, 0.0), v)  # nothing sent on: the shadow map's V
    np.testing.assert_allclose(interreflected_visibility(v, 1.0), 1.0)  # lossless yarns: the white furnace
    for rho in (0.3, 0.75, 0.95):
        w = interreflected_visibility(v, rho)
        assert np.all((w >= v - 1e-15) & (w <= 1.0)) and np.all(np.diff(w) > 0)
        # the receiver's incoming radiance V·L + (1 − V)·L_n with L_n = ρ (V L + (1 − V) L_n), L = 1
        neighbour = rho * v / (1 - rho * (1 - v))
        np.testing.assert_allclose(w, v + (1 - v) * neighbour, rtol=1e-12)
        np.testing.assert_allclose(neighbour, rho * w, rtol=1e-12)
    assert np.all(np.isfinite(interreflected_visibility([-1.0, 2.0, 0.0], [2.0, -1.0, 1.0])))


def test_visibility_broadcasts_a_row_down_the_lobes_and_writes_in_place():
    """The renderer's call: every lobe's visibility (L, N) with one albedo per point (1, N), into the visibility
    itself; the same as the formula element by element, whichever input is the row, and a wrong ``out`` refused."""
    rng = np.random.default_rng(5)
    v, rho = rng.uniform(0.0, 1.0, (16, 1000)), rng.uniform(0.0, 1.0, (1, 1000))
    expected = v / (1.0 - rho * (1.0 - v))
    np.testing.assert_allclose(interreflected_visibility(v, rho), expected, rtol=1e-15)
    np.testing.assert_allclose(interreflected_visibility(rho, v), rho / (1.0 - v * (1.0 - rho)), rtol=1e-15)
    column, row = v[:, :1], rho[0, :5]  # a column against a row: the general broadcast
    np.testing.assert_allclose(interreflected_visibility(column, row), column / (1 - row * (1 - column)), rtol=1e-15)
    inplace = v.copy()
    assert interreflected_visibility(inplace, rho, out=inplace) is inplace
    np.testing.assert_allclose(inplace, expected, rtol=1e-15)
    assert interreflected_visibility(np.zeros((16, 0)), np.zeros((1, 0))).shape == (16, 0)  # no points
    with pytest.raises(ValueError, match="out: expected"):
        interreflected_visibility(v, rho, out=np.empty((16, 999)))


def test_each_channel_takes_its_own_albedo_from_the_luminance_visibility():
    """``channel_visibility``: from V' inter-reflected with the luminance ρ, channel c's V'_c is the visibility
    inter-reflected with ρ_c directly; ρ_c = ρ gives V' back, ρ = 0 (no inter-reflection) V itself; ρ = 1 leaves V'
    (1, whatever V was); out-of-range inputs stay finite and in [0, 1]."""
    v = np.linspace(0.0, 1.0, 11)
    for rho, rho_c in ((0.743, 0.785), (0.743, 0.641), (0.3, 0.9), (0.9, 0.0)):
        inter = interreflected_visibility(v, rho)
        got = np.array([channel_visibility(x, rho, rho_c) for x in inter])
        np.testing.assert_allclose(got, interreflected_visibility(v, rho_c), rtol=1e-12, atol=1e-15)
        np.testing.assert_allclose([channel_visibility(x, rho, rho) for x in inter], inter, rtol=0, atol=0)
    np.testing.assert_allclose([channel_visibility(x, 0.0, 0.0) for x in v], v)
    assert channel_visibility(1.0, 1.0, 0.5) == 1.0
    odd = [channel_visibility(a, b, c) for a in (-1.0, 0.5, 2.0) for b in (-0.5, 0.5, 1.5) for c in (-0.5, 0.5, 1.5)]
    assert np.all(np.isfinite(odd)) and min(odd) >= 0.0 and max(odd) <= 1.0


def test_the_skys_light_between_yarns_takes_each_channels_albedo(tmp_path, pack):
    """Under the sky, the light the neighbours pass on takes the yarn's colour once per bounce: a crossing drawn with
    its hull albedo ρ_Y (per channel, in the entry's colour) against the same yarn with a grey ρ_Y of the same
    luminance (the model until stop 61) is brighter in the channel whose ρ_Y is above the luminance and darker in
    the one below it; a grey ρ_Y changes nothing against the luminance's own, and the shadows' inter-reflection
    switched off takes the colour dependence with it."""
    crossing = [straight(z=0.0), straight(z=0.12)[:, [1, 0, 2]]]
    scene = load_scene(write_scene(tmp_path, crossing, camera=FRONT, lights=SKY, name="crossing"))
    packs = {"cotton1": str(pack)}

    def draw(albedo=None, features=Features()):
        renderer = Renderer(scene, packs, features)
        if albedo is not None:
            renderer.looks = [dataclasses.replace(look, hull_albedo=np.asarray(albedo(look), np.float64))
                              for look in renderer.looks]
        return renderer.render().image.astype(np.float64)

    coloured = lambda look: np.array([1.15, 1.0, 0.8]) * look.yarn_albedo / (np.array([1.15, 1.0, 0.8]) @ LUMINANCE)
    grey = lambda look: np.full(3, look.yarn_albedo)
    warm, flat = draw(coloured), draw(grey)
    ratio = warm.sum(axis=(0, 1)) / flat.sum(axis=(0, 1))
    assert ratio[0] > 1.002 and ratio[2] < 0.998, ratio
    assert np.all(warm.sum(axis=(0, 1)) > 0.0)
    off = Features(interreflection=False)
    np.testing.assert_array_equal(draw(coloured, off), draw(grey, off))


def _lossless(spec):
    optics = dataclasses.replace(spec.optics, d_color=(0.0, 0.0, 0.0),
                                 tt_color=tuple(1.0 - c for c in spec.optics.r_color))
    return dataclasses.replace(spec, optics=optics)


def test_yarn_albedo_is_one_for_lossless_fibers_and_below_the_fiber_albedo_otherwise():
    """White furnace of the bake: with non-absorbing fibers every path leaves the tube, ρ_Y = 1 (within its standard
    error: Russian roulette is unbiased). Cotton's fibers absorb 5–10 % per event and its dense yarn (225 fibers)
    scatters most paths several times, so ρ_Y lies clearly below the fiber albedo, with a finite, positive error;
    its transmittance T_Y, the part of ρ_Y that leaves on the far side, lies below ρ_Y and well above what
    evenly spread fibers would pass (ā_f^{n_cross} ≈ 0.06)."""
    cotton = load_preset("cotton1")
    settings = {"n_views": 3, "rows": 8, "spp": 2, "batches": 2}
    tables, errors = bake_yarn_hull(_lossless(cotton), seed=3, **settings)
    assert np.all(np.abs(tables[TABLE] - 1.0) < 4 * errors[TABLE] + 0.01), (tables[TABLE], errors[TABLE])
    tables, errors = bake_yarn_hull(cotton, seed=3, **settings)
    fiber = np.add(cotton.optics.r_color, cotton.optics.tt_color) + cotton.optics.d_color
    assert np.all((tables[TABLE] > 0.3) & (tables[TABLE] < fiber - 0.05)), (tables[TABLE], fiber)
    t = tables[TRANSMITTANCE_TABLE]
    assert np.all((t > 0.2) & (t < tables[TABLE] - 0.1)), (t, tables[TABLE])
    for name in (TABLE, TRANSMITTANCE_TABLE):
        assert np.all(np.isfinite(errors[name]) & (errors[name] > 0))
    with pytest.raises(ValueError, match="batches = 1"):
        bake_yarn_hull(cotton, batches=1)


def _coloured(spec, colour):
    optics = spec.optics
    optics = dataclasses.replace(optics, **{name: tuple(np.multiply(getattr(optics, name), colour))
                                            for name in ("r_color", "tt_color", "d_color")})
    return dataclasses.replace(spec, optics=optics)


def test_hull_against_the_colour_is_the_coloured_yarns_own():
    """ρ_Y and T_Y against the colour scale k of the lobe albedos: the row at k = 1 is the white yarn's tables; at
    k = 0 no path scatters, so both are the light crossing between the fibers, alike in every channel and equal;
    both grow with k (common random numbers), T_Y ≤ ρ_Y. Read per channel at a colour, they are that coloured yarn's
    own bake within the errors and the interpolation's 1 %, where the white yarn's times the colour is far off in the
    dark channels (the gaps keep their colour). A count of samples that misses k = 0 or 1 is refused."""
    cotton = load_preset("cotton1")
    settings = {"n_views": 3, "rows": 8, "spp": 2, "batches": 2}
    tables, errors = bake_yarn_hull(cotton, seed=3, **settings)
    rho, t = tables[BY_COLOUR[TABLE]], tables[BY_COLOUR[TRANSMITTANCE_TABLE]]
    assert rho.shape == t.shape == (17, 3) and colour_scales(17)[[0, -1]].tolist() == [0.0, 1.0]
    np.testing.assert_array_equal(rho[-1], tables[TABLE])
    np.testing.assert_array_equal(t[-1], tables[TRANSMITTANCE_TABLE])
    np.testing.assert_allclose(rho[0], t[0], rtol=1e-12)
    np.testing.assert_allclose(rho[0], rho[0, 0], rtol=1e-12)
    assert 0.05 < rho[0, 0] < 0.4
    slack = 3 * errors[BY_COLOUR[TABLE]]
    assert np.all(np.diff(rho, axis=0) > -slack[1:]) and np.all(t <= rho + slack)
    red = np.array([0.9, 0.25, 0.2])
    own, own_err = bake_yarn_hull(_coloured(cotton, red), seed=3, n_colours=0, **settings)
    assert BY_COLOUR[TABLE] not in own
    for name in (TABLE, TRANSMITTANCE_TABLE):
        curve = tables[BY_COLOUR[name]]
        read = np.array([np.interp(red[c], colour_scales(17), curve[:, c]) for c in range(3)])
        np.testing.assert_allclose(read, own[name], rtol=0.02, atol=4 * float(np.max(own_err[name])))
        assert np.all(np.abs(tables[name] * red - own[name])[1:] > 0.15 * own[name][1:])  # first order: off
    with pytest.raises(ValueError, match="n_colours = 9"):
        bake_yarn_hull(cotton, n_colours=9, **settings)


def test_transmittance_and_reflectance_of_a_lossless_yarn_add_up_to_one():
    """The two hemispheres split the uniform environment: T_Y (radiance 1 behind the yarn) + R_Y (on the camera's
    side) = ρ_Y, and = 1 for non-absorbing fibers (every path leaves the tube on one side or the other), within the
    standard errors. A hemisphere switched the wrong way round, or a map that lights less than half the sphere,
    fails."""
    lossless = _lossless(load_preset("cotton1"))
    settings = {"n_views": 3, "rows": 8, "spp": 4, "batches": 3}
    far = hull_radiance(lossless, lambda wo: hemisphere_env(wo, far=True), seed=5, **settings)
    near = hull_radiance(lossless, lambda wo: hemisphere_env(wo, far=False), seed=5, **settings)
    total = far.mean(axis=0) + near.mean(axis=0)
    error = (far.std(axis=0, ddof=1) + near.std(axis=0, ddof=1)) / math.sqrt(3)
    assert np.all(np.abs(total - 1.0) < 4 * error + 0.02), (total, error)
    assert np.all(far.mean(axis=0) > 0.3) and np.all(near.mean(axis=0) > 0.1)  # both sides carry light


def test_transmittance_count_limits():
    """n_T = ln T_Y / ln ā_f: the count that passes T_Y; none for a clear yarn; the geometric count at most."""
    a = np.array([0.7, 0.69, 0.67])
    for n in (0.5, 2.0, 5.0):
        assert transmittance_count(a ** n, a, 7.7) == pytest.approx(n, rel=1e-12)
    assert transmittance_count([1.0, 1.0, 1.0], a, 7.7) == 0.0
    assert transmittance_count([0.0, 0.0, 0.0], a, 7.7) == pytest.approx(7.7, rel=1e-12)
    geometric = pytest.approx(7.7, rel=1e-12)
    assert transmittance_count(a ** 20, a, 7.7) == geometric  # darker than evenly spread fibers: clipped
    assert transmittance_count([0.5, 0.5, 0.5], [1.0, 1.0, 1.0], 7.7) == geometric  # no count passes 0.5


def test_transmittance_count_with_gaps_passes_the_scattered_rest():
    """With a gap transmittance τ the count is that of the scattered rest, τ + (1 − τ) ā_f^{n_T} = T_Y; τ = 0 is the
    plain count; a yarn whose gaps pass all of T_Y or more (nothing left to scatter) gets the geometric count; τ
    outside [0, 1) is refused."""
    a = np.array([0.7, 0.69, 0.67])
    for gap in (0.1, 0.16, 0.3):
        for n in (0.5, 2.0, 5.0):
            transmittance = gap + (1.0 - gap) * a ** n
            assert transmittance_count(transmittance, a, 7.7, gap) == pytest.approx(n, rel=1e-12)
    assert transmittance_count(a ** 2, a, 7.7, 0.0) == transmittance_count(a ** 2, a, 7.7)
    assert transmittance_count([0.2, 0.2, 0.2], a, 7.7, 0.25) == pytest.approx(7.7, rel=1e-12)
    for bad in (-0.1, 1.0):
        with pytest.raises(ValueError, match="gap transmittance"):
            transmittance_count(a, a, 7.7, bad)


def test_gap_transmittance_is_what_the_coverage_texture_leaves_uncovered(tmp_path, pack):
    """τ_Y = 1 − the coverage texture's mean; the session's pack has gaps (0 < τ_Y < T_Y), and its look carries both
    counts: n_cross passes all of T_Y (the environment's cells), n_cross_rest the rest once τ_Y is split out,
    τ_Y + (1 − τ_Y) ā_f^{n_cross_rest} = T_Y (directional lights and hairs; luminance-weighted counts)."""
    assert gap_transmittance([np.array([[1.0, 0.5], [0.0, 0.5]])]) == pytest.approx(0.5)
    assert gap_transmittance([np.ones((2, 2))]) == 0.0
    assert gap_transmittance([np.zeros((2, 2))]) < 1.0
    entry = load_scene(write_scene(tmp_path, [straight()], camera=FRONT, lights=SUN)).yarns[0]
    look = load_look(pack, entry, "cm")
    data = read_pack(pack)
    coverage_mean = float(np.mean(data.mip_chain("textures/coverage")[0]))
    assert look.gap == pytest.approx(1.0 - coverage_mean, rel=1e-12) and 0.0 < look.gap
    t_y = np.asarray(data.tables[TRANSMITTANCE_TABLE], np.float64)
    assert look.gap < float(t_y @ LUMINANCE)
    a_f0 = lookup_theta(data.tables["dual_scattering/a_f"], 0.0)
    assert look.n_cross_rest == pytest.approx(transmittance_count(t_y, a_f0, 1e9, look.gap), rel=1e-9)
    assert look.n_cross == pytest.approx(transmittance_count(t_y, a_f0, 1e9), rel=1e-9)
    assert look.n_cross_rest > look.n_cross  # less left to pass once the gaps are split out
    assert "between the fibers" in look.n_cross_from


def test_a_coloured_entry_reads_its_hull_off_the_curves_and_a_pack_without_them_tints(tmp_path, pack):
    """A red entry's ρ_Y and T_Y are the pack's curves read per channel at its colour (a white entry's the pack's
    tables, exactly); a schema-2.5 pack (no curves) gives the white yarn's times the colour; ``hull_from`` says
    which, and the luminance the environment's inter-reflection uses follows."""
    red = (0.9, 0.25, 0.2)
    entry = load_scene(write_scene(tmp_path, [straight()], camera=FRONT, lights=SUN)).yarns[0]
    data = read_pack(pack)
    white = load_look(pack, entry, "cm")
    np.testing.assert_array_equal(white.hull_albedo, data.tables[TABLE])
    np.testing.assert_array_equal(white.hull_transmittance, data.tables[TRANSMITTANCE_TABLE])
    look = load_look(pack, dataclasses.replace(entry, color=red), "cm")
    assert look.hull_from == "the pack's curves against the colour"
    for name, value in ((TABLE, look.hull_albedo), (TRANSMITTANCE_TABLE, look.hull_transmittance)):
        curve = np.asarray(data.tables[BY_COLOUR[name]], np.float64)
        np.testing.assert_allclose(value, [np.interp(red[c], colour_scales(17), curve[:, c]) for c in range(3)],
                                   rtol=1e-12)
        np.testing.assert_allclose(hull_colour(data, name, red), value, rtol=1e-12)
    assert look.yarn_albedo == pytest.approx(float(look.hull_albedo @ LUMINANCE), rel=1e-12)
    old = tmp_path / "old.h5"
    shutil.copy(pack, old)
    with h5py.File(old, "a") as f:
        for name in BY_COLOUR.values():
            del f[name], f[name + "_stderr"]
        f.attrs["schema_version"] = "2.5"
    tinted = load_look(old, dataclasses.replace(entry, color=red), "cm")
    assert "times the colour" in tinted.hull_from
    np.testing.assert_allclose(tinted.hull_albedo, data.tables[TABLE] * np.array(red), rtol=1e-6)
    np.testing.assert_allclose(tinted.hull_transmittance, data.tables[TRANSMITTANCE_TABLE] * np.array(red), rtol=1e-6)


def test_a_yarn_in_another_yarns_shadow_gets_the_light_the_yarn_lets_through(tmp_path, pack):
    """Two crossing yarns under the sun, the far one partly in the near one's shadow: with the pack's T_Y the fiber
    count for the crossing is the one that passes T_Y (facts say so), and the image is brighter where light crosses
    the near yarn, never darker; a schema-2.1 pack (no T_Y) and the switched-off term give the geometric count."""
    old = tmp_path / "old.h5"
    shutil.copy(pack, old)
    with h5py.File(old, "a") as f:
        del f[TRANSMITTANCE_TABLE], f[TRANSMITTANCE_TABLE + "_stderr"]
        f.attrs["schema_version"] = "2.1"
    crossing = [straight(z=0.0), straight(z=0.12)[:, [1, 0, 2]]]
    scene = write_scene(tmp_path, crossing, camera=FRONT, lights=SUN, name="crossing")
    without = _render(scene, old)
    assert without.facts["n_cross"]["cotton1"].startswith("geometry (no transmittance")
    switched_off = _render(scene, pack, features=Features(interreflection=False))
    assert switched_off.facts["n_cross"]["cotton1"].startswith("geometry (switched off")
    np.testing.assert_array_equal(without.image, switched_off.image)
    with_term = _render(scene, pack)
    assert with_term.facts["n_cross"]["cotton1"].startswith("transmittance")
    assert np.all(with_term.image >= without.image - 1e-6) and with_term.image.mean() > without.image.mean()


def test_two_blocking_yarns_let_less_light_between_their_fibers_than_one(tmp_path, pack):
    """Three yarns stacked under an overhead sun, seen from the side: counting two blockers
    (``Features.two_blockers``, the default) leaves the top yarn (none) and the middle one (one blocker) as they were
    and darkens only the bottom one, behind two yarns (τ_Y² instead of τ_Y, two crossings of the scattered rest); the
    facts say how much of the image lies behind one and behind two. Without the yarn-level bounce (``no_bounce``):
    the middle yarn also gets the light the bottom one scatters, which two blockers darken."""
    stack = [straight(z=z) for z in (0.24, 0.12, 0.0)]
    scene = write_scene(tmp_path, stack, camera=SIDE, lights=OVERHEAD_SUN, name="stack")
    one = _render(scene, pack, features=Features(two_blockers=False, yarn_bounce=False))
    two = _render(scene, pack, features=Features(yarn_bounce=False))
    assert "two_blockers" not in one.facts
    assert two.facts["two_blockers"]["behind_two_yarns"] > 0.05 and two.facts["two_blockers"]["behind_one_yarn"] > 0.05
    change = np.abs(two.image - one.image).max(axis=(1, 2))
    rows = np.flatnonzero(change > 1e-6)
    assert rows.size and rows.min() >= 0.55 * len(change), rows  # the bottom yarn's rows (row 0 is the top)
    assert np.all(two.image <= one.image + 1e-6) and two.image.mean() < one.image.mean()


def test_a_lone_straight_yarn_has_no_second_blocker(tmp_path, pack):
    """One straight yarn lit from low along its length, as the closure's views light the bake's yarn
    (``closure.render_bins`` draws them with one blocker counted, for speed): no second yarn layer lies between any
    of its points and the light, so counting two blockers leaves its image bit for bit."""
    low = """[[lights]]
type = "directional"
direction = [1.0, 0.25, 0.2]
irradiance = [2.0, 2.0, 2.0]"""
    scene = write_scene(tmp_path, [straight()], camera=FRONT, lights=low, name="lone")
    one = _render(scene, pack, features=Features(two_blockers=False))
    two = _render(scene, pack)
    assert two.facts["two_blockers"]["behind_two_yarns"] == 0.0 and one.image.max() > 0.0
    np.testing.assert_array_equal(one.image, two.image)


def test_renderer_reports_and_skips_inter_reflection_for_a_pack_without_yarn_albedo(tmp_path, pack):
    """A schema-2.0 pack (no ``/interreflection/albedo``) renders as before the term existed, and says so; with the
    table, blocked sky light comes back and the image is brighter; without the fiber-level detail (whose environment
    channel ρ_Y softens too, moving light between a row's texels: ``yarn_look.fiber_detail``) never darker."""
    old = tmp_path / "old.h5"
    shutil.copy(pack, old)
    with h5py.File(old, "a") as f:
        for name in (TABLE, TRANSMITTANCE_TABLE):
            del f[name], f[name + "_stderr"]
        f.attrs["schema_version"] = "2.0"
    crossing = [straight(z=0.0), straight(z=0.12)[:, [1, 0, 2]]]
    scene = write_scene(tmp_path, crossing, camera=FRONT, lights=SKY, name="crossing")
    without = _render(scene, old)
    assert "absent" in without.facts["interreflection"]["cotton1"]
    switched_off = _render(scene, pack, features=Features(interreflection=False))
    assert switched_off.facts["interreflection"]["cotton1"].startswith("off")
    np.testing.assert_array_equal(without.image, switched_off.image)
    with_term = _render(scene, pack)
    assert 0.0 < with_term.facts["interreflection"]["cotton1"] < 1.0
    assert with_term.image.mean() > without.image.mean()
    flat = Features(fiber_detail=False)
    assert np.all(_render(scene, pack, features=flat).image >= _render(scene, old, features=flat).image - 1e-6)
