"""Strip renderer against the reference path tracer on one scene: errors, times and a self-contained report.

``compare_scene`` renders the scene's reference (``knitbake.trace.reference`` + ``path_tracer``, or reads one), then the
strip renderer (``knitrun.render.pipeline``) with each ablation of Huang et al. 2025 Fig. 7 — plain DS, + ξ, +
fiber-level shadowing, + flyaways (= full) — plus the full renderer without the ξ and Ψ^Fiber tables and with the
paper's rank-1 factors in place of the full tables, and measures each against the reference with
``knitbake.compare.image_metrics`` (LDR-FLIP after our tone mapping, RMSE, relMSE). Strip times are the second of two
renders (the first pays Numba's cache load); the reference time is its fiber build plus path tracing. The report
folder holds ``reference.exr/.png``, per ablation ``strip_<name>.exr/.png``, ``flip_<name>.png`` (magma error map)
and ``diff_<name>.png`` (|difference|, ×4), ``side_by_side.png`` (reference | full | FLIP map; stacked for wide
images), ``report.md`` and ``report.json``.
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np

from data_formats.atomic import atomic_path
from data_formats.images import read_exr, write_exr, write_png
from data_formats.scene import load_scene
from knitbake.compare.image_metrics import compare_images, flip_error
from knitbake.trace.reference import read_summary, reference_seconds, trace_reference
from knitrun.render.ablations import ABLATION_LABELS, ABLATION_ORDER, ABLATIONS
from knitrun.render.pipeline import render


def _srgb_to_linear(c):
    """Display sRGB values in [0, 1] → linear, so that ``write_png`` (which encodes sRGB) shows them unchanged."""
    return np.where(c <= 0.04045, c / 12.92, ((c + 0.055) / 1.055) ** 2.4)


def compare_scene(scene_path, out_dir, reference=None, spp=None, packs=None, exposure=0.0, ablations=ABLATION_ORDER,
                  progress=None) -> dict:
    """Compare the strip renderer with the reference on ``scene_path``; write the report into ``out_dir``.
    ``reference``: an EXR to use instead of path tracing (its time is read from the JSON summary `knitbake reference`
    writes beside it, else unknown); ``spp``: reference samples
    per pixel (default: the scene's); ``packs``: yarn → pack overrides for the strip renderer. Returns the summary."""
    scene = load_scene(scene_path)
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    say = progress or (lambda message: None)
    if reference is not None:
        ref = read_exr(reference)
        summary = read_summary(reference)
        ref_seconds, ref_facts = (reference_seconds(summary) if summary else None), {"file": str(reference)}
        if ref.shape[:2] != (scene.camera.height, scene.camera.width):
            raise ValueError(f"{reference}: {ref.shape[1]}x{ref.shape[0]} image, the scene renders "
                             f"{scene.camera.width}x{scene.camera.height}")
    else:
        spp = spp or scene.render.spp
        say(f"reference: path tracing {scene.camera.width}x{scene.camera.height} at {spp} spp")
        ref, ref_facts = trace_reference(scene, spp, scene.render.seed, scene.render.max_depth)
        ref_seconds = reference_seconds(ref_facts)
    write_exr(out / "reference.exr", ref)
    write_png(out / "reference.png", ref, exposure)

    render(scene, packs, ABLATIONS["full"])  # pays the kernels' compile or cache load once
    rows, maps = {}, {}
    for name in ablations:
        say(f"strip renderer: {name}")
        result = render(scene, packs, ABLATIONS[name])
        seconds = sum(result.timings.values())
        flip_mean, error_map = flip_error(result.image, ref, exposure, magma=True)
        metrics = compare_images(result.image, ref, exposure, flip_mean=flip_mean)
        maps[name] = (result.image, error_map)
        write_exr(out / f"strip_{name}.exr", result.image)
        write_png(out / f"strip_{name}.png", result.image, exposure)
        write_png(out / f"flip_{name}.png", _srgb_to_linear(error_map))
        write_png(out / f"diff_{name}.png", 4.0 * np.abs(result.image - ref), exposure)
        rows[name] = {**metrics, "ms": seconds * 1e3, "ms_per_pass": {k: v * 1e3 for k, v in result.timings.items()},
                      "speedup": None if ref_seconds is None else ref_seconds / seconds}
    if "full" in rows:
        full, error_map = maps["full"]
        scale = 2.0 ** exposure
        wide = ref.shape[1] > ref.shape[0]  # stack wide images vertically
        write_png(out / "side_by_side.png", np.concatenate([np.clip(ref * scale, 0, 1), np.clip(full * scale, 0, 1),
                                                            _srgb_to_linear(error_map)], axis=0 if wide else 1))
    summary = {"scene": str(scene_path), "width": scene.camera.width, "height": scene.camera.height,
               "reference_seconds": ref_seconds, "reference": ref_facts, "exposure_stops": exposure,
               "flip_mode": next(iter(rows.values()))["flip_mode"] if rows else None,
               "ablations": {k: {m: v for m, v in row.items() if m != "flip_mode"} for k, row in rows.items()}}
    with atomic_path(out / "report.json") as tmp:
        Path(tmp).write_text(json.dumps(summary, indent=2))
    with atomic_path(out / "report.md") as tmp:
        Path(tmp).write_text(_markdown(summary))
    return summary


def _markdown(summary) -> str:
    ref_s = summary["reference_seconds"]
    lines = [f"# Strip renderer vs reference: `{summary['scene']}`", "",
             f"{summary['width']}×{summary['height']}; reference "
             + (f"{ref_s:.1f} s ({summary['reference'].get('spp')} spp)" if ref_s else f"from {summary['reference']}")
             + f". FLIP: {summary['flip_mode']}.", "",
             "| model | FLIP | RMSE | relMSE | strip time (ms) | speed-up vs reference |", "|---|---|---|---|---|---|"]
    for name, row in summary["ablations"].items():
        speed = f"{row['speedup']:.0f}×" if row["speedup"] else "—"
        lines.append(f"| {ABLATION_LABELS.get(name, name)} | {row['flip']:.4f} | {row['rmse']:.4f} | "
                     f"{row['rel_mse']:.4f} | {row['ms']:.0f} | {speed} |")
    lines += ["", "![reference | full | FLIP](side_by_side.png)", ""]
    for name in summary["ablations"]:
        lines.append(f"**{ABLATION_LABELS.get(name, name)}**: ![strip](strip_{name}.png) ![FLIP](flip_{name}.png)")
        lines.append("")
    return "\n".join(lines)
