"""Strip renderer: ms per frame and per pass for a stockinette patch, under a directional light and under the
built-in sky fitted with 16 SRBFs, and how the cost grows with control points and pixels.

Patch: ``knitrun.sim.crane_stockinette.stockinette_curves(rows, 21)`` (48 points per stitch, yarn radius 0.03 cm; 60
rows ≈ 60K control points, about 5 × 10 cm), cotton1, seen from the front (pinhole, fov 40°, whole patch in view),
MSAA 4, shadow maps 2048² (lobes 512²). Every figure is the median of ``--frames`` renders after one warm-up
render (which pays Numba's compile or cache load). Both backends time what an interactive viewer pays per frame:
one renderer is set up once (packs, curves, environment fit: the ``setup`` column, reported once) and then draws
the frames, whose ``load`` is evaluating this frame's curves into polylines. Before stop 30 the CPU rows timed a
whole one-shot ``pipeline.render`` per frame (set-up included: ``load`` ~110 ms, the sky's fit 4 ms from its cache).

    .venv/bin/python benchmarks/bench_render.py [--pack cotton1.h5] [--frames 3] [--light directional|sky16]
        [--no-sweep] [--backend cpu|gl] [--ablation diagonal_xi+no_parallax+no_bounce+axis_shadows]
        [--bounce-on auto|gpu|cpu]

``--ablation`` times another model than the default (an ablation or a combination a+b, ``ablations.combined``).

``--backend gl`` times the OpenGL backend (``knitrun.render.gl``) on whatever EGL gives: a GPU, or Mesa's llvmpipe;
``--bounce-on`` says where its yarn-level bounce's sums run (``GLRenderer``'s ``bounce_on``: the compute shader, the
Numba kernel, or "auto", the CPU on a software rasteriser and the GPU otherwise).

Without ``--pack`` a draft cotton1 pack is baked (or taken from the bake cache).
"""

import argparse
import tempfile
import time
from pathlib import Path

import numba

from data_formats.scene import RENDER_FIELDS, load_scene
from data_formats.yarn_curves import write_yarn_curves
from data_formats.yarn_spec import load_preset
from knitbake.bake import bake
from knitrun.render import pipeline
from knitrun.render.ablations import Features, combined
from knitrun.sim.crane_stockinette import stockinette_curves

SCENE = """format = "knit-scene"
version = "1.0"
units = "cm"
[[yarns]]
curves = "patch.h5"
yarn = "cotton1"
radius = 0.03
[camera]
position = [2.4, 5.0, 15.0]
look_at = [2.4, 5.0, 0.0]
fov_deg = 40.0
width = {width}
height = {height}
[[lights]]
{light}
[render]
msaa = 4
shadow_map_size = 2048
srbf_count = 16
layers = {layers}
hair_layers = {hair_layers}
"""
LIGHTS = {"directional": 'type = "directional"\ndirection = [0.4, 0.6, 1.0]\nirradiance = [3.0, 3.0, 3.0]',
          "sky16": 'type = "environment"\nbuiltin = "sky"'}


