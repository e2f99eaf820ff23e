"""At what scale the strip model's yarn-scale error lies (issue 13, the look): oracle corrections from the reference.

For each scene, the full model's image is multiplied by the brightness correction that the reference itself would
give it (an *oracle*: ratio of the reference's summed luminance to the model's over a set of pixels) and its
yarn-scale relative L1 at the projected diameter d (``knitbake.compare.image_metrics.yarn_scale_metrics``) is taken
again. What an oracle removes, a term of that form (a brightness that depends only on the oracle's bins) could remove;
what it leaves, no such term can. Oracles, each over the pixels the front strips cover (an MSAA-1 raster of the
regular strips, ``strip_raster.rasterize_visibility``):

* ``one gain``: one factor for the whole image (the mean ratio's part of the error);
* ``v``: one factor per 1/8 of the strip's width (16 bins of v ∈ [−1, 1]): a profile across the yarn, as the baked
  tables in v would give;
* ``v × angle``: per v bin and 10° bin of the strip tangent's direction on screen (in x–y: the examples look
  along −z): a brightness per part of the yarn and orientation to the light, as any table in (v, θ, φ) would give;
* ``gain at k·d``: the local ratio of the reference to the model, both box-filtered k·d pixels wide (k = 2, 4, 8):
  a brightness per stitch neighbourhood (shadows, inter-reflection between yarns). The same gain is applied to the
  reference's other fiber instance as a control: where it leaves the instance at its floor, the rest of the model's
  error lies below that scale.

Printed per scene: the instance floor, the model's error, and each oracle's error (and ratio to the floor). Needs
the references of ``bench_floors.py`` (``<scene>.exr`` and ``<scene>_instance.exr``). About 5 s per scene on 2 cores.

    .venv/bin/python benchmarks/probe_error_scale.py --pack out/bench/cotton1_standard.h5 \\
        --reference-dir out/bench/refs2 [--scenes knit_patch_directional,knit_patch_sky] [--ablation full]
"""

from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np

from data_formats.conventions import LUMINANCE
from data_formats.images import read_exr
from data_formats.scene import load_scene
from knitbake.compare.image_metrics import yarn_filter, yarn_scale_metrics
from knitbake.compare.report import yarn_diameter_px
from knitrun.render import pipeline
from knitrun.render.ablations import ABLATIONS
from knitrun.render.camera import scene_camera
from knitrun.render.strip_raster import rasterize_visibility, sample_attributes

EXAMPLES = Path(__file__).parent.parent / "examples" / "scenes"
PATCHES = "knit_patch_directional,knit_patch_sky,knit_patch_grazing,simulated_patch_directional"
V_BINS = 16
ANGLE_BINS = 18  # 10° each over [0°, 180°): a line on screen has no sign
GAIN_SCALES = (2, 4, 8)


def front_strips(scene, renderer):
    """Pixel rows, columns, v and the tangent's angle in the x–y plane (degrees in [0, 180); the screen's for the
    example scenes' cameras, which look along −z) of the samples the front regular strips of ``renderer``
    (a ``pipeline.Renderer`` of ``scene``) cover, at one sample per pixel."""
    lines = pipeline._polylines(scene, renderer.curves, renderer.frame_index(None), renderer.samples_per_segment)
    radius = np.array([renderer.looks[k].radius for k in lines.entry])
    vis = rasterize_visibility(lines.points, lines.offsets, False, lines.rest, radius, lines.entry,
                               scene_camera(scene), 1)
    rows, cols, sample = np.nonzero(vis.coverage)
    attributes = sample_attributes(vis, rows, cols, sample)
    t = np.asarray(attributes["tangent"], np.float64)
    return rows, cols, np.asarray(attributes["v"]), np.degrees(np.arctan2(t[:, 1], t[:, 0])) % 180.0


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


def probe(name, pack, reference_dir, ablation):
    scene = load_scene(EXAMPLES / f"{name}.toml")
    packs = {"cotton1": str(pack)}  # the example scenes draw cotton1, as bench_compare.py
    reference = read_exr(Path(reference_dir) / f"{name}.exr").astype(np.float64)[..., :3]
    instance = read_exr(Path(reference_dir) / f"{name}_instance.exr").astype(np.float64)[..., :3]
    renderer = pipeline.Renderer(scene, packs, features=ABLATIONS[ablation])  # the packs loaded once for both uses
    model = np.asarray(renderer.render().image, np.float64)[..., :3]
    d = yarn_diameter_px(scene)
    lum = np.asarray(LUMINANCE, np.float64)
    lm, lr, li = model @ lum, reference @ lum, instance @ lum
    floor = yarn_scale_metrics(instance, reference, d)["rel_l1"]

    def error(img, gain):
        return yarn_scale_metrics(img * gain[..., None], reference, d)["rel_l1"]

    rows, cols, v, angle = front_strips(scene, renderer)
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
    return "\n".join(lines)


def main():
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--pack", required=True)
    parser.add_argument("--reference-dir", required=True)
    parser.add_argument("--scenes", default=PATCHES)
    parser.add_argument("--ablation", choices=sorted(ABLATIONS), default="full")
    args = parser.parse_args()
    for name in args.scenes.split(","):
        print(probe(name, args.pack, args.reference_dir, args.ablation), flush=True)


if __name__ == "__main__":
    main()
