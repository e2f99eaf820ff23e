"""The strip renderer (Huang et al. 2025 §5.2): a scene file's yarn curves and asset packs → a linear HDR image.

A ``Renderer`` does the set-up once (packs, every frame of the curves, the environment fit) and then draws any
frame; ``render(scene)`` is one frame of a renderer used once. Passes, each timed (``RenderResult.timings``,
seconds; a ``Renderer``'s frames time the per-frame part, its ``setup_timings`` the rest):

1. ``load``: the scene's curves at ``render.frame`` (a stitch mesh is simulated at rest by ``knitrun.sim.simulate``
   with the entry's radius, and a radius more than 5 % off the templates' sizing gives a warning; curves that carry
   the radius they were built for and are drawn more than 5 % thicker or thinner give one too: both in
   ``RenderResult.facts["warnings"]``),
   evaluated by their curve type (``data_formats.curve_eval``: PL as drawn, C0 as uniform Catmull-Rom, BS, BZ) into
   polylines of ``samples_per_segment`` samples per smooth segment, each sample with its rest arc length; each
   yarn entry's pack (``knitrun.render.yarn_look``), reading only the tables the scene needs.
2. ``srbf_fit`` (environment light only): J = ``render.srbf_count`` spherical Gaussians fitted to the map
   (``knitrun.shading.srbf_fit``), or read from the fit cache by the map's content (``srbf_cache``); the fit's
   errors are in ``RenderResult.facts``. Lobes the fit leaves at zero weight are not drawn (no shadow map, no
   shading): they add nothing.
3. ``raster``: the regular-fiber strips (half-width = yarn radius) into a k-sample visibility buffer
   (``strip_raster``: triangle, curve and depth per sample; the other attributes are interpolated at the shading
   points alone); with flyaways, the flyaway strips (half-width = the pack's flyaway ``half_width``) into
   ``render.hair_layers`` more. With ``render.layers`` = 2 (the default) the regular strips are depth-peeled
   (``strip_raster.rasterize_behind``, on the front pass's triangles): at each sample the nearest strip more than
   the front yarn's radius behind the front strip, so the yarn behind shows through a strip's partial coverage
   (gaps between plies, the fuzzy edge) instead of the background. The flyaway layers are the K =
   ``render.hair_layers`` nearest flyaway strips at each sample among those less than the largest yarn radius
   behind its front regular strip (``strip_raster.rasterize_before``: one depth test keeping K per sample): in a
   knit two or three yarns' hair strips overlap almost everywhere (each 2.3 radii wide for cotton1), and with the
   nearest alone the hairs of all but one were lost — the gaps between stitches darker and emptier than the
   reference's (BENCHMARKS.md, "Issue 13: the hairs of every yarn that overlaps a pixel"). A flyaway shading point
   is kept where its hair texture covers anything (``strip_shading.flyaway_coverage``): one of zero coverage adds
   nothing to the image, so the passes below skip it.
4. ``shadow``: per directional light a yarn-level shadow map of ``render.shadow_map_size``² texels, filtered by PCF
   (a delta light); per SRBF lobe a map of a quarter of that size toward ω_j, filtered by PCSS with the lobe's
   angular radius 1/√λ_j (capped at 0.5 rad) for T̃_j (``knitrun.render.shadow_map``). Receivers are biased by
   ``SHADOW_BIAS_RADII`` = ½ yarn radius (the strip runs through the yarn axis; a yarn never shadows itself at yarn
   level, that is Ψ^Fiber's job), every point's beyond its own yarn's strip toward each light (``Receivers``,
   ``receiver_bias``): a flyaway point's too, since the kernels cross its own yarn's tube toward the light
   themselves (``strip_shading._hair_light``).
   A regular point looks its lights up on the tube surface the camera sees there (``Features.surface_shadows``, the
   default; ``strip_receivers``: the strip point r √(1 − v²) toward the camera) rather than on the strip plane through
   the axis, which lies up to a radius deeper: under a light from the fabric's side a receiver that deep falls into
   its neighbours' shadows (on the grazing patch the axis plane shadows one leg of every stitch that the reference
   lights; the ablation ``axis_shadows`` looks up there). A flyaway point looks its lights up at its own strip point:
   the hairs seen over a body lie in front of it and behind (``Features.hairs_behind``). Stops 36–74 a flyaway point
   at the MSAA sample of a regular point of its curve took that point's surface lookups instead, which saved half
   the hairs' lookups under the sky; with the bias of ½ radius that is no longer the same light, and the hairs' own
   lookups are nearer the reference (on the grazing patch 0.977 of its mean and 1.15× the floor against 0.987 and
   1.17×; BENCHMARKS.md, stop 75), as the GL backend's always were.
   With ``Features.interreflection`` each T̃_j becomes T̃_j / (1 − ρ (1 − T̃_j)), ρ the receiver's yarn hull albedo
   (``knitrun.render.interreflection``): the light the neighbours block and send on; and a directional light's V
   lets through the gap transmittance τ_Y of the blocker (``strip_shading.past_blockers``, in the kernels). With
   ``Features.yarn_bounce`` (the default) the directional lights are looked up at the polyline vertices as well,
   and the light the neighbouring yarns scatter onto each vertex (``frame_bounce``, ``knitrun.render.yarn_bounce``)
   is interpolated to the regular points. With ``Features.two_blockers`` (the default) each directional light's map
   also draws the second yarn layer (``shadow_map``, ``behind``), and V₂, the fraction that at most one yarn blocks,
   goes to the kernels as ``Lights.beyond`` (1 with the ablation ``one_blocker``): one gap transmittance per yarn
   crossed, up to two.
   With ``Features.hair_canopy`` (the default) every receiver's visibility V of each directional light (and the
   bounce vertices') is multiplied by the fraction the other yarns' hair layers let through (``hair_canopy``),
   computed at the polyline points and interpolated along the curves (``_canopy``); V₂ of ``two_blockers`` is not,
   so the light the canopy keeps off passes at τ_Y as under one blocker, with one blocker counted or two.
5. ``shade``: per yarn entry, regular fibers (DS + ξ + Ψ^Fiber, eq. 11 and eq. 17) and flyaways
   (``knitrun.render.strip_shading``). Texture phase: the pack's textures show the yarn seen from azimuth 0 of its yarn
   frame (N, T × N) (the bake's camera looks along −N); a helical yarn seen from azimuth γ looks like the yarn
   seen from azimuth 0 shifted along its axis by twist_sign·γ/(2π) ply periods, so the texture is read at
   u = (s − twist_sign·γ/(2π)·period)/period, γ = atan2(ω_o·(T × N), ω_o·N) with N of the curve's yarn frame
   (``data_formats.curve_eval.yarn_frame``, the frame the reference sweeps its fibers in). The ply pattern is
   then where the reference has it, and moves along the yarn as the camera circles it, as a real yarn's does.
   The second layer's points are shaded like the front's (its own shadow lookups).
   Axial parallax (``Features.parallax``, the default): a strip is drawn through the centre line, but where the
   yarn tilts toward the camera by θ_o (sin θ_o = ω_o·t) the tube's surface seen at the strip point (v) belongs to
   the centre line further along, at s + δ, δ = r √(1 − v²) tan θ_o (the front surface point c(s) + r n projects
   r sin θ_o back along the yarn's image, which covers cos θ_o of a unit of arc length; on a bend the root of the
   ray's offset from the surface seen at s + δ, by ``PARALLAX_PASSES`` Newton steps); with it the regular points
   take their texture coordinate and tangent there (``parallax_shift``; |sin θ_o| clamped at ``PARALLAX_MAX_SIN``).
   It moves nothing on a yarn that lies across the view, and on a bend turns the tangent that meets the mirror
   angle to where the reference's fibers meet it. Hairs keep their own strip's attributes.
   Fiber bend (``Features.fiber_bend``, the default since stop 69): the textures hold a straight yarn at rest, but
   where the curve bends or stretches the reference's swept fibers tilt toward its tangent on the outside of the
   bend and on a stretched yarn, away from it on the inside; the regular points carry their segment's curvature and
   stretch (``segment_bend``) and the shading scales their texture tangent's component along t by λ (1 − κ·o)
   (``strip_shading.fiber_bend``) before the fiber frame is built. Hairs are not scaled.
6. ``resolve``: coverage-weighted MSAA resolve, the second layer over the background, the front over that
   (``strip_shading.resolve_behind``), the flyaway layers on top, the K-th first.

``Features`` (``knitrun.render.ablations``) switch the baked terms off for the ablations of Huang et al. 2025
Fig. 7.
"""

from __future__ import annotations

import dataclasses
import math
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import NamedTuple

import numpy as np
from numba import njit, prange

