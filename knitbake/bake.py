"""The bake: one yarn type → one asset pack, in cached stages.

Stages (each a function ``(spec, settings, seed, progress) -> StageResult``; ``progress(done, total)``; the closure
also takes its input stages' results, ``run_stage``):

| stage | tables | baked when |
|---|---|---|
| dual_scattering | ``dual_scattering/*`` | always |
| correction | ``correction/*`` (ξ_M, ξ_N, residuals) | always |
| shadowing | ``shadowing/*`` (Ψ^Fiber_{G,M}, Ψ^Fiber_{G,N}, residuals) | always |
| textures | ``textures/{normal,tangent,ao,coverage}/mip*`` | always |
| flyaway | ``textures/flyaway/mip*`` | the yarn has flyaways |
| environment | ``environment/I_M_TT_D`` | no scene given, or the scene has an environment light |
| interreflection | ``interreflection/{albedo,transmittance}`` (the yarn tube's ρ_Y, T_Y) and ``*_by_colour`` | always |
| closure | ``correction/{xi_view,xi_closed,radiance_view}`` (ξ closed on the renderer) | its inputs are baked |
| | ``correction/*_ss``, ``*_ms`` (ξ closed apart) | closure setting ``split`` |
| colour_closure | ``correction/xi_view_ms_by_colour`` (ξ_ms closed in greys) | the closure, with ``split`` |

Quality presets (``QUALITY``) set every stage's resolution and sample counts. Every preset also closes ξ apart on
single and multiple scattering (closure setting ``split``; the renderer's default, ``Features.split_xi``): the
``overrides`` ``{"closure": {"split": False}}`` (``knitbake bake --whole-xi``) leave it out and save about half the
closure's time. The standard and final presets close ξ on cells of 10.6° × 10.6° × 40° (17 × 17 × 9, centres on
θ = 0 and φ = 0; 8 × 8 × 8 until stop 56): between the coarser cells' centres the strips missed the path tracer by up
to 23 % where the fibers' highlights end (BENCHMARKS.md, "Issue 13: where in a knit's shape the error starts"). The
draft preset closes it on 20° × 72° cells (9 × 9 × 5) in 2 iterations (the others in 4; more moved nothing at the
yarn scale): on 45° × 90° ones (4 × 4 × 4, until stop 58) the draft pack drew the example scenes at 0.70–1.16× the
path tracer's brightness (BENCHMARKS.md, "the draft preset on 9 × 5 cells"). With the split, every preset then
closes ξ of multiple scattering in three greys (``colour_closure``, 2 iterations, the draft 1): the white yarn's left
a red yarn's dark channels with 0.3–0.6 of the path tracer's multiple scattering (BENCHMARKS.md, stop 77). A
scene (``scene_needs``) removes stages it does not need and sets the texture resolution from the largest on-screen
yarn width. Each finished stage
is cached under ``cache_dir()`` by a hash of its inputs (stage, stage version, yarn spec, its settings, seed; the
closure's settings hold its input stages' settings and versions), so an
interrupted or partial re-bake reuses finished stages. An entry stores a SHA-256 of its content; an entry that is
unreadable, truncated or edited is a miss (the stage is baked again and the entry rewritten) and is reported in the
stage's ``cache_warning``. Same seed and settings → identical pack contents whatever
the thread count (every stage is deterministic for a seed).
"""

from __future__ import annotations

import hashlib
import importlib.metadata
import json
import math
import time
from pathlib import Path

try:
    import tomllib
except ModuleNotFoundError:  # Python < 3.11
    import tomli as tomllib

import numpy as np

from data_formats.asset_pack import write_pack
from data_formats.asset_pack.schema import CLOSURE_STAGE_VERSION
from data_formats.atomic import atomic_path
from data_formats.cache_folders import cache_root
from data_formats.errors import FormatError
from data_formats.input_files import regular_file
from data_formats.yarn_spec import YarnSpec, dumps_spec, fiber_bcsdf_attrs
from knitbake.fibers.procedural_yarn import check_fiber_budget
from knitbake.stages.closure import CLOSURE_INPUTS, bake_closure_stage, papers_xi_at_views
from knitbake.stages.colour_closure import COLOUR_CLOSURE_INPUTS, bake_colour_closure_stage
from knitbake.stages.correction import bake_correction_stage, bake_shadowing_stage
from knitbake.stages.ds_precompute import bake_dual_scattering_stage
from knitbake.stages.im_table import bake_environment_stage
from knitbake.stages.stage_result import StageResult
from knitbake.stages.textures import bake_flyaway_stage, bake_regular_stage, flyaway_periods
from knitbake.stages.yarn_hull import bake_yarn_hull_stage
from knitrun.render.camera import pixel_size, scene_camera

