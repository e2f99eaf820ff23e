"""Close the correction ξ on the strip renderer: the ``closure`` stage of the bake (ASSET_PACK.md §6, "Closure").

The paper's ξ = Ψ_*/Ψ_DS (Huang et al. 2025 eq. 9; ``correction.py``) divides the path-traced radiance by the
dual-scattering estimate of each fiber hit, in the hit fiber's own frame and lit or not by the explicit fibers. The
strip renderer never evaluates that estimate: it shades one texel-averaged fiber tangent (with its spread) per
point, lit by the fraction Ψ^Fiber_G of its table, times the AO detail (``data_formats/SHADING.md`` §2–§3). So the
paper's ξ does not make the renderer reproduce the path tracer even where ξ was measured: on the bake's own yarn,
seen and lit as the correction stage sees and lights it, the renderer was off by −15 % to +39 % (worst with the
light behind; ``benchmarks/probe_closure.py``, BENCHMARKS.md "where the regular fibers' error lies"). This stage
bakes ``correction/xi_view``, the factor that closes that gap at every view (until schema 2.3 it baked
``correction/xi_closed``, closed on the correction stage's diagonal only); the pack keeps the paper's ξ as well, and
the renderer uses the closed one by default where the pack has it (``Features.closed_xi``; measured in BENCHMARKS.md,
"Issue 13: ξ closed on the strip renderer" and "Issue 13: ξ closed at every view").

Method. Inputs: the baked ``dual_scattering``, ``correction``, ``shadowing`` and ``textures`` stages. Their tables
are written to a temporary pack; a scene holds the correction stage's straight yarn (a straight curve along +z over
z ∈ [−P, 2P], the spec's radius), seen by the correction stage's orthographic camera from θ_o
(``correction.strip_camera``, ``rows`` rows over v ∈ [−1, 1]) and lit from (θ_i, φ_i = −φ), irradiance 1, for every
bin centre (θ_i, θ_o, φ) of the correction stage's grid: off the diagonal too. The paper's ξ(v, θ_d, φ) is applied
at every θ_h = (θ_i + θ_o)/2 although it was measured only on θ_o = −θ_i, and the strip renderer with it (or with
a ξ closed on that diagonal alone) was off by up to +86 % on a straight yarn lit at θ_i = 65° and seen at θ_o = 0
(BENCHMARKS.md, "Issue 13: ξ closed at every view"). So this stage first path-traces Ψ_*(v, θ_i, θ_o, φ), the
mean radiance of each v bin's pixels (as the correction stage does on its diagonal: the same yarn tracer, camera,
spp and batches, ``correction/radiance_view``), then has the renderer (``knitrun.render.pipeline``, the full model
without flyaways, MSAA 4) draw every bin, S(v, θ_i, θ_o, φ) its mean radiance per v bin. The image is linear in ξ
(SHADING.md §3), but the renderer interpolates ξ between bins, so ξ is updated by the fixed point

    ξ ← ξ · Ψ_* / S(ξ)        (per v, θ_i, θ_o, φ, channel)

``iterations`` times from the paper's ξ at θ_d = (θ_o − θ_i)/2 (``papers_xi_at_views``), kept within a factor
``CLAMP`` of it, in the bins where Ψ_* is measured (above ``SIGNAL`` × its largest value, standard error ≤
``MAX_RELATIVE_ERROR`` of it, in every channel) and S exceeds ``SIGNAL`` × its largest value; other bins (grazing
views and lights and the strip's edges, where few fibers are hit) keep the starting value. A last render measures
what is left: the closure residual |S/Ψ_* − 1| over those bins (attributes ``closure_residual_max`` and
``closure_residual_rms`` of ``correction/xi_view``), and the table stored is the one it drew.

The diagonal θ_o = −θ_i of the result is stored as well, ``correction/xi_closed`` (v, θ_d, φ), the ξ of a renderer
that looks ξ up at θ_d alone (knit's default ξ; until closure version 2 this stage closed that diagonal only):
at a diagonal bin centre the two lookups read the same grid value and no other, so the diagonal's fixed point is
the one that stage ran, on the same Ψ_* (the diagonal bins of ``correction/radiance_view`` are the correction
stage's ``correction/radiance``, not traced again).

Apart on single and multiple scattering (closure version 3, schema 2.5; with the setting ``split``, which every
quality preset turns on since stop 56 and ``knitbake bake --whole-xi`` off: it costs 80–90 % more closure time, and
the renderer reads it by default, ``Features.split_xi``). One ξ scales the renderer's single
scattering and its multiple scattering alike, and closed on their sum it makes up for what one lacks with the
other: on cotton1 the renderer's multiple scattering is about half the path tracer's and its single scattering about
right (BENCHMARKS.md, "Issue 13: light that neighbouring yarns scatter"), so the closed ξ leaves single scattering
1.4–1.7× too bright wherever the mix differs from the bake's yarn. The stage therefore also traces each bin with
paths of one event, Ψ_SS (``radiance_view_ss``; multiple scattering Ψ_MS = Ψ_* − Ψ_SS), and runs the fixed point on
each part from the closed ξ: the renderer draws every bin with ξ_ss on single scattering and ξ_ms on the rest
(``Features.split_xi``), once whole (S) and once with single scattering alone (S_SS, the density factors at 0), and

    ξ_ss ← ξ_ss · Ψ_SS / S_SS,        ξ_ms ← ξ_ms · Ψ_MS / (S − S_SS)

in the bins where that part is measured (``SIGNAL``, ``MAX_RELATIVE_ERROR``), within ``CLAMP`` of the paper's ξ;
a bin whose row fails that test but whose angle bin (θ_i, θ_o, φ) passes it summed over v moves by the ratio of the
sums, Σ_v Ψ_SS / Σ_v S_SS (likewise for multiple scattering; ``part_ratio``, since closure version 5: one event's
glints are too sparse for most rows alone, and those bins fell back to the closed ξ, 1.8× theirs); the rest keep the
closed ξ. Stored: ``correction/xi_view_ss``, ``_ms`` and their diagonals ``xi_closed_ss``, ``_ms``.

Paths. Every trace here and in the correction stage follows paths of up to ``path_tracer.MAX_DEPTH`` scattering
events (Russian roulette past the third), the scene format's default depth, which the references use (16 until
closure version 5, correction version 8: 5 % of a knitted course's multiple scattering lay beyond it).

Errors. The closed ξ is Ψ_* over the renderer's estimate per unit ξ, so its relative standard error is Ψ_*'s (over
the batches); where a bin kept the starting ξ, the paper's error interpolated at its θ_d. It does not include the
closure residual, which is reported beside it. The split ξ's relative error is its part's (Ψ_MS's: Ψ_*'s and
Ψ_SS's in quadrature); in a bin moved by its angle bin's sums, the sums' relative error.
"""