def time_scene(folder, pack, rows, width, height, light, frames, backend="cpu", layers=2, features=Features(),
               hair_layers=RENDER_FIELDS["hair_layers"][0], bounce_on="auto"):
    """(median seconds per frame, its timings, facts, set-up seconds): one renderer set up once (``Renderer`` or
    ``GLRenderer``) with ``features``, then its frames (what a viewer pays per frame)."""
    write_yarn_curves(folder / "patch.h5", stockinette_curves(rows, 21))
    (folder / "scene.toml").write_text(SCENE.format(width=width, height=height, light=LIGHTS[light], layers=layers,
                                                    hair_layers=hair_layers))
    scene = load_scene(folder / "scene.toml")
    start = time.perf_counter()
    if backend == "gl":
        from knitrun.render.gl.gl_renderer import GLRenderer

        renderer = GLRenderer(scene, {"cotton1": str(pack)}, features, bounce_on=bounce_on)
    else:
        renderer = pipeline.Renderer(scene, {"cotton1": str(pack)}, features=features)
    setup = time.perf_counter() - start
    draw = renderer.render
    result = draw()
    runs = []
    for _ in range(frames):
        t0 = time.perf_counter()
        result = draw()
        runs.append((time.perf_counter() - t0, result.timings))
    total, timings = sorted(runs, key=lambda r: r[0])[len(runs) // 2]
    if backend == "gl":
        renderer.release()
    return total, timings, result.facts, setup


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--pack", default=None)
    parser.add_argument("--frames", type=int, default=3)
    parser.add_argument("--light", choices=sorted(LIGHTS), default=None, help="only the cases under this light")
    parser.add_argument("--no-sweep", action="store_true", help="only the 60K-point 1280×960 cases, not the sweep")
    parser.add_argument("--backend", choices=("cpu", "gl"), default="cpu",
                        help="gl: the OpenGL backend, plus the paper's 200K-point size under the sky")
    parser.add_argument("--layers", type=int, choices=(1, 2), default=2,
                        help="render.layers: 2 (default) draws the depth-peeled strips behind the front ones")
    parser.add_argument("--hair-layers", type=int, default=RENDER_FIELDS["hair_layers"][0], choices=range(1, 9),
                        metavar="K", help="render.hair_layers: the flyaway strips composited per sample (default: "
                                          "the scene format's)")
    parser.add_argument("--ablation", default="full", help="the model timed: an ablation or a combination a+b")
    parser.add_argument("--bounce-on", choices=("auto", "gpu", "cpu"), default="auto",
                        help="with --backend gl: where the yarn-level bounce's sums run (GLRenderer's bounce_on)")
    args = parser.parse_args()
    try:
        features = combined(args.ablation)
    except ValueError as e:
        parser.error(f"--ablation: {e}")
    folder = Path(tempfile.mkdtemp(prefix="knit_bench_render_"))
    pack = args.pack
    if pack is None:
        pack = folder / "cotton1_draft.h5"
        bake(load_preset("cotton1"), pack, quality="draft")
    where = f"{numba.get_num_threads()} threads"
    if args.backend == "gl":
        from knitrun.render.gl.gl_renderer import gl_context

        where = f"GL: {gl_context().info['GL_RENDERER']}, bounce on {args.bounce_on}"
    print(f"## Strip renderer (cotton1, {where}, pack {Path(pack).name}, render.layers = {args.layers}, "
          f"render.hair_layers = {args.hair_layers}, model {args.ablation})")
    print("| light | control points | pixels | shading points | set-up ms (once) | frame ms | load | raster | shadow "
          "| shade | resolve |")
    print("|---|---|---|---|---|---|---|---|---|---|---|")
    cases = [("directional", 60, 1280, 960), ("sky16", 60, 1280, 960),
             ("directional", 15, 1280, 960), ("directional", 30, 1280, 960), ("directional", 120, 1280, 960),
             ("directional", 60, 640, 480), ("directional", 60, 2560, 1920)]
    if args.backend == "gl":
        cases = cases[:2] + [("sky16", 200, 1280, 960)] + cases[2:]
    if args.no_sweep:
        cases = cases[:3 if args.backend == "gl" else 2]
    for light, rows, width, height in [c for c in cases if args.light in (None, c[0])]:
        total, timings, facts, setup = time_scene(folder, pack, rows, width, height, light, args.frames, args.backend,
                                                  args.layers, features, args.hair_layers, args.bounce_on)
        passes = " | ".join(f"{1e3 * timings.get(k, 0.0):.0f}" for k in
                            ("load", "raster", "shadow", "shade", "resolve"))
        points = facts.get("shading_points", "—")
        print(f"| {light} | {facts['points']} | {width}×{height} | {points} | {1e3 * setup:.0f} | {1e3 * total:.0f} "
              f"| {passes} |",
              flush=True)


if __name__ == "__main__":
    main()
