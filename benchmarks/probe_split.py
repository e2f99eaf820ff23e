"""Single and multiple scattering, reference against strips, scene by scene (issue 13, the look): which half of the
light the strip model gets wrong, and where.

The path tracer counts scattering events (``trace_reference(..., max_depth=1)`` ends every path at its first fiber:
camera ray, hit, next-event estimate of the lights there), so its image splits into single scattering SS (one
event) and multiple scattering MS = full − SS. The strip renderer's counterpart is ``Features(multiple_scattering=
False)``: Zinke's density factors d_f = d_b = 0, which leaves the fiber BCSDF f of each directional light and the
environment's I_M and drops every DS term of multiple scattering, and the yarn-level terms of light another fiber
scattered first (the bounce, the hairs' glow from their body, the sky's lobes inter-reflected between the yarns; until
stop 63 the last two counted as single scattering) (``knitrun.render.ablations``). Per scene this
traces the reference (seed and fiber seed of the scene) and a second fiber instance (seed + 1, fiber seed + 1),
each at the full depth and at one event, over a black background (so that SS and MS carry no background and the
means are the yarns' alone), and renders each model of ``--models`` both ways. Reported per model, all at the yarn
scale d (``knitbake.compare.image_metrics``):

* the ratio of the RGB means to the reference's (``knitrun compare`` weighs luminance), of the whole image, of SS
  and of MS;
* the yarn-scale rel L1 as a ratio to the instance floor (the second instance's rel L1), for the model and for two
  oracles: the model's SS with the instance's MS (what a perfect multiple-scattering term would leave), and the
  instance's SS with the model's MS (what a perfect single-scattering term would leave);
* each half alone: the model's SS against the reference's SS at the yarn scale, over the instance's SS against it
  (that half's own floor), and the same for MS: how far each half is placed from where the fibers put it.

``--tilt-bins`` adds, for scenes drawn from yarn-curve files whose curves turn (a straight yarn sits in one bin), the
mean of the yarn-scale SS and MS at the curves' control points binned by |ω_o · t| (as ``probe_tilt.py
--bins-from``): how each half changes as the yarn turns toward the camera.

``--loop-bins`` adds, on the Crane patch scenes (every stitch alike: ``probe_error_scale.loop_phase``), per loop-phase
bin of the interior courses (15° of Crane's t; the heads at 0°, the sinkers at 180°), over the pixels the first
model's front regular strips cover: the references' share of single scattering, the model's SS, MS and whole over
theirs (luminance; the reference and the second instance averaged), and the bin's share of their light: which part
of the loop has which half wrong.

``--layers`` adds, per scene and model, each half split again by the layer the camera ray meets first: the regular
fibers and the flyaways. The reference's regular part is traced with ``seen="regular"`` (the light of the paths whose
first hit is a regular fiber; the flyaways still block and scatter), at full depth and at one event, for the reference
and the second instance; the strips' with ``Features(hair_light=False)`` (the hairs opaque and black, the regular
strips' light between them). The flyaways' part is the whole less the regular part. Reported: each part's share of
the reference's light and the model's (and the instance's) part over the reference's: which layer holds which half's
error.

``--curves K,L`` keeps only those curves of each scene's yarn-curve files (e.g. one course of a patch: a yarn in its
knitted shape with no neighbour to shade it or send it light), ``--scale S`` scales what is kept by S about the
camera's look-at point, the camera S times as far (an orthographic one S times as tall) with S times the pixels per
side, so that the picture is the same, the yarn as many pixels wide, with every bend S times gentler against the
yarn's radius, and ``--no-flyaways`` draws the regular fibers alone in both (the bake's yarn; the reference without
its flyaways, the strips without the flyaway layer): which part of a scene's error a lone yarn in the scene's shape
already has, and whether it follows the bends (BENCHMARKS.md, "Issue 13: one course alone", stop 65).

``--ss-draws N`` traces N more fiber draws at one event (seed and fiber seed + 2 … + N + 1) and asks how far the
reference's single scattering at the yarn scale is fixed by the yarns rather than by the draw: per scene and model,
the rel L1 against the reference's single scattering, over its floor (the second instance's), of the mean of the
other draws (the instance and the N; with a leave-one-out mean over all of them), and of the model's single
scattering, as drawn and with its mean matched; and how concentrated each is: the share of it in the brightest 5 % and
20 % of the reference's lit pixels (above ``LIT`` of the draws' mean's largest, luminance), its coefficient of
variation there and its correlation with the draws' mean. A draws' mean as concentrated as one draw and nearer the
reference than the floor says where single scattering lies is the geometry's, which a model could place.

``--color R,G,B`` draws every yarn of each scene in that colour (both images), and ``--channels`` adds, per scene and
model, the whole, SS and MS over the reference's in each RGB channel: a colour's dark channels hold less multiple
scattering, mostly of two events, and a model can miss it there while the bright channel is right (BENCHMARKS.md,
"Issue 13: the multiple scattering of a coloured yarn", stop 77).

``--out DIR`` keeps the images
(``<scene>/{reference,instance}_{full,single}.exr``, ``strip_<model>_{full,single}.exr``).

    .venv/bin/python benchmarks/probe_split.py --pack out/bench/cotton1_standard.h5 [--scenes a,b] \\
        [--models full,no_tables,plain_ds] [--spp N] [--tilt-bins] [--loop-bins] [--layers] \\
        [--curves K,L] [--scale S] [--no-flyaways] [--ss-draws N] [--out DIR]

The spp per scene is the one the ruler picked (the Monte Carlo floor at most half the instance floor at d:
BENCHMARKS.md, "The ruler"), unless ``--spp`` is given.
"""

