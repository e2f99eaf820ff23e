"""Close the correction ξ on the strip renderer: the ``closure`` stage of the bake (ASSET_PACK.md §6, "Closure").

The paper's ξ = Ψ_*/Ψ_DS (Huang et al. 2025 eq. 9; ``correction.py``) divides the path-traced radiance by the
dual-scattering estimate of each fiber hit, in the hit fiber's own frame and lit or not by the explicit fibers. The
strip renderer never evaluates that estimate: it shades one texel-averaged fiber tangent (with its spread) per
point, lit by the fraction Ψ^Fiber_G of its table, times the AO detail (``data_formats/SHADING.md`` §2–§3). So the
paper's ξ does not make the renderer reproduce the path tracer even where ξ was measured: on the bake's own yarn,
seen and lit as the correction stage sees and lights it, the renderer was off by −15 % to +39 % (worst with the
light behind; ``benchmarks/probe_closure.py``, BENCHMARKS.md "where the regular fibers' error lies"). This stage
bakes ``correction/xi_closed``, the factor that closes that gap; the pack keeps the paper's ξ as well, and the
renderer uses the closed one by default where the pack has it (``Features.closed_xi``; measured in BENCHMARKS.md,
"Issue 13: ξ closed on the strip renderer" and "Issue 13: hairs in their own yarn's shadow, and the closed ξ with
flyaways as the default").

Method. Inputs: the baked ``dual_scattering``, ``correction``, ``shadowing`` and ``textures`` stages. Their tables
are written to a temporary pack; a scene holds the correction stage's straight yarn (a straight curve along +z over
z ∈ [−P, 2P], the spec's radius) and, per bin (θ_d, φ), the correction stage's orthographic camera
(``correction.strip_camera``, θ_o = θ_d, ``rows`` rows over v ∈ [−1, 1]) and its light (θ_i = −θ_d, φ_i = −φ,
irradiance 1). The renderer (``knitrun.render.pipeline``, the full model without flyaways, MSAA 4) draws it; S(v,
θ_d, φ) is the mean radiance of the pixels of each v bin (the bins of ``correction.v_bin_sums``), to be compared with
the correction stage's ``correction/radiance`` Ψ_* of the same pixels. The image is linear in ξ (SHADING.md §3), but
the renderer interpolates ξ between v bins, so ξ is updated by the fixed point

    ξ ← ξ · Ψ_* / S(ξ)        (per v, θ_d, φ, channel)

``iterations`` times from the paper's ξ, kept within a factor ``CLAMP`` of it, in the bins where Ψ_* is measured
(above ``SIGNAL`` × its largest value, standard error ≤ ``MAX_RELATIVE_ERROR`` of it, in every channel) and S
exceeds ``SIGNAL`` × its largest value; other bins (the grazing θ_d and the strip's edges, where few fibers are
hit: 5 % of Ψ_*'s energy at standard quality) keep the paper's ξ. A last render measures what is left: the closure
residual |S/Ψ_* − 1| over those bins (attributes ``closure_residual_max`` and ``closure_residual_rms`` of
``correction/xi_closed``).

Only the bake's diagonal θ_o = −θ_i = θ_d is closed, as only it is measured: ξ(v, θ_d, φ) is still applied at
every θ_h, where the closure says nothing.

Errors. The closed ξ is Ψ_* over the renderer's estimate per unit ξ, so its relative standard error is Ψ_*'s
(``correction/radiance_stderr``, over the correction stage's batches; where a bin kept the paper's ξ, the paper's
error). It does not include the closure residual, which is reported beside it.
"""

from __future__ import annotations

import dataclasses
import tempfile
from pathlib import Path

import numpy as np

from data_formats.conventions import PHI_RANGE, THETA_RANGE, cell_centres
from data_formats.scene import Camera as SceneCamera
from data_formats.scene import DirectionalLight, scene_from_dict
from data_formats.yarn_curves import make_yarn_curves, write_yarn_curves
from data_formats.yarn_spec import YarnSpec, dumps_spec
from knitbake.stages.correction import row_v, strip_camera, v_bin_sums, yarn_direction
from knitbake.stages.stage_result import StageResult

CLOSURE_INPUTS = ("dual_scattering", "correction", "shadowing", "textures")
SIGNAL = 1e-3  # a bin takes part when Ψ_* and S both exceed this fraction of their largest value
MAX_RELATIVE_ERROR = 0.25  # ... and Ψ_*'s standard error is at most this fraction of it (every channel)
CLAMP = 4.0  # the closed ξ stays within this factor of the paper's either way
MSAA = 4


def _scene(folder: Path, spec: YarnSpec, pack: Path):
    """The correction stage's yarn as a scene (camera and light set per bin by ``_view``)."""
    period = spec.geometry.ply_pitch
    z = np.linspace(-period, 2 * period, 31)
    points = np.stack([np.zeros_like(z), np.zeros_like(z), z], axis=1)
    write_yarn_curves(folder / "yarn.h5", make_yarn_curves(points, np.array([0, len(z)], np.int64),
                                                            yarn_types=[spec.name], units=spec.units))
    (folder / "yarn.toml").write_text(dumps_spec(spec))
    data = {"format": "knit-scene", "version": "1.0", "units": spec.units, "background": [0.0, 0.0, 0.0],
            "yarns": [{"curves": "yarn.h5", "yarn": "yarn.toml", "pack": str(Path(pack).resolve())}],
            "camera": {"position": [1.0, 0.0, 0.0], "look_at": [0.0, 0.0, 0.0], "up": [0.0, 1.0, 0.0],
                       "ortho_height": 1.0, "width": 8, "height": 8},
            "lights": [{"type": "directional", "direction": [1.0, 0.0, 0.0], "irradiance": [1.0, 1.0, 1.0]}],
            "render": {"msaa": MSAA}}
    return scene_from_dict(data, "closure scene", folder)


