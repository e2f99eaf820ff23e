"""``knitrun``: the runtime's command line. Thin: parse, call ``data_formats``/``knitrun``, report."""

from __future__ import annotations

import os
import sys
import time
from pathlib import Path

import click

from cli.common import CONTEXT, FriendlyGroup, SuffixPath, check_outputs, echo_json, file_kind
from data_formats import FormatError
from data_formats.input_files import regular_file
from knitrun.render.ablations import ABLATION_LABELS, ABLATIONS, combined

PROGRESS_FRAMES = 100  # simulate shows a progress bar from this many frames on


@click.group(name="knitrun", cls=FriendlyGroup, context_settings=CONTEXT)
@click.version_option(package_name="knit", prog_name="knitrun")
def main():
    """Runtime of knit: yarn curves and asset packs in, images out.

    \b
    Examples:
      knitrun convert yarns.h5 yarns.usda
      knitrun pattern eyelet --rows 16 --cols 16 -o eyelet.h5
      knitrun simulate eyelet.h5 --deform stretch-x=1.5 --frames 31 -o yarns.h5
    """


@main.command()
@click.argument("source", type=click.Path(dir_okay=False))
@click.argument("target", type=SuffixPath(".bcc", ".h5", ".hdf5", ".obj", ".usd", ".usda", ".usdc"))
@click.option("--frame", type=click.IntRange(min=0), default=0, show_default=True,
              help="Frame to write when the target is BCC or OBJ (one frame per file).")
@click.option("--units", default="cm", show_default=True,
              help="Units to record when the source has none (BCC; OBJ without a knit header).")
@click.option("--radius", type=click.FloatRange(min=0, min_open=True), default=None,
              help="Yarn radius for the USD widths (diameters) when the curves carry none.")
def convert(source, target, frame, units, radius):
    """Convert yarn curves between our HDF5 file, BCC and OBJ polylines, or write them as USD BasisCurves for DCC
    tools (all frames as time samples, widths = yarn diameter, rest arc length as a primvar); by the target's
    extension, the source recognised by content.

    \b
    Examples:
      knitrun convert cotton1.bcc cotton1.h5 --units cm
      knitrun convert yarns.h5 yarns.usda
      knitrun convert yarns.h5 yarns.obj --frame 30
    """
    from data_formats.bcc import read_bcc, write_bcc
    from data_formats.curves_dcc import read_obj_curves, write_obj_curves, write_usd_curves
    from data_formats.yarn_curves import read_yarn_curves, write_yarn_curves

    check_outputs({"TARGET": target}, [source])
    kind, _ = file_kind(source)
    readers = {"bcc": lambda: read_bcc(source, units=units), "yarn-curves": lambda: read_yarn_curves(source),
               "yarn-curves-obj": lambda: read_obj_curves(source, units=units)}
    if kind not in readers:
        raise FormatError(f"{source}: is a {kind}, not yarn curves")
    curves = readers[kind]()
    suffix = Path(target).suffix.lower()
    if suffix in (".bcc", ".obj") and frame >= curves.points.shape[0]:
        raise FormatError(f"--frame {frame}: {source} has {curves.points.shape[0]} frame(s)")
    if suffix == ".bcc":
        write_bcc(target, curves, frame=frame)
    elif suffix == ".obj":
        write_obj_curves(target, curves, frame=frame)
    elif suffix in (".usd", ".usda", ".usdc"):
        write_usd_curves(target, curves, radius)
    else:
        write_yarn_curves(target, curves)
    click.echo(f"{source} ({kind}, {len(curves.closed)} curves) → {target}")


def _design_mesh(path):
    """The stitch mesh of a knit-design file (knitout, .smobj) recognised by content, else None."""
    from data_formats import smobj
    from knitrun.sim import knitout

    if knitout.sniff(path):
        return knitout.read_knitout(path)
    if smobj.sniff(path):
        return smobj.read_smobj(path)
    return None


