"""Where the strip renderer's shading time goes (issue 15: profile before optimising).

1. The `shade_regular` calls of the bench_render frame (1280×960, 60,540 control points, MSAA 4; the front layer
   and, at ``--layers 2``, the default, the layer behind it) are captured from the pipeline and timed alone (best
   of 3 after a warm-up), with all lights, with none (frames and texture lookups), and with one kind of light at a
   time (directional; SRBF lobes' I_M terms; multiple-scattering clusters). A kind of light the scene lacks is a
   tuple of no rows, as the pipeline passes it (``shading_inputs.no_lights``, ``no_lobes``).
2. Per-call costs on 1M random inputs, 2 threads: one DS evaluation (``dual_scattering._ds_batch``, D inside
   (0, 1), D = 0, D = 1) and one I_M evaluation (view context + table + R rule, ``im_lookup._im_batch``) at the
   sky's sun-sized λ and at wide ones.

    .venv/bin/python benchmarks/profile_shading.py --pack out/bench/cotton1_standard.h5 \
        [--light directional|sky16] [--layers 1|2]
"""

import argparse
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
import bench_render  # noqa: E402

from data_formats.asset_pack import read_pack  # noqa: E402
from data_formats.scene import load_scene  # noqa: E402
from data_formats.yarn_curves import write_yarn_curves  # noqa: E402
from knitrun.render import pipeline  # noqa: E402
from knitrun.render.shading_inputs import no_lights, no_lobes, no_rows  # noqa: E402
from knitrun.render.strip_shading import shade_regular  # noqa: E402
from knitrun.shading.dual_scattering import D_B, D_F, _ds_batch  # noqa: E402
from knitrun.shading.im_lookup import _im_batch, im_table_from, no_im_table  # noqa: E402
from knitrun.sim.crane_stockinette import stockinette_curves  # noqa: E402

IM_TABLE = "environment/I_M_TT_D"


def captured_calls(pack, light, layers):
    """The arguments of the frame's (single-yarn) ``shade_regular`` calls: the front layer's, then (``layers`` 2)
    the depth-peeled layer's behind it."""
    captured = []

    def capture(*args):
        captured.append(list(args))
        return shade_regular(*args)

    folder = Path(tempfile.mkdtemp(prefix="knit_profile_"))
    write_yarn_curves(folder / "patch.h5", stockinette_curves(60, 21))
    hair_layers = bench_render.RENDER_FIELDS["hair_layers"][0]
    (folder / "scene.toml").write_text(bench_render.SCENE.format(width=1280, height=960,
                                                                 light=bench_render.LIGHTS[light],
                                                                 layers=layers, hair_layers=hair_layers))
    original, pipeline.shade_regular = pipeline.shade_regular, capture
    try:
        pipeline.render(load_scene(folder / "scene.toml"), {"cotton1": str(pack)})
    finally:
        pipeline.shade_regular = original
    return captured


def best_ms(args, repeats=3):
    shade_regular(*args)
    times = []
    for _ in range(repeats):
        start = time.perf_counter()
        shade_regular(*args)
        times.append(time.perf_counter() - start)
    return 1e3 * min(times)


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--pack", required=True)
    parser.add_argument("--light", choices=sorted(bench_render.LIGHTS), default=None)
    parser.add_argument("--layers", type=int, choices=(1, 2), default=2, help="render.layers of the frame")
    args = parser.parse_args()
    cases = []
    for light in [args.light] if args.light else sorted(bench_render.LIGHTS):
        cases += zip([light] * 2, ("front", "behind"), captured_calls(args.pack, light, args.layers))
    for light, layer, call in cases:
        idx, points, look, corrections, tangent, coverage, detail, lights, lobes, ms, im, bounce, rgb, alpha = call
        n = len(points.view_dir)
        off, dark = no_lights(n), no_lobes(n)
        print(f"## {light}, {layer} layer: shade_regular on {len(idx)} shading points ({len(lights.direction)} "
              f"directional, {len(lobes.direction)} SRBF lobes, {len(ms.direction)} multiple-scattering clusters)")
        base = call[:7]
        rest = [no_rows()] + call[12:]  # no yarn-level bounce but in "all lights"
        rows = [("all lights", call), ("no light (frames, textures)", base + [off, dark, off, im] + rest)]
        if len(lights.direction) and len(lobes.direction):
            rows.append(("directional only", base + [lights, dark, off, im] + rest))
        if len(lobes.direction):
            rows.append(("SRBF lobes only (I_M)", base + [off, lobes, off, im] + rest))
            rows.append(("multiple-scattering clusters only", base + [off, dark, ms, im] + rest))
        for label, variant in rows:
            print(f"  {label}: {best_ms(variant):.0f} ms", flush=True)
    rng = np.random.default_rng(0)
    m = 1_000_000
    theta_i, theta_o, phi = rng.uniform(-1.2, 1.2, m), rng.uniform(-1.2, 1.2, m), rng.uniform(-3.1, 3.1, m)
    n_front = rng.uniform(0, 10, m)
    print(f"## per call, {m} random inputs, wall time on the machine's threads")
    for label, direct in (("D in (0, 1)", rng.uniform(0.05, 0.95, m)), ("D = 0", np.zeros(m)), ("D = 1", np.ones(m))):
        _ds_batch(look.params, look.ds, theta_i, theta_o, phi, n_front, direct, D_F, D_B)
        start = time.perf_counter()
        _ds_batch(look.params, look.ds, theta_i, theta_o, phi, n_front, direct, D_F, D_B)
        print(f"  DS evaluation, {label}: {(time.perf_counter() - start) / m * 1e9:.0f} ns")
    # the pack's whole table: a captured call holds the table sliced at its lobes' λ (``im_lookup.IMSlices``), which
    # ``_im_batch`` does not take
    pack = read_pack(args.pack, tables=[IM_TABLE])
    im = im_table_from(pack.tables[IM_TABLE], pack.info[IM_TABLE].axes) if IM_TABLE in pack.tables else no_im_table()
    for lam in (6600.0, 10.0, 0.7):
        lams = np.full(m, lam)
        _im_batch(im, look.params, theta_o, theta_i, phi, lams)
        start = time.perf_counter()
        _im_batch(im, look.params, theta_o, theta_i, phi, lams)
        print(f"  I_M evaluation (view context + table + R rule), λ = {lam:g}: "
              f"{(time.perf_counter() - start) / m * 1e9:.0f} ns")


if __name__ == "__main__":
    main()