STAGE_ORDER = ("dual_scattering", "correction", "shadowing", "textures", "flyaway", "environment", "interreflection",
               "closure", "colour_closure")

QUALITY = {
    "draft": {
        "dual_scattering": {"n_theta": 32},
        "correction": {"n_v": 8, "n_theta": 9, "n_phi": 5, "rows": 16, "spp": 2, "batches": 2,
                       "ds": {"n_theta": 32}},
        "shadowing": {"n_v": 8, "n_theta": 9, "n_phi": 5, "rows": 16, "spp": 2, "batches": 2},
        "textures": {"width": 128, "height": 32, "samples": 2, "ao_rays": 8},
        "flyaway": {"width": 128, "height": 32, "samples": 2},
        "environment": {"shape": (12, 24, 12, 32)},
        "interreflection": {"n_views": 4, "rows": 8, "spp": 2, "batches": 2, "n_colours": 17},
        "closure": {"iterations": 2, "split": True},
        "colour_closure": {"iterations": 1},
    },
    "standard": {
        "dual_scattering": {"n_theta": 64},
        "correction": {"n_v": 16, "n_theta": 17, "n_phi": 9, "rows": 32, "spp": 4, "batches": 3,
                       "ds": {"n_theta": 64}},
        "shadowing": {"n_v": 16, "n_theta": 17, "n_phi": 9, "rows": 32, "spp": 4, "batches": 3},
        "textures": {"width": 256, "height": 64, "samples": 4, "ao_rays": 16},
        "flyaway": {"width": 256, "height": 64, "samples": 4},
        "environment": {"shape": (24, 48, 24, 96)},
        "interreflection": {"n_views": 6, "rows": 16, "spp": 4, "batches": 3, "n_colours": 17},
        "closure": {"iterations": 4, "split": True},
        "colour_closure": {"iterations": 2},
    },
    "final": {
        "dual_scattering": {"n_theta": 128},
        "correction": {"n_v": 16, "n_theta": 17, "n_phi": 9, "rows": 32, "spp": 8, "batches": 4,
                       "ds": {"n_theta": 128}},
        "shadowing": {"n_v": 32, "n_theta": 16, "n_phi": 16, "rows": 64, "spp": 8, "batches": 4},
        "textures": {"width": 512, "height": 128, "samples": 6, "ao_rays": 32},
        "flyaway": {"width": 512, "height": 128, "samples": 6},
        "environment": {"shape": (32, 64, 32, 128)},
        "interreflection": {"n_views": 8, "rows": 32, "spp": 8, "batches": 4, "n_colours": 17},
        "closure": {"iterations": 4, "split": True},
        "colour_closure": {"iterations": 2},
    },
}
# Bump a stage's version when its code changes what it computes: old cache entries stop matching.
# correction 2: weighted ξ factorization; 3, shadowing 2: the unfactorized tables are stored too;
# correction 4: ξ divides by the DS the renderer evaluates (n_occluded for shadowed hits);
# environment 2: the table holds the TT and D lobes (schema 2.0), finer grids, measured lookup error; 3: scalar
# quadrature error; correction 5, shadowing 3, interreflection 2, textures 2, flyaway 2: the fibers traced as Embree
# curves, not tubes; correction 6, interreflection 3: the oblique strip cameras start their rays outside the yarn;
# interreflection 4: the yarn's transmittance T_Y as well; correction 7: Ψ_* kept (correction/radiance);
# closure 2: ξ closed at every view (θ_i, θ_o), correction/xi_view; 3: and apart on single and multiple scattering;
# interreflection 5: ρ_Y and T_Y against the colour (interreflection/*_by_colour); closure 4: the renderer it closes
# on no longer shadows the lone yarn by its own strip (shadow_map.own_strip_depth), the ξ stored is the one drawn last,
# CLAMP 4 → 8; flyaway 3: the draw of flyaways nearest the yarn's coverage profile (textures.nearest_flyaway_draw);
# correction 8, closure 5: paths as long as the references' (path_tracer.MAX_DEPTH, 32 events, not 16); closure 5
# also: a part's bin that fails the per-row test takes its angle bin's v-summed ratio where that sum is measured;
# colour_closure 1 (stop 77): ξ of multiple scattering closed on the yarn in greys k = 1/8, 1/4, 1/2; 2 (stop 78):
# the greys from the lightest, each darker one starting from the lighter two's ratio carried on
STAGE_VERSION = {**{name: 1 for name in STAGE_ORDER}, "correction": 8, "shadowing": 3, "environment": 3,
                 "interreflection": 5, "textures": 2, "flyaway": 3, "closure": CLOSURE_STAGE_VERSION,
                 "colour_closure": 2}


