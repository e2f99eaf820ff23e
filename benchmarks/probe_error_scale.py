"""At what scale the strip model's yarn-scale error lies (issue 13, the look): oracle corrections from the reference.

For each scene, the full model's image is multiplied by the brightness correction that the reference itself would
give it (an *oracle*: ratio of the reference's summed luminance to the model's over a set of pixels) and its
yarn-scale relative L1 at the projected diameter d (``knitbake.compare.image_metrics.yarn_scale_metrics``) is taken
again. What an oracle removes, a term of that form (a brightness that depends only on the oracle's bins) could remove;
what it leaves, no such term can. The first four oracles are over the pixels the front strips cover (an MSAA-1 raster
of the regular strips, ``strip_raster.rasterize_visibility``):

* ``one gain``: one factor for the whole image (the mean ratio's part of the error);
* ``v``: one factor per 1/8 of the strip's width (16 bins of v ∈ [−1, 1]): a profile across the yarn, as the baked
  tables in v would give;
* ``v × angle``: per v bin and 10° bin of the strip tangent's direction on screen (in x–y: the examples look
  along −z): a brightness per part of the yarn and orientation to the light, as any table in (v, θ, φ) would give;
* ``gain at k·d``: the local ratio of the reference to the model, both box-filtered k·d pixels wide (k = 2, 4, 8):
  a brightness per stitch neighbourhood (shadows, inter-reflection between yarns). The same gain is applied to the
  reference's other fiber instance as a control: where it leaves the instance at its floor, the rest of the model's
  error lies below that scale.
* ``stitch phase`` (the Crane patch scenes only, whose stitches are all alike: ``knitrun.sim.crane_stockinette``):
  one factor per place inside the stitch, over every pixel whose ray meets the fabric plane z = 0 at least one stitch
  inside the patch: per bin of (x mod the stitch width, y mod the row spacing), bins about a pixel wide, the ratio of
  the reference's summed luminance to the model's. A bin pools the same place of 16 stitches, so the gain follows
  what the stitches have in common and not one instance's fibers: what it removes is an error that every stitch
  repeats (light placed or shaded wrongly in the stitch), which a model can fix. Its control is the same oracle built
  for the other fiber instance (how far such a gain goes on an image that has no systematic error). This oracle and
  the next are measured on the interior's bounding box, against that crop's own instance floor.
* ``loop phase`` (the same scenes): one factor per place along the loop, over the pixels the front regular strips
  cover: per bin of the front strip's rest arc length along its course, modulo one stitch (``LOOP_BINS`` per
  stitch, 15° of Crane's t each, from the middle of a leg), the interior courses apart from the first and last. It
  pools a part of the yarn's path (a leg, the bend into a head, a sinker) wherever the camera sees it, whatever lies
  around it; printed with the model over the reference per bin over the interior courses (and the instance over the
  reference, how far one draw moves a bin): which part of the loop is lit wrongly.
* ``average stitch`` (the same scenes and bins): the image with each interior pixel replaced by its bin's mean (the
  stitch that the image shows on average), for the model, the reference and the instance: if the model's average
  stitch scores as the model does, its stitch-to-stitch variation costs nothing and the error is in the average
  stitch; the reference's own average stitch is the best any image that repeats per stitch can do.

With ``--out``, the stitch-phase scenes also get ``<scene>_average_stitch.png``: the reference's average stitch, the
model's, and the log ratio of their luminance at half the yarn scale (red: the model too bright, blue: too dark,
green: within ±19 %), over a window of 2 × 2 stitches, enlarged 3×; and ``<scene>_loop_phase.png``: the reference,
the model, and the model's front strips painted by their loop-phase bin's ratio in the same colours, same window.

Printed per scene: the instance floor, the model's error, and each oracle's error (and ratio to the floor). Needs
the references of ``bench_floors.py`` (``<scene>.exr`` and ``<scene>_instance.exr``). About 5 s per scene on 2 cores.

    .venv/bin/python benchmarks/probe_error_scale.py --pack out/bench/cotton1_standard.h5 \\
        --reference-dir out/bench/refs2 [--scenes knit_patch_directional,knit_patch_sky] [--ablation full] [--out DIR]
"""

from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np