from __future__ import annotations

import argparse
import dataclasses
import math
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

from data_formats.conventions import LUMINANCE
from data_formats.images import write_exr
from data_formats.scene import load_scene
from data_formats.yarn_curves import make_yarn_curves, read_yarn_curves, write_yarn_curves
from knitbake.compare.image_metrics import yarn_filter, yarn_scale_metrics
from knitbake.compare.report import yarn_diameter_px
from knitbake.trace.reference import trace_reference
from knitrun.render import pipeline
from knitrun.render.ablations import combined

sys.path.insert(0, str(Path(__file__).resolve().parent))
from probe_error_scale import CRANE_CURVES, LOOP_BINS, front_strips, loop_phase  # noqa: E402
from probe_tilt import TILT_BINS, curve_tilts  # noqa: E402

ROOT = Path(__file__).resolve().parent.parent
LIT = 0.01  # --ss-draws: lit pixels, the draws' mean single scattering above this share of its largest
SCENES = {"straight_yarn_directional": 16, "straight_yarn_sky": 16, "straight_yarn_backlit": 16,
          "knit_patch_directional": 16, "knit_patch_sky": 64, "knit_patch_grazing": 16,
          "simulated_patch_directional": 32}  # name → the ruler's spp


def traced(scene, spp, seed, fiber_seed, seen="all", flyaways=True):
    """(full, single) reference images of ``scene`` (RGB float64) and the seconds both took; ``seen`` and
    ``flyaways`` as ``trace_reference``'s."""
    t0 = time.perf_counter()
    full, _ = trace_reference(scene, spp, seed, scene.render.max_depth, fiber_seed=fiber_seed, seen=seen,
                              flyaways=flyaways)
    single, _ = trace_reference(scene, spp, seed, 1, fiber_seed=fiber_seed, seen=seen, flyaways=flyaways)
    return full.astype(np.float64), single.astype(np.float64), time.perf_counter() - t0


def rendered(scene, pack, model, hair_light=True, flyaways=True):
    """(full, single) strip images of ``scene`` for ablation ``model``; ``hair_light`` False: the hairs black (the
    regular strips' light alone, ``Features.hair_light``); ``flyaways`` False: no flyaway layer."""
    features = combined(model)
    if not hair_light:
        features = dataclasses.replace(features, hair_light=False)
    if not flyaways:
        features = dataclasses.replace(features, flyaways=False)
    full = pipeline.Renderer(scene, {"cotton1": pack}, features).render().image
    single = pipeline.Renderer(scene, {"cotton1": pack},
                               dataclasses.replace(features, multiple_scattering=False)).render().image
    return np.asarray(full, np.float64)[..., :3], np.asarray(single, np.float64)[..., :3]