from data_formats.curve_eval import yarn_frame
from data_formats.errors import FormatError
from data_formats.scene import EnvironmentLight, Scene, read_curves
from knitrun.render.ablations import Features
from knitrun.render.camera import scene_camera
from knitrun.render.compile_ahead import start_compile_ahead
from knitrun.render.hair_canopy import canopy_grid, canopy_transmittance
from knitrun.render.interreflection import interreflected_visibility
from knitrun.render.ms_lights import ms_lights
from knitrun.render.shading_inputs import Lights, Lobes, Points, no_rows
from knitrun.render.shadow_map import behind_map, build_shadow_map, own_strip_depth, shadow_visibility
from knitrun.render.strip_raster import (rasterize_before, rasterize_behind, rasterize_visibility, vertex_tangent,
                                         vertex_tangents)
from knitrun.render.strip_shading import (flyaway_coverage, hair_bounce, no_shading_points, past_blockers, resolve,
                                          resolve_behind, shade_flyaway, shade_regular, shading_points)
from knitrun.render.texture_sampling import no_texture
from knitrun.render.yarn_bounce import (BounceLights, BounceYarns, bounce_at_points, lambert_phase, tube_optics,
                                        vertex_bounce)
from knitrun.render.yarn_look import load_look, no_full_table, no_view_table, ones_factor, shading_look
from knitrun.shading.builtin_sky import environment_image
from knitrun.shading.im_lookup import im_slices, no_im_table
from knitrun.shading.srbf_cache import cached_fit
from knitrun.sim.simulate import RADIUS_TOLERANCE

# yarn radii beyond a receiver's own strip (its margin for the map's texels and filter): a neighbour in contact (axes
# 2 r apart) shadows a point of the tube's lit side once the ray toward the light crosses the neighbour's axis plane
# more than this far on; 1.5 hid most contact shadows. The patches' error is flat from 1.0 down to 0.25 at every map
# size, a lone yarn shadows itself at 0 (BENCHMARKS.md, "contact shadows", stop 75).
SHADOW_BIAS_RADII = 0.5
LOBE_SHADOW_DIVISOR = 4
RECEIVER_KEYS = ("position", "view_dir", "tangent", "v", "yarn")  # what ``strip_receivers`` reads of a point
BOUNCE_SPACING_RADII = 1.5  # yarn radii between the polyline points the yarn-level bounce is computed at
MAX_LOBE_ANGULAR_RADIUS = 0.5  # rad


@dataclass
class RenderResult:
    image: np.ndarray  # (H, W, 3) float32, linear RGB
    timings: dict  # pass → seconds
    facts: dict = field(default_factory=dict)


class _FrameRaster(NamedTuple):
    """What a frame's ``raster`` pass hands on: the shading points of the front layer, of the layer behind it (None at
    ``render.layers`` 1) and of the flyaway layers (None without flyaways; one set, ``layer_start`` the points of
    each layer, ``_stacked``) as ``strip_shading.shading_points`` gives them, the flyaway points as the kernels read
    them (``hairs``), which of them a hair covers (``covered``), and the yarn entries whose flyaways are drawn."""

    points: dict
    behind_points: dict | None
    fly_points: dict | None
    hairs: Points | None
    covered: np.ndarray | None
    drawn_fly: list
    # the visibility buffers, held to the end of the frame: freed after the raster pass, their pages went to the
    # shadow pass's arrays and the next frame's rasterizer faulted in fresh ones (+45 ms a frame, BENCHMARKS.md
    # "Stop 44: a cold first frame on both cores")
    buffers: tuple = ()


@dataclass
class _Polylines:
    points: np.ndarray  # (P, 3)
    offsets: np.ndarray  # (C+1,)
    rest: np.ndarray  # (P,)
    entry: np.ndarray  # (C,) yarn entry index
    normal: np.ndarray  # (P, 3) the yarn frame's normal N (data_formats.curve_eval.yarn_frame)


def _scene_curves(entry, units, warnings):
    """The yarn curves of a scene entry, every frame: its curve file, or its stitch mesh simulated at rest."""
    if entry.stitch_mesh is not None:
        from data_formats.stitch_mesh import load_stitch_mesh
        from knitrun.sim.simulate import simulate

        mesh = load_stitch_mesh(entry.stitch_mesh)
        curves, report = simulate(mesh, mesh.vertices[None], radius=entry.radius)
        warnings.extend(f"{entry.stitch_mesh}: {w}" for w in report["warnings"])
        return curves
    return read_curves(entry.curves, units)


def radius_mismatch(curves, drawn: float, where: str) -> str | None:
    """A one-line warning when curves built for a yarn radius (``YarnCurves.radius``, e.g. the knot simulator's r)
    are drawn more than ``RADIUS_TOLERANCE`` thicker or thinner: the yarns then overlap or gap where the simulation
    kept them apart. None when the radius is unknown or close enough."""
    if curves.radius is None or abs(drawn / curves.radius - 1.0) <= RADIUS_TOLERANCE:
        return None
    return (f"{where}: drawn with radius {drawn:.4g} but the curves were built for {curves.radius:.4g} "
            f"({drawn / curves.radius:.2f}×): the yarns will {'overlap' if drawn > curves.radius else 'leave gaps'}; "
            f"simulate with the drawn radius or set the entry's radius")


def _no_polylines() -> _Polylines:
    """A frame without a yarn to draw."""
    return _Polylines(np.zeros((0, 3)), np.zeros(1, np.int64), np.zeros(0), np.zeros(0, np.int64), np.zeros((0, 3)))


def _polylines(scene: Scene, entry_curves: list, frame: int, samples_per_segment: int) -> _Polylines:
    """The scene's yarns at ``frame`` as polylines (an entry with a single frame is drawn at it whatever ``frame``)."""
    pts, rest, normals, entry_of, sizes = [], [], [], [], [0]
    for k, (entry, curves) in enumerate(zip(scene.yarns, entry_curves)):
        f = frame if curves.points.shape[0] > 1 else 0
        wanted = entry.yarn_type_indices or tuple(range(len(curves.yarn_types)))
        for c in range(len(curves.offsets) - 1):
            control = curves.points[f, curves.offsets[c]:curves.offsets[c + 1]]
            if curves.yarn_type[c] not in wanted or len(control) < 2 or np.all(control == control[0]):
                continue  # not this entry's, or nothing to draw (a point)
            xyz, sigma, _, normal = yarn_frame(curves, c, f, None if curves.curve_type == "PL" else samples_per_segment)
            pts.append(xyz)
            rest.append(sigma)
            normals.append(normal)
            entry_of.append(k)
            sizes.append(len(xyz))
    if not pts:
        return _no_polylines()
    return _Polylines(np.concatenate(pts), np.cumsum(sizes), np.concatenate(rest), np.array(entry_of, np.int64),
                      np.concatenate(normals))


PARALLAX_MAX_SIN = 0.94  # |sin θ_o| of the axial parallax: tan θ_o ≤ 2.76 (a yarn seen nearly end-on)
PARALLAX_PASSES = 3  # Newton steps toward the tube's surface the ray meets (1: the straight tube's δ)


def parallax_shift(points, lines, looks):
    """``points`` with its ``segment``, rest ``arclength`` and ``tangent`` moved by the axial parallax (module
    docstring, step 5): a new dict (the inputs are not changed). The shift δ is walked along the curve's polyline in
    current length (stopping at the curve's ends), the rest arc length interpolated where it ends; the tangent moves
    by the change of the polyline's vertex tangents (the rasterizer's, ``strip_raster.vertex_tangent``) between the
    two places, so a zero shift keeps the rasterizer's.

    On a bend the straight tube's δ = h tan θ_o (h = r √(1 − v²)) misses the surface the ray meets: δ is the root of
    R(δ) = e·(c(s + δ) − c(s)) − h tan θ'_o (e·t'), the offset along the yarn's image (e, the strip point's tangent
    made normal to ω_o) between the strip point and the surface point c(s + δ) + h m' seen at s + δ (m' the normal
    there nearest ω_o, t' and θ'_o the tangent and its angle there), taken by ``PARALLAX_PASSES`` Newton steps
    δ ← δ − R/(e·t') from δ = 0 (the first gives h tan θ_o; on a straight yarn R = 0 after it). On a ring seen
    edge-on three land within 0.7 % of the ray–torus intersection on the convex and the concave side, where the
    first alone errs by 15–29 % (``tests/test_render.py``)."""
    n = len(points["arclength"])
    out = dict(points)
    if n == 0:
        return out
    segment = np.ascontiguousarray(points["segment"], np.int64)
    s = np.ascontiguousarray(points["arclength"], np.float64)
    tangent = np.ascontiguousarray(points["tangent"], np.float64)
    radius = np.array([look.radius for look in looks], np.float64)
    new_segment, new_s, new_tangent = np.empty_like(segment), np.empty_like(s), np.empty_like(tangent)
    _parallax(segment, np.ascontiguousarray(points["curve"], np.int64), s,
              np.ascontiguousarray(points["v"], np.float64), tangent, np.ascontiguousarray(points["view_dir"]),
              np.ascontiguousarray(points["yarn"], np.int64), radius, lines.points, lines.rest, lines.offsets,
              PARALLAX_PASSES, new_segment, new_s, new_tangent)
    out.update(segment=new_segment, arclength=new_s, tangent=new_tangent)
    return out


