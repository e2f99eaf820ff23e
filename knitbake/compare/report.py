"""Strip renderer against the reference path tracer on one scene: errors next to the reference's own floors, times
and a self-contained report.

``compare_scene`` renders the scene's reference (``knitbake.trace.reference`` + ``path_tracer``, or reads one), then the
strip renderer (``knitrun.render.pipeline``) with each ablation of ``knitrun.render.ablations`` — the ladder of
Huang et al. 2025 Fig. 7, plain DS, + ξ, + fiber-level shadowing, + yarn-level inter-reflection (= full), then + the
flyaway layer (off by default) — plus the full renderer without the ξ and Ψ^Fiber tables and with the paper's
rank-1 factors in place of the full tables, and measures each against the reference with
``knitbake.compare.image_metrics`` (LDR-FLIP after our tone mapping, RMSE, relMSE). Strip times are the second of two
renders (the first pays Numba's cache load); the reference time is its fiber build plus path tracing. The report
folder holds ``reference.exr/.png``, per ablation ``strip_<name>.exr/.png``, ``flip_<name>.png`` (magma error map)
and ``diff_<name>.png`` (|difference|, ×4), ``side_by_side.png`` (reference | full | FLIP map of the two at the
yarn scale; stacked for wide images), ``report.md`` and ``report.json``.

The ruler. One path-traced fiber instance is not the only right image: another draw of the same yarn's fibers
differs from it by as much as a model may. So every error is reported next to two floors, the reference against
itself (``FLOORS``): the **fiber-instance floor**, a reference of another fiber instance traced with another sampling
seed, and the **Monte Carlo floor**, the same fibers traced with another sampling seed (at the reference's spp).
Errors are measured per pixel and at the yarn scale (``image_metrics.yarn_scale_metrics``: images box-filtered to
the yarn's projected diameter, ``yarn_diameter_px``), and the yarn-scale errors also as a ratio to the instance
floor's at the same scale: a model at ratio 1 is as close to the reference as another fiber instance is.

One instance's mean radiance is itself a draw: over eight draws of the back-lit straight yarn it varies by 5.4 % (its
flyaways), as much as the ±5 % a model's mean is held to. Given further fiber instances (``instances``), the report
adds the **ensemble** (``image_metrics.ensemble_metrics``): each model's mean radiance over the mean of all K
instances (the reference, the instance floor and the further ones), with the instances' own spread, and its
leave-one-out yarn-scale rel L1 over the ensemble floor.

The yarn scale filters the look away: a strip image of polished tubes and one of matte cotton can have the same
errors there. So every row also has its **sub-yarn contrast** (``image_metrics.sub_yarn_contrast``): the brightness
variation inside a yarn's width over the reference's, with the path tracer's noise taken off the reference's by the
Monte Carlo floor; the floors' rows show how far another draw's contrast lies from the reference's.
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np

from data_formats.atomic import atomic_path
from data_formats.errors import FormatError
from data_formats.images import read_exr, write_exr, write_png
from data_formats.scene import load_scene
from knitbake.compare.image_metrics import (compare_images, ensemble_floor, ensemble_metrics, flip_error,
                                            sub_yarn_contrast, yarn_filter, yarn_scale_metrics)
from knitbake.trace.reference import read_summary, reference_seconds, trace_reference
from knitrun.render.ablations import ABLATION_LABELS, ABLATION_ORDER, ABLATIONS, combined
from knitrun.render.camera import pixel_size, scene_camera
from knitrun.render.pipeline import render


def _srgb_to_linear(c):
    """Display sRGB values in [0, 1] → linear, so that ``write_png`` (which encodes sRGB) shows them unchanged."""
    return np.where(c <= 0.04045, c / 12.92, ((c + 0.055) / 1.055) ** 2.4)


# floor → (sampling seed offset, fiber seed offset) from the reference's seed, and what the floor image is
FLOORS = {"instance": ((1, 1), "another fiber instance traced with another sampling seed"),
          "monte_carlo": ((1, 0), "the same fibers traced with another sampling seed")}
FLOOR_LABELS = {"instance": "reference, other fiber instance (instance floor)",
                "monte_carlo": "reference, other sampling seed (Monte Carlo floor)"}


def yarn_diameter_px(scene) -> float:
    """The widest yarn entry's diameter on screen, in pixels, at the camera's look-at distance."""
    return 2.0 * max(entry.radius for entry in scene.yarns) / pixel_size(scene_camera(scene))


def _metrics(image, ref, diameter, exposure, magma=False):
    """Pixel and yarn-scale metrics of ``image`` against ``ref`` (and the pixel FLIP map when ``magma``)."""
    flip_mean, error_map = flip_error(image, ref, exposure, magma=magma)
    row = compare_images(image, ref, exposure, flip_mean=flip_mean)
    row["yarn"] = yarn_scale_metrics(image, ref, diameter, exposure)
    return row, error_map


def _to_floor(row, floor):
    """The yarn-scale errors (and pixel FLIP) of ``row`` over the instance floor's at the same scale."""
    if floor is None:
        return None
    pairs = {"rel_l1": (row["yarn"]["rel_l1"], floor["yarn"]["rel_l1"]),
             "rel_l1_2x": (row["yarn"]["rel_l1_2x"], floor["yarn"]["rel_l1_2x"]),
             "flip_yarn": (row["yarn"]["flip"], floor["yarn"]["flip"]), "flip": (row["flip"], floor["flip"])}
    return {k: (a / b if b > 0 else None) for k, (a, b) in pairs.items()}


