"""``knitbake``: the offline baker's command line (yarn presets, fibers, inspect, validate).

Thin: parse, call ``data_formats``/``knitbake``, report. Errors are one line on stderr (see ``cli.common``).
"""

from __future__ import annotations

import os
import sys
import time
from pathlib import Path

import click

from cli.common import CONTEXT, SEED, FriendlyGroup, SuffixPath, check_outputs, echo_json, echo_tree, file_kind
from data_formats import FormatError
from data_formats.input_files import regular_file
from data_formats.yarn_spec import FIELDS, SECTIONS, describe_spec, dumps_spec, load_preset, preset_names, resolve_yarn


@click.group(name="knitbake", cls=FriendlyGroup, context_settings=CONTEXT)
@click.version_option(package_name="knit", prog_name="knitbake")
def main():
    """Offline baker of knit: yarn types in, asset packs out.

    \b
    Examples:
      knitbake yarn list
      knitbake yarn show cotton1
      knitbake fibers cotton1 -o cotton1_fibers.bcc --preview cotton1.png
      knitbake inspect cotton1_fibers.bcc
      knitbake validate my_yarn.toml
    """


@main.group(cls=FriendlyGroup)
def yarn():
    """Yarn types: the built-in presets and yarn-spec TOML files.

    Example: knitbake yarn show cotton1
    """


@yarn.command("list")
@click.option("--json", "as_json", is_flag=True, help="Print JSON.")
def yarn_list(as_json):
    """List the built-in presets (measured yarns of Zhao et al. 2016).

    Example: knitbake yarn list --json
    """
    rows = [describe_spec(load_preset(name)) for name in preset_names()]
    if as_json:
        echo_json([{k: r[k] for k in ("name", "description", "plies", "fibers", "radius", "period", "units")}
                   for r in rows])
        return
    click.echo(f"{'name':<12}{'plies':>6}{'fibers':>8}{'radius':>10}{'period':>10}  units  description")
    for r in rows:
        click.echo(f"{r['name']:<12}{r['plies']:>6}{r['fibers']:>8}{r['radius']:>10.4f}{r['period']:>10.4f}  "
                   f"{r['units']:<5}  {r['description']}")


@yarn.command("show")
@click.argument("yarn_name", metavar="NAME|FILE")
@click.option("--json", "as_json", is_flag=True, help="Print JSON.")
@click.option("--toml", "as_toml", is_flag=True, help="Print the spec as TOML (a starting point for your own yarn).")
def yarn_show(yarn_name, as_json, as_toml):
    """Show every parameter of a preset or yarn-spec file, with units and provenance.

    Example: knitbake yarn show cotton1 --toml > my_yarn.toml
    """
    spec = resolve_yarn(yarn_name)
    if as_toml:
        click.echo(dumps_spec(spec), nl=False)
        return
    summary = describe_spec(spec)
    if as_json:
        echo_json(summary)
        return
    click.echo(f"{spec.name}: {spec.description}")
    click.echo(f"units: {spec.units}   outer radius: {spec.radius:.5g}   period (ply pitch): "
               f"{spec.geometry.ply_pitch:.5g}   flyaways: {'yes' if spec.has_flyaways else 'no'}")
    for section in SECTIONS:
        click.echo(f"[{section}]")
        obj = getattr(spec, section)
        for f in FIELDS:
            if f.section == section:
                unit = spec.units if f.unit == "length" else ("1/" + spec.units if f.unit == "1/length" else f.unit)
                value = getattr(obj, f.key)
                text = ", ".join(f"{v:.6g}" for v in value) if isinstance(value, tuple) else f"{value:.6g}" \
                    if isinstance(value, float) else str(value)
                click.echo(f"  {f.key:<24}{text:<28}{unit:<8}{f.doc}")
    click.echo("[provenance]")
    for key, text in spec.provenance.items():
        click.echo(f"  {key}: {text}")


@main.command()
@click.argument("path", type=click.Path(dir_okay=False))
@click.option("--json", "as_json", is_flag=True, help="Print JSON.")
@click.option("--radius", type=click.FloatRange(min=0.0, min_open=True),
              help="Yarn radius (file units) for the contact statistic of yarn curves; default: the file's own "
                   "radius (written by knitrun simulate).")