from __future__ import annotations

import dataclasses
import tempfile
from pathlib import Path

import numpy as np

from data_formats.asset_pack.schema import CLOSURE_STAGE_VERSION
from data_formats.conventions import PHI_RANGE, THETA_RANGE, cell_centres
from data_formats.scene import Camera as SceneCamera
from data_formats.scene import DirectionalLight, scene_from_dict
from data_formats.yarn_curves import make_yarn_curves, write_yarn_curves
from data_formats.yarn_spec import YarnSpec, dumps_spec
from knitbake.stages.correction import row_v, strip_camera, v_bin_sums, yarn_direction, yarn_tracer
from knitbake.stages.stage_result import StageResult
from knitbake.trace.path_tracer import MAX_DEPTH, render
from knitrun.shading.table_lookup import axis_cell

CLOSURE_INPUTS = ("dual_scattering", "correction", "shadowing", "textures")
SIGNAL = 1e-3  # a bin takes part when Ψ_* and S both exceed this fraction of their largest value
MAX_RELATIVE_ERROR = 0.25  # ... and Ψ_*'s standard error is at most this fraction of it (every channel)
# the closed ξ stays within this factor of the paper's either way: at 4 (until closure version 4) a fifth of the
# standard pack's bins with the light 78.75° from the yarn's normal plane sat at ξ/4 with the renderer still 1.5–3×
# the path tracer there (BENCHMARKS.md, "Issue 13: a yarn's own strip", item 5)
CLAMP = 8.0
MSAA = 4