@njit(cache=True, inline='always')
def _open_tangent(xyz, lo, hi, j):
    """``strip_raster.vertex_tangent`` of vertex j of the open curve whose vertices are lo … hi."""
    return vertex_tangent(xyz, j, j - 1 if j > lo else -1, j + 1 if j < hi else -1)


@njit(cache=True, inline='always')
def _segment_length(xyz, j):
    return math.sqrt((xyz[j + 1, 0] - xyz[j, 0]) ** 2 + (xyz[j + 1, 1] - xyz[j, 1]) ** 2
                     + (xyz[j + 1, 2] - xyz[j, 2]) ** 2)


@njit(cache=True, inline='always')
def _projected(xyz, j, f, e0, e1, e2):
    """e·c of the polyline point a fraction f along segment j."""
    return (e0 * (xyz[j, 0] + f * (xyz[j + 1, 0] - xyz[j, 0])) + e1 * (xyz[j, 1] + f * (xyz[j + 1, 1] - xyz[j, 1]))
            + e2 * (xyz[j, 2] + f * (xyz[j + 1, 2] - xyz[j, 2])))


# the Newton step's divisor e·t' at least this (a tangent turned out of the image; a yarn seen within 6° of end-on
# takes a first step shorter than the clamp's δ)
PARALLAX_MIN_SLOPE = 0.1


@njit(parallel=True, cache=True)
def _parallax(segment, curve, s, v, tangent, view_dir, yarn, radius, xyz, rest, offsets, passes, out_segment, out_s,
              out_tangent):
    """``parallax_shift`` per point (each point writes its own rows). A point on a closed curve's closing segment
    (which joins its last vertex to its first) keeps its attributes; so does one that looks along its yarn."""
    max_tan = PARALLAX_MAX_SIN / math.sqrt(1.0 - PARALLAX_MAX_SIN * PARALLAX_MAX_SIN)
    for k in prange(s.shape[0]):
        lo, hi = offsets[curve[k]], offsets[curve[k] + 1] - 1
        i = segment[k]
        out_segment[k], out_s[k] = i, s[k]
        for c in range(3):
            out_tangent[k, c] = tangent[k, c]
        w0, w1, w2 = view_dir[k, 0], view_dir[k, 1], view_dir[k, 2]
        along = tangent[k, 0] * w0 + tangent[k, 1] * w1 + tangent[k, 2] * w2
        e0, e1, e2 = tangent[k, 0] - along * w0, tangent[k, 1] - along * w1, tangent[k, 2] - along * w2
        e_norm = math.sqrt(e0 * e0 + e1 * e1 + e2 * e2)
        if i >= hi or e_norm == 0.0:
            continue
        e0, e1, e2 = e0 / e_norm, e1 / e_norm, e2 / e_norm
        d_rest = rest[i + 1] - rest[i]
        f0 = min(max((s[k] - rest[i]) / d_rest, 0.0), 1.0) if d_rest > 0.0 else 0.0
        a0, a1, a2 = _open_tangent(xyz, lo, hi, i)
        b0, b1, b2 = _open_tangent(xyz, lo, hi, i + 1)
        h0, h1, h2 = (1.0 - f0) * a0 + f0 * b0, (1.0 - f0) * a1 + f0 * b1, (1.0 - f0) * a2 + f0 * b2
        start = _projected(xyz, i, f0, e0, e1, e2)  # e·c(s)
        height = radius[yarn[k]] * math.sqrt(max(0.0, 1.0 - v[k] * v[k]))
        t0, t1, t2 = tangent[k, 0], tangent[k, 1], tangent[k, 2]
        j, f, shift, seen = i, f0, 0.0, 0.0  # seen: e·c(s + δ) − e·c(s)
        for _ in range(passes):
            sin_o = min(max(t0 * w0 + t1 * w1 + t2 * w2, -PARALLAX_MAX_SIN), PARALLAX_MAX_SIN)
            slope = t0 * e0 + t1 * e1 + t2 * e2
            residual = seen - height * sin_o / math.sqrt(1.0 - sin_o * sin_o) * slope
            shift -= residual / max(slope, PARALLAX_MIN_SLOPE)
            shift = min(max(shift, -height * max_tan), height * max_tan)
            j, length = i, _segment_length(xyz, i)
            at = f0 * length + shift  # current length from vertex j
            while at > length and j + 1 < hi:
                at -= length
                j += 1
                length = _segment_length(xyz, j)
            while at < 0.0 and j > lo:
                j -= 1
                length = _segment_length(xyz, j)
                at += length
            f = min(max(at / length, 0.0), 1.0) if length > 0.0 else 0.0
            seen = _projected(xyz, j, f, e0, e1, e2) - start
            a0, a1, a2 = _open_tangent(xyz, lo, hi, j)
            b0, b1, b2 = _open_tangent(xyz, lo, hi, j + 1)
            m0 = tangent[k, 0] + (1.0 - f) * a0 + f * b0 - h0
            m1 = tangent[k, 1] + (1.0 - f) * a1 + f * b1 - h1
            m2 = tangent[k, 2] + (1.0 - f) * a2 + f * b2 - h2
            norm = math.sqrt(m0 * m0 + m1 * m1 + m2 * m2)
            if norm > 0.0:
                t0, t1, t2 = m0 / norm, m1 / norm, m2 / norm
            else:
                t0, t1, t2 = tangent[k, 0], tangent[k, 1], tangent[k, 2]
        out_tangent[k, 0], out_tangent[k, 1], out_tangent[k, 2] = t0, t1, t2
        out_segment[k] = j
        out_s[k] = rest[j] + f * (rest[j + 1] - rest[j])


def view_phase_arclength(points, lines, looks):
    """Rest arc length shifted so the texture shows the yarn as seen from the view's azimuth (module docstring)."""
    s = np.ascontiguousarray(points["arclength"], np.float64)
    out = np.empty_like(s)
    if len(s) == 0:
        return out
    sign = np.array([look.twist_sign for look in looks], np.float64)
    period = np.array([look.period for look in looks], np.float64)
    _view_phase(np.ascontiguousarray(points["segment"], np.int64), s, np.ascontiguousarray(points["yarn"], np.int64),
                np.ascontiguousarray(points["tangent"], np.float64), np.ascontiguousarray(points["view_dir"]),
                lines.rest, np.ascontiguousarray(lines.normal, np.float64), sign, period, out)
    return out


@njit(parallel=True, cache=True)
def _view_phase(segment, s, yarn, tangent, view_dir, rest, normal, sign, period, out):
    """``view_phase_arclength`` per point: the curve frame's N at the point (interpolated along its segment by arc
    length, made normal to the tangent t; the segment's N where that vanishes), γ = atan2(ω_o·(t × N), ω_o·N),
    s − sign·γ/(2π)·period."""
    for k in prange(s.shape[0]):
        i = segment[k]
        ds = rest[i + 1] - rest[i]
        f = min(max((s[k] - rest[i]) / ds, 0.0), 1.0) if ds > 0.0 else 0.0
        t0, t1, t2 = tangent[k, 0], tangent[k, 1], tangent[k, 2]
        n0 = (1.0 - f) * normal[i, 0] + f * normal[i + 1, 0]
        n1 = (1.0 - f) * normal[i, 1] + f * normal[i + 1, 1]
        n2 = (1.0 - f) * normal[i, 2] + f * normal[i + 1, 2]
        c = n0 * t0 + n1 * t1 + n2 * t2
        n0, n1, n2 = n0 - c * t0, n1 - c * t1, n2 - c * t2
        norm = math.sqrt(n0 * n0 + n1 * n1 + n2 * n2)
        if norm > 1e-9:
            n0, n1, n2 = n0 / norm, n1 / norm, n2 / norm
        else:
            n0, n1, n2 = normal[i, 0], normal[i, 1], normal[i, 2]
        w0, w1, w2 = view_dir[k, 0], view_dir[k, 1], view_dir[k, 2]
        b0, b1, b2 = t1 * n2 - t2 * n1, t2 * n0 - t0 * n2, t0 * n1 - t1 * n0
        gamma = math.atan2(w0 * b0 + w1 * b1 + w2 * b2, w0 * n0 + w1 * n1 + w2 * n2)
        out[k] = s[k] - sign[yarn[k]] * gamma / (2.0 * math.pi) * period[yarn[k]]