def inspect(path, as_json, radius):
    """Describe any file the toolchain reads, recognised by content: asset pack, yarn spec, yarn curves (HDF5 or
    BCC) — kind, counts, bounds, provenance, and for packs every table's error estimate. For yarn curves, the
    contact statistic (distance to the nearest other yarn over 2r, percentiles; 1 = touching, below 1 the yarns
    interpenetrate) on the first and the last frame, when the radius is known.

    Example: knitbake inspect cotton1.h5 --json
    """
    kind, module = file_kind(path)
    info = module.describe(path)
    if kind in ("yarn-curves", "bcc"):
        info["contact"] = _contact(path, kind, radius if radius is not None else info.get("radius"))
    elif radius is not None:
        raise FormatError(f"--radius applies to yarn curves, and {path} is a {kind} file")
    if as_json:
        echo_json(info)
        return
    tables = info.pop("tables", None) if kind == "asset-pack" else None
    info.pop("spec", None)
    echo_tree(info)
    if tables is not None:
        click.echo(f"tables ({len(tables)}):")
        for name, t in tables.items():
            err = t.get("error_estimate")
            err_text = "—" if err is None else f"{err:.3g} ({t.get('error_statistic') or t.get('error_kind')})"
            click.echo(f"  {name:<36}{str(tuple(t['shape'])):<22}error {err_text}")
            for key, value in t.get("notes", {}).items():
                click.echo(f"  {'':<36}{key} {value:.3g}" if isinstance(value, float) else f"  {'':<36}{key} {value}")


def _contact(path, kind, radius):
    """The contact statistic of yarn curves on their first and last frame, or why it is missing."""
    if radius is None:
        return "unknown yarn radius: pass --radius"
    from data_formats.bcc import read_bcc
    from data_formats.yarn_curves import read_yarn_curves
    from knitrun.sim.contact import contact_over_frames

    curves = read_yarn_curves(path) if kind == "yarn-curves" else read_bcc(path)
    return contact_over_frames(curves, radius, max_frames=2)


@main.command()
@click.argument("path", type=click.Path(dir_okay=False))
def validate(path):
    """Check a file's schema and numbers (no NaN/Inf, shapes, versions); exit 1 with the reasons.

    Example: knitbake validate cotton1.h5
    """
    regular_file(path, "a file the toolchain reads")
    try:
        kind, module = file_kind(path)
        problems = module.validate(path)
    except FormatError as exc:
        kind, problems = "file", [str(exc)]
    if problems:
        click.echo(f"{path}: INVALID {kind} ({len(problems)} problem{'s' * (len(problems) != 1)})", err=True)
        for p in problems:
            click.echo(f"  - {p}", err=True)
        sys.exit(1)
    click.echo(f"{path}: valid {kind}")


@main.command()
@click.argument("yarn_name", metavar="YARN")
@click.option("-o", "--output", type=SuffixPath(".h5", ".hdf5", ".bcc"), required=True,
              help="Fiber curves: .h5 (our yarn-curve HDF5) or .bcc (polylines).")
@click.option("--periods", type=click.FloatRange(min=0, min_open=True), default=1.0, show_default=True,
              help="Length of yarn to generate, in ply-twist periods.")
@click.option("--seed", type=SEED, default=0, show_default=True, help="Random seed (same seed → identical fibers).")
@click.option("--segments-per-period", type=click.IntRange(min=4), default=None,
              help="Polyline segments per period (default: 24 per turn).")
@click.option("--no-flyaways", is_flag=True, help="Regular fibers only.")
@click.option("--preview", type=click.Path(dir_okay=False), default=None,
              help="Also write a PNG: cross-section and side view.")