def _reference_image(scene, path, spp, seed, fiber_seed, say, what, future=None):
    """A reference: read from ``path`` (checked against the scene's size; its cost from its summary), the result of
    ``future`` (``knitbake.scale_out.submit_reference``, the same image) or traced here."""
    if path is not None:
        image = read_exr(path)
        if image.shape[:2] != (scene.camera.height, scene.camera.width):
            raise FormatError(f"{path}: {image.shape[1]}x{image.shape[0]} image, the scene renders "
                              f"{scene.camera.width}x{scene.camera.height}")
        summary = read_summary(path)
        return image, {"file": str(path), **({"spp": summary.get("spp")} if summary else {})}, \
            (reference_seconds(summary) if summary else None)
    say(f"{what}: path tracing {scene.camera.width}x{scene.camera.height} at {spp} spp (seed {seed}, fiber seed "
        f"{fiber_seed}){' on the cluster' if future is not None else ''}")
    image, facts = future.result() if future is not None else \
        trace_reference(scene, spp, seed, scene.render.max_depth, fiber_seed=fiber_seed)
    return image, facts, reference_seconds(facts)


def compare_scene(scene_path, out_dir, reference=None, spp=None, packs=None, exposure=0.0, ablations=ABLATION_ORDER,
                  floors=True, floor_references=None, progress=None, client=None, instances=None) -> dict:
    """Compare the strip renderer with the reference on ``scene_path``; write the report into ``out_dir``; return the
    summary.

    ``reference``: an EXR to use instead of path tracing one (its cost is read from the JSON summary `knitbake
    reference` writes beside it, else unknown); ``spp``: samples per pixel of what is path traced (default: the
    scene's); ``packs``: yarn → pack overrides for the strip renderer; ``ablations``: the models drawn, each an
    ablation or a combination "a+b" (``knitrun.render.ablations.combined``). ``floor_references``: floor name
    (``FLOORS``) → an EXR of that floor image, rendered at the reference's spp with the seeds ``FLOORS`` gives; a
    floor not given is path traced when ``floors`` is true and the reference is traced here too (a given
    reference's seeds are not known), else not reported. ``client``: a Dask client
    (``knitbake.scale_out.dask_client``) that traces the reference and the floors at once, as tasks (the same
    images). ``instances``: EXRs of further fiber instances of the reference (other fiber seeds, the reference's
    spp; ``benchmarks/bench_instances.py``): with the reference and the instance floor at least three, the report
    adds the ensemble (module docstring)."""
    scene = load_scene(scene_path)
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    say = progress or (lambda message: None)
    spp = spp or scene.render.spp
    seed = scene.render.seed
    traced = {name: (seed + d_sample, seed + d_fiber) for name, ((d_sample, d_fiber), _) in FLOORS.items()
              if (floor_references or {}).get(name) is None and floors and reference is None}
    if reference is None:
        traced["reference"] = (seed, seed)
    futures = {}
    if client is not None:
        from knitbake.scale_out import submit_reference

        futures = {name: submit_reference(client, scene, spp, s, f, scene.render.max_depth)
                   for name, (s, f) in traced.items()}
    ref, ref_facts, ref_seconds = _reference_image(scene, reference, spp, seed, seed, say, "reference",
                                                   futures.get("reference"))
    write_exr(out / "reference.exr", ref)
    write_png(out / "reference.png", ref, exposure)
    diameter = yarn_diameter_px(scene)
    floor_rows, floor_facts, floor_images = {}, {}, {}
    for name, ((d_sample, d_fiber), _) in FLOORS.items():
        given = (floor_references or {}).get(name)
        if given is None and not (floors and reference is None):
            continue
        image, facts, _ = _reference_image(scene, given, spp, seed + d_sample, seed + d_fiber, say, f"{name} floor",
                                           futures.get(name))
        write_exr(out / f"floor_{name}.exr", image)
        write_png(out / f"floor_{name}.png", image, exposure)
        floor_rows[name], _ = _metrics(image, ref, diameter, exposure)
        floor_images[name] = image
        floor_facts[name] = facts
    monte_carlo = floor_images.get("monte_carlo")  # the path tracer's noise in the contrast (``sub_yarn_contrast``)
    for name, row in floor_rows.items():
        row["contrast"] = sub_yarn_contrast(floor_images[name], ref, diameter, monte_carlo, test_traced=True)
    instance = floor_rows.get("instance")
    ensemble, draws = None, []
    if instances:
        draws = [ref] + ([floor_images["instance"]] if instance is not None else []) + \
            [_reference_image(scene, path, spp, None, None, say, "instance")[0] for path in instances]
        ensemble = {**ensemble_floor(draws, diameter), "files": [str(path) for path in instances]}
        filtered = [yarn_filter(draw, diameter) for draw in draws]  # once for every model measured against them

    render(scene, packs, ABLATIONS["full"])  # pays the kernels' compile or cache load once
    rows, full = {}, None
    for name in ablations:
        say(f"strip renderer: {name}")
        result = render(scene, packs, combined(name))
        seconds = sum(result.timings.values())
        metrics, error_map = _metrics(result.image, ref, diameter, exposure, magma=True)
        if name == "full":
            full = result.image
        write_exr(out / f"strip_{name}.exr", result.image)
        write_png(out / f"strip_{name}.png", result.image, exposure)
        write_png(out / f"flip_{name}.png", _srgb_to_linear(error_map))
        write_png(out / f"diff_{name}.png", 4.0 * np.abs(result.image - ref), exposure)
        rows[name] = {**metrics, "to_instance_floor": _to_floor(metrics, instance), "ms": seconds * 1e3,
                      "contrast": sub_yarn_contrast(result.image, ref, diameter, monte_carlo),
                      "ms_per_pass": {k: v * 1e3 for k, v in result.timings.items()},
                      "speedup": None if ref_seconds is None else ref_seconds / seconds, "xi": result.facts["xi"]}
        if ensemble is not None:
            rows[name]["ensemble"] = ensemble_metrics(result.image, draws, diameter, ensemble, filtered)
    if full is not None:
        _, yarn_map = flip_error(yarn_filter(full, diameter).astype(np.float32),
                                 yarn_filter(ref, diameter).astype(np.float32), exposure, magma=True)
        scale = 2.0 ** exposure
        wide = ref.shape[1] > ref.shape[0]  # stack wide images vertically
        write_png(out / "side_by_side.png", np.concatenate([np.clip(ref * scale, 0, 1), np.clip(full * scale, 0, 1),
                                                            _srgb_to_linear(yarn_map)], axis=0 if wide else 1))
    summary = {"scene": str(scene_path), "width": scene.camera.width, "height": scene.camera.height,
               "yarn_px": diameter, "reference_seconds": ref_seconds, "reference": ref_facts,
               "exposure_stops": exposure, "flip_mode": next(iter(rows.values()))["flip_mode"] if rows else None,
               "floors": {k: {**_without_mode(row), "what": FLOORS[k][1], "image": floor_facts[k]}
                          for k, row in floor_rows.items()},
               "ablations": {k: _without_mode(row) for k, row in rows.items()},
               **({"ensemble": ensemble} if ensemble is not None else {})}
    with atomic_path(out / "report.json") as tmp:
        Path(tmp).write_text(json.dumps(summary, indent=2))
    with atomic_path(out / "report.md") as tmp:
        Path(tmp).write_text(_markdown(summary))
    return summary