def _scene(folder: Path, spec: YarnSpec, pack: Path, colour_scale: float = 1.0):
    """The correction stage's yarn as a scene (camera and light set per bin by ``_view``), drawn in the grey
    ``colour_scale``."""
    period = spec.geometry.ply_pitch
    z = np.linspace(-period, 2 * period, 31)
    points = np.stack([np.zeros_like(z), np.zeros_like(z), z], axis=1)
    write_yarn_curves(folder / "yarn.h5", make_yarn_curves(points, np.array([0, len(z)], np.int64),
                                                            yarn_types=[spec.name], units=spec.units))
    (folder / "yarn.toml").write_text(dumps_spec(spec))
    data = {"format": "knit-scene", "version": "1.0", "units": spec.units, "background": [0.0, 0.0, 0.0],
            "yarns": [{"curves": "yarn.h5", "yarn": "yarn.toml", "pack": str(Path(pack).resolve()),
                       "color": [float(colour_scale)] * 3}],
            "camera": {"position": [1.0, 0.0, 0.0], "look_at": [0.0, 0.0, 0.0], "up": [0.0, 1.0, 0.0],
                       "ortho_height": 1.0, "width": 8, "height": 8},
            "lights": [{"type": "directional", "direction": [1.0, 0.0, 0.0], "irradiance": [1.0, 1.0, 1.0]}],
            "render": {"msaa": MSAA}}
    return scene_from_dict(data, "closure scene", folder)


def _view(scene, spec: YarnSpec, theta_i: float, theta_o: float, phi: float, rows: int):
    """``scene`` seen by the correction stage's camera from θ_o and lit from (θ_i, φ_i = −φ)."""
    cam = strip_camera(spec, theta_o, rows)
    camera = SceneCamera(tuple(cam.position.tolist()), tuple(cam.look_at.tolist()), tuple(cam.up.tolist()), None,
                         float(cam.ortho_height), int(cam.width), int(cam.height))
    light = DirectionalLight(tuple(yarn_direction(theta_i, -phi).tolist()), (1.0, 1.0, 1.0))
    return dataclasses.replace(scene, camera=camera, lights=(light,))


def _views(n_theta: int, n_phi: int):
    """Every bin centre (k, l, m, θ_i, θ_o, φ) of the view grid, in table order."""
    thetas, phis = cell_centres(*THETA_RANGE, n_theta), cell_centres(*PHI_RANGE, n_phi)
    for k, theta_i in enumerate(thetas):
        for ell, theta_o in enumerate(thetas):
            for m, phi in enumerate(phis):
                yield k, ell, m, theta_i, theta_o, phi


def trace_view_radiance(spec: YarnSpec, diagonal: tuple, rows: int, spp: int, batches: int, seed: int,
                        max_depth: int = MAX_DEPTH, progress=None, shape=None):
    """Ψ_* (N_v, N_θ, N_θ, N_φ, 3) on axes (v, θ_i, θ_o, φ) and its standard error over ``batches``: the path-traced
    mean radiance per v bin of the correction stage's yarn, camera and light (module docstring), paths of at most
    ``max_depth`` scattering events (1: single scattering). ``diagonal``: the correction stage's
    (``correction/radiance``, its error) (N_v, N_θ, N_φ, 3), Ψ_* on θ_o = −θ_i = θ_d measured the same way, which
    fills those bins instead of tracing them again; or None to trace them too, on the grid ``shape`` (N_v, N_θ,
    N_φ)."""
    radiance, error = diagonal if diagonal is not None else (None, None)
    samples = trace_view_samples(spec, radiance.shape[:3] if diagonal is not None else shape, rows, spp, batches,
                                 seed, max_depth, progress, skip_diagonal=diagonal is not None)
    mean, stderr = samples.mean(axis=0), samples.std(axis=0, ddof=1) / np.sqrt(batches)
    for ell in range(mean.shape[1] if diagonal is not None else 0):
        mean[:, -1 - ell, ell], stderr[:, -1 - ell, ell] = radiance[:, ell], error[:, ell]
    return mean, stderr