@click.option("--json", "as_json", is_flag=True, help="Print a JSON summary.")
def fibers(yarn_name, output, periods, seed, segments_per_period, no_flyaways, preview, as_json):
    """Generate the procedural fibers of a straight yarn and write them as curves.

    Example: knitbake fibers cotton1 --periods 2 -o cotton1.bcc --preview cotton1.png
    """
    from data_formats.bcc import write_bcc
    from data_formats.yarn_curves import make_yarn_curves, write_yarn_curves
    from knitbake.fibers.fiber_set import KIND_NAMES
    from knitbake.fibers.procedural_yarn import generate_fibers

    check_outputs({"--output": output, "--preview": preview}, [yarn_name])
    suffix = Path(output).suffix.lower()
    spec = resolve_yarn(yarn_name)
    t0 = time.perf_counter()
    fib = generate_fibers(spec, length=periods * spec.geometry.ply_pitch, seed=seed,
                          segments_per_period=segments_per_period, flyaways=not no_flyaways)
    t_gen = time.perf_counter() - t0
    curves = make_yarn_curves(fib.points, fib.offsets, yarn_type=fib.kind.astype("int32"),
                              yarn_types=[f"{spec.name}:{KIND_NAMES[k]}" for k in sorted(KIND_NAMES)],
                              curve_type="PL", units=spec.units, where=output)
    (write_bcc if suffix == ".bcc" else write_yarn_curves)(output, curves)
    summary = {"yarn": spec.name, "output": output, "fibers": fib.n_fibers, "segments": fib.n_segments,
               "regular": fib.info["regular"], "loops": fib.info["loops"], "hairs": fib.info["hairs"],
               "length": fib.z_end - fib.z_start, "units": spec.units, "seed": seed, "generate_s": t_gen,
               "fiber_pitch_change_mean": fib.info["fiber_pitch_change_mean"]}
    if preview:
        from knitbake.trace.preview import preview as write_preview

        summary["preview"] = {"path": preview, **write_preview(fib, spec.radius, preview)}
    if as_json:
        echo_json(summary)
        return
    click.echo(f"{spec.name}: {fib.n_fibers} fibers ({summary['regular']} regular, {summary['loops']} loops, "
               f"{summary['hairs']} hairs), {fib.n_segments} segments over {summary['length']:.4g} {spec.units} "
               f"in {t_gen * 1e3:.0f} ms → {output}")
    if preview:
        click.echo(f"preview → {preview}")


@main.command()
@click.argument("scene_path", metavar="SCENE", type=click.Path(dir_okay=False))
@click.option("-o", "--output", type=SuffixPath(".exr"), required=True,
              help="Linear float32 EXR; a tone-mapped PNG preview and a JSON summary are written next to it.")
@click.option("--spp", type=click.IntRange(min=1), default=None, help="Samples per pixel (default: the scene's).")
@click.option("--seed", type=SEED, default=None, help="Random seed of the path sampling (default: the scene's).")
@click.option("--fiber-seed", type=SEED, default=None,
              help="Random seed of the fibers (default: --seed). Another fiber seed draws another instance of the "
                   "same yarns: the fiber-instance floor of knitrun compare.")
@click.option("--max-depth", type=click.IntRange(min=1), default=None,
              help="Maximum scattering events per path (default: the scene's).")
@click.option("--exposure", type=float, default=0.0, show_default=True, help="PNG preview exposure in stops.")
@click.option("--geometry", type=click.Choice(["curves", "tubes"]), default="curves", show_default=True,
              help="Fibers as Embree's round curves, or tessellated into 6-sided tubes (the former path, to validate).")
@click.option("--batch-spp", type=click.IntRange(min=1), default=None,
              help="Sum the samples in batches of this many (the image a distributed run gives bit for bit; with "
                   "--scheduler/--workers each batch is a task). Default: one batch.")
@click.option("--frames", "frame_range", default=None, metavar="A:B",
              help="Frames A..B-1 of animated curves, each a reference; -o then needs a run of '#' for the frame "
                   "number (out/ref_####.exr).")
@click.option("--scheduler", default=None, metavar="ADDRESS",
              help="Run the batches and frames on this Dask scheduler (or $KNIT_DASK_SCHEDULER).")
@click.option("--workers", type=click.IntRange(min=1), default=None,
              help="Run them on an embedded Dask cluster of this many worker processes.")
@click.option("--resume", is_flag=True,
              help="Skip the frames whose EXR and JSON summary are already there from a run with the same settings "
                   "(an interrupted --frames run goes on where it stopped).")