MAX_SEED = 2**62 - 1  # stages add batch and view offsets (< 2^20) to the seed and pass it to Numba as int64


def cache_dir() -> Path:
    return cache_root() / "bake"


def stage_key(stage: str, spec: YarnSpec, settings: dict, seed: int) -> str:
    text = json.dumps({"stage": stage, "version": STAGE_VERSION[stage], "spec": dumps_spec(spec),
                       "settings": settings, "seed": seed}, sort_keys=True)
    return hashlib.sha256(text.encode()).hexdigest()[:24]


def _content_hash(arrays: dict, meta: str) -> str:
    """SHA-256 over every array (name, dtype, shape, bytes, in name order) and the metadata of a cache entry."""
    digest = hashlib.sha256(meta.encode())
    for name in sorted(arrays):
        value = np.ascontiguousarray(arrays[name])
        digest.update(f"{name}|{value.dtype.str}|{value.shape}".encode())
        digest.update(value.tobytes())
    return digest.hexdigest()


def _save_stage(path: Path, result: StageResult) -> None:
    """Write a cache entry atomically under a writer-unique temporary name (concurrent bakes of one yarn may write
    the same entry; both succeed), with the content hash that ``_load_stage`` checks."""
    path.parent.mkdir(parents=True, exist_ok=True)
    arrays = {f"t:{k}": np.asarray(v) for k, v in result.tables.items()}
    arrays.update({f"e:{k}": np.asarray(v) for k, v in result.errors.items()})
    meta = json.dumps({"attrs": result.attrs, "counts": result.counts})
    with atomic_path(path) as tmp, open(tmp, "wb") as f:
        np.savez(f, **arrays, meta=np.array(meta), checksum=np.array(_content_hash(arrays, meta)))


def _load_stage(path: Path) -> tuple[StageResult | None, str | None]:
    """(the cached result, None), or (None, why) for an entry that cannot be used: missing, unreadable, truncated,
    or whose content no longer matches its hash (edited). Any such entry is a miss; the stage is baked again and
    the entry overwritten."""
    if not path.exists():
        return None, None
    try:
        with np.load(path) as data:
            arrays = {k: data[k] for k in data.files if k.startswith(("t:", "e:"))}
            meta = str(data["meta"])
            if "checksum" not in data.files:
                return None, f"cache entry {path.name} has no checksum (an older version's): baking again"
            if str(data["checksum"]) != _content_hash(arrays, meta):
                return None, f"cache entry {path.name} does not match its checksum (edited or damaged): baking again"
            parsed = json.loads(meta)
    except Exception as e:  # noqa: BLE001  (zipfile.BadZipFile, EOFError, OSError, ValueError, KeyError, ...)
        return None, f"cache entry {path.name} is unreadable ({type(e).__name__}): baking again"
    tables = {k[2:]: v for k, v in arrays.items() if k.startswith("t:")}
    errors = {k[2:]: (v if v.ndim else float(v)) for k, v in arrays.items() if k.startswith("e:")}
    return StageResult(tables, errors, parsed["attrs"], parsed["counts"]), None


# the stages that draw the strip renderer on their input stages' pack, and those inputs
STAGE_INPUTS = {"closure": CLOSURE_INPUTS, "colour_closure": COLOUR_CLOSURE_INPUTS}
STAGES = {"dual_scattering": bake_dual_scattering_stage, "correction": bake_correction_stage,
          "shadowing": bake_shadowing_stage, "textures": bake_regular_stage, "flyaway": bake_flyaway_stage,
          "environment": bake_environment_stage, "interreflection": bake_yarn_hull_stage,
          "closure": bake_closure_stage, "colour_closure": bake_colour_closure_stage}