def _check_pack_keys(scene: Scene, packs: dict) -> None:
    """Refuse a pack override that names no yarn entry of the scene (a typo would otherwise be ignored)."""
    known = {key for k, e in enumerate(scene.yarns) for key in (str(k), e.yarn, e.spec.name)}
    unknown = sorted(set(packs) - known)
    if unknown:
        raise FormatError(f"--pack {unknown[0]}={packs[unknown[0]]}: the scene has no yarn {unknown[0]!r} (its yarns: "
                          f"{', '.join(sorted({e.spec.name for e in scene.yarns}))}; or an entry index 0.."
                          f"{len(scene.yarns) - 1})")


def _pack_path(k, entry, packs):
    """The pack of yarn entry k: ``packs`` by the entry's index, its ``yarn`` as written or its spec's name, else
    the scene's ``pack``."""
    path = next((packs[key] for key in (str(k), entry.yarn, entry.spec.name) if key in packs), entry.pack)
    if path is None:
        name = entry.spec.name
        raise FormatError(f"yarns[{k}] ({name}) has no asset pack: bake one (knitbake bake {entry.yarn} -o "
                          f"{name}.h5) and name it in the scene (pack = ...) or with --pack {name}=FILE")
    if not Path(path).is_file():
        raise FormatError(f"yarns[{k}] ({entry.yarn}): pack {path} does not exist")
    return path


def _environment(scene: Scene, use_cache: bool):
    """(SRBF fit of the scene's environment, fit read from the cache), or (None, False) without one."""
    envs = [light for light in scene.lights if isinstance(light, EnvironmentLight)]
    if not envs:
        return None, False
    env = envs[0]
    image = environment_image(env)
    return cached_fit(np.asarray(image, np.float64) * np.asarray(env.scale, np.float64), scene.render.srbf_count,
                      scene.render.seed, use_cache)


class Receivers(NamedTuple):
    """A set of shadow-map receivers (module docstring, step 4): world ``position`` (N, 3) and ``bias`` (N,) scene
    units. Receivers off their yarn's axis also carry their ``offset`` (N, 3) from the axis and the yarn's
    ``tangent`` (N, 3) there; toward each light their bias grows by how far they lie behind their own yarn's strip
    (``receiver_bias``)."""

    position: np.ndarray
    bias: np.ndarray
    offset: np.ndarray | None = None
    tangent: np.ndarray | None = None


def strip_receivers(points, looks, surface: bool, flyaway: bool = False) -> Receivers:
    """The receivers of regular ``points``, biased by ``SHADOW_BIAS_RADII`` yarn radii: on the tube surface the camera
    sees there (the strip point moved toward the camera along its view ray by r √(1 − v²), where a tube of radius r
    about the strip's axis meets the ray; the strip point itself at the edges v = ±1) or, ``surface`` False, the strip
    points themselves. Both lie off the yarn's axis: a
    strip point v r along the strip's half-width direction b = normalize(ω_o × t) (``strip_raster``; taken here at
    the point's own ω_o and t), the surface r √(1 − v²) further toward the camera.

    ``flyaway``: ``points`` are the flyaway layer's, on strips of the entry's ``flyaway_half_width`` h: the strip
    points themselves (``surface`` is ignored), v h off the axis, with the same bias and so the same margin from their
    own yarn's strip as a regular point. Their own yarn's shadow on them is the kernels' (``strip_shading._hair_light``
    crosses the tube toward the light), not the map's: without the margin a hair behind its yarn from the light took
    that shadow twice."""
    radius = np.array([look.radius for look in looks], np.float64)[points["yarn"]]
    width = radius if not flyaway else np.array([look.flyaway_half_width for look in looks],
                                                np.float64)[points["yarn"]]
    position = np.ascontiguousarray(points["position"], np.float64)
    tangent = np.ascontiguousarray(points["tangent"], np.float64)
    out_position, offset = np.empty_like(position), np.empty_like(position)
    _strip_receivers(position, np.ascontiguousarray(points["view_dir"], np.float64), tangent,
                     np.ascontiguousarray(points["v"], np.float64), width, surface and not flyaway, out_position,
                     offset)
    return Receivers(out_position, SHADOW_BIAS_RADII * radius, offset, tangent)


@njit(parallel=True, cache=True)
def _strip_receivers(position, view_dir, tangent, v, radius, surface, out_position, out_offset):
    """``strip_receivers`` per point (each point writes its own rows): its position and its offset from the axis."""
    for k in prange(position.shape[0]):
        vk = min(max(v[k], -1.0), 1.0)
        height = radius[k] * math.sqrt(1.0 - vk * vk) if surface else 0.0
        w0, w1, w2 = view_dir[k, 0], view_dir[k, 1], view_dir[k, 2]
        t0, t1, t2 = tangent[k, 0], tangent[k, 1], tangent[k, 2]
        b0, b1, b2 = w1 * t2 - w2 * t1, w2 * t0 - w0 * t2, w0 * t1 - w1 * t0
        norm = math.sqrt(b0 * b0 + b1 * b1 + b2 * b2)
        lateral = radius[k] * vk / norm if norm > 0.0 else 0.0
        out_position[k, 0] = position[k, 0] + height * w0
        out_position[k, 1] = position[k, 1] + height * w1
        out_position[k, 2] = position[k, 2] + height * w2
        out_offset[k, 0] = lateral * b0 + height * w0
        out_offset[k, 1] = lateral * b1 + height * w1
        out_offset[k, 2] = lateral * b2 + height * w2


def axis_receivers(lines, looks, at) -> Receivers:
    """The receivers at polyline points ``at`` (on their yarns' axes), biased by ``SHADOW_BIAS_RADII`` yarn radii."""
    radius = np.array([look.radius for look in looks], np.float64)
    return Receivers(lines.points[at], SHADOW_BIAS_RADII * np.repeat(radius[lines.entry], np.diff(lines.offsets))[at])


def receiver_bias(receivers: Receivers, direction) -> np.ndarray:
    """The bias (N,) of ``receivers`` in a map toward unit ``direction``: a receiver off its yarn's axis keeps its
    margin from its own yarn's strip (``shadow_map.own_strip_depth``), which tilts toward it as the light turns
    along the yarn; without that the far side of a yarn lit along its length fell into its own strip's shadow
    (BENCHMARKS.md, "Issue 13: a yarn's own strip, and the closure's stored ξ")."""
    if receivers.offset is None or len(receivers.bias) == 0:
        return receivers.bias
    return receivers.bias + own_strip_depth(receivers.offset, receivers.tangent, direction)


def canopy_at_vertices(lines, looks, direction) -> np.ndarray:
    """(P,) the hair canopy's transmittance toward unit ``direction`` (``hair_canopy``) at each polyline point of
    ``lines``, taken on its tube surface toward the light, where its lit fibers lie: a ray from the axis runs a
    radius deeper through the neighbours' layers (nearly twice the traced canopy in the grazing patch's interior,
    BENCHMARKS.md, stop 60). Both backends interpolate it along the curves by rest arc length, as the bounce
    (``_canopy``; the GL backend's canopy texture)."""
    radius = np.array([looks[k].radius for k in lines.entry], np.float64)
    grid = canopy_grid(lines, radius, [looks[k].hair_shells for k in lines.entry], direction)
    point_curve = np.repeat(np.arange(len(lines.offsets) - 1), np.diff(lines.offsets))
    tangent = vertex_tangents(lines.points, lines.offsets)
    d = np.asarray(direction, np.float64) / np.linalg.norm(direction)
    across = d - (tangent @ d)[:, None] * tangent
    norm = np.linalg.norm(across, axis=1, keepdims=True)
    across = np.divide(across, norm, out=np.zeros_like(across), where=norm > 1e-9)
    lit_side = lines.points + across * np.repeat(radius, np.diff(lines.offsets))[:, None]
    return canopy_transmittance(grid, lit_side, point_curve, lines.rest)


def _canopy(lines, looks, direction, sets, where, at_bounce) -> list:
    """The hair canopy's transmittance toward ``direction`` (``hair_canopy``) for each receiver set of a frame's shadow
    pass (``Renderer`` order: the point sets at ``where``, then the bounce's polyline points ``at_bounce`` if any):
    ``canopy_at_vertices`` interpolated along the curves by rest arc length, as the bounce. The canopy varies over
    the hair layers' size (a few yarn radii) and the shading points are many per polyline point: at every shading
    point it took 0.5 s a frame under the grazing light, here it costs nothing measurable (BENCHMARKS.md, stop 60)."""
    vertex = canopy_at_vertices(lines, looks, direction)[:, None]
    out = []
    for s, at in zip(sets, where):
        values = np.empty((len(s["weight"]), 1))
        bounce_at_points(np.ascontiguousarray(s["segment"], np.int64), np.ascontiguousarray(s["arclength"], np.float64),
                         lines.rest, vertex, values)
        out.append(values[at, 0])
    return out + ([vertex[at_bounce, 0]] if len(at_bounce) else [])