@click.option("--json", "as_json", is_flag=True, help="Print a JSON summary (progress still goes to stderr).")
def reference(scene_path, output, spp, seed, fiber_seed, max_depth, exposure, geometry, batch_spp, frame_range,
              scheduler, workers, resume, as_json):
    """Path-trace a scene with explicit fibers: the ground truth every fast image is compared with.

    \b
    Examples:
      knitbake reference examples/scenes/straight_yarn_directional.toml -o ref.exr --spp 64
      knitbake reference anim.toml --frames 0:4 -o out/ref_####.exr --batch-spp 16 --workers 2
    """
    from data_formats.scene import load_scene, read_curves
    from knitbake.scale_out import SCHEDULER_ENV
    from knitbake.trace.reference import trace_reference, write_reference
    from knitrun.render.sequence import frame_path, parse_frames

    scene = load_scene(scene_path)
    spp = spp or scene.render.spp
    seed = scene.render.seed if seed is None else seed
    max_depth = max_depth or scene.render.max_depth
    frames = [scene.render.frame]
    if frame_range is not None:
        entry = next(e for e in scene.yarns if e.curves is not None)
        frames = list(parse_frames(frame_range, read_curves(entry.curves, scene.units).points.shape[0]))
        if len(frames) > 1 and frame_path(output, 0) == Path(output):
            raise FormatError(f"{output}: an output for {len(frames)} frames needs a run of '#' for the frame "
                              f"number, e.g. out/ref_####.exr")
    outputs = {f: str(frame_path(output, f)) for f in frames}
    if resume:
        settings = {"spp": spp, "batch_spp": batch_spp, "seed": seed, "max_depth": max_depth, "geometry": geometry,
                    "fiber_seed": seed if fiber_seed is None else fiber_seed}
        done = [f for f in frames if _finished_reference(outputs[f], {**settings, "frame": f})]
        if done:
            click.echo(f"--resume: frame(s) {', '.join(map(str, done))} already traced with these settings", err=True)
        frames = [f for f in frames if f not in done]
        outputs = {f: outputs[f] for f in frames}
        if not frames:
            return
    check_outputs({f"{label} of frame {f}": str(Path(o).with_suffix(suffix)) for f, o in outputs.items()
                   for label, suffix in (("--output", ".exr"), ("PNG preview", ".png"), ("JSON summary", ".json"))},
                  [scene_path])
    if scheduler or workers or os.environ.get(SCHEDULER_ENV):
        _distributed_reference(scene_path, scene, frames, outputs, spp, seed, fiber_seed, max_depth, geometry,
                               batch_spp, scheduler, workers, exposure, as_json)
        return
    if len(frames) > 1:
        summaries = []
        for f in frames:
            image, facts = trace_reference(_at_frame(scene, f), spp, seed, max_depth, fiber_seed=fiber_seed,
                                           geometry=geometry, batch_spp=batch_spp)
            summaries.append(write_reference(outputs[f], image, {"scene": scene_path, **facts}, exposure))
            click.echo(f"{outputs[f]}: frame {f}, {facts['render_s']:.1f} s, {facts['rays_per_s'] / 1e6:.2f} M rays/s",
                       err=True)
        if as_json:
            echo_json(summaries)
        return

    def built(facts):
        shape = (f"{facts['triangles']} triangles, tessellate {facts['tessellate_s']:.1f} s"
                 if facts["geometry"] == "tubes" else f"{facts['segments']} curve segments")
        click.echo(f"{scene_path}: {facts['fibers']} fibers, {shape} (sweep {facts['sweep_s']:.1f} s, "
                   f"Embree {facts['embree_build_s']:.1f} s)", err=True)

    with click.progressbar(length=spp, label=f"rendering {scene.camera.width}x{scene.camera.height}, {spp} spp",
                           file=sys.stderr, show_eta=True, show_percent=True) as bar:
        last = [0]

        def progress(done, total):
            bar.update(done - last[0])
            last[0] = done

        image, facts = trace_reference(_at_frame(scene, frames[0]), spp, seed, max_depth, progress=progress,
                                       on_built=built, fiber_seed=fiber_seed, geometry=geometry, batch_spp=batch_spp)
    output = outputs[frames[0]]
    summary = write_reference(output, image, {"scene": scene_path, **facts}, exposure)
    if as_json:
        echo_json(summary)
        return
    click.echo(f"{output}: {facts['render_s']:.1f} s, {facts['rays'] / 1e6:.1f} M rays, "
               f"{facts['rays_per_s'] / 1e6:.2f} M rays/s; preview {summary['preview']}")


def _at_frame(scene, frame: int):
    """``scene`` drawing ``frame`` of its curves."""
    import dataclasses

    return dataclasses.replace(scene, render=dataclasses.replace(scene.render, frame=frame))