def trace_view_samples(spec: YarnSpec, shape: tuple, rows: int, spp: int, batches: int, seed: int,
                       max_depth: int = MAX_DEPTH, progress=None, skip_diagonal=False, colour_scale: float = 1.0):
    """(batches, N_v, N_θ, N_θ, N_φ, 3): each batch's estimate of ``trace_view_radiance``'s Ψ_* on the grid ``shape``
    (N_v, N_θ, N_φ); ``skip_diagonal``: the bins θ_o = −θ_i left at 0. ``colour_scale`` k: the fibers' lobe albedos
    A_R, A_TT, A_D times k (the yarn drawn in the grey k, as the reference tracer draws a scene colour). Batch b
    traces the fibers of seed + b and every bin's paths from a seed of (seed, b, bin) alone, whatever ``max_depth``
    and k: two traces of one bake differ only past the paths' first event (at one event in the grey k, exactly k
    times the white's), so their difference per batch holds no noise of the first event (``colour_closure``)."""
    n_v, n_theta, n_phi = shape
    samples = np.zeros((batches, n_v, n_theta, n_theta, n_phi, 3))
    per_batch = n_theta * n_theta * n_phi
    for b in range(batches):
        geometry = yarn_tracer(spec, seed + b, colour_scale)
        for k, ell, m, theta_i, theta_o, phi in _views(n_theta, n_phi):
            if k + ell == n_theta - 1 and skip_diagonal:
                continue
            cam = strip_camera(spec, theta_o, rows)
            lit = geometry.with_lights(yarn_direction(theta_i, -phi)[None], np.ones((1, 3)))
            traced, _ = render(lit, cam, spp, seed=seed + 1000 * b + 401 * k + 37 * ell + m, max_depth=max_depth)
            sums, pixels = v_bin_sums(traced, np.ones(traced.shape[:2]), row_v(rows), n_v)
            samples[b, :, k, ell, m] = sums / np.maximum(pixels, 1)[:, None]
            if progress:
                progress(b * per_batch + (k * n_theta + ell) * n_phi + m + 1, batches * per_batch)
    return samples


def diagonal_of(view: np.ndarray) -> np.ndarray:
    """A view table (N_v, N_θ, N_θ, N_φ, ...) on axes (v, θ_i, θ_o, φ) on the diagonal θ_o = −θ_i = θ_d: (N_v, N_θ,
    N_φ, ...) on axes (v, θ_d, φ) (the θ centres are symmetric, so θ_i = −θ_o[ℓ] is centre N_θ − 1 − ℓ)."""
    n_theta = view.shape[1]
    return np.stack([view[:, n_theta - 1 - ell, ell] for ell in range(n_theta)], axis=1)


def render_bins(pack: Path, spec: YarnSpec, shape: tuple, rows: int, progress=None, split=False,
                single=False, colour_scale: float = 1.0) -> np.ndarray:
    """S (N_v, N_θ, N_θ, N_φ, 3): the strip renderer's mean radiance per v bin of the correction stage's camera,
    for each bin centre (θ_i, θ_o, φ), of the yarn drawn from ``pack`` (full model without flyaways, ξ from the
    pack's ``correction/xi_view``; ``split``: from its ``correction/xi_view_ss`` and ``_ms``; ``single``: single
    scattering alone, ``Features.multiple_scattering`` False), in the grey ``colour_scale``. The lone yarn has no
    neighbour to shadow it; its own strip in the shadow maps does not either (``shadow_map.own_strip_depth``: up to
    θ_i = 80.4°). Until closure version 4 it did, with the light more than ~48° from the yarn's normal plane, and ξ
    learnt it (the standard pack's bins at θ_i = ±78.75° moved by 27–29 % on average: BENCHMARKS.md, "Issue 13: a
    yarn's own strip")."""
    from knitrun.render.ablations import Features
    from knitrun.render.pipeline import Renderer

    n_v, n_theta, _, n_phi = shape
    out = np.zeros(tuple(shape) + (3,))
    with tempfile.TemporaryDirectory(prefix="knit-closure-") as tmp:
        scene = _scene(Path(tmp), spec, pack, colour_scale)
        # one straight yarn has no second yarn layer toward a light (V₂ = 1 at every point): the peeled map would
        # only double each view's cost (BENCHMARKS.md, stop 71)
        renderer = Renderer(scene, features=Features(flyaways=False, view_xi=True, split_xi=split,
                                                     multiple_scattering=not single, two_blockers=False))
        done = 0
        for k, ell, m, theta_i, theta_o, phi in _views(n_theta, n_phi):
            renderer.scene = _view(scene, spec, theta_i, theta_o, phi, rows)
            image = renderer.render().image.astype(np.float64)
            sums, pixels = v_bin_sums(image, np.ones(image.shape[:2]), row_v(rows), n_v)
            out[:, k, ell, m] = sums / np.maximum(pixels, 1)[:, None]
            done += 1
            if progress:
                progress(done, n_theta * n_theta * n_phi)
    return out