from data_formats.conventions import LUMINANCE
from data_formats.images import read_exr, write_png
from data_formats.scene import load_scene
from knitbake.compare.image_metrics import yarn_filter, yarn_scale_metrics
from knitbake.compare.report import yarn_diameter_px
from knitrun.render import pipeline
from knitrun.render.ablations import combined
from knitrun.render.camera import scene_camera, tan_half_fov
from knitrun.sim.crane_stockinette import CRANE_RADIUS, ROW_SPACING
from knitrun.render.strip_raster import rasterize_visibility, sample_attributes

EXAMPLES = Path(__file__).parent.parent / "examples" / "scenes"
PATCHES = "knit_patch_directional,knit_patch_sky,knit_patch_grazing,simulated_patch_directional"
V_BINS = 16
ANGLE_BINS = 18  # 10° each over [0°, 180°): a line on screen has no sign
GAIN_SCALES = (2, 4, 8)
CRANE_CURVES = "knit_patch_6x6.h5"  # the example scenes' Crane patch: every stitch the same (stitch-phase oracle)
CRANE_COLS = 6  # its stitches per course
LOOP_BINS = 24  # loop-phase bins per stitch (15° of Crane's t each)


def front_strips(scene, renderer):
    """Pixel rows, columns, v and the tangent's angle in the x–y plane (degrees in [0, 180); the screen's for the
    example scenes' cameras, which look along −z) of the samples the front regular strips of ``renderer``
    (a ``pipeline.Renderer`` of ``scene``) cover, at one sample per pixel; and each sample's curve and the fraction
    of its curve's rest length at it."""
    lines = pipeline._polylines(scene, renderer.curves, renderer.frame_index(None), renderer.samples_per_segment)
    radius = np.array([renderer.looks[k].radius for k in lines.entry])
    vis = rasterize_visibility(lines.points, lines.offsets, False, lines.rest, radius, lines.entry,
                               scene_camera(scene), 1)
    rows, cols, sample = np.nonzero(vis.coverage)
    attributes = sample_attributes(vis, rows, cols, sample)
    t = np.asarray(attributes["tangent"], np.float64)
    curve = vis.curve[rows, cols, sample].astype(np.int64)
    return (rows, cols, np.asarray(attributes["v"]), np.degrees(np.arctan2(t[:, 1], t[:, 0])) % 180.0, curve,
            fraction_along(lines, curve, attributes["arclength"]))


def fraction_along(lines, curve, arclength):
    """The fraction (N,) of its curve's rest length at points of ``curve`` (N,) and rest ``arclength`` (N,) on
    ``lines`` (the renderer's polylines)."""
    start, end = lines.rest[lines.offsets[:-1]], lines.rest[lines.offsets[1:] - 1]
    return (np.asarray(arclength, np.float64) - start[curve]) / (end - start)[curve]


def loop_phase(curve, along, curves, cols=CRANE_COLS):
    """The loop phase bin (``LOOP_BINS`` per stitch) of front-strip samples of the Crane patch (its rows run
    ``cols`` whole stitches, t ∈ [−π/2, 2π·cols − π/2], every stitch the same length: the phase is the fraction
    ``along`` the curve times ``cols``, mod 1; phase 0 is the middle of a leg, t = −π/2) and whether the sample's
    course is an interior one (neither the first nor the last curve)."""
    phase = (along * cols) % 1.0
    n_curves = sum(len(c.offsets) - 1 for c in curves)
    return np.minimum((phase * LOOP_BINS).astype(np.int64), LOOP_BINS - 1), (curve > 0) & (curve < n_curves - 1)