def _finished_reference(exr, settings: dict) -> bool:
    """True when ``exr`` and the JSON summary beside it (written last) are there and the summary's ``settings``
    keys match."""
    from knitbake.trace.reference import read_summary

    summary = read_summary(exr)
    return summary is not None and Path(exr).is_file() and all(summary.get(k) == v for k, v in settings.items())


def _distributed_reference(scene_path, scene, frames, outputs, spp, seed, fiber_seed, max_depth, geometry,
                           batch_spp, scheduler, workers, exposure, as_json):
    """``knitbake reference`` on Dask: every frame's sample batches as tasks; each frame written as it finishes."""
    from distributed import as_completed

    from knitbake.scale_out import dask_client, submit_reference
    from knitbake.trace.reference import write_reference

    summaries = []
    with dask_client(scheduler, workers) as client:
        futures = {submit_reference(client, _at_frame(scene, f), spp, seed, fiber_seed, max_depth, batch_spp,
                                    geometry): f for f in frames}
        with click.progressbar(length=len(frames), label=f"{len(frames)} frame(s), {spp} spp", file=sys.stderr,
                               show_pos=True, show_eta=True) as bar:
            for future in as_completed(futures):
                f = futures[future]
                image, facts = future.result()
                summaries.append(write_reference(outputs[f], image, {"scene": scene_path, **facts}, exposure))
                bar.update(1)
    summaries.sort(key=lambda s: s["frame"])
    if as_json:
        echo_json(summaries if len(summaries) > 1 else summaries[0])
        return
    for summary in summaries:
        click.echo(f"{summary['output']}: frame {summary['frame']}, {summary['batches']} batch(es), "
                   f"{summary['render_s']:.1f} s of rendering in all, {summary['rays'] / 1e6:.1f} M rays")


def _bake_overrides(settings_path, whole_xi: bool) -> dict | None:
    """The stage overrides of ``--settings`` (a file) and ``--whole-xi``."""
    from knitbake.bake import load_settings, merge_overrides

    return merge_overrides(load_settings(settings_path) if settings_path else None,
                           {"closure": {"split": False}} if whole_xi else None)


@main.command("bake")
@click.argument("yarn_name", metavar="YARN")
@click.option("-o", "--output", type=SuffixPath(".h5", ".hdf5"), required=True, help="The asset pack (.h5).")
@click.option("--quality", type=click.Choice(["draft", "standard", "final"]), default="draft", show_default=True,
              help="Resolution and sample counts of every table (the speed/accuracy trade: see BENCHMARKS.md).")
@click.option("--only", default=None, help="Comma-separated table groups to bake (dual_scattering, correction, "
                                           "shadowing, textures, flyaway, environment, interreflection; closure "
                                           "comes with correction when its four inputs are baked).")
@click.option("--scene", "scene_path", type=click.Path(dir_okay=False), default=None,
              help="Bake only what this scene needs (no I_M without environment light; texture size from the "
                   "largest on-screen yarn width).")
@click.option("--seed", type=SEED, default=0, show_default=True, help="Same seed and settings → identical pack.")
@click.option("--threads", type=click.IntRange(min=1), default=None, help="Worker threads (default: all cores).")
@click.option("--no-cache", is_flag=True, help="Recompute every stage instead of reusing cached ones.")
@click.option("--whole-xi", is_flag=True,
              help="Close one ξ for single and multiple scattering together, not also apart (what the ablation "
                   "whole_xi draws; the renderer's default reads the split tables): the closure takes about half "
                   "as long.")
@click.option("--settings", "settings_path", type=click.Path(dir_okay=False), default=None,
              help="A TOML file of per-stage settings that replace the preset's, e.g. '[correction]' then "
                   "'n_theta = 9' (README, \"Bake settings\"); an unknown stage or setting is refused.")
