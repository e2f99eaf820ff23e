"""Where along the loop a directional light reaches the fibers the camera sees: the reference's fibers traced against
what the strip renderer's two shadow terms take off, per place along the loop of the Crane patch (issue 13).

``probe_error_scale.py``'s loop-phase oracle says which part of a course's loop the strips light wrongly; this says
whether the light the reference's fibers get there is what the strips' shadows let through. Geometry for the
reference, no shading: per pixel (one ray through its centre), the camera ray's first regular fiber of the
reference's draw (the scene's fiber seed; flyaways passed through) is a receiver, binned by its course's loop phase
(the rest arc length of the nearest point of a 0.2-radius polyline, modulo one stitch: ``probe_error_scale.
loop_phase``'s bins), and from it (moved 2e-4 along the radial direction from that point) a ray toward the first
directional light is traced over the reference's fibers twice:

* **lit past every regular fiber** (the receiver's own fiber and every flyaway passed through): what reaches it;
* **lit past its own cross-section** (only the regular fibers of the receiver's own course within ``OWN_ARC_RADII``
  radii of rest arc length block): what its own yarn there lets through, the self-shadowing the strips take from
  Ψ^Fiber, baked on a straight yarn (the rest of its course shadows it at yarn level, as another yarn would).

For the strips, over their front regular points and the pixels their front regular strips of that bin cover (the
interior courses): the mean yarn-level visibility V of the first directional light at the points (the shadow map's,
``pipeline._visibility``, before the light passed through blockers), the full image over the same image with every
yarn-level lookup lit (what the shadow maps take off, with the light passed through blockers, the bounce and the
canopy as they follow from it), the full image over the one without fiber-level shadowing
(``Features(fiber_shadowing=False)``: what Ψ^Fiber takes off), and the full image over the reference. The image
columns are ratios of summed luminance, so a term that also moves the multiple scattering moves its ratio too; the
reference's columns are shares of receivers, not of light.

    .venv/bin/python benchmarks/probe_loop_light.py --pack out/bench/cotton1_standard_56.h5 \\
        --reference-dir out/bench/refs2 [--scenes knit_patch_grazing,knit_patch_directional]
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np
from scipy.spatial import cKDTree

from data_formats.conventions import LUMINANCE
from data_formats.images import read_exr
from data_formats.scene import EnvironmentLight, load_scene
from knitbake.fibers.fiber_set import KIND_REGULAR
from knitbake.trace.path_tracer import camera_rays
from knitrun.render import pipeline
from knitrun.render.ablations import Features
from knitrun.render.camera import scene_camera, tan_half_fov

sys.path.insert(0, str(Path(__file__).resolve().parent))
from probe_error_scale import CRANE_COLS, LOOP_BINS, fraction_along, front_strips, loop_phase  # noqa: E402
from probe_hair_canopy import dense_polylines, first_hits, reference_fibers  # noqa: E402

ROOT = Path(__file__).resolve().parent.parent
SCENES = "knit_patch_grazing,knit_patch_directional"
OWN_ARC_RADII = 4.0  # the receiver's own cross-section: its course's fibers within this rest arc length (radii)


def reference_receivers(scene):
    """The reference's receivers (module docstring): (loop-phase bin, interior course, lit past every regular fiber,
    lit past its own cross-section) per pixel whose camera ray meets a regular fiber."""
    radius = scene.yarns[0].radius
    fibers, curves = reference_fibers(scene)
    kind = fibers.kind
    points, curve, arc, offsets = dense_polylines(scene, radius)
    tree = cKDTree(points)
    length = arc[offsets[1:] - 1] - arc[offsets[:-1]]
    camera = scene_camera(scene)
    fwd, right, up = camera.basis()
    n = camera.width * camera.height
    origins, directions = np.empty((n, 3)), np.empty((n, 3))
    camera_rays(np.asarray(camera.position, float), fwd, right, up, camera.width, camera.height, tan_half_fov(camera),
                float(camera.ortho_height), 0, 0, 1, origins, directions)
    t, fiber = first_hits(curves, curves.segment_fiber, origins, directions,
                          lambda f, i, p: kind[f] != KIND_REGULAR)
    seen = np.flatnonzero(fiber >= 0)
    hit = origins[seen] + directions[seen] * t[seen, None]
    _, near = tree.query(hit)
    radial = hit - points[near]
    radial /= np.maximum(np.linalg.norm(radial, axis=1, keepdims=True), 1e-300)
    light = [lt for lt in scene.lights if not isinstance(lt, EnvironmentLight)]
    if not light:
        raise SystemExit(f"{scene.name}: no directional light")
    start = hit + radial * 2e-4
    toward = np.broadcast_to(np.asarray(light[0].unit_direction, np.float64), start.shape).copy()
    own_fiber, own_curve, own_arc = fiber[seen], curve[near], arc[near]
    lit = first_hits(curves, curves.segment_fiber, start, toward,
                     lambda f, i, p: (kind[f] != KIND_REGULAR) | (f == own_fiber[i]))[1] < 0

    def elsewhere(f, i, p):  # not the receiver's own cross-section: passed through
        _, at = tree.query(p)
        return (kind[f] != KIND_REGULAR) | (f == own_fiber[i]) | (curve[at] != own_curve[i]) | \
            (np.abs(arc[at] - own_arc[i]) > OWN_ARC_RADII * radius)

    lit_own = first_hits(curves, curves.segment_fiber, start, toward, elsewhere)[1] < 0
    phase = ((arc[near] - arc[offsets[own_curve]]) / length[own_curve] * CRANE_COLS) % 1.0
    bins = np.minimum((phase * LOOP_BINS).astype(np.int64), LOOP_BINS - 1)
    interior = (own_curve > 0) & (own_curve < len(length) - 1)
    return bins, interior, lit, lit_own


def point_visibility(scene, packs):
    """The strips' full render, caught as the renderer looks its lights up: (its renderer, its luminance image, and
    per front regular shading point the first directional light's yarn-level visibility V (its first map of the
    scene's ``shadow_map_size``: the directional lights' come before the lobes'), loop-phase bin, interior course and
    weight)."""
    caught = {}
    receivers_of, shadows = pipeline.strip_receivers, pipeline._visibility

    def catch_points(points, looks, surface, flyaway=False):
        caught.setdefault("points", points)  # the front layer's are the first
        return receivers_of(points, looks, surface, flyaway)

    def catch_visibility(lines, radius, direction, size, *rest):
        found = shadows(lines, radius, direction, size, *rest)
        if size == scene.render.shadow_map_size and "V" not in caught:
            caught.update(V=found[0], lines=lines)
        return found

    try:
        pipeline.strip_receivers, pipeline._visibility = catch_points, catch_visibility
        renderer = pipeline.Renderer(scene, packs)
        full = np.asarray(renderer.render().image, np.float64)[..., :3] @ np.asarray(LUMINANCE, np.float64)
    finally:
        pipeline.strip_receivers, pipeline._visibility = receivers_of, shadows
    points, lines = caught["points"], caught["lines"]
    curve = np.asarray(points["curve"], np.int64)
    phase, interior = loop_phase(curve, fraction_along(lines, curve, points["arclength"]), renderer.curves)
    return renderer, full, (caught["V"], phase, interior, np.asarray(points["weight"], np.float64))


def strip_images(scene, packs, renderer):
    """(yarn-level lookups all lit, without Ψ^Fiber) luminance images of the strips, and the front strips' (rows, cols,
    loop-phase bin, interior course) of ``renderer``'s frame."""
    lum = np.asarray(LUMINANCE, np.float64)
    rows, cols, _, _, curve, along = front_strips(scene, renderer)
    phase, interior = loop_phase(curve, along, renderer.curves)
    shadows = pipeline._visibility
    try:
        pipeline._visibility = lambda lines, radius, direction, size, angular, receivers, *rest: \
            [np.ones(len(r.position)) for r in receivers]
        unshadowed = np.asarray(pipeline.Renderer(scene, packs).render().image, np.float64)[..., :3] @ lum
    finally:
        pipeline._visibility = shadows
    no_psi = np.asarray(pipeline.Renderer(scene, packs, features=Features(fiber_shadowing=False)).render().image,
                        np.float64)[..., :3] @ lum
    return unshadowed, no_psi, (rows, cols, phase, interior)