def papers_xi_at_views(xi: np.ndarray) -> np.ndarray:
    """The paper's ξ (N_v, N_θ, N_φ, 3) on axes (v, θ_d, φ) at every view bin centre: (N_v, N_θ, N_θ, N_φ, 3) on axes
    (v, θ_i, θ_o, φ), linear in θ_d = (θ_o − θ_i)/2 with the clamp of ASSET_PACK.md §4.3."""
    n_theta = xi.shape[1]
    thetas = cell_centres(*THETA_RANGE, n_theta)
    out = np.empty((xi.shape[0], n_theta, n_theta) + xi.shape[2:])
    for k, theta_i in enumerate(thetas):
        for ell, theta_o in enumerate(thetas):
            i0, i1, f = axis_cell(0.5 * (theta_o - theta_i), THETA_RANGE[0], THETA_RANGE[1], n_theta, False)
            out[:, k, ell] = (1.0 - f) * xi[:, i0] + f * xi[:, i1]
    return out


def close_correction(spec: YarnSpec, inputs: dict, write_pack_to, rows: int, iterations: int, spp: int,
                     batches: int, seed: int, progress=None, split=True) -> tuple[dict, dict, dict, dict]:
    """(tables, errors, counts, closure residuals: table → {max, rms}) of the view-closed ξ, its diagonal and the Ψ_*
    it closes on, and, with ``split``, of the ξ closed apart on single and multiple scattering (module docstring).
    ``inputs``: stage → StageResult of ``CLOSURE_INPUTS``; ``write_pack_to(path, xi_view, split)`` writes them as a
    pack with ``correction/xi_view`` = ``xi_view`` and, with ``split`` = (ss, ms), ``correction/xi_view_ss``,
    ``_ms``; ``spp``, ``batches``: the correction stage's."""
    paper_tab = inputs["correction"].tables["correction/xi"]
    n_v, n_theta, n_phi = paper_tab.shape[:3]
    shape = (n_v, n_theta, n_theta, n_phi)
    per_view = n_theta * n_theta * n_phi
    # progress in passes over every view bin: the whole trace, the renders closing ξ, then (split) the one-event
    # trace and the renders closing each part
    split_from = batches + iterations + 1
    total = (split_from + (batches + 2 * (iterations + 1) if split else 0)) * per_view

    def passes(start):
        """progress of the passes from pass ``start`` on (each pass draws or traces every view bin once)."""
        if progress is None:
            return lambda p: None
        return lambda p: (lambda done, _: progress((start + p) * per_view + done, total))

    diagonal = inputs["correction"].tables["correction/radiance"], inputs["correction"].errors["correction/radiance"]
    target, target_err = trace_view_radiance(spec, diagonal, rows, spp, batches, seed, progress=passes(0)(0))
    paper = papers_xi_at_views(paper_tab)
    paper_err = papers_xi_at_views(inputs["correction"].errors["correction/xi"])

    def measured(radiance, error):
        return np.all((radiance > SIGNAL * target.max()) & (error <= MAX_RELATIVE_ERROR * radiance), axis=-1,
                      keepdims=True)

    xi = paper.copy()
    used_total = measured(target, target_err)
    moved = np.zeros(paper.shape, bool)  # the bins some update has moved from the paper's ξ
    with tempfile.TemporaryDirectory(prefix="knit-closure-pack-") as tmp:
        pack = Path(tmp) / "inputs.h5"
        step = passes(batches)
        for it in range(iterations + 1):  # ξ closed on the totals
            write_pack_to(pack, xi)
            rendered = render_bins(pack, spec, shape, rows, step(it))
            used = used_total & (rendered > SIGNAL * rendered.max())
            if it == iterations:
                break
            ratio = np.where(used, target / np.where(used, rendered, 1.0), 1.0)
            xi = np.clip(xi * ratio, paper / CLAMP, paper * CLAMP)
            moved |= used
        # the table the last render drew, whose residual is measured (until closure version 4 the bins that fell
        # below the signal in the last render went back to the paper's ξ, which moved their neighbours' lookups)
        closed = xi
        relative = np.where(moved, target_err / np.where(moved, target, 1.0), paper_err / np.maximum(paper, 1e-300))
        counts = {"iterations": iterations, "bins_closed": int(moved.all(axis=-1).sum()),
                  "bins": int(np.prod(shape)), "batches": batches, "paths_per_pixel": spp}
        left = {"correction/xi_view": _residual(rendered, target, used),
                "correction/xi_closed": _residual(diagonal_of(rendered), diagonal_of(target), diagonal_of(used))}
        tables = {"correction/xi_view": closed, "correction/radiance_view": target,
                  "correction/xi_closed": diagonal_of(closed)}
        errors = {"correction/xi_view": closed * relative, "correction/radiance_view": target_err,
                  "correction/xi_closed": diagonal_of(closed * relative)}
        if not split:
            return tables, errors, counts, left
        # ξ closed apart: single scattering on the one-event radiance, multiple on the rest, from the closed ξ
        single, single_err = trace_view_radiance(spec, None, rows, spp, batches, seed, max_depth=1,
                                                 shape=(n_v, n_theta, n_phi), progress=passes(split_from)(0))
        tables["correction/radiance_view_ss"], errors["correction/radiance_view_ss"] = single, single_err
        parts = {"ss": (single, single_err), "ms": (target - single, np.hypot(target_err, single_err))}
        apart = {name: closed.copy() for name in parts}
        moved_parts = {name: np.zeros(closed.shape, bool) for name in parts}
        pooled_parts = {name: np.zeros(closed.shape, bool) for name in parts}
        measured_parts = {name: measured(*value) for name, value in parts.items()}
        step = passes(split_from + batches)
        for it in range(iterations + 1):
            write_pack_to(pack, closed, (apart["ss"], apart["ms"]))
            drawn = render_bins(pack, spec, shape, rows, step(2 * it), split=True)
            drawn_single = render_bins(pack, spec, shape, rows, step(2 * it + 1), split=True, single=True)
            drawn_parts = {"ss": drawn_single, "ms": drawn - drawn_single}
            used_parts = {name: measured_parts[name] & (drawn_parts[name] > SIGNAL * drawn.max()) for name in parts}
            if it == iterations:
                break
            for name, (want, want_err) in parts.items():
                ratio, pooled = part_ratio(want, want_err, drawn_parts[name], used_parts[name],
                                           SIGNAL * target.sum(axis=0).max(), SIGNAL * drawn.sum(axis=0).max())
                apart[name] = np.clip(apart[name] * ratio, paper / CLAMP, paper * CLAMP)
                moved_parts[name] |= used_parts[name]
                pooled_parts[name] |= pooled & ~moved_parts[name]
    for name, (want, want_err) in parts.items():
        ok, moved, pooled = used_parts[name], moved_parts[name], pooled_parts[name] & ~moved_parts[name]
        counts[f"bins_closed_{name}"] = int(moved.all(axis=-1).sum())
        counts[f"bins_pooled_{name}"] = int(pooled.all(axis=-1).sum())
        value = apart[name]  # the tables the last render drew, as for the totals
        pooled_relative = (np.sqrt((want_err ** 2).sum(axis=0, keepdims=True))
                           / np.maximum(np.abs(want.sum(axis=0, keepdims=True)), 1e-300))
        error = value * np.where(moved, want_err / np.where(moved, np.abs(want), 1.0),
                                 np.where(pooled, pooled_relative, relative))
        tables[f"correction/xi_view_{name}"], errors[f"correction/xi_view_{name}"] = value, error
        tables[f"correction/xi_closed_{name}"] = diagonal_of(value)
        errors[f"correction/xi_closed_{name}"] = diagonal_of(error)
        left[f"correction/xi_view_{name}"] = _residual(drawn_parts[name], want, ok)
        left[f"correction/xi_closed_{name}"] = _residual(diagonal_of(drawn_parts[name]), diagonal_of(want),
                                                         diagonal_of(ok))
    return tables, errors, counts, left