@main.command()
@click.argument("source")
@click.option("--rows", type=click.IntRange(min=1), help="Courses of a named pattern.  [default: 12]")
@click.option("--cols", type=click.IntRange(min=1), help="Stitches per course of a named pattern.  [default: 12]")
@click.option("-o", "--output", required=True, type=SuffixPath(".h5", ".hdf5", ".obj"),
              help="MESH.h5 (knit-stitch-mesh) or MESH.obj (also writes MESH.labels).")
@click.option("--in-the-round", "in_the_round", is_flag=True,
              help="Knit a chart or named pattern as a tube: each course closed, the yarn one spiral.")
@click.option("--json", "as_json", is_flag=True, help="Print the mesh summary as JSON.")
def pattern(source, rows, cols, output, in_the_round, as_json):
    """Stitch mesh from a knit chart file, a knitout or .smobj file (recognised by content), or a named pattern.

    A chart is text, top course first: k knit, p purl, o yarn-over, / k2tog, \\ ssk (data_formats/STITCH_MESH.md).
    Named patterns: stockinette, garter, rib1x1, rib2x2, seed, diamond, eyelet.

    \b
    Examples:
      knitrun pattern eyelet --rows 16 --cols 16 -o eyelet.h5
      knitrun pattern my_chart.txt -o patch.obj
      knitrun pattern rib-2x2.knitout -o rib.h5
      knitrun pattern stockinette --rows 12 --cols 24 --in-the-round -o tube.h5

    A knitout tube (front and back beds knitted in turn) is knitted in the round by itself.
    """
    from data_formats.stitch_mesh import summary, write_obj_stitch_mesh, write_stitch_mesh
    from knitrun.sim.knit_chart import PATTERNS, chart_to_mesh, pattern_chart

    check_outputs({"--output": output, "labels": _labels(output)}, [source])
    suffix = Path(output).suffix.lower()
    if os.path.lexists(source):  # a chart, knitout or .smobj file (a FIFO or folder is refused, not read)
        if rows is not None or cols is not None:
            raise FormatError(f"--rows/--cols size a named pattern, but {source} is a file")
        regular_file(source, "a knit chart, knitout or .smobj file")
        mesh = _design_mesh(source)
        if mesh is not None and in_the_round:
            raise FormatError(f"--in-the-round applies to charts and named patterns; {source} gives its own shape")
        if mesh is None:
            mesh = chart_to_mesh(Path(source).read_text(encoding="utf-8"), where=source, in_the_round=in_the_round)
    elif source in PATTERNS:
        mesh = chart_to_mesh(pattern_chart(source, rows or 12, cols or 12), where=f"pattern {source}",
                             in_the_round=in_the_round)
    else:
        raise FormatError(f"{source}: neither a chart file nor a pattern name, expected a file or one of "
                          f"{', '.join(PATTERNS)}")
    (write_obj_stitch_mesh if suffix == ".obj" else write_stitch_mesh)(output, mesh)
    info = {"output": output, **summary(mesh)}
    if as_json:
        echo_json(info)
    else:
        click.echo(f"{source} → {output}: {info['faces']} faces in {info['courses']} courses"
                   f"{', knitted in the round' if info['in_the_round'] else ''} "
                   f"({', '.join(f'{n} {k}' for k, n in info['faces_per_stitch_type'].items())})")


@main.command()
@click.argument("mesh_path", metavar="MESH")
@click.option("--deform", "deforms", multiple=True, metavar="NAME=VALUE",
              help="Built-in deformation, repeatable, applied in order: stretch-x=S, stretch-y=S, shear=G, "
                   "cylinder=RADIUS.")
@click.option("--frames", type=click.IntRange(min=1),
              help="Frames: 1 = the full deformation; N > 1 = stretch and release (rest, full at the middle, rest).  "
                   "[default: 1]")