def _view(scene, spec: YarnSpec, theta_d: float, phi: float, rows: int):
    """``scene`` seen by the correction stage's camera for θ_d and lit by its light for (θ_d, φ)."""
    cam = strip_camera(spec, theta_d, rows)
    camera = SceneCamera(tuple(cam.position.tolist()), tuple(cam.look_at.tolist()), tuple(cam.up.tolist()), None,
                         float(cam.ortho_height), int(cam.width), int(cam.height))
    light = DirectionalLight(tuple(yarn_direction(-theta_d, -phi).tolist()), (1.0, 1.0, 1.0))
    return dataclasses.replace(scene, camera=camera, lights=(light,))


def render_bins(pack: Path, spec: YarnSpec, shape: tuple, rows: int, progress=None) -> np.ndarray:
    """S (N_v, N_θ, N_φ, 3): the strip renderer's mean radiance per v bin of the correction stage's camera, for
    each bin centre (θ_d, φ), of the yarn drawn from ``pack`` (full model, no flyaways)."""
    from knitrun.render.ablations import Features
    from knitrun.render.pipeline import Renderer

    n_v, n_theta, n_phi = shape
    out = np.zeros((n_v, n_theta, n_phi, 3))
    with tempfile.TemporaryDirectory(prefix="knit-closure-") as tmp:
        scene = _scene(Path(tmp), spec, pack)
        renderer = Renderer(scene, features=Features(flyaways=False, closed_xi=False))  # ξ: the iterate's pack
        for k, theta_d in enumerate(cell_centres(*THETA_RANGE, n_theta)):
            for m, phi in enumerate(cell_centres(*PHI_RANGE, n_phi)):
                renderer.scene = _view(scene, spec, theta_d, phi, rows)
                image = renderer.render().image.astype(np.float64)
                sums, pixels = v_bin_sums(image, np.ones(image.shape[:2]), row_v(rows), n_v)
                out[:, k, m] = sums / np.maximum(pixels, 1)[:, None]
                if progress:
                    progress(k * n_phi + m + 1, n_theta * n_phi)
    return out


def close_correction(spec: YarnSpec, inputs: dict, write_pack_to, rows: int, iterations: int,
                     progress=None) -> tuple[dict, dict, dict, dict]:
    """(tables, errors, counts, closure residual {max, rms}) of the closed ξ (module docstring). ``inputs``: stage →
    StageResult of ``CLOSURE_INPUTS``; ``write_pack_to(path, xi)`` writes them as a pack whose ``correction/xi`` is
    ``xi``."""
    target = inputs["correction"].tables["correction/radiance"]
    target_err = inputs["correction"].errors["correction/radiance"]
    paper = inputs["correction"].tables["correction/xi"]
    xi = paper.copy()
    shape = xi.shape[:3]
    measured = np.all((target > SIGNAL * target.max()) & (target_err <= MAX_RELATIVE_ERROR * target), axis=-1,
                      keepdims=True)
    per_sweep = int(np.prod(shape[1:]))
    with tempfile.TemporaryDirectory(prefix="knit-closure-pack-") as tmp:
        pack = Path(tmp) / "inputs.h5"
        for it in range(iterations + 1):
            write_pack_to(pack, xi)
            step = None if progress is None else \
                (lambda done, _, it=it: progress(it * per_sweep + done, (iterations + 1) * per_sweep))
            rendered = render_bins(pack, spec, shape, rows, step)
            used = measured & (rendered > SIGNAL * rendered.max())
            if it == iterations:
                break
            ratio = np.where(used, target / np.where(used, rendered, 1.0), 1.0)
            xi = np.clip(xi * ratio, paper / CLAMP, paper * CLAMP)
    miss = np.abs(rendered[used] / target[used] - 1.0)
    counts = {"iterations": iterations, "bins_closed": int(used.all(axis=-1).sum()), "bins": int(np.prod(shape))}
    left = {"closure_residual_max": float(miss.max()) if miss.size else 0.0,
            "closure_residual_rms": float(np.sqrt(np.mean(miss ** 2))) if miss.size else 0.0}

    closed = np.where(used, xi, paper)
    relative = np.where(used, target_err / np.where(used, target, 1.0),
                        inputs["correction"].errors["correction/xi"] / np.maximum(paper, 1e-300))
    return {"correction/xi_closed": closed}, {"correction/xi_closed": closed * relative}, counts, left


def bake_closure_stage(spec, settings, seed, progress=None, inputs=None, write_pack_to=None) -> StageResult:
    """Stage ``closure`` of ``knitbake.bake``: settings ``rows`` (the correction stage's), ``iterations`` and
    ``inputs`` (the settings of ``CLOSURE_INPUTS``, part of the cache key only). ``inputs``: their StageResults;
    ``write_pack_to``: see ``close_correction``."""
    tables, errors, counts, left = close_correction(spec, inputs, write_pack_to, settings["rows"],
                                                    settings["iterations"], progress)
    kind = "standard error of the path-traced radiance Ψ_* (correction stage batches) carried into the closed ξ"
    attrs = {name: {"error_kind": kind} for name in tables}
    attrs["correction/xi_closed"].update(left)
    return StageResult(tables, errors, attrs, counts)