def _without_mode(row):
    """A metrics row without its FLIP mode text (the summary states it once)."""
    return {m: v for m, v in row.items() if m != "flip_mode"}


def _fmt(x, spec=".3f"):
    return "—" if x is None else format(x, spec)


def _markdown(summary) -> str:
    ref_s = summary["reference_seconds"]
    d = summary["yarn_px"]
    floors = summary["floors"]
    inst = floors.get("instance")
    lines = [f"# Strip renderer vs reference: `{summary['scene']}`", "",
             f"{summary['width']}×{summary['height']}; reference "
             + (f"{ref_s:.1f} s ({summary['reference'].get('spp')} spp)" if ref_s else f"from {summary['reference']}")
             + f". Yarn scale: box filter of the yarn's projected diameter, {d:.1f} px (and 2×). FLIP:"
             f" {summary['flip_mode']}.", "",
             "## Verdict", "",
             "Ratio to floor: the model's yarn-scale rel L1 over that of another fiber instance of the reference "
             "(1 = as close as another draw of the same fibers)." if inst else
             "No floors: the reference was given without floor images, so no error has a ratio to the floor.", "",
             "Ply-scale contrast: the brightness variation inside a yarn (d/6 to d/2) over the reference's, its "
             "path-tracing noise taken off " + ("with the Monte Carlo floor" if "monte_carlo" in floors else
                                                "— not here: no Monte Carlo floor, so the reference's counts its noise")
             + " (1 = the reference's; above 1 harder: tubes, grooves, streaks; below flatter).", "",
             "| model | mean radiance ratio | yarn-scale rel L1 | ratio to instance floor | ply-scale contrast | "
             "pixel FLIP | strip ms |",
             "|---|---|---|---|---|---|---|"]
    for name, row in floors.items():
        lines.append(f"| *{FLOOR_LABELS[name]}* | {row['yarn']['mean_ratio']:.3f} | {row['yarn']['rel_l1']:.3f} | "
                     f"{_fmt(row['yarn']['rel_l1'] / inst['yarn']['rel_l1'] if inst else None, '.2f')} | "
                     f"{_fmt(row['contrast']['ply'], '.2f')} | {row['flip']:.4f} | — |")
    for name, row in summary["ablations"].items():
        ratio = row["to_instance_floor"]["rel_l1"] if row["to_instance_floor"] else None
        lines.append(f"| {ABLATION_LABELS.get(name, name)} | {row['yarn']['mean_ratio']:.3f} | "
                     f"{row['yarn']['rel_l1']:.3f} | {_fmt(ratio, '.2f')} | "
                     f"{_fmt(row['contrast']['ply'], '.2f')} | {row['flip']:.4f} | {row['ms']:.0f} |")
    xi = summary["ablations"].get("full", {}).get("xi")
    if xi:
        lines += ["", "ξ of the full model: " + "; ".join(f"{yarn}: {how}" for yarn, how in xi.items()) + "."]
    # an ablation whose tables the pack lacks draws what it falls back to: say so beside its row's figures
    lacking = [f"{ABLATION_LABELS.get(name, name)}: "
               + "; ".join(f"{yarn}: ξ {how}" for yarn, how in row["xi"].items())
               for name, row in summary["ablations"].items()
               if name != "full" and any("the pack has no" in how for how in (row.get("xi") or {}).values())]
    if lacking:
        lines += ["", "Rows drawn without the tables they ask for: " + ". ".join(lacking) + "."]
    if summary.get("ensemble"):
        lines += _ensemble_markdown(summary)
    lines += ["", "## Every metric", "",
              "Yarn scale (d = the projected yarn diameter): rel L1, relMSE and FLIP of the box-filtered images; mean "
              "and worst-tile radiance ratios over tiles of 2d px where the reference has signal. Contrast: the "
              "sub-yarn contrast over the reference's at the ply scale (d/6 to d/2) and across the yarn (d/2 to d).",
              "",
              "| model | FLIP | RMSE | relMSE | yarn FLIP | rel L1 (d) | rel L1 (2d) | relMSE (d) | relMSE (2d) | "
              "mean ratio | worst tile | contrast: ply | across | speed-up |",
              "|---|---|---|---|---|---|---|---|---|---|---|---|---|---|"]
    for label, row in [(FLOOR_LABELS[k], r) for k, r in floors.items()] + \
            [(ABLATION_LABELS.get(k, k), r) for k, r in summary["ablations"].items()]:
        y = row["yarn"]
        speed = f"{row['speedup']:.0f}×" if row.get("speedup") else "—"
        lines.append(f"| {label} | {row['flip']:.4f} | {row['rmse']:.4f} | {row['rel_mse']:.4f} | {y['flip']:.4f} | "
                     f"{y['rel_l1']:.3f} | {y['rel_l1_2x']:.3f} | {y['rel_mse']:.4f} | {y['rel_mse_2x']:.4f} | "
                     f"{y['mean_ratio']:.3f} | {_fmt(y['worst_tile_ratio'])} | "
                     f"{_fmt(row['contrast']['ply'], '.2f')} | "
                     f"{_fmt(row['contrast']['across'], '.2f')} | {speed} |")
    lines += ["", "![reference | full | FLIP at the yarn scale](side_by_side.png)", ""]
    for name in summary["ablations"]:
        lines.append(f"**{ABLATION_LABELS.get(name, name)}**: ![strip](strip_{name}.png) ![FLIP](flip_{name}.png)")
        lines.append("")
    return "\n".join(lines)


def _ensemble_markdown(summary) -> list:
    """The report's section on the ensemble of fiber instances (module docstring)."""
    e = summary["ensemble"]
    lines = ["", f"## Against {e['instances']} fiber instances", "",
             f"The reference, its instance floor and {len(e['files'])} further draws of the fibers. Their mean "
             f"radiances spread by {100 * e['mean_sd']:.1f} % (sd; the ensemble's mean: ±{100 * e['mean_se']:.1f} %). "
             f"Ensemble floor: an instance's yarn-scale rel L1 against the mean of the others, "
             f"{e['rel_l1']:.3f} (each: {', '.join(f'{x:.3f}' for x in e['rel_l1_each'])}).", "",
             "| model | mean radiance ratio (ensemble) | yarn-scale rel L1 (leave one out) | ratio to ensemble floor |",
             "|---|---|---|---|"]
    for name, row in summary["ablations"].items():
        r = row.get("ensemble")
        if r:
            spread = r["mean_ratio"] * e["mean_se"]
            lines.append(f"| {ABLATION_LABELS.get(name, name)} | {r['mean_ratio']:.3f} ± {spread:.3f} | "
                         f"{r['rel_l1']:.3f} | {_fmt(r['to_floor'], '.2f')} |")
    return lines