@click.option("--obj-dir", type=click.Path(file_okay=False),
              help="Folder of OBJ frames with the mesh's topology (instead of --deform/--frames).")
@click.option("-o", "--output", required=True, type=SuffixPath(".h5", ".hdf5", ".bcc"),
              help="YARNS.h5 (all frames) or YARNS.bcc (the last frame).")
@click.option("--iterations", type=click.IntRange(min=0), default=3, show_default=True,
              help="Gauss-Newton iterations per frame.")
@click.option("--w-length", type=float, default=100.0, show_default=True, help="Weight of the length energy.")
@click.option("--beta", type=float, default=1.0, show_default=True,
              help="Knot spacing blend: 1 interpolates knots with the mesh, 0 keeps their rest spacing.")
@click.option("--json", "as_json", is_flag=True, help="Print the report as JSON.")
def simulate(mesh_path, deforms, frames, obj_dir, output, iterations, w_length, beta, as_json):
    """Knot simulation: yarn curves of a stitch mesh (.h5, or .obj + .labels) driven by deformations or OBJ frames.

    Reports the whole run's seconds and where they went: milliseconds per frame (median; Numba compile or cache load
    excluded, in "prepare"), building the curves, the contact statistic and writing; the final energy and the contact
    statistic (knitrun/sim/contact.py: how far each yarn stays from the others, over 2r; below 1 they interpenetrate).

    \b
    Examples:
      knitrun simulate eyelet.h5 --deform stretch-x=1.5 --deform shear=0.3 --frames 31 -o yarns.h5
      knitrun simulate patch.obj --obj-dir frames/ -o yarns.h5 --json
      knitrun simulate patch.obj --deform cylinder=2.0 -o bent.bcc
    """
    from data_formats import stitch_mesh
    from data_formats.bcc import write_bcc
    from data_formats.yarn_curves import write_yarn_curves
    from knitrun.sim.contact import contact_over_frames
    from knitrun.sim.deformations import deformation_frames, parse_deformation, read_obj_frames
    from knitrun.sim.simulate import simulate as run_simulation

    started = time.perf_counter()
    check_outputs({"--output": output}, [mesh_path, _labels(mesh_path)])
    suffix = Path(output).suffix.lower()
    if obj_dir is not None and (deforms or frames is not None):
        raise FormatError("--obj-dir gives the frames: use it without --deform and --frames")
    specs = [parse_deformation(spec) for spec in deforms]
    mesh = _design_mesh(mesh_path) or stitch_mesh.load_stitch_mesh(mesh_path)
    vertex_frames = read_obj_frames(obj_dir, mesh) if obj_dir is not None else \
        deformation_frames(mesh.vertices, specs, frames or 1)
    count = len(vertex_frames)
    with click.progressbar(length=count, label="simulating", file=sys.stderr, show_pos=True, show_eta=True,
                           hidden=count < PROGRESS_FRAMES) as bar:
        curves, report = run_simulation(mesh, vertex_frames, iterations=iterations, w_length=w_length, beta=beta,
                                        progress=lambda done, total: bar.update(done - bar.pos))
    t0 = time.perf_counter()
    report["contact"] = contact_over_frames(curves, report["yarn_radius"])
    report["contact_s"] = time.perf_counter() - t0
    for warning in report["warnings"]:
        click.echo(f"warning: {warning}", err=True)
    t0 = time.perf_counter()
    if suffix == ".bcc":
        write_bcc(output, curves, frame=curves.points.shape[0] - 1)
    else:
        write_yarn_curves(output, curves)
    report["write_s"] = time.perf_counter() - t0
    report["total_s"] = time.perf_counter() - started
    report = {"mesh": mesh_path, "output": output, **{k: v for k, v in report.items() if k != "ms_per_frame"}}
    if as_json:
        echo_json(report)
    else:
        solve_s = report["seconds"] - report["prepare_s"] - report["curves_s"]
        click.echo(f"{mesh_path} → {output}: {report['faces']} faces, {report['frames']} frame(s), "
                   f"{report['render_points']} points in {report['curves']} curves, {report['total_s']:.1f} s in all: "
                   f"{report['ms_per_frame_median']:.2f} ms/frame (median, {report['threads']} threads; "
                   f"{solve_s:.1f} s for all frames), prepare {report['prepare_s']:.1f} s, building the curves "
                   f"{report['curves_s']:.1f} s, contact {report['contact_s']:.1f} s, "
                   f"writing {report['write_s']:.1f} s; "
                   f"final energy {report['final_energy']:.6g}")
        worst = report["contact"]["worst"]
        click.echo(f"contact (distance to the nearest other yarn / 2r, r = {report['yarn_radius']:.4g}; 1 = touching), "
                   f"worst of {len(report['contact']['frames_evaluated'])} frame(s) (frame {worst['frame']}): "
                   f"5th percentile {worst['p5']:.3f}, median {worst['p50']:.3f}")