def part_ratio(want, want_err, drawn, rows_ok, want_floor, drawn_floor):
    """(ratio, pooled) of one iteration of the split closure for one part (module docstring), arrays (N_v, N_θ, N_θ,
    N_φ, 3) but ``rows_ok`` and ``pooled`` (…, 1): a bin whose row is measured (``rows_ok``) moves by want/drawn; one
    whose row is not but whose angle bin (θ_i, θ_o, φ) is, summed over v, moves by Σ_v want / Σ_v drawn (``pooled``
    True); the rest by 1. An angle bin is measured summed over v when, in every channel, Σ_v want exceeds
    ``want_floor``, its standard error (the rows' in quadrature) is at most ``MAX_RELATIVE_ERROR`` of it, and Σ_v
    drawn exceeds ``drawn_floor``. Without the pooled sums most of the single scattering's bins failed the per-row
    test and fell back to the whole ξ, 1.8× theirs (closure stage version 4: 23.5 % of cotton1's bins closed;
    BENCHMARKS.md, "Issue 13: one course alone", item 6)."""
    total, total_drawn = want.sum(axis=0, keepdims=True), drawn.sum(axis=0, keepdims=True)
    total_err = np.sqrt((want_err ** 2).sum(axis=0, keepdims=True))
    pooled = np.all((total > want_floor) & (total_err <= MAX_RELATIVE_ERROR * total) & (total_drawn > drawn_floor),
                    axis=-1, keepdims=True)
    pooled = np.broadcast_to(pooled, rows_ok.shape) & ~rows_ok
    row_ratio = want / np.where(rows_ok, drawn, 1.0)
    pooled_ratio = total / np.where(total_drawn > 0.0, total_drawn, 1.0)
    return np.where(rows_ok, row_ratio, np.where(pooled, pooled_ratio, 1.0)), pooled