def _mean_ratio(test, reference):
    return float(test.mean() / reference.mean()) if reference.mean() > 0 else float("nan")


def split_rows(name, d, ref, inst, strips):
    """Markdown rows: the instance, then each model (``strips``: model → (full, single))."""
    floor = yarn_scale_metrics(inst[0], ref[0], d)["rel_l1"]
    rows = []
    for label, (full, single) in [("*other fiber instance*", inst), *strips.items()]:
        ms, ref_ms = full - single, ref[0] - ref[1]
        err = yarn_scale_metrics(full, ref[0], d)["rel_l1"]
        cells = [name, label, f"{_mean_ratio(full, ref[0]):.3f}", f"{_mean_ratio(single, ref[1]):.3f}",
                 f"{_mean_ratio(ms, ref_ms):.3f}", f"{err / floor:.2f}×"]
        if label in strips:
            perfect_ms = yarn_scale_metrics(single + (inst[0] - inst[1]), ref[0], d)["rel_l1"]
            perfect_ss = yarn_scale_metrics(inst[1] + ms, ref[0], d)["rel_l1"]
            cells += [f"{perfect_ms / floor:.2f}×", f"{perfect_ss / floor:.2f}×"]
            for own, other, mine in ((single, inst[1], ref[1]), (ms, inst[0] - inst[1], ref_ms)):
                half_floor = yarn_scale_metrics(other, mine, d)["rel_l1"]
                cells.append(f"{yarn_scale_metrics(own, mine, d)['rel_l1'] / half_floor:.2f}×" if half_floor > 0
                             else "—")
        else:
            cells += ["—"] * 4
        rows.append("| " + " | ".join(cells) + " |")
    return rows, floor


def channel_rows(name, scene, ref, inst, strips):
    """Markdown rows: per RGB channel, the instance's and each model's whole, SS and MS over the reference's (a
    colour's dark channels hold less multiple scattering, which a model may get wrong apart from the bright one)."""
    def ratios(full, single):
        sums = [x.sum(axis=(0, 1)) for x in (full, single, full - single)]
        refs = [x.sum(axis=(0, 1)) for x in (ref[0], ref[1], ref[0] - ref[1])]
        return [" / ".join(f"{a / b:.3f}" if b > 0 else "—" for a, b in zip(part, whole))
                for part, whole in zip(sums, refs)]

    share = (ref[0] - ref[1]).sum(axis=(0, 1)) / np.maximum(ref[0].sum(axis=(0, 1)), 1e-300)
    colour = " / ".join(f"{c:g}" for c in scene.yarns[0].color)
    return ["| " + " | ".join([name, colour, label, *ratios(*images), " / ".join(f"{x:.3f}" for x in share)]) + " |"
            for label, images in [("*other fiber instance*", inst), *strips.items()]]


def tilt_rows(name, d, at, ref, strips):
    """Markdown rows of the yarn-scale SS and MS at the control points ``at`` = (row, col, tilt), by tilt bin."""
    row, col, tilt = at

    def sampled(image):
        return yarn_filter(image, d).mean(-1)[row, col]

    out = []
    for label, (full, single) in [("reference", ref), *strips.items()]:
        ss, ms = sampled(single), sampled(full - single)
        cells = []
        for lo, hi in zip(TILT_BINS[:-1], TILT_BINS[1:]):
            inside = (tilt >= lo) & ((tilt < hi) | (hi == TILT_BINS[-1]))
            cells.append(f"{ss[inside].mean():.4f} / {ms[inside].mean():.4f}" if inside.any() else "—")
        out.append(f"| {name} | {label} | " + " | ".join(cells) + " |")
    return out