def probe(name, pack, reference_dir) -> str:
    scene = load_scene(ROOT / "examples" / "scenes" / f"{name}.toml")
    bins, inner, lit, lit_own = reference_receivers(scene)
    packs = {"cotton1": str(pack)}  # the example scenes draw cotton1, as bench_compare.py
    renderer, full, (vis, vis_phase, vis_interior, weight) = point_visibility(scene, packs)
    unshadowed, no_psi, (rows, cols, phase, interior) = strip_images(scene, packs, renderer)
    reference = read_exr(Path(reference_dir) / f"{name}.exr").astype(np.float64)[..., :3] @ np.asarray(LUMINANCE)

    def ratio(a, b, r, c):
        return a[r, c].sum() / max(b[r, c].sum(), 1e-30)

    lines = [f"\n{name} (interior courses):\n",
             "| loop phase (Crane's t) | reference: lit past every regular fiber | lit past its own cross-section | "
             "strips: V | what the shadow maps leave | what Ψ^Fiber leaves | strips / reference |",
             "|---|---|---|---|---|---|---|"]
    for b in range(LOOP_BINS):
        m = inner & (bins == b)
        at = interior & (phase == b)
        r, c = rows[at], cols[at]
        v = vis_interior & (vis_phase == b)
        lines.append(f"| {-90 + 15 * b:+d}° | {lit[m].mean():.2f} | {lit_own[m].mean():.2f} | "
                     f"{np.average(vis[v], weights=weight[v]) if weight[v].sum() > 0 else np.nan:.2f} | "
                     f"{ratio(full, unshadowed, r, c):.2f} | {ratio(full, no_psi, r, c):.2f} | "
                     f"{ratio(full, reference, r, c):.2f} |")
    return "\n".join(lines)


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--pack", required=True)
    parser.add_argument("--reference-dir", required=True)
    parser.add_argument("--scenes", default=SCENES)
    args = parser.parse_args(argv)
    for name in args.scenes.split(","):
        print(probe(name, args.pack, args.reference_dir), flush=True)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