def _visibility(lines, radius_of_curve, direction, size, angular_radius, receivers, depth_maps, two_layers=False):
    """Yarn-level visibility of each set of ``Receivers`` toward ``direction``; the shadow map's depth is drawn into
    ``depth_maps[size]`` (kept there for the next map of that size). With ``two_layers``, (visibility, the fraction
    at most one yarn blocks) of each set, from the map's second layer (``shadow_map.behind_map``)."""
    if len(lines.entry) == 0:
        return [(np.ones(len(r.position)),) * 2 if two_layers else np.ones(len(r.position)) for r in receivers]
    sm = build_shadow_map(lines.points, lines.offsets, False, lines.rest, radius_of_curve, direction, size,
                          lines.points.min(axis=0), lines.points.max(axis=0), out=depth_maps.get(size),
                          layers=2 if two_layers else 1)
    depth_maps[size] = sm.depth
    return map_visibility(sm, direction, angular_radius, receivers, two_layers)


def map_visibility(sm, direction, angular_radius, receivers, two_layers=False) -> list:
    """``_visibility``'s lookups in a shadow map ``sm`` already drawn toward ``direction`` (with ``two_layers``, its
    ``behind`` layer too): the CPU's own maps, or the GL backend's read back (its yarn-level bounce)."""
    unit = np.asarray(direction, np.float64) / np.linalg.norm(direction)
    biases = [receiver_bias(r, unit) for r in receivers]
    if not two_layers:
        return [shadow_visibility(sm, r.position, bias, angular_radius) for r, bias in zip(receivers, biases)]
    behind = behind_map(sm)
    return [(shadow_visibility(sm, r.position, bias, angular_radius),
             shadow_visibility(behind, r.position, bias, angular_radius)) for r, bias in zip(receivers, biases)]