@main.group(cls=FriendlyGroup)
def templates():
    """The knot simulator's stitch templates."""


@templates.command()
@click.option("-o", "--output", type=SuffixPath(".json"),
              help="Where to write the relaxed templates [default: the package's knitrun/sim/relaxed_templates.json, "
                   "which the simulator reads].")
@click.option("--json", "as_json", is_flag=True, help="Print the result (figures per stitch type) as JSON.")
def relax(output, as_json):
    """Relax the stitch templates: knit (and so purl) on a periodic tile, at rest and its shape on a sheared face,
    then yarn-over, k2tog and ssk in an eyelet context: yarns as elastic rods with bending, stretching and contact at
    2r (knitrun/sim/template_relax.py, patch_relax.py; about 55 s on 2 cores). Prints each round and the tile's
    contact before and after. The simulator reads the package's file at import, so a new file takes effect in a new
    process.

    Example: knitrun templates relax -o my_templates.json --json
    """
    from knitrun.sim.stitch_templates import RELAXED_PATH
    from knitrun.sim.template_relax import relax_templates, write_relaxed

    def progress(rounds, cost, pairs):
        click.echo(f"  round {rounds}: energy {cost:.4g}, {pairs} contact pairs", err=True)

    document = relax_templates(progress)
    path = output or str(RELAXED_PATH)
    write_relaxed(path, document)
    if as_json:
        echo_json({"output": path, **document})
        return
    others = ", ".join(name for name in document["stitch_types"] if name != "knit")
    pattern, rows, cols = document["context"]["chart"]
    for label, result in (("knit (periodic tile)", document["stitch_types"]["knit"]),
                          (f"{others} (in a {rows}×{cols} {pattern} chart)", document["context"])):
        before, after = result["contact_before"], result["contact_after"]
        click.echo(f"{label}: contact p5 {before['p5']:.3f} → {after['p5']:.3f}, median {before['p50']:.3f} → "
                   f"{after['p50']:.3f}; energy {result['energy_before']:.4g} → {result['energy_after']:.4g}; "
                   f"{result['rounds']} rounds, {result['seconds']:.1f} s")
        if not result["converged"]:
            click.echo(f"warning: {label} stopped after {result['rounds']} rounds without converging: the file "
                       "depends on this machine's rounding", err=True)
    shear = document["stitch_types"]["knit"]["shear"]
    before, after = shear["before"], shear["after"]
    click.echo(f"knit shear shape (face sheared {shear['deformation'][0][1]:g}): contact p5 {before['p5']:.3f} → "
               f"{after['p5']:.3f}, control-segment length error {before['segment_error']:.3f} → "
               f"{after['segment_error']:.3f}; {shear['rounds']} rounds, {shear['seconds']:.1f} s")
    if not shear["converged"]:
        click.echo("warning: the knit's shear shape did not converge: the file depends on this machine's rounding",
                   err=True)
    click.echo(f"wrote {path}")