def _residual(rendered, target, used) -> dict:
    """The closure residual |S/Ψ_* − 1| over the ``used`` bins: its largest and RMS value."""
    miss = np.abs(rendered[used] / target[used] - 1.0)
    return {"closure_residual_max": float(miss.max()) if miss.size else 0.0,
            "closure_residual_rms": float(np.sqrt(np.mean(miss ** 2))) if miss.size else 0.0}


def bake_closure_stage(spec, settings, seed, progress=None, inputs=None, write_pack_to=None) -> StageResult:
    """Stage ``closure`` of ``knitbake.bake``: settings ``rows``, ``spp``, ``batches`` (the correction stage's),
    ``iterations``, ``split`` (ξ closed apart as well) and ``inputs`` (the settings of ``CLOSURE_INPUTS``, part of the
    cache key only). ``inputs``: their StageResults; ``write_pack_to``: see ``close_correction``."""
    tables, errors, counts, left = close_correction(spec, inputs, write_pack_to, settings["rows"],
                                                    settings["iterations"], settings["spp"], settings["batches"],
                                                    seed, progress, settings["split"])
    kind = (f"standard error of the path-traced radiance Ψ_* over {settings['batches']} independent batches (fiber "
            f"geometry, paths and pixel jitter reseeded), carried into the closed ξ")
    attrs = {name: {"error_kind": kind, "closure_version": CLOSURE_STAGE_VERSION} for name in tables}
    for name, residual in left.items():
        attrs[name].update(residual)
    return StageResult(tables, errors, attrs, counts)