class Renderer:
    """A scene made ready to draw: its asset packs read (``yarn_look``), its yarn curves read once with all their
    frames (a stitch mesh simulated at rest), the environment's SRBFs fitted (or read from the fit cache) and the
    kernels compiled by the first frame. ``render(frame)`` then draws any frame of the curves without reloading
    anything; an interactive viewer or a sequence keeps one ``Renderer``.

    ``packs`` maps an entry index (as a string), a yarn as written in the scene or a yarn spec's name to a pack path,
    overriding the scene's ``pack``; ``use_cache`` False fits the environment again instead of reading the fit cache
    (``knitrun.shading.srbf_cache``). FormatError (one line) for a scene the renderer cannot draw (a missing pack, a
    pack for another yarn, a ``packs`` key that names no yarn). ``setup_timings`` holds the seconds of ``load`` and
    ``srbf_fit`` spent here. ``compile_ahead``: on an empty kernel cache, start a helper process that compiles the
    ``shade`` and ``resolve`` passes' kernels while the first frame compiles the rasterizer's
    (``knitrun.render.compile_ahead``; the frame waits for it before its ``shade`` pass). Off by default: a caller
    that runs renderers side by side (Dask workers) has no core to spare."""

    def __init__(self, scene: Scene, packs: dict | None = None, features: Features = Features(),
                 samples_per_segment: int = 4, use_cache: bool = True, progress=None, compile_ahead: bool = False):
        packs = packs or {}
        _check_pack_keys(scene, packs)
        # a helper process compiling the later passes' kernels while this one loads, fits and rasterizes
        # (``knitrun.render.compile_ahead``); None when not asked for or when the kernel cache has them
        self._compile_helper = start_compile_ahead(scene, packs, features, samples_per_segment) if compile_ahead \
            else None
        self.scene, self.features, self.samples_per_segment = scene, features, samples_per_segment
        self.setup_timings, self.setup_facts = {}, {}
        start = time.perf_counter()
        environment = any(isinstance(light, EnvironmentLight) for light in scene.lights)
        looks = [load_look(_pack_path(k, e, packs), e, scene.units,
                           corrections=features.xi or features.fiber_shadowing, full_tables=features.full_tables,
                           flyaways=features.flyaways, environment=environment, detail=features.fiber_detail,
                           transmission=features.interreflection, closed_xi=features.closed_xi,
                           view_xi=features.view_xi, split_xi=features.split_xi,
                           colour_xi=features.colour_xi)
                 for k, e in enumerate(scene.yarns)]
        for look in looks:
            if not features.xi:
                look.xi_full, look.xi_m, look.xi_n = no_full_table(), ones_factor(), ones_factor()
                look.xi_view, look.xi_single, look.xi_single_view = no_view_table(), no_full_table(), no_view_table()
            if not features.fiber_shadowing:
                look.psi_full, look.psi_gm, look.psi_gn = no_full_table(), ones_factor(), ones_factor()
                look.n_occluded = 0.0
            if not features.multiple_scattering:
                look.d_f = look.d_b = 0.0
        self.looks = looks
        self.setup_facts["n_cross"] = {look.name: look.n_cross_from for look in looks}
        self.setup_facts["xi"] = {look.name: look.xi_from if features.xi else "none (switched off)" for look in looks}
        self.setup_facts["yarn_hull"] = {look.name: look.hull_from for look in looks}
        self.kernel_looks = [shading_look(look) for look in looks]
        self.im_tables = [look.im if look.im is not None else no_im_table() for look in looks]
        self.environment = environment
        self.warnings = [w for look in looks for w in look.warnings]
        self.curves = [_scene_curves(entry, scene.units, self.warnings) for entry in scene.yarns]
        for k, (entry, curves) in enumerate(zip(scene.yarns, self.curves)):
            message = radius_mismatch(curves, entry.radius, f"yarns[{k}]")
            if message is not None:
                self.warnings.append(message)
        counts = {c.points.shape[0] for c in self.curves if c.points.shape[0] > 1}
        self.frame_count = min(counts) if counts else 1  # entries with one frame are drawn in every frame
        now = time.perf_counter()
        self.setup_timings["load"] = now - start
        if progress is not None:
            progress("load", now - start)
        fit, cached = _environment(scene, use_cache)
        if fit is not None:
            used = np.any(np.asarray(fit.weights) > 0.0, axis=1)  # lobes of zero weight add nothing: not drawn
            self.setup_facts.update(srbf_lobes=int(len(fit.sharpness)), srbf_lobes_drawn=int(used.sum()),
                                    srbf_fit_cached=cached, srbf_relative_l2_error=fit.relative_l2_error,
                                    srbf_irradiance_error=fit.irradiance_error)
            fit = dataclasses.replace(fit, directions=fit.directions[used], sharpness=fit.sharpness[used],
                                      weights=fit.weights[used])
            self.setup_timings["srbf_fit"] = time.perf_counter() - now
            if progress is not None:
                progress("srbf_fit", self.setup_timings["srbf_fit"])
        self.fit = fit
        # the I_M tables at the lobes' λ, once (``im_lookup.im_slices``; no slice without an environment): the shading
        # kernels read these
        lambdas = np.zeros(0) if fit is None else fit.sharpness
        self.im_slices = [im_slices(table, lambdas) for table in self.im_tables]
        self.shadow_depth = {}  # shadow maps by size, drawn over by the next map of that size

    def frame_index(self, frame: int | None) -> int:
        """``frame`` as an index into the curves' frames (None: the scene's ``render.frame``); FormatError (one line)
        when out of range."""
        frame = self.scene.render.frame if frame is None else int(frame)
        if not 0 <= frame < self.frame_count:
            raise FormatError(f"frame {frame} is out of range: the scene's curves have {self.frame_count} frame(s)")
        return frame

    def render(self, frame: int | None = None, progress=None) -> RenderResult:
        """Draw ``frame`` of the yarn curves (default: the scene's ``render.frame``); ``progress(name, seconds)`` is
        called as each pass ends. Timings are this frame's passes (``load``: evaluating its curves)."""
        scene, looks = self.scene, self.looks
        frame = self.frame_index(frame)
        timings, facts = {}, {"warnings": list(self.warnings), **self.setup_facts, "frame": frame,
                              "layers": scene.render.layers, "hair_layers": scene.render.hair_layers}
        clock = [time.perf_counter()]

        def lap(name):
            now = time.perf_counter()
            start = clock[0]
            timings[name] = timings.get(name, 0.0) + now - clock[0]
            clock[0] = now
            if progress is not None:
                progress(name, now - start)

        lines = _polylines(scene, self.curves, frame, self.samples_per_segment)
        facts.update(curves=int(len(lines.entry)), points=int(len(lines.points)))
        lap("load")

        camera = scene_camera(scene)
        raster = self._raster(lines, camera)
        facts.update(shading_points=int(len(raster.points["weight"])),
                     flyaway_points=0 if raster.fly_points is None else int(len(raster.fly_points["weight"])),
                     flyaway_points_covered=0 if raster.fly_points is None else int(raster.covered.sum()))
        lap("raster")
        image = self._light_and_shade(lines, camera, raster, facts, lap)
        facts["residuals"] = {look.name: look.residuals for look in looks}
        return RenderResult(image, timings, facts)

    def hair_cover(self, frame: int | None = None) -> np.ndarray:
        """(H, W) the fraction of each pixel of ``frame`` (default: the scene's) that the flyaway layers cover: their
        points' hair coverage α composited as the resolve composites them, every hair opaque (the share of the pixel
        where a camera ray's first surface is a hair); zeros without flyaways. A diagnostic, not part of a frame:
        its counterpart on the reference is the share of camera rays whose first hit is a loop or hair fiber
        (``benchmarks/probe_hair_coverage.py``, by which stop 61 chose ``render.hair_layers``)."""
        lines = _polylines(self.scene, self.curves, self.frame_index(frame), self.samples_per_segment)
        camera = scene_camera(self.scene)
        out = np.zeros((camera.height * camera.width, 3))
        raster = self._raster(lines, camera) if len(lines.entry) else None
        if raster is not None and raster.fly_points is not None:
            alpha = self._hair_coverage(raster.hairs, raster.fly_points["yarn"], raster.drawn_fly)
            resolve(raster.fly_points["layer_start"], raster.fly_points["weight"], np.ones((len(alpha), 3)), alpha,
                    np.zeros((len(alpha), 3)), out, out)
        return out[:, 0].reshape(camera.height, camera.width)

    def _raster(self, lines, camera) -> _FrameRaster:
        """The ``raster`` pass of a frame's polylines (module docstring)."""
        looks, scene = self.looks, self.scene
        msaa = scene.render.msaa
        radius = np.array([looks[k].radius for k in lines.entry])
        fly_radius = np.array([looks[k].flyaway_half_width for k in lines.entry])
        vis = rasterize_visibility(lines.points, lines.offsets, False, lines.rest, radius, lines.entry, camera, msaa)
        points = shading_points(vis, camera)
        behind_points = behind = None
        fly_buffers = []
        if scene.render.layers > 1 and len(lines.entry):
            behind = rasterize_behind(vis, camera, radius)
            behind_points = shading_points(behind, camera)
        drawn_fly = [k for k, look in enumerate(looks) if look.flyaway is not None]
        fly_points = hairs = covered = None
        if drawn_fly and len(lines.entry):
            fly_curves = np.isin(lines.entry, drawn_fly)
            fly_buffers = rasterize_before(lines.points, lines.offsets, False, lines.rest,
                                           np.where(fly_curves, fly_radius, 1e-9), lines.entry, camera, vis,
                                           float(radius.max()), scene.render.hair_layers)
            # uncovered samples (curve −1) are dropped by the coverage anyway
            fly_points = _stacked([shading_points(b, camera, mask=fly_curves[b.curve]) for b in fly_buffers])
            hairs = _kernel_points(fly_points, lines, looks)
            covered = self._hair_coverage(hairs, fly_points["yarn"], drawn_fly) > 0.0
        return _FrameRaster(points, behind_points, fly_points, hairs, covered, drawn_fly, (vis, behind, *fly_buffers))

    def _light_and_shade(self, lines, camera, raster, facts, lap) -> np.ndarray:
        """The ``shadow``, ``shade`` and ``resolve`` passes of a frame (module docstring): its (H, W, 3) float32 image.
        ``facts`` gets the passes' facts, ``lap(name)`` is called as each pass ends."""
        scene, features, looks, fit = self.scene, self.features, self.looks, self.fit
        points, behind_points, fly_points = raster.points, raster.behind_points, raster.fly_points
        hairs, covered, drawn_fly = raster.hairs, raster.covered, raster.drawn_fly
        radius = np.array([looks[k].radius for k in lines.entry])

        # the receivers of each set of points: all regular points; the flyaway points the hairs cover (a point of zero
        # coverage adds nothing to the image, so it gets no shadow lookups and no shading; its visibility reads 1)
        layers = [points] + ([behind_points] if behind_points is not None else [])  # regular fibers, front to back
        sets = layers + ([fly_points] if fly_points is not None else [])
        where = [slice(None)] * len(layers) + ([np.flatnonzero(covered)] if fly_points is not None else [])
        receivers = [strip_receivers(s, looks, features.surface_shadows) for s in layers] + \
            [strip_receivers({key: s[key][at] for key in RECEIVER_KEYS}, looks, False, flyaway=True)
             for s, at in zip(sets[len(layers):], where[len(layers):])]
        directional = [light for light in scene.lights if not isinstance(light, EnvironmentLight)]
        light_dir = np.array([light.unit_direction for light in directional], np.float64).reshape(-1, 3)
        light_e = np.array([light.irradiance for light in directional], np.float64).reshape(-1, 3)
        size = scene.render.shadow_map_size
        light_vis = [np.ones((len(light_dir), len(s["weight"]))) for s in sets]
        # ``Lights.beyond``: V₂ with ``two_blockers``, else (L, 0), read as 1
        light_beyond = [np.ones((len(light_dir), len(s["weight"]) if features.two_blockers else 0)) for s in sets]
        # the yarn-level bounce under the directional lights (``yarn_bounce``) looks the lights up at the polyline
        # vertices too
        bounce_on = bounce_drawn(features, looks, len(light_dir))
        at_bounce = bounce_vertices(lines, looks) if bounce_on else np.zeros(0, np.int64)
        vertex_receivers = [axis_receivers(lines, looks, at_bounce)] if bounce_on else []
        vertex_vis = np.ones((len(light_dir), len(at_bounce)))
        vertex_beyond = np.ones((len(light_dir), len(at_bounce)))
        canopy = features.hair_canopy and features.flyaways and len(light_dir) > 0
        for i, d in enumerate(light_dir):
            found = _visibility(lines, radius, d, size, 0.0, receivers + vertex_receivers, self.shadow_depth,
                                features.two_blockers)
            if canopy:  # other yarns' hair layers (``hair_canopy``) dim what the bodies let through
                through = _canopy(lines, looks, d, sets, where, at_bounce)
                # V only: with ``two_blockers`` the light the canopy keeps off passes the bodies as under one
                # blocker (τ_Y), as it does without, not as behind a second yarn
                found = [(v[0] * t, v[1]) if features.two_blockers else v * t for v, t in zip(found, through)]
            pairs = found if features.two_blockers else [(vis, None) for vis in found]
            for out, beyond, at, (vis, past_one) in zip(light_vis, light_beyond, where, pairs):
                out[i, at] = vis
                if past_one is not None:
                    beyond[i, at] = past_one
            if bounce_on:
                vertex_vis[i] = pairs[-1][0]
                if features.two_blockers:
                    vertex_beyond[i] = pairs[-1][1]
        if features.two_blockers and len(light_dir) and len(light_beyond[0][0]):
            facts["two_blockers"] = {"behind_two_yarns": round(float(np.mean(1.0 - light_beyond[0][0])), 4),
                                     "behind_one_yarn": round(float(np.mean(light_beyond[0][0] - light_vis[0][0])),
                                                              4)}
        lobe_dir = np.zeros((0, 3)) if fit is None else np.asarray(fit.directions, np.float64)
        lobe_lambda = np.zeros(0) if fit is None else np.asarray(fit.sharpness, np.float64)
        lobe_w = np.zeros((0, 3)) if fit is None else np.asarray(fit.weights, np.float64)
        lobe_vis = [np.ones((len(lobe_dir), len(s["weight"]))) for s in sets]
        for j, d in enumerate(lobe_dir):
            angular = min(1.0 / math.sqrt(lobe_lambda[j]), MAX_LOBE_ANGULAR_RADIUS)
            for out, at, vis in zip(lobe_vis, where, _visibility(lines, radius, d, max(64, size // LOBE_SHADOW_DIVISOR),
                                                                 angular, receivers, self.shadow_depth)):
                out[j, at] = vis
        # the lobes' inter-reflection is light another yarn scattered first: multiple scattering
        albedo = np.array([look.yarn_albedo or 0.0 for look in looks]) \
            if features.interreflection and features.multiple_scattering else np.zeros(len(looks))
        if len(lobe_dir) and albedo.any():
            lobe_vis = [interreflected_visibility(v, albedo[s["yarn"]][None, :], out=v)
                        for v, s in zip(lobe_vis, sets)]
        # per yarn, the ρ the lobes were inter-reflected with and ρ_Y per channel, which the kernels take each
        # channel's visibility by (``interreflection.channel_visibility``)
        lobe_albedo = [np.concatenate([[a], np.reshape(look.hull_albedo, 3)]) if a > 0.0 else np.zeros(4)
                       for look, a in zip(looks, albedo)]
        if self.environment:
            facts["interreflection"] = {
                look.name: "off (Features.interreflection)" if not features.interreflection else
                "off (Features.multiple_scattering: single scattering alone)" if not features.multiple_scattering else
                round(float(a), 4) if look.yarn_albedo is not None else "absent from the pack (schema < 2.1)"
                for look, a in zip(looks, albedo)}
        ms_dir, ms_e, ms_vis = ms_lights(lobe_dir, lobe_lambda, lobe_w, lobe_vis)
        facts["ms_lights"] = int(len(ms_dir))
        bounce, fly_arriving = [no_rows()] * len(layers), None
        if bounce_on:
            bounce, fly_arriving = _yarn_bounce(lines, looks, camera, light_dir, light_e, at_bounce, vertex_vis,
                                                vertex_beyond, layers, fly_points, facts)
        lap("shadow")

        if self._compile_helper is not None:  # its kernels are in the cache by now, or soon: load them, not compile
            if self._compile_helper.wait() != 0:
                facts["warnings"].append(f"the compile-ahead helper failed (exit {self._compile_helper.returncode}): "
                                         "this frame compiled its kernels itself")
            self._compile_helper = None
        h, w = camera.height, camera.width
        shaded = []  # (rgb, alpha) of each layer of regular fibers
        for m, layer in enumerate(layers):
            rgb, alpha = np.zeros((len(layer["weight"]), 3)), np.zeros(len(layer["weight"]))
            regular = _kernel_points(parallax_shift(layer, lines, looks) if self.features.parallax else layer, lines,
                                     looks, self.features.fiber_bend)
            for k, look in enumerate(looks):
                idx = np.flatnonzero(layer["yarn"] == k)
                kernel_look, corrections, _ = self.kernel_looks[k]
                shade_regular(idx, regular, kernel_look, corrections, look.tangent, look.coverage, look.detail,
                              Lights(light_dir, light_e, light_vis[m], light_beyond[m]),
                              Lobes(lobe_dir, lobe_lambda, lobe_w, lobe_vis[m], lobe_albedo[k]),
                              Lights(ms_dir, ms_e, ms_vis[m], np.zeros((len(ms_dir), 0))), self.im_slices[k],
                              bounce[m], rgb, alpha)
            shaded.append((rgb, alpha))
        if fly_points is not None:
            n_fly = len(fly_points["weight"])
            fly_rgb, fly_alpha, fly_transmit = np.zeros((n_fly, 3)), np.zeros(n_fly), np.zeros((n_fly, 3))
            for k in drawn_fly:
                idx = np.flatnonzero((fly_points["yarn"] == k) & covered)
                glow = hair_glow(looks[k]) if glow_on(features) else None
                shade_flyaway(idx, hairs, *self.kernel_looks[k],
                              looks[k].coverage if features.hairs_behind else no_texture(1),
                              Lights(light_dir, light_e, light_vis[-1], light_beyond[-1]),
                              no_rows() if glow is None else glow,
                              Lobes(lobe_dir, lobe_lambda, lobe_w, lobe_vis[-1], lobe_albedo[k]), self.im_slices[k],
                              fly_rgb, fly_alpha, fly_transmit)
                if fly_arriving is not None and features.hair_bounce:  # the neighbours' light on the hairs
                    fly_rgb[idx] += hair_bounce(fly_arriving[idx], looks[k].params)
            if not features.hair_light:  # the split of ``Features.hair_light``: opaque black hairs
                fly_rgb[:] = 0.0
                fly_transmit[:] = 0.0
        lap("shade")

        background = np.asarray(scene.background, np.float64)
        image = np.empty((h * w, 3))
        image[:] = background
        if len(layers) > 1:
            resolve_behind(points["start"], points["weight"], shaded[0][1], behind_points["start"],
                           behind_points["weight"], shaded[1][0], shaded[1][1], background, image)
        rgb, alpha = shaded[0]
        resolve(points["start"], points["weight"], rgb, alpha, np.zeros_like(rgb), image, image)
        if fly_points is not None:
            resolve(fly_points["layer_start"], fly_points["weight"], fly_rgb, fly_alpha, fly_transmit, image, image)
        if not np.all(np.isfinite(image)):
            raise RuntimeError("strip renderer produced a non-finite pixel (a bug: please report the scene)")
        lap("resolve")
        return image.reshape(h, w, 3).astype(np.float32)

    def compile_shading(self):
        """Compile the kernels of the ``shade`` and ``resolve`` passes and the flyaway coverage for this scene (its
        layers and flyaways decide which kernels a frame calls, its size does not) by running them on a frame with no
        shading point: what ``compile_ahead``'s helper does while the first frame compiles the rasterizer. Draws
        nothing, costs only the compilation (or the cache's load)."""
        camera = scene_camera(self.scene)
        lines = _no_polylines()
        pixels = camera.height * camera.width
        drawn_fly = [k for k, look in enumerate(self.looks) if look.flyaway is not None]
        fly_points = hairs = covered = None
        if drawn_fly:
            fly_points = _stacked([no_shading_points(pixels)])
            hairs = _kernel_points(fly_points, lines, self.looks)
            covered = self._hair_coverage(hairs, fly_points["yarn"], drawn_fly) > 0.0
        behind = no_shading_points(pixels) if self.scene.render.layers > 1 else None
        raster = _FrameRaster(no_shading_points(pixels), behind, fly_points, hairs, covered, drawn_fly)
        self._light_and_shade(lines, camera, raster, {}, lambda name: None)

    def _hair_coverage(self, hairs, yarn, drawn_fly):
        """The coverage the flyaway layer's points get from their yarn's hair texture (``flyaway_coverage``)."""
        coverage = np.zeros(len(yarn))
        for k in drawn_fly:
            flyaway_coverage(np.flatnonzero(yarn == k), hairs, self.kernel_looks[k][0], self.kernel_looks[k][2],
                             coverage)
        return coverage


def render(scene: Scene, packs: dict | None = None, features: Features = Features(), samples_per_segment: int = 4,
           progress=None, use_cache: bool = True, compile_ahead: bool = False) -> RenderResult:
    """Render one frame of ``scene`` (its ``render.frame``): a ``Renderer`` set up and used once (arguments there);
    the timings include the setup (``load``: packs, curves and this frame's polylines; ``srbf_fit``)."""
    renderer = Renderer(scene, packs, features, samples_per_segment, use_cache, progress, compile_ahead)
    result = renderer.render(progress=progress)
    timings = {name: renderer.setup_timings.get(name, 0.0) + result.timings.get(name, 0.0)
               for name in ("load", "srbf_fit") if name in renderer.setup_timings or name in result.timings}
    result.timings = {**timings, **{k: v for k, v in result.timings.items() if k not in timings}}
    return result


def bounce_drawn(features: Features, looks, n_lights: int) -> bool:
    """Whether a frame draws the yarn-level bounce (``knitrun.render.yarn_bounce``): asked for, with the yarn-level
    light transport it belongs to, a directional light, and every yarn's pack holding ρ_Y and T_Y."""
    return features.yarn_bounce and features.interreflection and features.multiple_scattering and n_lights > 0 and \
        all(look.hull_albedo is not None and look.hull_transmittance is not None for look in looks)


def _yarn_bounce(lines, looks, camera, light_dir, light_e, at, vertex_vis, vertex_beyond, layers, fly_points,
                 facts) -> tuple:
    """(the yarn-level bounce radiance (N, 3) of each layer's points, the neighbours' light arriving at the flyaway
    points (N_fly, 3) or None without them): ``frame_bounce``'s values interpolated along the curves;
    ``facts["yarn_bounce"]`` gets the vertices' mean covered fraction of the sphere and mean bounce radiance."""
    vertex, covered, arriving = frame_bounce(lines, looks, camera, light_dir, light_e, at, vertex_vis, vertex_beyond)
    if len(covered):
        facts["yarn_bounce"] = bounce_facts(vertex, covered)

    def at_points(points, per_vertex):
        values = np.empty((len(points["weight"]), 3))
        bounce_at_points(np.ascontiguousarray(points["segment"], np.int64),
                         np.ascontiguousarray(points["arclength"], np.float64), lines.rest, per_vertex, values)
        return values

    hairs = None if fly_points is None else at_points(fly_points, arriving)
    return [at_points(layer, vertex) for layer in layers], hairs


def glow_on(features: Features) -> bool:
    """Whether the hairs take their body's glow (``Features.hair_glow``): light the body's fibers scattered first, so
    multiple scattering, which ``Features.multiple_scattering`` False leaves out."""
    return features.hair_glow and features.multiple_scattering


def hair_glow(look) -> np.ndarray | None:
    """(2, 3): R_Y and S_Y of ``look``'s yarn tube (``yarn_bounce.tube_optics``, in the entry's colour) for the
    body's glow on its hairs (``strip_shading.body_glow``, ``Features.hair_glow``); None for a pack without ρ_Y and
    T_Y (no glow)."""
    if look.hull_albedo is None or look.hull_transmittance is None:
        return None
    return np.ascontiguousarray(np.stack(tube_optics(np.reshape(look.hull_albedo, 3),
                                                     np.reshape(look.hull_transmittance, 3), look.gap)), np.float64)


def bounce_facts(vertex, covered) -> dict:
    """``RenderResult.facts["yarn_bounce"]``: the polyline points' mean covered fraction of the sphere and mean bounce
    radiance (``frame_bounce``'s values; at least one point)."""
    return {"covered_sphere": round(float(covered.mean()), 4),
            "radiance": [round(float(x), 6) for x in vertex.mean(axis=0)]}


def bounce_vertices(lines, looks) -> np.ndarray:
    """Indices (sorted) of the polyline points the yarn-level bounce is computed at (``frame_bounce``): along each
    curve every k-th point and its last, k the stride that spaces them about ``BOUNCE_SPACING_RADII`` yarn radii apart
    by the curve's mean segment length (at least 1). Why: the bounce varies over the distance to the neighbouring
    yarns (two radii and more), and its cost grows with the square of the points, since each sums over the
    neighbours' segments (BENCHMARKS.md, "Issue 13: the default model of stop 49")."""
    counts = np.diff(lines.offsets)
    curve = np.repeat(np.arange(len(counts)), counts)
    step = np.linalg.norm(np.diff(lines.points, axis=0), axis=1)
    within = curve[1:] == curve[:-1]
    length = np.bincount(curve[1:][within], step[within], minlength=len(counts))
    spacing = BOUNCE_SPACING_RADII * np.array([looks[k].radius for k in lines.entry], np.float64)
    per_step = np.divide(spacing * np.maximum(counts - 1, 0), length, out=np.zeros(len(counts)), where=length > 0.0)
    stride = np.maximum(np.minimum(per_step, counts), 1.0).astype(np.int64)
    local = np.arange(len(curve)) - lines.offsets[:-1][curve]
    return np.flatnonzero((local % stride[curve] == 0) | (local == counts[curve] - 1)).astype(np.int64)


def frame_bounce(lines, looks, camera, light_dir, light_e, at, vertex_vis, vertex_beyond,
                 solve=vertex_bounce) -> tuple:
    """(bounce radiance (P, 3), covered fraction of the sphere (P,), the neighbours' light arriving (P, 3), which
    the hairs take: ``yarn_bounce.vertex_bounce``'s I) at the frame's polyline vertices under the
    directional lights (``yarn_bounce.vertex_bounce``): computed at the points ``at`` (``bounce_vertices``) on the
    polylines through them, from the lights' visibility ``vertex_vis`` (L, len(at)) there (and ``vertex_beyond``,
    the fraction at most one yarn blocks, ``Lights.beyond``), and interpolated between them by rest arc length.
    Both backends draw it; ``solve`` (``BounceYarns``, ``BounceLights``) → (B, f, I) does the sums: the Numba
    kernel, or the GL backend's compute shader (``gl.gl_bounce``)."""
    full, lines = lines, _thinned(lines, at)
    entry = np.repeat(lines.entry, np.diff(lines.offsets))
    albedo = np.array([look.hull_albedo for look in looks], np.float64).reshape(-1, 3)[entry]
    transmit = np.array([look.hull_transmittance for look in looks], np.float64).reshape(-1, 3)[entry]
    gap = np.array([look.gap for look in looks])[entry]
    if camera.ortho_height > 0:
        view = np.broadcast_to(-camera.basis()[0], lines.points.shape)
    else:
        view = np.asarray(camera.position, np.float64) - lines.points
        view = view / np.maximum(np.linalg.norm(view, axis=1, keepdims=True), 1e-300)
    reflect, transmit = tube_optics(albedo, transmit, gap[:, None])
    yarns = BounceYarns(lines.points, vertex_tangents(lines.points, lines.offsets),
                        np.repeat(np.arange(len(lines.entry)), np.diff(lines.offsets)), lines.offsets, lines.rest,
                        np.array([looks[k].radius for k in lines.entry], np.float64), reflect + transmit,
                        np.ascontiguousarray(view, np.float64), bounce_phases(looks),
                        np.asarray(lines.entry, np.int64))
    direct = past_blockers.py_func(vertex_vis, vertex_beyond, gap[None, :])  # numpy: no array kernel to compile
    vertex, covered, arriving = solve(yarns, BounceLights(light_dir, light_e, direct))
    return (_between(full.rest, at, vertex), _between(full.rest, at, covered[:, None])[:, 0],
            _between(full.rest, at, arriving))


def bounce_phases(looks) -> np.ndarray:
    """(entries, …): each yarn entry's tube phase for the bounce on the shared grid (``YarnLook.tube_phase``, from
    its pack's ``correction/radiance_view``; a Lambertian cylinder's, ``yarn_bounce.lambert_phase``, where the pack
    has none)."""
    out = []
    for look in looks:
        if look.tube_phase is not None:
            out.append(look.tube_phase)
        else:
            out.append(lambert_phase(*tube_optics(np.reshape(look.hull_albedo, 3),
                                                  np.reshape(look.hull_transmittance, 3), look.gap)))
    return np.ascontiguousarray(np.stack(out), np.float64)


def _thinned(lines, at) -> _Polylines:
    """``lines`` with only the points ``at`` (sorted indices that keep every curve's first and last point)."""
    n_curves = len(lines.offsets) - 1
    curve = np.repeat(np.arange(n_curves), np.diff(lines.offsets))
    offsets = np.concatenate([[0], np.cumsum(np.bincount(curve[at], minlength=n_curves))]).astype(np.int64)
    return dataclasses.replace(lines, points=lines.points[at], rest=lines.rest[at], offsets=offsets,
                               normal=lines.normal[at])


def _between(rest, at, values) -> np.ndarray:
    """(P, C): ``values`` (len(at), C) known at the points ``at`` (``bounce_vertices``) interpolated linearly by rest
    arc length ``rest`` (P,) to every point, each between the known points of its own curve."""
    below = np.searchsorted(at, np.arange(len(rest)), side="right") - 1
    above = np.minimum(below + 1, len(at) - 1)
    a, b = at[below], at[above]
    span = rest[b] - rest[a]
    f = np.where((b > a) & (span > 0.0), (rest - rest[a]) / np.where(span > 0.0, span, 1.0), 0.0)
    f = np.clip(f, 0.0, 1.0)[:, None]
    return (1.0 - f) * values[below] + f * values[above]


def _stacked(layers: list) -> dict:
    """One dict of shading points from a list of ``shading_points`` dicts, the points of each in turn; its
    ``layer_start`` (L, H·W + 1) holds each one's ``start`` into them (in place of ``start``)."""
    base = np.cumsum([0] + [len(layer["weight"]) for layer in layers])
    out = {key: np.concatenate([layer[key] for layer in layers]) for key in layers[0] if key != "start"}
    out["layer_start"] = np.stack([layer["start"] + b for layer, b in zip(layers, base)])
    return out


def _kernel_points(points, lines, looks, bend: bool = False) -> Points:
    """The shading kernels' view of a set of shading points (``shading_inputs.Points``); with ``bend`` the curvature
    and stretch of each point's segment (``segment_bend``, for ``strip_shading.fiber_bend``), else none (zeros and
    ones: hairs; ``Features.fiber_bend`` off)."""
    n = len(points["v"])
    curvature, stretch = segment_bend(points, lines) if bend else (np.zeros((n, 3)), np.ones(n))
    return Points(points["view_dir"], points["tangent"], view_phase_arclength(points, lines, looks),
                  points["v"].astype(np.float64), points["footprint"], points["curve"].astype(np.int64), curvature,
                  stretch)


def segment_bend(points, lines):
    """(curvature (N, 3), stretch (N,)) of each point's polyline segment j (its ``segment``, after the axial
    parallax): κ = (t_{j+1} − t_j)/L_j with the rasterizer's vertex tangents (1/length, toward the centre of the
    bend) and λ = L_j / (σ_{j+1} − σ_j), L_j the segment's current length and σ the rest arc length; 0 and 1 on a
    closed curve's closing segment and on a segment of zero length or rest length. What the fiber bend reads
    (``strip_shading.fiber_bend``; module docstring, step 5)."""
    j = np.asarray(points["segment"], np.int64)
    if len(j) == 0:
        return np.zeros((0, 3)), np.ones(0)
    tangents = vertex_tangents(lines.points, lines.offsets)
    last = np.zeros(len(lines.points), bool)
    last[np.asarray(lines.offsets[1:], np.int64) - 1] = True  # a curve's last point starts no open segment
    k = np.where(last[j], j, j + 1)
    length = np.linalg.norm(lines.points[k] - lines.points[j], axis=1)
    d_rest = lines.rest[k] - lines.rest[j]
    ok = (k > j) & (length > 0.0) & (d_rest > 0.0)
    length, d_rest = np.where(ok, length, 1.0), np.where(ok, d_rest, 1.0)
    curvature = np.where(ok[:, None], (tangents[k] - tangents[j]) / length[:, None], 0.0)
    return np.ascontiguousarray(curvature), np.where(ok, length / d_rest, 1.0)