def _labels(path):
    """The ``.labels`` sidecar of an OBJ stitch mesh (None for other files)."""
    return str(Path(path).with_suffix(".labels")) if str(path).lower().endswith(".obj") else None


def _ablation(ctx, param, value):
    """``--ablation``: an ablation or a combination a+b (``ablations.combined``); a usage error naming the unknown
    part otherwise."""
    try:
        combined(value)
    except ValueError as e:
        raise click.BadParameter(str(e)) from None
    return value


def _pack_overrides(values):
    """--pack YARN=FILE (or INDEX=FILE) options as a dict."""
    out = {}
    for value in values:
        name, sep, path = value.partition("=")
        if not sep or not name or not path:
            raise FormatError(f"--pack {value!r}: expected YARN=FILE, e.g. --pack cotton1=cotton1.h5")
        out[name] = path
    return out


@main.command()
@click.argument("scene_path", metavar="SCENE", type=click.Path(dir_okay=False))
@click.option("-o", "--output", type=SuffixPath(".png"), required=True,
              help="Tone-mapped PNG image; with --frames a pattern whose run of '#' takes the frame number "
                   "(out/frame_####.png).")
@click.option("--exr", "exr_path", type=SuffixPath(".exr"), default=None,
              help="Also write the linear EXR (a pattern with --frames).")
@click.option("--frames", "frame_range", default=None, metavar="A:B",
              help="Draw frames A to B−1 of the scene's yarn curves (A:, N) with one renderer: packs, kernels and "
                   "the environment fit are loaded once.")
@click.option("--gif", "gif_path", type=SuffixPath(".gif"), default=None,
              help="With --frames: also an animated GIF of the frames.")
@click.option("--fps", type=click.FloatRange(min=0.1, max=100), default=12.0, show_default=True,
              help="Frame rate of the GIF.")
@click.option("--pack", "pack_values", multiple=True, metavar="YARN=FILE",
              help="Asset pack for a yarn (its name or entry index); overrides the scene's `pack`. Repeatable.")
@click.option("--ablation", default="full", show_default=True, callback=_ablation,
              help="Which baked terms to use (the ablations of Huang et al. 2025 Fig. 7): one of "
                   f"{', '.join(ABLATIONS)}, or a combination a+b (the full model with what each changes).")
@click.option("--samples-per-segment", type=click.IntRange(1, 64), default=4, show_default=True,
              help="Polyline samples per segment of smooth (C0/BS/BZ) curves.")
@click.option("--msaa", type=click.Choice(["1", "2", "4", "8", "16"]), default=None,
              help="Samples per pixel (default: the scene's).")
@click.option("--exposure", type=float, default=0.0, show_default=True, help="PNG exposure in stops.")
@click.option("--backend", type=click.Choice(["cpu", "gl"]), default="cpu", show_default=True,
              help="cpu: the Numba renderer; gl: the same model in OpenGL 4.5 through EGL (a GPU, or Mesa's llvmpipe "
                   "without one; needs libEGL and a GL driver).")