def stitch_phase_bins(scene, curves, shape):
    """(H·W,) bin of each pixel's place inside the stitch, −1 for a pixel whose ray meets the fabric plane z = 0
    less than one stitch inside the patch; None for a scene that is not the example Crane patch. The place is (x mod
    2πs, y mod w·s) of the ray's hit (``crane_stockinette``: one stitch per 2π·s along x, rows w·s apart, s = radius
    / CRANE_RADIUS), binned about a pixel wide there; the patch is the box of the points of ``curves`` (the
    renderer's ``YarnCurves``, one per yarn entry)."""
    if len(scene.yarns) != 1 or Path(scene.yarns[0].curves).name != CRANE_CURVES:
        return None
    camera = scene_camera(scene)
    rows, cols = np.divmod(np.arange(shape[0] * shape[1]), shape[1])
    fwd, right, up = (np.asarray(a, np.float64) for a in camera.basis())
    sx = (2.0 * (cols + 0.5) - camera.width) / camera.height
    sy = 1.0 - 2.0 * (rows + 0.5) / camera.height
    if camera.ortho_height > 0:
        origin = np.asarray(camera.position) + 0.5 * camera.ortho_height * (sx[:, None] * right + sy[:, None] * up)
        ray = np.broadcast_to(fwd, origin.shape)
        pixel = camera.ortho_height / camera.height
    else:
        origin = np.broadcast_to(np.asarray(camera.position, np.float64), (len(rows), 3))
        ray = fwd + tan_half_fov(camera) * (sx[:, None] * right + sy[:, None] * up)
        pixel = abs(float(camera.position[2] / fwd[2])) * 2.0 * tan_half_fov(camera) / camera.height
    hit = origin - (origin[:, 2] / ray[:, 2])[:, None] * ray
    s = scene.yarns[0].radius / CRANE_RADIUS
    period = np.array([2.0 * np.pi * s, ROW_SPACING * s])
    points = np.concatenate([np.asarray(c.points, np.float64).reshape(-1, 3) for c in curves])
    lo, hi = points.min(axis=0)[:2] + period, points.max(axis=0)[:2] - period
    inside = np.all((hit[:, :2] > lo) & (hit[:, :2] < hi), axis=1)
    n = np.maximum(1, np.round(period / pixel)).astype(np.int64)
    phase = (hit[:, :2] / period) % 1.0
    ix, iy = (np.minimum((phase[:, k] * n[k]).astype(np.int64), n[k] - 1) for k in range(2))
    return np.where(inside, iy * n[0] + ix, -1)


def average_stitch(img, bins):
    """``img`` (H, W, C) with each pixel of bin ≥ 0 replaced by its bin's mean (``stitch_phase_bins``)."""
    flat = img.reshape(-1, img.shape[-1]).copy()
    at = bins >= 0
    count = np.maximum(np.bincount(bins[at]), 1)
    for c in range(flat.shape[1]):
        flat[at, c] = (np.bincount(bins[at], weights=flat[at, c], minlength=len(count)) / count)[bins[at]]
    return flat.reshape(img.shape)


def stitch_gain(test, reference, bins):
    """(H, W) gains: per stitch-phase bin, the reference's summed luminance over ``test``'s (1 outside the bins)."""
    at = bins >= 0
    lt = np.bincount(bins[at], weights=test.reshape(-1)[at])
    lr = np.bincount(bins[at], weights=reference.reshape(-1)[at], minlength=len(lt))
    gain = np.ones(test.size)
    gain[at] = np.where(lt > 0.0, lr / np.where(lt > 0.0, lt, 1.0), 1.0)[bins[at]]
    return gain.reshape(test.shape)


def average_stitch_png(path, reference, model, bins, d):
    """``--out``'s picture (module docstring) of the images cropped to the stitch interior (``bins`` of the crop):
    reference and model average stitches, and their log luminance ratio."""
    lum = np.asarray(LUMINANCE, np.float64)
    ref_avg, model_avg = average_stitch(reference, bins), average_stitch(model, bins)
    window = (slice(0, int(round(5.6 * d))), slice(0, int(round(7.9 * d))))  # ~2 × 2 stitches from the top left
    half = max(1, int(round(d / 2)))
    ratio = np.log2(np.maximum(yarn_filter((model_avg @ lum)[..., None], half)[..., 0], 1e-9)
                    / np.maximum(yarn_filter((ref_avg @ lum)[..., None], half)[..., 0], 1e-9))[window]
    scale = 1.0 / max(float(np.percentile(ref_avg[window], 99.5)), 1e-12)
    tone = [np.clip(a[window] * scale, 0.0, 1.0) ** (1 / 2.2) for a in (ref_avg, model_avg)]
    signed = np.stack([np.clip(ratio, 0, 1.5) / 1.5, 0.6 * np.clip(1 - np.abs(ratio) / 0.25, 0, 1),
                       np.clip(-ratio, 0, 1.5) / 1.5], axis=-1)
    gap = np.ones((tone[0].shape[0], 3, 3))
    picture = np.concatenate([tone[0], gap, tone[1], gap, signed], axis=1) ** 2.2
    write_png(path, np.repeat(np.repeat(picture, 3, axis=0), 3, axis=1))  # 3× nearest: a stitch ~200 px wide