def stages_for(spec: YarnSpec, only: list[str] | None = None, needs: dict | None = None) -> list[str]:
    """Stages to bake: all that apply to the yarn, narrowed by ``only`` (stage or table-group names) and by what a
    scene needs (``scene_needs``)."""
    stages = [s for s in STAGE_ORDER if s != "flyaway" or spec.has_flyaways]
    if needs is not None and not needs["environment"]:
        stages.remove("environment")
    if only is not None:
        if not any(only):
            raise FormatError(f"--only names no table group (known: {', '.join(STAGE_ORDER)})")
        unknown = [o for o in only if o not in STAGE_ORDER]
        if unknown:
            raise FormatError(f"--only {','.join(unknown)}: unknown table group (known: {', '.join(STAGE_ORDER)})")
        stages = [s for s in stages if s in only or (s in ("closure", "colour_closure") and "correction" in only)]
    if "closure" in stages and not set(CLOSURE_INPUTS) <= set(stages):
        stages.remove("closure")  # a partial pack keeps the paper's ξ (ASSET_PACK.md §6)
    if "colour_closure" in stages and "closure" not in stages:
        stages.remove("colour_closure")  # it starts from the closure's ξ_ms
    return stages


def scene_needs(scene, spec: YarnSpec) -> dict:
    """What a scene needs of a yarn's pack: environment light or not, and the texture height in texels for the
    largest on-screen yarn width (power of two, 8–512), width from the period/diameter aspect."""
    from data_formats.scene import EnvironmentLight

    pixel = pixel_size(scene_camera(scene))  # at the look-at point: the nearest plausible distance
    widths = [2 * entry.radius / pixel for entry in scene.yarns if entry.spec.name == spec.name]
    height = int(min(512, max(8, 2 ** math.ceil(math.log2(max(widths or [8.0]))))))
    width = int(min(4096, 2 ** math.ceil(math.log2(height * spec.geometry.ply_pitch / (2 * spec.radius)))))
    return {"environment": any(isinstance(light, EnvironmentLight) for light in scene.lights),
            "texture_height": height, "texture_width": width, "on_screen_width_px": max(widths or [0.0])}


def _check_fiber_windows(spec: YarnSpec, stages) -> None:
    """Refuse, before the first stage runs, a yarn whose fiber windows would not fit in memory: the traced stages
    generate three periods of regular fibers, the flyaway stage ``flyaway_periods + 1`` periods with flyaways."""
    if set(stages) - {"dual_scattering", "environment"}:
        check_fiber_budget(spec, 3 * spec.geometry.ply_pitch, flyaways=False)
    if "flyaway" in stages:
        check_fiber_budget(spec, (flyaway_periods(spec) + 1) * spec.geometry.ply_pitch)


def _check_setting(where: str, value, preset) -> None:
    """``value`` may replace the preset's ``preset``: the same kind (a table with known keys, a yes/no, a count ≥ 1,
    a list of as many counts)."""
    if isinstance(preset, dict):
        if not isinstance(value, dict):
            raise FormatError(f"{where}: expected a table of {', '.join(preset)}, got {value!r}")
        for key, item in value.items():
            if key not in preset:
                raise FormatError(f"{where}.{key}: unknown setting (known: {', '.join(preset)})")
            _check_setting(f"{where}.{key}", item, preset[key])
    elif isinstance(preset, bool):
        if not isinstance(value, bool):
            raise FormatError(f"{where} = {value!r}: expected true or false")
    elif isinstance(preset, (tuple, list)):
        if (not isinstance(value, (tuple, list)) or len(value) != len(preset)
                or not all(isinstance(v, int) and not isinstance(v, bool) and v >= 1 for v in value)):
            raise FormatError(f"{where} = {value!r}: expected {len(preset)} integers ≥ 1")
    elif isinstance(value, bool) or not isinstance(value, int) or value < 1:
        raise FormatError(f"{where} = {value!r}: expected an integer ≥ 1")


def check_overrides(overrides: dict, quality: str = "draft") -> None:
    """Refuse, in one line naming it, a stage override the preset ``quality`` has no setting for or a value of
    another kind than the preset's (a misspelt key would otherwise bake the preset's value without a word)."""
    if not isinstance(overrides, dict):
        raise FormatError(f"bake settings: expected a table of stages, got {overrides!r}")
    for stage, values in overrides.items():
        if stage not in QUALITY[quality]:
            raise FormatError(f"bake settings [{stage}]: unknown stage (known: {', '.join(QUALITY[quality])})")
        _check_setting(stage, values, QUALITY[quality][stage])