@click.option("--json", "as_json", is_flag=True, help="Print a JSON summary: time per pass, counts.")
def render(scene_path, output, exr_path, frame_range, gif_path, fps, pack_values, ablation, samples_per_segment, msaa,
           exposure, backend, as_json):
    """Render a scene with the strip renderer (yarns as textured strips shaded from their asset packs).

    \b
    Examples:
      knitrun render examples/scenes/knit_patch_directional.toml --pack cotton1=cotton1.h5 -o patch.png
      knitrun render stretch.toml --frames 0:30 -o out/frame_####.png --gif stretch.gif
    """
    import dataclasses

    from data_formats.images import write_exr, write_png
    from data_formats.scene import load_scene
    if backend == "gl":
        from knitrun.render.gl.gl_renderer import GLRenderer as Renderer
        from knitrun.render.gl.gl_renderer import render as render_scene
        ahead = {}
    else:
        from knitrun.render.pipeline import Renderer
        from knitrun.render.pipeline import render as render_scene
        ahead = {"compile_ahead": True}  # on an empty kernel cache, a helper compiles the later passes' kernels

    scene = load_scene(scene_path)
    check_outputs({"--output": output, "--exr": exr_path, "--gif": gif_path},
                  [scene_path] + [p for e in scene.yarns for p in (e.curves, e.stitch_mesh, e.pack) if p])
    if msaa is not None:
        scene = dataclasses.replace(scene, render=dataclasses.replace(scene.render, msaa=int(msaa)))
    if gif_path is not None and frame_range is None:
        raise FormatError("--gif needs --frames (the frames to animate)")
    if frame_range is not None:
        _render_frames(Renderer(scene, _pack_overrides(pack_values), combined(ablation), samples_per_segment,
                                **ahead), scene_path, frame_range, output, exr_path, gif_path, fps, exposure, as_json)
        return
    result = render_scene(scene, _pack_overrides(pack_values), combined(ablation), samples_per_segment,
                          progress=lambda name, s: click.echo(f"  {name}: {s * 1e3:.0f} ms", err=True), **ahead)
    for warning in result.facts["warnings"]:
        click.echo(f"warning: {warning}", err=True)
    write_png(output, result.image, exposure)
    if exr_path is not None:
        write_exr(exr_path, result.image)
    total = sum(result.timings.values())
    summary = {"scene": scene_path, "output": output, "exr": exr_path, "ablation": ablation, "backend": backend,
               "width": scene.camera.width, "height": scene.camera.height, "msaa": scene.render.msaa,
               "ms_total": total * 1e3, "ms_per_pass": {k: v * 1e3 for k, v in result.timings.items()},
               **result.facts, "mean_rgb": result.image.reshape(-1, 3).mean(axis=0).tolist()}
    if as_json:
        echo_json(summary)
        return
    passes = ", ".join(f"{k} {v * 1e3:.0f}" for k, v in result.timings.items())
    click.echo(f"{output}: {scene.camera.width}x{scene.camera.height}, {result.facts['points']} points, "
               f"{total * 1e3:.0f} ms ({passes} ms)")


def _render_frames(renderer, scene_path, frame_range, output, exr_path, gif_path, fps, exposure, as_json):
    """``knitrun render --frames``: a progress bar over the frames, each frame's time, a summary."""
    import statistics

    from knitrun.render.sequence import parse_frames, render_sequence

    frames = parse_frames(frame_range, renderer.frame_count)
    for warning in renderer.warnings:
        click.echo(f"warning: {warning}", err=True)
    setup = {k: v * 1e3 for k, v in renderer.setup_timings.items()}
    click.echo("setup: " + ", ".join(f"{k} {v:.0f} ms" for k, v in setup.items()), err=True)
    with click.progressbar(length=len(frames), label="frames", file=sys.stderr,
                           item_show_func=lambda r: r and f"frame {r['frame']}: {r['ms']:.0f} ms") as bar:
        records = render_sequence(renderer, frames, output, exposure=exposure, exr_pattern=exr_path, gif=gif_path,
                                  gif_fps=fps, on_frame=lambda record: bar.update(1, record))
    ms = [r["ms"] for r in records]
    summary = {"scene": scene_path, "frames": [frames.start, frames.stop], "output": output, "exr": exr_path,
               "gif": gif_path, "setup_ms": setup, "ms_per_frame": ms, "ms_median": statistics.median(ms),
               "per_frame": records}
    if as_json:
        echo_json(summary)
        return
    click.echo(f"{len(records)} frames → {output}{' and ' + gif_path if gif_path else ''}: median "
               f"{statistics.median(ms):.0f} ms per frame (first {ms[0]:.0f}, min {min(ms):.0f}, max {max(ms):.0f})")