def loop_rows(name, scene, pack, model, ref, inst, strip):
    """Markdown rows of ``--loop-bins`` for the Crane patch ``scene``: per loop-phase bin of the interior courses,
    the references' (``ref``, ``inst``: (full, single), averaged) SS share, ``strip``'s (full, single) SS, MS and
    whole over theirs, and the bin's share of their light, over the pixels ``model``'s front regular strips cover."""
    lum = np.asarray(LUMINANCE, np.float64)
    full, single = (0.5 * (a + b) @ lum for a, b in zip(ref, inst))
    model_full, model_single = (a @ lum for a in strip)
    renderer = pipeline.Renderer(scene, {"cotton1": pack}, combined(model))
    rows, cols, _, _, curve, along = front_strips(scene, renderer)
    phase, interior = loop_phase(curve, along, renderer.curves)
    _, first = np.unique(rows * scene.camera.width + cols, return_index=True)  # one sample per pixel
    rows, cols, phase, interior = rows[first], cols[first], phase[first], interior[first]
    total = full[rows[interior], cols[interior]].sum()
    out = []
    for b in range(LOOP_BINS):
        at = interior & (phase == b)
        r, c = rows[at], cols[at]
        ss, ms = single[r, c].sum(), (full - single)[r, c].sum()
        cells = [f"{-90 + 15 * b:+d}°", f"{ss / (ss + ms):.2f}", f"{model_single[r, c].sum() / ss:.2f}",
                 f"{(model_full - model_single)[r, c].sum() / ms:.2f}",
                 f"{model_full[r, c].sum() / (ss + ms):.2f}", f"{(ss + ms) / total:.3f}"]
        out.append(f"| {name} | " + " | ".join(cells) + " |")
    return out


LAYER_PARTS = ("regular SS", "regular MS", "flyaways' SS", "flyaways' MS")