def loop_phase_png(path, reference, model, rows, cols, phase, interior, ratio, origin, d):
    """``--out``'s loop-phase picture: the reference, the model, and the model's front-strip pixels of the interior
    courses painted by their bin's model / reference (``ratio`` per loop-phase bin; red: the model too bright, blue:
    too dark, green: within ±19 %, as the average stitch's), over a window of about 2 × 2 stitches from ``origin``
    (row, column), enlarged 3×."""
    window = (slice(origin[0], origin[0] + int(round(5.6 * d))), slice(origin[1], origin[1] + int(round(7.9 * d))))
    log_ratio = np.zeros(model.shape[:2])
    painted = np.zeros(model.shape[:2], bool)
    log_ratio[rows[interior], cols[interior]] = np.log2(np.maximum(ratio[phase[interior]], 1e-9))
    painted[rows[interior], cols[interior]] = True
    scale = 1.0 / max(float(np.percentile(reference[window], 99.5)), 1e-12)
    tone = [np.clip(a[window] * scale, 0.0, 1.0) ** (1 / 2.2) for a in (reference, model)]
    r = log_ratio[window]
    signed = np.stack([np.clip(r, 0, 1.5) / 1.5, 0.6 * np.clip(1 - np.abs(r) / 0.25, 0, 1),
                       np.clip(-r, 0, 1.5) / 1.5], axis=-1) * painted[window][..., None]
    gap = np.ones((tone[0].shape[0], 3, 3))
    picture = np.concatenate([tone[0], gap, tone[1], gap, signed], axis=1) ** 2.2
    write_png(path, np.repeat(np.repeat(picture, 3, axis=0), 3, axis=1))


def binned_gain(model, reference, rows, cols, bins):
    """(H, W) gains: per bin, the reference's luminance over the model's, summed over the bin's pixels; 1 elsewhere."""
    gain = np.ones(model.shape)
    lm, lr = model[rows, cols], reference[rows, cols]
    for b in np.unique(bins):
        at = bins == b
        den = lm[at].sum()
        gain[rows[at], cols[at]] = lr[at].sum() / den if den > 0.0 else 1.0
    return gain


def local_gain(test, reference, size):
    """(H, W) gains: the reference's luminance over ``test``'s, both box-filtered ``size`` pixels wide."""
    ft = yarn_filter(test[..., None], size)[..., 0]
    fr = yarn_filter(reference[..., None], size)[..., 0]
    return np.where(ft > 0.0, fr / np.where(ft > 0.0, ft, 1.0), 1.0)