@click.option("--json", "as_json", is_flag=True, help="Print a JSON summary (progress still goes to stderr).")
def bake_command(yarn_name, output, quality, only, scene_path, seed, threads, no_cache, whole_xi, settings_path,
                 as_json):
    """Bake one yarn type into an asset pack: stage by stage, cached, with an error estimate for every table.

    Example: knitbake bake cotton1 -o cotton1.h5 --quality draft
    """
    import numba

    from knitbake.bake import bake, cache_dir, scene_needs

    check_outputs({"--output": output}, [yarn_name, scene_path, settings_path])
    spec = resolve_yarn(yarn_name)
    overrides = _bake_overrides(settings_path, whole_xi)
    needs = None
    if scene_path:
        from data_formats.scene import load_scene

        scene = load_scene(scene_path)
        if not any(e.spec.name == spec.name for e in scene.yarns):
            raise FormatError(f"{scene_path}: no yarn of the scene is {spec.name!r}")
        needs = scene_needs(scene, spec)
    if threads:
        numba.set_num_threads(min(threads, numba.config.NUMBA_NUM_THREADS))
    bars = {}

    def progress_factory(stage):
        bar = click.progressbar(length=1, label=f"  {stage:<16}", file=sys.stderr, show_eta=True, show_percent=True)
        bar.__enter__()
        bars[stage] = bar

        def progress(done, total):
            bar.length = total
            bar.update(done - bar.pos)
            if done >= total:
                bar.__exit__(None, None, None)
        return progress

    def on_stage(stage, index, count):
        click.echo(f"[{index + 1}/{count}] {stage}", err=True)

    t0 = time.perf_counter()
    only_list = [o.strip() for o in only.split(",")] if only is not None else None
    summary = bake(spec, output, quality=quality, only=only_list, needs=needs, seed=seed, use_cache=not no_cache,
                   on_stage=on_stage, progress_factory=progress_factory, overrides=overrides)
    for bar in bars.values():
        if not bar.finished:
            bar.__exit__(None, None, None)
    total = time.perf_counter() - t0
    for stage, row in summary.items():
        if "cache_warning" in row:
            click.echo(f"warning: {stage}: {row['cache_warning']}", err=True)
    if as_json:
        echo_json({"yarn": spec.name, "output": output, "quality": quality, "overrides": overrides, "seed": seed,
                   "seconds": total, "stages": summary, "needs": needs, "cache": str(cache_dir())})
        return
    click.echo(f"{'stage':<18}{'seconds':>9}  {'cached':<7}{'tables':>7}  error estimate (max)")
    for stage, row in summary.items():
        click.echo(f"{stage:<18}{row['seconds']:>9.2f}  {'yes' if row['cached'] else 'no':<7}{row['tables']:>7}  "
                   f"{row['error_estimate']:.3g}")
    changed = f" with {settings_path}" if settings_path else ""
    click.echo(f"{spec.name} → {output} ({quality}{changed}, {total:.1f} s)")


@main.command("bake-library")
@click.argument("yarn_names", metavar="YARN...", nargs=-1)
@click.option("-o", "--output-dir", type=click.Path(file_okay=False), required=True,
              help="Folder of the packs, one NAME.h5 per yarn (it must exist).")
@click.option("--all", "all_presets", is_flag=True, help="Every built-in preset, besides the yarns named.")
@click.option("--quality", type=click.Choice(["draft", "standard", "final"]), default="draft", show_default=True,
              help="Resolution and sample counts of every table (as for bake).")
@click.option("--seed", type=SEED, default=0, show_default=True, help="Same seed and settings → identical packs.")
@click.option("--scheduler", default=None, metavar="ADDRESS",
              help="A running Dask scheduler (e.g. tcp://10.0.0.5:8786; or $KNIT_DASK_SCHEDULER). Default: an "
                   "embedded cluster of worker processes on this machine.")
@click.option("--workers", type=click.IntRange(min=1), default=None,
              help="Worker processes of the embedded cluster (default: one per 2 cores); each gets cores/workers "
                   "Numba threads.")
@click.option("--no-cache", is_flag=True, help="Recompute every stage instead of reusing cached ones.")
@click.option("--whole-xi", is_flag=True, help="Close one ξ only, not also apart (as for bake).")
@click.option("--settings", "settings_path", type=click.Path(dir_okay=False), default=None,
              help="Per-stage settings that replace the preset's, for every yarn (as for bake).")