def draw_rows(name, d, reference, draws, models):
    """``--ss-draws``' rows for one scene (module docstring): ``reference`` and each of ``draws`` (the instance first)
    and ``models`` (name → image) single-scattering images (H, W, 3)."""
    lum = np.asarray(LUMINANCE, np.float64)

    def filtered(image):
        return yarn_filter(image, d) @ lum

    ref = filtered(reference)
    others = [filtered(x) for x in draws]
    mean = np.mean(others, axis=0)
    lit = mean > LIT * mean.max()
    order = np.argsort(ref[lit])[::-1]
    top = [order[:max(1, len(order) * k // 100)] for k in (5, 20)]

    def error(image, against=ref):
        return np.abs(image - against).sum() / against.sum()

    floor = error(others[0])

    def row(label, image, errors):
        values = image[lit]
        shares = " / ".join(f"{values[t].sum() / values.sum():.2f}" for t in top)
        correlation = "—" if image is mean else f"{np.corrcoef(values, mean[lit])[0, 1]:.2f}"
        return f"| {name} | {label} | {errors} | {shares} | {values.std() / values.mean():.2f} | {correlation} |"

    rows = [row("reference", ref, "— | —"), row("other fiber instance (the floor)", others[0], "1.00× | —")]
    if len(others) > 2:
        loo = np.mean([error(np.mean(others[:k] + others[k + 1:], axis=0), others[k]) for k in range(len(others))])
        rows.append(row(f"mean of the {len(others)} other draws", mean,
                        f"{error(mean) / floor:.2f}× (leave one out: {loo / floor:.2f}×) | —"))
    for model, image in models.items():
        drawn = filtered(image)
        matched = error(drawn * ref.sum() / drawn.sum())
        rows.append(row(model, drawn, f"{error(drawn) / floor:.2f}× | {matched / floor:.2f}×"))
    return rows


def layer_parts(whole, regular):
    """The four parts of ``LAYER_PARTS`` (RGB means) from the (full, single) images of the whole light and of the
    light whose camera ray first meets a regular fiber."""
    full, single = (float(np.mean(a)) for a in whole)
    reg_full, reg_single = (float(np.mean(a)) for a in regular)
    return (reg_single, reg_full - reg_single, single - reg_single, (full - single) - (reg_full - reg_single))


def layer_rows(name, ref, inst, strips):
    """Markdown rows of ``--layers``: ``ref``, ``inst`` and each entry of ``strips`` (label → (whole, regular), each
    a (full, single) pair) as their parts' ratios to the reference's, after a row of the reference's shares."""
    parts = layer_parts(*ref)
    total = float(np.mean(ref[0][0]))
    rows = [f"| {name} | *reference: share of its light* | " + " | ".join(f"{p / total:.3f}" for p in parts) + " |"]
    for label, (whole, regular) in [("*other fiber instance*", inst), *strips.items()]:
        rows.append(f"| {name} | {label} | " + " | ".join(
            f"{q / p:.2f}×" if p > 0 else "—" for q, p in zip(layer_parts(whole, regular), parts)) + " |")
    return rows


def kept_curves(scene, keep, scale, folder):
    """``scene`` with only the curves ``keep`` (indices, or None: all) of each yarn entry's curve file, scaled by
    ``scale`` about the camera's look-at point with the camera ``scale`` times as far and ``scale`` times the pixels
    per side (module docstring, ``--curves``, ``--scale``); the new curve files are written under ``folder``.
    ValueError (one line) for an entry without a curve file or an index it lacks."""
    centre = np.asarray(scene.camera.look_at, np.float64)
    yarns = []
    for k, entry in enumerate(scene.yarns):
        if entry.curves is None:
            raise ValueError(f"yarns[{k}] draws a stitch mesh, not a curve file: --curves and --scale need curves")
        curves = read_yarn_curves(entry.curves)
        chosen = range(len(curves.offsets) - 1) if keep is None else keep
        bad = [c for c in chosen if not 0 <= c < len(curves.offsets) - 1]
        if bad:
            raise ValueError(f"yarns[{k}]: {entry.curves} has {len(curves.offsets) - 1} curves, no curve {bad[0]}")
        spans = [slice(curves.offsets[c], curves.offsets[c + 1]) for c in chosen]
        points = centre + (np.concatenate([curves.points[:, s] for s in spans], axis=1) - centre) * scale
        kept = make_yarn_curves(points, np.concatenate([[0], np.cumsum([s.stop - s.start for s in spans])]),
                                closed=curves.closed[list(chosen)], yarn_type=curves.yarn_type[list(chosen)],
                                yarn_types=curves.yarn_types,
                                rest_arclength=np.concatenate([curves.rest_arclength[s] for s in spans]) * scale,
                                curve_type=curves.curve_type, units=curves.units, frame_time=curves.frame_time,
                                radius=curves.radius)
        path = Path(folder) / f"yarn{k}_curves.h5"
        write_yarn_curves(path, kept)
        yarns.append(dataclasses.replace(entry, curves=path))
    camera = scene.camera
    position = centre + (np.asarray(camera.position, np.float64) - centre) * scale
    camera = dataclasses.replace(camera, position=tuple(position.tolist()),
                                 ortho_height=None if camera.ortho_height is None else camera.ortho_height * scale,
                                 width=max(1, round(camera.width * scale)), height=max(1, round(camera.height * scale)))
    return dataclasses.replace(scene, yarns=tuple(yarns), camera=camera)


def checked_models_and_scenes(parser, args):
    """(models, scene names) of ``--models`` and ``--scenes``, each checked, and ``--pack`` a file; a one-line
    ``parser.error`` for the first that is not."""
    models = args.models.split(",")
    for model in models:
        try:
            combined(model)
        except ValueError as error:
            parser.error(f"--models: {error}")
    names = args.scenes.split(",")
    missing = [n for n in names if not (ROOT / "examples" / "scenes" / f"{n}.toml").is_file()]
    if missing:
        parser.error(f"--scenes: no example scene {missing[0]!r}")
    if not Path(args.pack).is_file():
        parser.error(f"--pack: no file {args.pack}")
    return models, names


def main():
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--pack", required=True, help="the asset pack of cotton1")
    parser.add_argument("--scenes", default=",".join(SCENES), help="comma-separated example scene names")
    parser.add_argument("--models", default="full,no_tables,plain_ds",
                        help="names of knitrun.render.ablations, or combinations a+b")
    parser.add_argument("--spp", type=int, default=None, help="samples per pixel (default: the ruler's per scene)")
    parser.add_argument("--tilt-bins", action="store_true", help="bin SS and MS along the curves by |ω_o · t|")
    parser.add_argument("--loop-bins", action="store_true", help="on the Crane patches, SS and MS per loop-phase bin")
    parser.add_argument("--layers", action="store_true",
                        help="each half split again by the layer seen first: regular fibers, flyaways")
    parser.add_argument("--curves", default=None,
                        help="comma-separated curve indices: keep only those of each scene's curve files")
    parser.add_argument("--scale", type=float, default=1.0,
                        help="scale the curves about the look-at point, the camera S times as far and S times the "
                             "pixels per side (the same picture, every bend gentler)")
    parser.add_argument("--no-flyaways", action="store_true", help="the regular fibers alone, in both")
    parser.add_argument("--ss-draws", type=int, default=0, help="trace N more fiber draws at one event: how much of "
                        "the single scattering's place the yarns fix (module docstring)")
    parser.add_argument("--color", default=None, help="R,G,B: draw every yarn in this colour instead of the scene's")
    parser.add_argument("--channels", action="store_true",
                        help="each model's whole, SS and MS over the reference's per RGB channel")
    parser.add_argument("--out", type=Path, default=None, help="keep the images here")
    args = parser.parse_args()
    models, names = checked_models_and_scenes(parser, args)
    if not (math.isfinite(args.scale) and args.scale > 0.0):
        parser.error(f"--scale: {args.scale} is not a positive number")
    if args.ss_draws < 0:
        parser.error(f"--ss-draws: {args.ss_draws} is negative")
    if args.layers and args.no_flyaways:
        parser.error("--layers splits the light by the flyaways: not with --no-flyaways")
    if args.loop_bins and (args.curves is not None or args.scale != 1.0):
        parser.error("--loop-bins reads the whole Crane patch: not with --curves or --scale")
    try:
        keep = None if args.curves is None else [int(c) for c in args.curves.split(",")]
    except ValueError:
        parser.error(f"--curves: {args.curves!r} is not a comma-separated list of curve indices")
    colour = None
    if args.color is not None:
        try:
            colour = tuple(float(c) for c in args.color.split(","))
        except ValueError:
            colour = ()
        if len(colour) != 3 or not all(math.isfinite(c) and c >= 0.0 for c in colour):
            parser.error(f"--color: {args.color!r} is not three finite numbers ≥ 0 (R,G,B)")
    flyaways = not args.no_flyaways
    scratch = tempfile.TemporaryDirectory(prefix="probe_split_")
    print("Over a black background; ratios of RGB means to the reference's (the compare weighs luminance); rel L1 at "
          "the yarn scale over the instance floor.\n")
    print("| scene | model | mean ratio | SS mean ratio | MS mean ratio | rel L1 (d) / floor | with the instance's MS "
          "| with the instance's SS | SS / its floor | MS / its floor |")
    print("|---" * 10 + "|")
    tilt_tables, loop_tables, layer_tables, draw_tables, channel_tables = [], [], [], [], []
    for name in names:
        scene = load_scene(ROOT / "examples" / "scenes" / f"{name}.toml")
        scene = dataclasses.replace(scene, background=(0.0, 0.0, 0.0))
        if colour is not None:
            scene = dataclasses.replace(scene, yarns=tuple(dataclasses.replace(y, color=colour) for y in scene.yarns))
        if keep is not None or args.scale != 1.0:
            folder = Path(scratch.name) / name
            folder.mkdir()
            try:
                scene = kept_curves(scene, keep, args.scale, folder)
            except ValueError as error:
                parser.error(f"--curves/--scale on {name}: {error}")
        spp = args.spp or SCENES.get(name, 16)
        seed, d = scene.render.seed, yarn_diameter_px(scene)
        *ref, ref_s = traced(scene, spp, seed, seed, flyaways=flyaways)
        *inst, inst_s = traced(scene, spp, seed + 1, seed + 1, flyaways=flyaways)
        strips = {m: rendered(scene, args.pack, m, flyaways=flyaways) for m in models}
        rows, floor = split_rows(name, d, ref, inst, strips)
        print("\n".join(rows), flush=True)
        print(f"<!-- {name}: {spp} spp, d = {d:.1f} px, instance floor {floor:.3f}; traced {ref_s:.0f} + "
              f"{inst_s:.0f} s; SS is {ref[1].mean() / ref[0].mean():.2f} of the reference -->", flush=True)
        if args.out is not None:
            folder = args.out / name
            folder.mkdir(parents=True, exist_ok=True)
            for label, (full, single) in [("reference", ref), ("instance", inst),
                                          *((f"strip_{m}", s) for m, s in strips.items())]:
                write_exr(folder / f"{label}_full.exr", full.astype(np.float32))
                write_exr(folder / f"{label}_single.exr", single.astype(np.float32))
        if args.channels:
            channel_tables += channel_rows(name, scene, ref, inst, strips)
        if args.layers:
            *ref_regular, _ = traced(scene, spp, seed, seed, seen="regular")
            *inst_regular, _ = traced(scene, spp, seed + 1, seed + 1, seen="regular")
            layer_tables += layer_rows(name, (ref, ref_regular), (inst, inst_regular),
                                       {m: (strips[m], rendered(scene, args.pack, m, hair_light=False))
                                        for m in models})
        if args.ss_draws:
            more = [trace_reference(scene, spp, seed + k, 1, fiber_seed=seed + k, flyaways=flyaways)[0]
                    for k in range(2, args.ss_draws + 2)]
            draw_tables += draw_rows(name, d, ref[1], [inst[1], *(np.asarray(x, np.float64)[..., :3] for x in more)],
                                     {m: single for m, (_, single) in strips.items()})
        if args.tilt_bins:
            at = curve_tilts(scene)
            populated = 0 if at is None else len(np.unique(np.digitize(at[2], TILT_BINS[1:-1])))
            if populated > 1:  # a straight yarn sits in one bin
                tilt_tables += tilt_rows(name, d, at, ref, strips)
        if args.loop_bins and all(y.curves is not None and Path(y.curves).name == CRANE_CURVES for y in scene.yarns):
            loop_tables += loop_rows(name, scene, args.pack, models[0], ref, inst, strips[models[0]])
    scratch.cleanup()
    if channel_tables:
        print("\nPer channel (R / G / B) over the reference's: whole, SS, MS; the yarns' colour and the reference's "
              "share of MS in each channel:\n")
        print("| scene | colour | image | whole | SS | MS | reference's MS share |")
        print("|---" * 7 + "|")
        print("\n".join(channel_tables))
    if tilt_tables:
        print("\nYarn-scale SS / MS at the control points, by |ω_o · t|:\n")
        print("| scene | image | " + " | ".join(f"{lo:.1f}–{hi:.1f}" for lo, hi in zip(TILT_BINS[:-1], TILT_BINS[1:]))
              + " |")
        print("|---" * 7 + "|")
        print("\n".join(tilt_tables))
    if draw_tables:
        print("\nSingle scattering at the yarn scale against the reference's: rel L1 over its floor (the instance's); "
              "share in the reference's brightest 5 % / 20 % of the lit pixels, coefficient of variation there, "
              "correlation with the other draws' mean:\n")
        print("| scene | image | rel L1 / floor | mean matched | top 5 % / 20 % | CV | correlation |")
        print("|---" * 7 + "|")
        print("\n".join(draw_tables))
    if layer_tables:
        print("\nEach half by the layer the camera ray meets first (RGB means; the model's and the instance's part "
              "over the reference's):\n")
        print("| scene | image | " + " | ".join(LAYER_PARTS) + " |")
        print("|---" * 6 + "|")
        print("\n".join(layer_tables))
    if loop_tables:
        print(f"\nPer loop-phase bin of the interior courses ({models[0]} over the mean of the reference and the "
              "instance, luminance):\n")
        print("| scene | loop phase | reference SS share | SS | MS | whole | share of the light |")
        print("|---" * 7 + "|")
        print("\n".join(loop_tables))


if __name__ == "__main__":
    main()