def probe(name, pack, reference_dir, ablation, out=None):
    scene = load_scene(EXAMPLES / f"{name}.toml")
    packs = {"cotton1": str(pack)}  # the example scenes draw cotton1, as bench_compare.py
    reference = read_exr(Path(reference_dir) / f"{name}.exr").astype(np.float64)[..., :3]
    instance = read_exr(Path(reference_dir) / f"{name}_instance.exr").astype(np.float64)[..., :3]
    renderer = pipeline.Renderer(scene, packs, features=combined(ablation))  # the packs loaded once for both uses
    model = np.asarray(renderer.render().image, np.float64)[..., :3]
    d = yarn_diameter_px(scene)
    lum = np.asarray(LUMINANCE, np.float64)
    lm, lr, li = model @ lum, reference @ lum, instance @ lum
    floor = yarn_scale_metrics(instance, reference, d)["rel_l1"]

    def error(img, gain):
        return yarn_scale_metrics(img * gain[..., None], reference, d)["rel_l1"]

    rows, cols, v, angle, curve, along = front_strips(scene, renderer)
    v_bin = np.clip(((v + 1.0) * 0.5 * V_BINS).astype(np.int64), 0, V_BINS - 1)
    angle_bin = np.clip((angle / 180.0 * ANGLE_BINS).astype(np.int64), 0, ANGLE_BINS - 1)
    plain = error(model, np.ones(lm.shape))
    lines = [f"{name}: d = {d:.1f} px, instance floor {floor:.4f}, {ablation} {plain:.4f} ({plain / floor:.2f}× floor)"]
    for label, bins in (("one gain", np.zeros(len(rows), np.int64)), ("v", v_bin),
                        ("v × angle", v_bin * ANGLE_BINS + angle_bin)):
        e = error(model, binned_gain(lm, lr, rows, cols, bins))
        lines.append(f"  oracle {label:12s} {e:.4f} ({e / floor:.2f}× floor)")
    for k in GAIN_SCALES:
        size = max(1, int(round(k * d)))
        e, e_instance = error(model, local_gain(lm, lr, size)), error(instance, local_gain(li, lr, size))
        lines.append(f"  oracle gain at {k}d  {e:.4f} ({e / floor:.2f}× floor); the instance under the same oracle "
                     f"{e_instance:.4f}")
    bins = stitch_phase_bins(scene, renderer.curves, lm.shape)
    if bins is not None:  # on the interior's bounding box alone, where every pixel has a bin
        rows_in, cols_in = np.divmod(np.flatnonzero(bins >= 0), lm.shape[1])
        box = (slice(rows_in.min(), rows_in.max() + 1), slice(cols_in.min(), cols_in.max() + 1))
        bins = bins.reshape(lm.shape)[box].reshape(-1)
        crop = [a[box] for a in (model, reference, instance)]
        inner_floor = yarn_scale_metrics(crop[2], crop[1], d)["rel_l1"]

        def inner(img, gain=None):
            test = img if gain is None else img * gain[..., None]
            return yarn_scale_metrics(test, crop[1], d)["rel_l1"] / inner_floor

        lm_in, lr_in, li_in = (a @ lum for a in crop)
        lines.append(f"  stitch interior ({box[0].stop - box[0].start} × {box[1].stop - box[1].start} px, every "
                     f"pixel in a bin): instance floor {inner_floor:.4f}, {ablation} {inner(crop[0]):.2f}× floor; "
                     f"oracle stitch phase {inner(crop[0], stitch_gain(lm_in, lr_in, bins)):.2f}×, the instance "
                     f"under the same oracle {inner(crop[2], stitch_gain(li_in, lr_in, bins)):.2f}×")
        lines.append("  average stitch: the model's {:.2f}× floor, the reference's {:.2f}×, the instance's {:.2f}×"
                     .format(*(inner(average_stitch(img, bins)) for img in crop)))
        phase, interior = loop_phase(curve, along, renderer.curves)
        e = error(model, binned_gain(lm, lr, rows, cols, phase + LOOP_BINS * interior))
        lines.append(f"  oracle loop phase ({LOOP_BINS} bins, interior and outer courses apart) {e:.4f} "
                     f"({e / floor:.2f}× floor); model / reference per bin over the interior courses' front-strip "
                     f"pixels (instance / reference), from a leg's middle (t = −90°) in steps of 15° of t:")
        profile, ratio = [], np.ones(LOOP_BINS)
        for b in range(LOOP_BINS):
            at = interior & (phase == b)
            r, c = rows[at], cols[at]
            ratio[b] = lm[r, c].sum() / max(lr[r, c].sum(), 1e-30)
            profile.append(f"{-90 + 15 * b:+4d}°: {ratio[b]:.2f} ({li[r, c].sum() / max(lr[r, c].sum(), 1e-30):.2f}) "
                           f"n={at.sum()}")
        lines.extend("    " + "; ".join(profile[k:k + 4]) for k in range(0, LOOP_BINS, 4))
        if out is not None:
            loop_phase_png(Path(out) / f"{name}_loop_phase.png", reference, model, rows, cols, phase, interior,
                           ratio, (box[0].start, box[1].start), d)
            average_stitch_png(Path(out) / f"{name}_average_stitch.png", crop[1], crop[0], bins, d)
    return "\n".join(lines)


def main():
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--pack", required=True)
    parser.add_argument("--reference-dir", required=True)
    parser.add_argument("--scenes", default=PATCHES)
    parser.add_argument("--ablation", default="full", help="an ablation or a combination a+b (ablations.combined)")
    parser.add_argument("--out", help="folder for the stitch-phase scenes' average-stitch pictures (module docstring)")
    args = parser.parse_args()
    try:
        combined(args.ablation)
    except ValueError as e:
        parser.error(f"--ablation: {e}")
    if args.out:
        Path(args.out).mkdir(parents=True, exist_ok=True)
    for name in args.scenes.split(","):
        print(probe(name, args.pack, args.reference_dir, args.ablation, args.out), flush=True)


if __name__ == "__main__":
    main()