@main.command()
@click.argument("scene_path", metavar="SCENE", type=click.Path(dir_okay=False))
@click.option("--pack", "pack_values", multiple=True, metavar="YARN=FILE",
              help="Asset pack for a yarn (its name or entry index); overrides the scene's `pack`. Repeatable.")
@click.option("--samples-per-segment", type=click.IntRange(1, 64), default=4, show_default=True,
              help="Polyline samples per segment of smooth (C0/BS/BZ) curves.")
@click.option("--exposure", type=float, default=0.0, show_default=True, help="Display exposure in stops.")
@click.option("--screenshot", type=SuffixPath(".png"), default=None,
              help="Draw one frame, save the window as this PNG and exit (e.g. under xvfb-run).")
def view(scene_path, pack_values, samples_per_segment, exposure, screenshot):
    """Look at a scene interactively: the GL backend in a window (glfw).

    \b
    Left drag orbits, scroll zooms, right drag turns the first light, ←/→ and space step and play the frames,
    1–6 switch the ablation (full, plain DS, + ξ, + Ψ^Fiber, no tables, factored), r resets, s saves a screenshot,
    Esc quits; the title shows the frame time. Needs a display: headless machines get a one-line error.

    \b
    Examples:
      knitrun view examples/scenes/knit_patch_directional.toml --pack cotton1=cotton1.h5
      xvfb-run -s "-screen 0 1280x1024x24" knitrun view scene.toml --screenshot view.png
    """
    from data_formats.scene import load_scene
    from knitrun.render.gl.viewer import view as open_viewer

    scene = load_scene(scene_path)
    if screenshot is not None:
        check_outputs({"--screenshot": screenshot}, [scene_path])
    open_viewer(scene, _pack_overrides(pack_values), samples_per_segment, screenshot=screenshot, exposure=exposure)
    if screenshot is not None:
        click.echo(f"{screenshot}: {scene.camera.width}x{scene.camera.height}")


@main.command()
@click.argument("scene_path", metavar="SCENE", type=click.Path(dir_okay=False))
@click.option("-o", "--output", "out_dir", type=click.Path(file_okay=False), required=True,
              help="Report folder (created): report.md, report.json and the images.")
@click.option("--reference", type=click.Path(dir_okay=False), default=None,
              help="A reference EXR to compare with instead of path tracing one.")
@click.option("--spp", type=click.IntRange(min=1), default=None,
              help="Reference samples per pixel (default: the scene's).")
@click.option("--pack", "pack_values", multiple=True, metavar="YARN=FILE",
              help="Asset pack for a yarn; overrides the scene's `pack`. Repeatable.")
@click.option("--exposure", type=float, default=0.0, show_default=True,
              help="Exposure in stops of the PNGs and of the tone mapping FLIP sees.")
@click.option("--instance-floor", type=SuffixPath(".exr"), default=None,
              help="With --reference: the reference of another fiber instance and sampling seed (knitbake reference "
                   "--seed S+1 --fiber-seed S+1).")
@click.option("--mc-floor", type=SuffixPath(".exr"), default=None,
              help="With --reference: the same fibers with another sampling seed (knitbake reference --seed S+1 "
                   "--fiber-seed S).")
@click.option("--no-floors", is_flag=True, help="Do not path trace the two floor references (a third of the time).")
@click.option("--instance", "instances", type=SuffixPath(".exr"), multiple=True,
              help="With --reference: a further fiber instance of it (knitbake reference --seed K --fiber-seed K, the "
                   "reference's spp). Repeatable; with the reference and its instance floor at least three: the "
                   "report adds each model against their ensemble (mean radiance over the draws' mean, with their "
                   "spread).")
@click.option("--workers", type=click.IntRange(min=1), default=None,
              help="Trace the reference and its floors at once on an embedded Dask cluster of this many worker "
                   "processes (the same images). The speed-ups then divide the tasks' summed times, each task on "
                   "cores/workers threads.")
