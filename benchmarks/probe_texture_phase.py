"""How much the strip model's yarn-scale error depends on where its textures' ply pattern lies (issue 13, the look).

The textures are read at the view-phase arc length (``pipeline.view_phase_arclength``: the rest arc length shifted
by the yarn's twist as seen from the view's azimuth, so the ply crests lie where the reference's fibers put them).
This probe shifts that arc length and measures the full model's yarn-scale relative L1 at the projected diameter d
(``knitbake.compare.image_metrics.yarn_scale_metrics``) against the reference, as a ratio to the fiber-instance floor:

* ``offset`` o: every point's arc length + o · period (o in ply periods, all yarns alike): is the computed phase the
  best single one, and how fast does the error grow away from it;
* ``tile oracle``: per square tile 2d pixels wide, the offset image with the lowest yarn-scale L1 inside the tile (the
  offset-0 image where the tiles do not reach): what a phase that drifts from stitch to stitch could gain at most
  (an upper bound: picking the best of several images also fits the reference's noise);
* ``parallax`` ±1: + (±) r · √(1 − v²) · tan θ_o, the axial distance between the centre line's point and the yarn's
  surface seen at strip coordinate v when the yarn tilts by θ_o toward the camera (the textures are baked at
  θ_o = 0), tan θ_o capped at 3.

The shift is made by wrapping ``pipeline.view_phase_arclength`` for the probe's renders (the renderer is not
changed). Needs the references of ``bench_floors.py`` (``<scene>.exr``, ``<scene>_instance.exr``). About 25 s per scene
on 2 cores (12 renders).

    .venv/bin/python benchmarks/probe_texture_phase.py --pack out/bench/cotton1_standard.h5 \\
        --reference-dir out/bench/refs2 [--scenes knit_patch_directional,straight_yarn_directional]
"""

from __future__ import annotations

import argparse
from contextlib import contextmanager
from pathlib import Path

import numpy as np

from data_formats.images import read_exr
from data_formats.scene import load_scene
from knitbake.compare.image_metrics import yarn_filter, yarn_scale_metrics
from knitbake.compare.report import yarn_diameter_px
from knitrun.render import pipeline

EXAMPLES = Path(__file__).parent.parent / "examples" / "scenes"
OFFSETS = (-0.3, -0.2, -0.1, -0.05, 0.0, 0.05, 0.1, 0.2, 0.3, 0.5)  # ply periods
MAX_TAN = 3.0  # cap on tan θ_o for the parallax (a yarn seen within 18° of its axis)


@contextmanager
def shifted_phase(offset: float = 0.0, parallax: float = 0.0):
    """Renders inside the block read the textures at the view-phase arc length + ``offset`` periods + ``parallax``
    × r √(1 − v²) tan θ_o (module docstring)."""
    original = pipeline.view_phase_arclength

    def shifted(points, lines, looks):
        s = original(points, lines, looks)
        yarn = np.asarray(points["yarn"], np.int64)
        period = np.array([look.period for look in looks], np.float64)[yarn]
        radius = np.array([look.radius for look in looks], np.float64)[yarn]
        cos_t = np.einsum("ij,ij->i", np.asarray(points["tangent"], np.float64),
                          np.asarray(points["view_dir"], np.float64))
        tan_t = np.clip(cos_t / np.sqrt(np.maximum(1.0 - cos_t ** 2, 1e-12)), -MAX_TAN, MAX_TAN)
        v = np.clip(np.asarray(points["v"], np.float64), -1.0, 1.0)
        return s + offset * period + parallax * radius * np.sqrt(1.0 - v * v) * tan_t

    pipeline.view_phase_arclength = shifted
    try:
        yield
    finally:
        pipeline.view_phase_arclength = original


def tile_oracle(images, reference, d, base):
    """The image that takes, per tile 2d pixels wide, the one of ``images`` with the lowest L1 at the yarn scale
    inside the tile; ``images[base]`` outside the whole tiles."""
    filtered = [yarn_filter(img, d) for img in images]
    f_ref = yarn_filter(reference, d)
    out = images[base].copy()
    tile = max(1, int(round(2 * d)))
    for i in range(0, reference.shape[0] - tile + 1, tile):
        for j in range(0, reference.shape[1] - tile + 1, tile):
            at = (slice(i, i + tile), slice(j, j + tile))
            best = int(np.argmin([np.abs(f[at] - f_ref[at]).sum() for f in filtered]))
            out[at] = images[best][at]
    return out


def probe(name, pack, reference_dir):
    scene = load_scene(EXAMPLES / f"{name}.toml")
    reference = read_exr(Path(reference_dir) / f"{name}.exr").astype(np.float64)[..., :3]
    instance = read_exr(Path(reference_dir) / f"{name}_instance.exr").astype(np.float64)[..., :3]
    renderer = pipeline.Renderer(scene, {"cotton1": str(pack)})  # the example scenes draw cotton1; the full model
    d = yarn_diameter_px(scene)
    floor = yarn_scale_metrics(instance, reference, d)["rel_l1"]

    def ratio(img):
        return yarn_scale_metrics(img, reference, d)["rel_l1"] / floor

    def image(**shift):
        with shifted_phase(**shift):
            return np.asarray(renderer.render().image, np.float64)[..., :3]

    images = [image(offset=o) for o in OFFSETS]
    oracle = tile_oracle(images, reference, d, OFFSETS.index(0.0))
    lines = [f"{name}: d = {d:.1f} px, instance floor {floor:.4f}",
             "  offset (periods): " + ", ".join(f"{o:+.2f} {ratio(img):.2f}×" for o, img in zip(OFFSETS, images)),
             f"  tile oracle (2d tiles, best of the offsets): {ratio(oracle):.2f}×"]
    lines += [f"  parallax {sign:+.0f}: {ratio(image(parallax=sign)):.2f}×" for sign in (1.0, -1.0)]
    return "\n".join(lines)


def main():
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--pack", required=True)
    parser.add_argument("--reference-dir", required=True)
    parser.add_argument("--scenes", default="knit_patch_directional,straight_yarn_directional,knit_patch_sky")
    args = parser.parse_args()
    for name in args.scenes.split(","):
        print(probe(name, args.pack, args.reference_dir), flush=True)


if __name__ == "__main__":
    main()