def load_settings(path) -> dict:
    """The stage overrides of a bake settings file (TOML: one table per stage, e.g. ``[correction]`` with
    ``n_theta = 9``), checked against the draft preset's settings (every preset has the same keys)."""
    path = regular_file(path, "bake settings (.toml)")
    try:
        data = tomllib.loads(path.read_text(encoding="utf-8"))
    except (OSError, UnicodeDecodeError, tomllib.TOMLDecodeError) as exc:
        raise FormatError(f"{path}: cannot read bake settings ({exc.__class__.__name__}: {exc})") from None
    try:
        check_overrides(data)
    except FormatError as exc:
        raise FormatError(f"{path}: {exc}") from None
    return data


def merge_overrides(*parts: dict | None) -> dict | None:
    """Stage overrides ``parts`` merged stage by stage, later ones winning; None when there are none."""
    out = {}
    for part in parts:
        for stage, values in (part or {}).items():
            out[stage] = {**out.get(stage, {}), **values}
    return out or None


def bake_plan(spec: YarnSpec, quality: str = "draft", only=None, needs=None, seed: int = 0,
              overrides=None) -> tuple[dict, list[str]]:
    """(settings per stage, stages to bake) of a bake (``bake`` explains the arguments), after checking the seed,
    the quality and that the yarn's fiber windows fit in memory; nothing is baked."""
    if isinstance(seed, bool) or not isinstance(seed, (int, np.integer)) or not 0 <= seed <= MAX_SEED:
        raise FormatError(f"seed = {seed!r}: expected an integer in [0, 2^62 - 1] (the stages derive int64 batch "
                          f"seeds from it)")
    if quality not in QUALITY:
        raise FormatError(f"quality {quality!r} is not one of {', '.join(QUALITY)}")
    check_overrides(overrides or {}, quality)
    settings = {k: {**v, **(overrides or {}).get(k, {})} for k, v in QUALITY[quality].items()}
    if needs is not None:
        for stage in ("textures", "flyaway"):
            settings[stage]["height"] = needs["texture_height"]
            settings[stage]["width"] = needs["texture_width"]
    correction = settings["correction"]
    settings["closure"] = {"spp": correction["spp"], "batches": correction["batches"], **settings["closure"],
                           "rows": max(correction["rows"], correction["n_v"]),
                           "inputs": {s: {"settings": settings[s], "version": STAGE_VERSION[s]}
                                      for s in CLOSURE_INPUTS}}
    closure = settings["closure"]
    settings["colour_closure"] = {**{k: closure[k] for k in ("spp", "batches", "rows")}, **settings["colour_closure"],
                                  "inputs": {s: {"settings": settings[s], "version": STAGE_VERSION[s]}
                                             for s in COLOUR_CLOSURE_INPUTS}}
    stages = stages_for(spec, only, needs)
    if not closure["split"] and "colour_closure" in stages:
        stages.remove("colour_closure")  # it closes the split ξ_ms, which the closure then does not bake
    _check_fiber_windows(spec, stages)
    return settings, stages


def run_stage(spec: YarnSpec, stage: str, settings: dict, seed: int, use_cache: bool = True,
              progress=None, inputs: dict | None = None) -> tuple[StageResult, dict]:
    """(result, summary row) of one stage: from the stage cache when a valid entry exists, else baked and cached.
    The row holds seconds, cached, tables, error_estimate (the largest of its tables) and, when an entry was
    damaged, cache_warning. Deterministic for a seed whatever the thread count, so any process may run it.
    ``inputs`` (the closures only): stage → ``run_stage``'s (result, row) of each of its ``STAGE_INPUTS``."""
    key = stage_key(stage, spec, settings, seed)
    path = cache_dir() / f"{stage}-{key}.npz"
    t0 = time.perf_counter()
    result, damaged = _load_stage(path) if use_cache else (None, None)
    cached = result is not None
    if result is None:
        extra = {}
        if stage in STAGE_INPUTS:
            given = {s: inputs[s][0] for s in STAGE_INPUTS[stage]}
            writer = _input_pack_writer(spec, seed, {s: given[s] for s in CLOSURE_INPUTS})
            extra = {"inputs": given, "write_pack_to": writer}
        result = STAGES[stage](spec, settings, seed, progress, **extra)
        if use_cache:
            _save_stage(path, result)
    worst = max((float(np.max(e)) if np.ndim(e) else float(e)) for e in result.errors.values())
    row = {"seconds": time.perf_counter() - t0, "cached": cached, "tables": len(result.tables), "error_estimate": worst}
    if damaged:
        row["cache_warning"] = damaged
    return result, row