@click.option("--scheduler", default=None, metavar="ADDRESS",
              help="Trace them on this Dask scheduler instead (or $KNIT_DASK_SCHEDULER).")
@click.option("--json", "as_json", is_flag=True, help="Print the summary as JSON.")
def compare(scene_path, out_dir, reference, spp, pack_values, exposure, instance_floor, mc_floor, no_floors,
            instances, workers, scheduler, as_json):
    """Compare the strip renderer (full model and its ablations) with the reference path tracer, next to the
    reference's own floors (another fiber instance; another sampling seed), per pixel and at the yarn scale.

    Example: knitrun compare examples/scenes/straight_yarn_directional.toml --pack cotton1=cotton1.h5 --spp 64 -o
    report/
    """
    from knitbake.compare.report import compare_scene

    if reference is not None and spp is not None:
        raise FormatError("--reference and --spp exclude each other (--spp sets the reference's samples)")
    if reference is None and (instance_floor or mc_floor):
        raise FormatError("--instance-floor and --mc-floor go with --reference (without it the floors are traced)")
    floor_files = {k: v for k, v in (("instance", instance_floor), ("monte_carlo", mc_floor)) if v}
    if instances and (reference is None or 1 + bool(instance_floor) + len(instances) < 3):
        raise FormatError("--instance goes with --reference, and the reference, --instance-floor and the --instance "
                          "files must make at least 3 fiber instances")
    run = dict(reference=reference, spp=spp, packs=_pack_overrides(pack_values), exposure=exposure,
               floors=not no_floors, floor_references=floor_files, instances=list(instances) or None,
               progress=lambda message: click.echo(message, err=True))
    if workers or scheduler or os.environ.get("KNIT_DASK_SCHEDULER"):
        from knitbake.scale_out import dask_client

        with dask_client(scheduler, workers) as client:
            summary = compare_scene(scene_path, out_dir, client=client, **run)
    else:
        summary = compare_scene(scene_path, out_dir, **run)
    if as_json:
        echo_json(summary)
        return
    for name, row in summary["floors"].items():
        click.echo(f"{name + ' floor':30s} yarn-scale rel L1 {row['yarn']['rel_l1']:.3f}  mean ratio "
                   f"{row['yarn']['mean_ratio']:.3f}  FLIP {row['flip']:.4f}")
    for name, row in summary["ablations"].items():
        speed = f", {row['speedup']:.0f}x faster than the reference" if row["speedup"] else ""
        floor = f" ({row['to_instance_floor']['rel_l1']:.2f}x the floor)" if row["to_instance_floor"] else ""
        ply = row["contrast"]["ply"]
        contrast = f"  ply-scale contrast {ply:.2f}x" if ply is not None else ""
        click.echo(f"{ABLATION_LABELS[name]:30s} yarn-scale rel L1 {row['yarn']['rel_l1']:.3f}{floor}  mean ratio "
                   f"{row['yarn']['mean_ratio']:.3f}{contrast}  FLIP {row['flip']:.4f}  {row['ms']:.0f} ms{speed}")
    if "ensemble" in summary:
        e = summary["ensemble"]
        click.echo(f"against {e['instances']} fiber instances (their means spread {100 * e['mean_sd']:.1f} %; "
                   f"ensemble floor {e['rel_l1']:.3f}):")
        for name, row in summary["ablations"].items():
            r = row["ensemble"]
            floor = f" ({r['to_floor']:.2f}x the ensemble floor)" if r["to_floor"] is not None else ""
            click.echo(f"{ABLATION_LABELS[name]:30s} mean ratio {r['mean_ratio']:.3f}  yarn-scale rel L1 "
                       f"{r['rel_l1']:.3f}{floor}")
    click.echo(f"report: {Path(out_dir) / 'report.md'}")