@click.option("--json", "as_json", is_flag=True, help="Print a JSON summary.")
def bake_library_command(yarn_names, output_dir, all_presets, quality, seed, scheduler, workers, no_cache, whole_xi,
                         settings_path, as_json):
    """Bake many yarn types at once on Dask: one task per stage of each yarn, the stage cache shared with bake.

    Runs on an embedded cluster sized to this machine, or on a Dask cluster given by --scheduler (README, "Running
    on a cluster"). One yarn's failure is reported and does not stop the others (exit code 1).

    \b
    Examples:
      knitbake bake-library cotton1 silk1 -o packs/
      knitbake bake-library --all -o packs/ --quality standard --scheduler tcp://scheduler:8786
    """
    from knitbake.scale_out import bake_library, dask_client

    names = list(dict.fromkeys([*yarn_names, *(preset_names() if all_presets else [])]))
    if not names:
        raise click.UsageError("name at least one yarn, or --all")
    if not os.path.isdir(output_dir):
        raise FormatError(f"{output_dir}: output folder does not exist (--output-dir)")
    specs = [resolve_yarn(name) for name in names]
    overrides = _bake_overrides(settings_path, whole_xi)
    seen = {}
    for name, spec in zip(names, specs):
        if spec.name in seen:
            raise FormatError(f"{name} and {seen[spec.name]} are both yarn {spec.name!r}: their packs would share "
                              f"{spec.name}.h5")
        seen[spec.name] = name
    jobs = [(spec, os.path.join(output_dir, f"{spec.name}.h5")) for spec in specs]
    t0 = time.perf_counter()
    with dask_client(scheduler, workers) as client:
        with click.progressbar(length=1, label=f"baking {len(jobs)} yarn(s)", file=sys.stderr, show_pos=True,
                               show_eta=True) as bar:
            def on_task(done, total):
                bar.length = total
                bar.update(done - bar.pos)
            results = bake_library(client, jobs, quality, seed, not no_cache, on_task, overrides)
    total = time.perf_counter() - t0
    failed = {name: exc for name, exc in results.items() if isinstance(exc, Exception)}
    if as_json:
        echo_json({"quality": quality, "seed": seed, "seconds": total, "scheduler": scheduler,
                   "yarns": {spec.name: ({"output": out, "stages": results[spec.name]} if spec.name not in failed
                                         else {"output": out, "error": str(failed[spec.name])})
                             for spec, out in jobs}})
    else:
        click.echo(f"{'yarn':<14}{'stages':>7}{'seconds':>9}  {'cached':<7}{'error estimate (max)':>21}  pack")
        for spec, out in jobs:
            summary = results[spec.name]
            if spec.name in failed:
                click.echo(f"{spec.name:<14}  failed: {' '.join(str(summary).split())}")
                continue
            cached = sum(row["cached"] for row in summary.values())
            click.echo(f"{spec.name:<14}{len(summary):>7}{sum(r['seconds'] for r in summary.values()):>9.1f}  "
                       f"{f'{cached}/{len(summary)}':<7}{max(r['error_estimate'] for r in summary.values()):>21.3g}  "
                       f"{out}")
        click.echo(f"{len(jobs) - len(failed)} of {len(jobs)} pack(s) in {total:.1f} s ({quality})")
    if failed:
        sys.exit(1)


@main.command("export")
@click.argument("pack", type=click.Path(dir_okay=False))
@click.argument("out_dir", metavar="DIR", type=click.Path(file_okay=False))
@click.option("--dtype", type=click.Choice(["float32", "float16"]), default="float32", show_default=True,
              help="Values of the .bin files: float32 (exact) or float16 (half the bytes, rounding ≤ 2^-11).")
@click.option("--csv", "as_csv", is_flag=True,
              help="Instead: textures as PNG/EXR and tables as CSV with axis values and errors (for people, not "
                   "engines).")
def export_command(pack, out_dir, dtype, as_csv):
    """Write a pack for engines: every table as a raw little-endian .bin (RGB tables as RGBA) and a manifest.json
    of shapes, axes, ranges and lookup rules, checked against the schema shipped with knit (ASSET_PACK.md §14).

    Example: knitbake export cotton1.h5 cotton1_export/ [--dtype float16]
    """
    if as_csv:
        from data_formats.pack_export import export_pack

        manifest = export_pack(pack, out_dir)
        n_files = sum(len(f["files"]) for f in manifest["files"])
        click.echo(f"{pack} → {out_dir}: {len(manifest['files'])} datasets, {n_files} files (manifest.json)")
        return
    from data_formats.engine_export import export_engine

    manifest = export_engine(pack, out_dir, dtype)
    size = sum(t["byte_length"] for t in manifest["tables"])
    click.echo(f"{pack} → {out_dir}: {len(manifest['tables'])} tables as {dtype} .bin ({size / 2**20:.1f} MiB), "
               f"manifest.json")