def write_baked_pack(spec: YarnSpec, output, quality: str, settings: dict, stages: list[str], needs, seed: int,
                     results: dict) -> dict:
    """Write the pack of ``results`` (stage → ``run_stage``'s (result, row)) with its provenance; returns the
    summary (stage → row)."""
    tables, errors, attrs, counts = {}, {}, {}, {}
    for stage in stages:
        result = results[stage][0]
        tables.update(result.tables)
        errors.update(result.errors)
        attrs.update(result.attrs)
        counts[stage] = result.counts
    summary = {stage: results[stage][1] for stage in stages}
    yarn = {"name": spec.name, "units": spec.units, "radius": spec.radius, "period": spec.geometry.ply_pitch,
            "plies": spec.geometry.plies}
    provenance = {"yarn_spec_toml": dumps_spec(spec),
                  "bake_settings": {"quality": quality, "stages": stages, "settings": settings, "needs": needs},
                  "seed": int(seed), "code_version": importlib.metadata.version("knit"),
                  "timings": {s: round(v["seconds"], 4) for s, v in summary.items()}, "sample_counts": counts}
    write_pack(output, yarn, provenance, fiber_bcsdf_attrs(spec.optics), tables, errors, attrs)
    return summary


def _input_pack_writer(spec: YarnSpec, seed: int, inputs: dict):
    """``write(path, xi_view, split=None)``: the pack of the closure's input stages with ``correction/xi_view`` =
    ``xi_view`` and, with ``split`` = (ss, ms), ``correction/xi_view_ss`` and ``_ms`` (closure iterates; their error
    estimate in this temporary pack: the paper's ξ's at the views)."""
    corr = inputs["correction"]
    error = papers_xi_at_views(corr.errors["correction/xi"])

    def write(path, xi_view, split=None):
        results = {s: (r, {"seconds": 0.0}) for s, r in inputs.items()}
        tables = {"correction/xi_view": xi_view}
        if split is not None:
            tables.update({"correction/xi_view_ss": split[0], "correction/xi_view_ms": split[1]})
        results["correction"] = (StageResult({**corr.tables, **tables},
                                             {**corr.errors, **{name: error for name in tables}}, corr.attrs,
                                             corr.counts),
                                 {"seconds": 0.0})
        write_baked_pack(spec, path, "closure input", {}, list(inputs), None, seed, results)
    return write


def _lazy_progress(progress_factory, stage):
    """A progress callback that asks ``progress_factory`` for the stage's bar only once the stage reports (a cached
    stage shows none)."""
    made = []

    def progress(done, total):
        if not made:
            made.append(progress_factory(stage))
        made[0](done, total)
    return progress


def bake(spec: YarnSpec, output, quality: str = "draft", only=None, needs=None, seed: int = 0, use_cache=True,
         on_stage=None, progress_factory=None, overrides=None) -> dict:
    """Bake ``spec`` into the asset pack ``output``; returns the summary (per stage: seconds, cached, error).

    ``overrides`` (stage → settings) replaces individual settings of the quality preset (tests, sweeps).
    ``on_stage(stage, index, count)`` is called as a stage starts; ``progress_factory(stage)`` returns the
    ``progress(done, total)`` callback for that stage (both optional, for the CLI). ``knitbake.scale_out`` runs the
    same stages as Dask tasks."""
    settings, stages = bake_plan(spec, quality, only, needs, seed, overrides)
    results = {}
    for i, stage in enumerate(stages):
        if on_stage:
            on_stage(stage, i, len(stages))
        results[stage] = run_stage(spec, stage, settings[stage], seed, use_cache,
                                   _lazy_progress(progress_factory, stage) if progress_factory else None,
                                   inputs=results if stage in STAGE_INPUTS else None)
    return write_baked_pack(spec, output, quality, settings, stages, needs, seed, results)
