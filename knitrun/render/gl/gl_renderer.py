"""The strip renderer on OpenGL (Huang et al. 2025 §5.2 draw their strips with OpenGL): the CPU renderer's model
(``knitrun.render.strip_shading``) ported to GLSL, drawn through moderngl on a headless EGL context (any GPU, or
Mesa's llvmpipe on a machine without one).

What runs where
---------------
* Set-up (once, on the CPU, shared with the CPU renderer): ``pipeline.Renderer`` reads the packs (with the ablation's
  tables), the yarn curves and the environment's SRBF fit; the multiple-scattering lights (cells of the sky) are
  formed once (``knitrun.render.ms_lights.ms_cells``). Here every pack table becomes a GL texture: the DS tables
  (``ds_table``), ξ (with single scattering's, ``Features.split_xi``) and Ψ^Fiber (3-D textures for the full tables,
  2-D for the factors), the I_M^{TT,D} table (a 3-D
  texture, its second and third axes merged into one), the tangent, coverage and fiber-detail mip chains (each level
  uploaded as that GL mip level).
* Per frame (``render``): the curves' polylines (``pipeline._polylines``) and their vertex tangents are uploaded as
  segments with their neighbours (GL_LINES_ADJACENCY); a geometry shader builds the camera-facing strips
  (``shaders/strip.geom``, the quads of ``strip_raster``). Pass 1, per directional light and per SRBF lobe: the
  strips seen from the light camera of ``shadow_map.build_shadow_map`` into a tile of a depth atlas (lights at
  ``shadow_map_size``, lobes at a quarter, at least 64); with ``Features.two_blockers`` the lights' maps are drawn
  twice, the second time peeled (``shaders/depth.frag``: only strips more than the first layer's radius behind it,
  ``strip_raster.rasterize_behind``'s rule) into an atlas of the second yarn layer. Pass 2: the strips seen from the
  scene camera into a multisampled float framebuffer; the fragment shader (``shaders/regular.frag``) shades the
  regular fibers exactly as ``shade_regular`` does, with PCSS visibility from the atlases (``shaders/shadow.glsl``),
  and writes (α·L, α) and the front strips' coverage and peel floor (view depth + radius). A fragment is shaded at
  the first sample of the CPU's pattern that lies on its curve's strip (the CPU shades a pixel once per curve, at its
  first covered sample). With ``render.layers`` = 2 (the default) pass 2 runs again for the strips behind: a sample
  mask keeps the samples where a fragment lies beyond the front strip's floor (``strip_raster.rasterize_behind``'s
  rule), the depth test the nearest of them (until knit's stop 73 this backend drew one layer: the patches 1.5–3 %
  darker). Pass 3: the MSAA resolves, composed by SHADING.md §6 on the GPU (``_composite``, ``composite.frag``), one
  image read back; or, for a window (``render(into=…)``, the viewer), none: the same pass tone-maps it into the
  window's framebuffer (``_display``). At the front strips' edges a strip behind is shaded at its first sample on
  the strip, where the CPU shades it at its first sample behind the front (0.7 % of a test image per pixel, 0.36 % at
  the yarn scale).
* Table lookups follow ASSET_PACK.md §4.3 by ``texelFetch`` and explicit weights (``axis_cell``), textures
  ``texture_sampling.sample_mip`` likewise: the GL image does not depend on a driver's filtering rules.

Differences from the CPU renderer, by design: single precision; the driver's sample positions decide coverage (the
CPU's are the Direct3D patterns: the same x and y values at 4×, in other pairs), so edges that are not along the
image axes cover other samples; a primitive shades one fragment per pixel (a pixel two segments of one curve share
is shaded twice, each weighted by its own coverage); the shadow maps are rasterised by the driver; the nearest depth
of a shadow map is the nearest projected polyline point.
``tests/test_gl_render.py`` holds the two renderers together (per pixel on axis-aligned orthographic scenes, else at
the yarn scale).

Five terms read more than a fragment's own attributes: ``Features.surface_shadows`` looks
the lights up on the tube surface seen (the fragment's position moved r √(1 − v²) toward the camera,
``pipeline.strip_receivers``); ``Features.parallax`` walks the frame's polylines (a texture of points, rest arc
lengths, vertex tangents and yarn frame normals, ``_polyline_textures``) from the fragment's segment as
``pipeline.parallax_shift`` does, first to the segment its sample lies on (a fragment's sample may lie past its own
segment's end), then by each of the shift's Newton steps, at most ``PARALLAX_STEPS`` segments each way;
``Features.fiber_bend`` reads the bend and stretch of the segment it ends on from the same texture
(``pipeline.segment_bend``, ``strip_shading.fiber_bend``);
``Features.yarn_bounce``, the light the neighbouring yarns scatter onto each polyline point, is prepared on the
CPU (``pipeline.frame_bounce``, the lights' visibility at the points looked up in this frame's light atlas read back,
``_read_light_maps``; until stop 72 the CPU twin drew them again, ~106 ms a light on 2 cores), its sums over the
neighbouring segments run in a compute shader (``gl_bounce``, ``shaders/bounce.comp``; the Numba kernel instead on a
software rasteriser, where it is the faster, or as ``bounce_on`` asks), and it is uploaded as a texture of the points
(``_bounce_texture``), which a fragment interpolates along its segment by rest arc length as
``yarn_bounce.bounce_at_points`` does; ``Features.hair_canopy``, the fraction of each directional light that other
yarns' hair layers let through, likewise (``pipeline.canopy_at_vertices`` on the CPU, one texture of the points per
frame, ``_canopy_texture``), read by both passes where they take a light's visibility. What depends on the frame's
curves and the lights alone, the canopy and the lights' visibility at the bounce's points (with the atlas's
read-back, which waits for the GPU to draw it), is kept while they stay: a viewer's orbit about a still frame
computes neither again.

The flyaway layers (``Features.flyaways``): pass 2b draws the flyaway strips (half-width of the pack's flyaway textures)
once per layer of ``render.hair_layers`` K, each fragment with its depth less the largest yarn radius; its sample mask
keeps the samples where no regular strip is nearer than that radius (the regular pass's depth, a multisampled depth
texture) and, from the second layer on, where it lies beyond the previous layer's flyaway strip in the order (depth,
curve) (a target that layer wrote: depth peeling, strips at one depth in successive layers), and the depth test keeps
the nearest such strip of each sample: the K nearest flyaway strips of a sample, as ``strip_raster.rasterize_before``
finds them (until knit's stop 73 this backend drew K = 1, its patches 2.5–5 % darker than the CPU's default of three,
BENCHMARKS.md); ``shaders/flyaway.frag`` shades each as ``shade_flyaway`` does into two targets, A·L and A·(1 − τ),
whose resolves are composited over the regular image as the CPU's resolve does.
"""

from __future__ import annotations

import functools
import math
import time
from pathlib import Path

import numpy as np

from data_formats.errors import FormatError
from data_formats.scene import EnvironmentLight
from knitrun.render import pipeline
from knitrun.render.ablations import Features
from knitrun.render.camera import Camera, scene_camera
from knitrun.render.gl.gl_bounce import gpu_vertex_bounce
from knitrun.render.ms_lights import ms_cells
from knitrun.render.shadow_map import MAX_FILTER_TEXELS, MAX_TAPS, OWN_STRIP_MAX, ShadowMap
from knitrun.render.strip_raster import SAMPLE_PATTERNS, vertex_tangents
from knitrun.render.yarn_bounce import CONTACT_RADII, PHASE_PHI, PHASE_THETA, vertex_bounce
from knitrun.shading import fiber_bcsdf as fb

SHADERS = Path(__file__).with_name("shaders")
FRAGMENT_COMMON = ("shading.glsl", "shadow.glsl", "point.glsl", "yarn.glsl")  # what the shading passes share
MAX_LIGHTS = 8  # directional lights a scene may have on this backend
MAX_LOBES = 64  # SRBF lobes (the scene format's largest srbf_count)
NO_YARN = 3.0e38  # depth of a shadow-map texel no yarn covers
PCF_RADIUS = 1.5  # texels (shadow_map.shadow_visibility's default)
ATLAS_UNITS = (22, 23, 24, 25, 26, 27, 28, 29, 30)  # texture units of the light atlas, lobe atlas, cluster
# weights, flyaway variants, the axial parallax's polyline and curve bounds, the yarn-level bounce, the hair canopy at
# the polyline points and the lights' second yarn layer (Features.two_blockers; the peel's floors while it is drawn);
# not 31, moderngl's ``default_texture_unit``, where it binds each texture it creates or writes
POLYLINE_ROW = 1024  # polyline points per row of the parallax's texture (regular.frag)
PARALLAX_STEPS = 64  # segments the parallax walks at most each way (the CPU walks to the curve's end)
# (a yarn entry's own textures take units 0, 1, … in the order of ``_upload_look``)
PEEL_UNITS = (20, 21)  # the peeled passes' masks: the front strips' floors (regular.frag's ``behind`` pass); the
# regular depth and the previous flyaway layer's (depth, curve) (flyaway.frag)
VARIANT_OFFSET = 2  # column of period index 0 in the flyaway variant table (flyaway.frag)
NON_FINITE = "GL strip renderer produced a non-finite pixel (a bug: please report the scene)"


BOUNCE_ON = ("auto", "gpu", "cpu")  # where the yarn-level bounce's sums may run (``GLRenderer``)
SOFTWARE_RENDERERS = ("llvmpipe", "softpipe", "swiftshader", "software rasterizer")  # GL_RENDERER of a CPU driver


def software_renderer(name: str) -> bool:
    """Whether ``name`` (the context's GL_RENDERER) is a driver that runs the shaders on the CPU (Mesa's llvmpipe
    and softpipe, SwiftShader)."""
    return any(s in name.lower() for s in SOFTWARE_RENDERERS)


class GLUnavailable(FormatError):
    """No OpenGL 4.5 context could be made (no moderngl, no EGL, no GL driver): the message says which."""


_CONTEXT = []


def gl_context():
    """The process's headless moderngl context (EGL; OpenGL 4.5 core), made on first use. GLUnavailable (one line)
    when the libraries or the driver are missing."""
    if _CONTEXT:
        return _CONTEXT[0]
    try:
        import moderngl
    except ImportError as e:
        raise GLUnavailable(f"the GL backend needs the Python package moderngl ({e}): pip install -e .") from None
    try:
        ctx = moderngl.create_context(standalone=True, backend="egl", require=450)
    except Exception as e:  # moderngl raises plain Exceptions for a missing libEGL or driver
        reason = str(e).strip().splitlines()[0] if str(e).strip() else type(e).__name__
        raise GLUnavailable(f"no OpenGL 4.5 context through EGL ({reason}): install libegl1 and libgl1-mesa-dri "
                            f"(Debian/Ubuntu), or a GPU driver with EGL") from None
    _CONTEXT.append(ctx)
    return ctx


def _glsl_array(name, values):
    return f"const float {name}[{len(values)}] = float[{len(values)}](" + ", ".join(f"{v:.17g}" for v in values) + ");"


def gl_constants() -> str:
    """The GLSL constants the shaders share with the Python definitions they follow (one source of each number)."""
    from knitrun.render import strip_shading
    from knitrun.shading import dual_scattering, fiber_bcsdf, im_lookup

    lines = [
        f"const float LOBE_WINDOW = {fiber_bcsdf.LOBE_WINDOW!r};",
        f"const float WIDTH_FLOOR = {dual_scattering.WIDTH_FLOOR!r};",
        f"const float D_F = {dual_scattering.D_F!r};",
        f"const float D_B = {dual_scattering.D_B!r};",
        f"const float R_NEGLIGIBLE = {im_lookup.R_NEGLIGIBLE!r};",
        f"const float R_WINDOW = {im_lookup.R_WINDOW!r};",
        f"const int R_NODES = {im_lookup.R_NODES};",
        _glsl_array("R_X", im_lookup._R_GX), _glsl_array("R_W", im_lookup._R_GW),
        f"const float R_HERMITE_REACH = {im_lookup.R_HERMITE_REACH!r};",
        f"const int R_HERMITE_NODES = {im_lookup.R_HERMITE_NODES};",
        _glsl_array("RH_X", im_lookup._R_HX), _glsl_array("RH_W", im_lookup._R_HW),
        f"const int GL_NODES = {len(fiber_bcsdf._GL_X)};",
        _glsl_array("GL_X", fiber_bcsdf._GL_X), _glsl_array("GL_W", fiber_bcsdf._GL_W),
        f"const float MAX_TANGENT_SPREAD = {strip_shading.MAX_TANGENT_SPREAD!r};",
        f"const float DEGENERATE = {strip_shading.DEGENERATE!r};",
        f"const int HAIR_DEPTHS = {strip_shading.HAIR_DEPTHS};",
        f"const float MAX_FILTER_TEXELS = {MAX_FILTER_TEXELS!r};",
        f"const int MAX_TAPS = {MAX_TAPS};",
        f"const float NO_YARN = {NO_YARN!r};",
        f"const float PCF_RADIUS = {PCF_RADIUS!r};",
        f"const float PARALLAX_MAX_SIN = {pipeline.PARALLAX_MAX_SIN!r};",
        f"const int PARALLAX_PASSES = {pipeline.PARALLAX_PASSES};",
        f"const float PARALLAX_MIN_SLOPE = {pipeline.PARALLAX_MIN_SLOPE!r};",
        f"const float MIN_ALONG = {strip_shading.MIN_ALONG!r};",
        f"const float OWN_STRIP_MAX = {OWN_STRIP_MAX!r};",
        f"const int PARALLAX_STEPS = {PARALLAX_STEPS};",
        f"const int POLYLINE_ROW = {POLYLINE_ROW};",
        f"const int PHASE_THETA = {PHASE_THETA};",
        f"const int PHASE_PHI = {PHASE_PHI};",
        f"const float CONTACT_RADII = {CONTACT_RADII!r};",
        f"#define MAX_LIGHTS {MAX_LIGHTS}",
        f"#define MAX_LOBES {MAX_LOBES}",
    ]
    return "\n".join(lines) + "\n"


def _source(*names) -> str:
    return "#version 450 core\n" + gl_constants() + "\n".join((SHADERS / n).read_text() for n in names)


def _programs(ctx):
    """(regular-fiber, shadow-map, flyaway programs, the bounce's compute shader, the composite program), compiled
    once per context."""
    cache = getattr(ctx, "_knit_programs", None)
    if cache is None:
        vertex, geometry = _source("strip.vert"), _source("strip.geom")
        regular = ctx.program(vertex_shader=vertex, geometry_shader=geometry,
                              fragment_shader=_source(*FRAGMENT_COMMON, "regular.frag"))
        depth = ctx.program(vertex_shader=vertex, geometry_shader=geometry, fragment_shader=_source("depth.frag"))
        flyaway = ctx.program(vertex_shader=vertex, geometry_shader=geometry,
                              fragment_shader=_source(*FRAGMENT_COMMON, "flyaway.frag"))
        composite = ctx.program(vertex_shader=_source("composite.vert"), fragment_shader=_source("composite.frag"))
        cache = (regular, depth, flyaway, ctx.compute_shader(_source("bounce.comp")), composite)
        ctx._knit_programs = cache
    return cache


def release_targets(ctx):
    """Release the frame targets the renderers of ``ctx`` keep (``GLRenderer._target``: ~1 GB of GPU memory at
    1280 × 960 with the default layers); the next frame makes them again."""
    for obj in getattr(ctx, "_knit_targets", (None, {}))[1].values():
        obj.release()
    ctx._knit_targets = (None, {})


def _set(program, name, value):
    """Set a uniform if the compiler kept it (an unused uniform has no location); sequences fill a vector or an
    array of scalars."""
    if name not in program:
        return
    member = program[name]
    if member.array_length > 1:  # an array: rows of ``value``, padded with zeros to its length
        rows = np.asarray(value).reshape(-1, member.dimension)
        padded = np.zeros((member.array_length, member.dimension), rows.dtype)
        padded[:len(rows)] = rows
        member.value = [tuple(r) if member.dimension > 1 else r[0] for r in padded.tolist()]
    elif isinstance(value, (list, tuple, np.ndarray)):
        flat = np.asarray(value).ravel().tolist()
        member.value = tuple(flat) if len(flat) > 1 else flat[0]
    else:
        member.value = value


def _clear(ctx, target, value):
    """Clear one colour ``target`` (texture or renderbuffer) to ``value`` (4 floats), leaving the others bound."""
    fbo = ctx.framebuffer(color_attachments=[target])
    fbo.clear(*value)
    fbo.release()


def _texture2d(ctx, array):
    """A float32 2-D texture of an (H, W, C) or (H, W) array, texel (x = column, y = row)."""
    a = np.ascontiguousarray(array, np.float32)
    a = a[..., None] if a.ndim == 2 else a
    return ctx.texture((a.shape[1], a.shape[0]), a.shape[2], a.tobytes(), dtype="f4")


def _texture3d(ctx, array):
    """A float32 3-D texture of a (D, H, W, C) array, texel (x = W index, y = H index, z = D index); FormatError
    when a side exceeds the driver's limit (a texture that size would read as zeros)."""
    a = np.ascontiguousarray(array, np.float32)
    limit = int(ctx.info["GL_MAX_3D_TEXTURE_SIZE"])
    if max(a.shape[:3]) > limit:
        raise FormatError(f"a pack table of {a.shape[:3]} texels exceeds this GL driver's 3-D texture size {limit}")
    return ctx.texture3d((a.shape[2], a.shape[1], a.shape[0]), a.shape[3], a.tobytes(), dtype="f4")


def _polyline_textures(ctx, lines, tangent):
    """The frame's polylines for the axial parallax and the fiber bend (``regular.frag``): (points, curve bounds)
    textures. Point i at
    row i // POLYLINE_ROW, columns 3 (i mod POLYLINE_ROW) + 0, 1, 2: (x, y, z, rest arc length), (vertex tangent,
    0), (the yarn frame's normal N, 0); curve c at (c mod POLYLINE_ROW, c // POLYLINE_ROW): (its first point, its
    last point), exact as float32 below 2²⁴ points."""
    n, n_curves = len(lines.points), len(lines.offsets) - 1
    data = np.zeros((-(-n // POLYLINE_ROW) * POLYLINE_ROW, 3, 4), np.float32)
    data[:n, 0, :3], data[:n, 0, 3] = lines.points, lines.rest
    data[:n, 1, :3], data[:n, 2, :3] = tangent, lines.normal
    bounds = np.zeros((-(-n_curves // POLYLINE_ROW) * POLYLINE_ROW, 2), np.float32)
    bounds[:n_curves, 0], bounds[:n_curves, 1] = lines.offsets[:-1], lines.offsets[1:] - 1
    return (_texture2d(ctx, data.reshape(-1, 3 * POLYLINE_ROW, 4)),
            _texture2d(ctx, bounds.reshape(-1, POLYLINE_ROW, 2)))


def _mip_texture(ctx, mip, variant=0):
    """A 2-D texture whose GL mip levels are the levels of ``variant`` of a ``texture_sampling.MipStack``."""
    data, offset, rows, cols = mip
    levels = offset.shape[1]
    r0, c0 = int(rows[variant, 0]), int(cols[variant, 0])
    first = data[offset[variant, 0]:offset[variant, 0] + r0 * c0].reshape(r0, c0, -1)
    tex = ctx.texture((c0, r0), first.shape[2], np.ascontiguousarray(first, np.float32).tobytes(), dtype="f4")
    if levels > 1:
        tex.build_mipmaps(0, levels - 1)
    for level in range(1, levels):
        h, w = int(rows[variant, level]), int(cols[variant, level])
        if (w, h) != (max(1, c0 >> level), max(1, r0 >> level)):
            raise FormatError(f"texture level {level} is {h}×{w}: not the GL mip chain of a {r0}×{c0} level 0")
        block = data[offset[variant, level]:offset[variant, level] + h * w]
        tex.write(np.ascontiguousarray(block, np.float32).tobytes(), level=level)
    return tex, levels


def _light_camera(direction, lo, hi, radius_max, size):
    """The orthographic light camera of ``shadow_map.build_shadow_map`` and its sphere radius."""
    sphere = 0.5 * float(np.linalg.norm(hi - lo)) + radius_max
    if not sphere > 0:
        sphere = 1.0
    centre = 0.5 * (lo + hi)
    up = np.eye(3)[int(np.argmin(np.abs(direction)))]
    return Camera(centre + 2 * sphere * direction, centre, up, size, size, ortho_height=2 * sphere), sphere


class GLRenderer:
    """``pipeline.Renderer``'s interface on OpenGL: ``render(frame)`` → ``RenderResult``; ``frame_count``,
    ``warnings``, ``setup_timings`` as there (plus ``gl_setup``: context, shaders, textures). Arguments as
    ``pipeline.Renderer``, and ``ctx``: a moderngl context to draw with (default: the headless one of ``gl_context``;
    a window's, for the viewer). ``light_dir`` (L, 3), unit vectors toward the directional lights, may be changed
    between frames. ``bounce_on`` says where the yarn-level bounce's sums run: "gpu" (``gl_bounce``, a compute
    shader), "cpu" (the Numba kernel) or "auto" (the default): the GPU unless the context is a software rasteriser
    (``software_renderer``), on which the Numba kernel is the faster. FormatError (one line) for what this backend
    cannot draw, GLUnavailable without GL.

    The GL objects it makes (the yarn entries' textures, the sky's cluster weights, the kept frame's arrays) live
    until ``release()`` (or the end of a ``with`` block); the context's programs and frame targets stay with the
    context (``release_targets``)."""

    def __init__(self, scene, packs=None, features: Features = Features(), samples_per_segment: int = 4,
                 use_cache: bool = True, progress=None, ctx=None, bounce_on: str = "auto"):
        if bounce_on not in BOUNCE_ON:
            raise FormatError(f"bounce_on {bounce_on!r}: expected one of {', '.join(BOUNCE_ON)}")
        if not features.multiple_scattering:
            raise FormatError("the GL backend draws the full light transport; Features.multiple_scattering=False "
                              "(single scattering alone) is drawn by the CPU renderer")
        if not features.hair_light:
            raise FormatError("the GL backend draws the hairs' light; Features.hair_light=False (the split by the "
                              "surface seen first) is the CPU renderer's")
        lights = [light for light in scene.lights if not isinstance(light, EnvironmentLight)]
        if len(lights) > MAX_LIGHTS:
            raise FormatError(f"the scene has {len(lights)} directional lights; the GL backend draws at most "
                              f"{MAX_LIGHTS}")
        self.ctx = gl_context() if ctx is None else ctx
        self.cpu = pipeline.Renderer(scene, packs, features, samples_per_segment, use_cache, progress)
        start = time.perf_counter()
        self.scene, self.features = scene, features
        self.regular, self.depth, self.flyaway, self.bounce_program, self.composite = _programs(self.ctx)
        self.looks = [self._upload_look(k) for k in range(len(self.cpu.looks))]
        fit = self.cpu.fit
        if fit is not None and len(fit.sharpness) > MAX_LOBES:
            raise FormatError(f"{len(fit.sharpness)} SRBF lobes: the GL backend draws at most {MAX_LOBES}")
        self.lobe_dir = np.zeros((0, 3)) if fit is None else np.asarray(fit.directions, np.float64)
        self.lobe_lambda = np.zeros(0) if fit is None else np.asarray(fit.sharpness, np.float64)
        self.lobe_w = np.zeros((0, 3)) if fit is None else np.asarray(fit.weights, np.float64)
        self.ms_dir, self.ms_e, ms_weights = ms_cells(self.lobe_dir, self.lobe_lambda, self.lobe_w)
        self.cluster_weights = _texture2d(self.ctx, ms_weights if ms_weights.size else np.zeros((1, 1)))
        self.light_dir = np.array([light.unit_direction for light in lights], np.float64).reshape(-1, 3)
        self.light_e = np.array([light.irradiance for light in lights], np.float64).reshape(-1, 3)
        self.bounce = pipeline.bounce_drawn(features, self.cpu.looks, len(self.light_dir))
        software = software_renderer(self.ctx.info["GL_RENDERER"])
        self.bounce_on = ("cpu" if software else "gpu") if bounce_on == "auto" else bounce_on
        self.canopy = features.hair_canopy and features.flyaways and len(self.light_dir) > 0
        # what depends on the frame's curves and the lights alone, kept while they stay (``render``): a viewer's orbit
        # about a still frame reuses it. (frame, light directions) → {"canopy": the hair canopy at the polyline points,
        # "bounce_light": the lights' visibility at the bounce's points}
        self._light_side = (None, {})
        # what depends on the frame alone, kept while it stays: (frame, (its polylines, the segments' vertex arrays,
        # the polyline textures)); 45 ms of CPU work a frame on bench_render's 60K-point patch, which an orbit no
        # longer pays (BENCHMARKS.md stop 74)
        self._frame_side = (None, None)
        self.setup_timings = dict(self.cpu.setup_timings, gl_setup=time.perf_counter() - start)
        self.setup_facts = dict(self.cpu.setup_facts, gl_renderer=self.ctx.info["GL_RENDERER"],
                                layers=scene.render.layers, hair_layers=scene.render.hair_layers,
                                bounce_on=self.bounce_on)

    @property
    def frame_count(self):
        return self.cpu.frame_count

    def release(self):
        """Release the GL objects this renderer holds; it draws nothing after. Until stop 75 nothing did: a process
        that made renderers on one context (the tests, ``render``, ``bench_gl_agreement``) kept every renderer's
        textures until it exited."""
        self._release_frame_side()
        objects = {id(o): o for _, textures in self.looks for o in textures.values()}
        objects[id(self.cluster_weights)] = self.cluster_weights
        for obj in objects.values():
            obj.release()
        self.looks = None

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        self.release()

    @property
    def warnings(self):
        return self.cpu.warnings

    def _upload_look(self, k):
        """GL textures and uniforms of yarn entry k (``pipeline.Renderer``'s look with the ablation applied)."""
        ctx, look = self.ctx, self.cpu.looks[k]
        kernel_look, corr, _ = self.cpu.kernel_looks[k]
        im = self.cpu.im_tables[k]
        table = im.table
        na, nb, nc, nd = table.shape[:4]
        tangent, levels = _mip_texture(ctx, look.tangent)
        flyaway = [_mip_texture(ctx, look.flyaway, v) for v in range(3)] if look.flyaway is not None else None
        coverage, levels_c = _mip_texture(ctx, look.coverage)
        detail, detail_levels = _mip_texture(ctx, look.detail)
        if levels_c != levels:
            raise FormatError(f"yarn {look.name}: tangent and coverage textures have {levels} and {levels_c} levels")

        def full(tab):
            return (_texture3d(ctx, tab), 1) if tab.shape[0] > 0 else (_texture3d(ctx, np.zeros((1, 1, 1, 3))), 0)

        def view_rows(tab):  # a view-closed table (N_v, N_θ, N_θ, N_φ, 3) as texel (φ, θ_i·N_θ + θ_o, v)
            return tab.reshape(tab.shape[0], tab.shape[1] * tab.shape[2], tab.shape[3], 3)

        xi_full, use_xi = full(corr.xi_full)
        view, single_view = corr.xi_view, corr.xi_single_view
        xi_view, use_view = full(view_rows(view))
        psi_full, use_psi = full(corr.psi_full)
        # ξ of single scattering (Features.split_xi; shading.glsl xi_single_kind): view-closed (2), a full table (1)
        # or none (0)
        if single_view.shape[0] > 0:
            xi_single, single_kind = full(view_rows(single_view))[0], 2
        else:
            xi_single, single_kind = full(corr.xi_single)
        p = kernel_look.params
        albedo = (look.yarn_albedo or 0.0) if self.features.interreflection else 0.0
        uniforms = {
            "p_a_r": p[fb.P_A_R:fb.P_A_R + 3], "p_a_tt": p[fb.P_A_TT:fb.P_A_TT + 3],
            "p_a_d": p[fb.P_A_D:fb.P_A_D + 3], "p_beta_r": float(p[fb.P_BETA_R]), "p_beta_tt": float(p[fb.P_BETA_TT]),
            "p_gamma_tt": float(p[fb.P_GAMMA_TT]), "p_alpha_r": float(p[fb.P_ALPHA_R]),
            "p_alpha_tt": float(p[fb.P_ALPHA_TT]),
            "period": float(kernel_look.period), "radius": float(kernel_look.radius),
            "strip_half_width": float(kernel_look.radius),
            "n_occluded": float(kernel_look.n_occluded), "n_cross": float(kernel_look.n_cross),
            "n_cross_rest": float(kernel_look.n_cross_rest), "gap": float(kernel_look.gap),
            "twist_sign": float(look.twist_sign), "yarn_albedo": float(albedo),
            "yarn_albedo_rgb": np.reshape(look.hull_albedo, 3).astype(float) if albedo > 0.0 else np.zeros(3),
            "shadow_bias": float(pipeline.SHADOW_BIAS_RADII * look.radius), "texture_levels": int(levels),
            "detail_levels": int(detail_levels),
            "use_xi_full": use_xi, "use_psi_full": use_psi, "use_xi_view": use_view,
            "surface_shadows": int(self.features.surface_shadows), "parallax": int(self.features.parallax),
            "fiber_bend": int(self.features.fiber_bend),
            "xi_view_n_theta": int(view.shape[2]), "xi_single_kind": single_kind,
            "xi_single_n_theta": int(single_view.shape[2]),
            "im_lo": im.lo, "im_hi": im.hi, "im_repeat": [int(r) for r in im.repeat],
            "im_size": [na, nb, nc, nd], "im_code": [int(c) for c in im.codes],
        }
        textures = {
            "ds_table": _texture2d(ctx, kernel_look.ds.reshape(5, -1, 3)),
            "xi_view": xi_view, "xi_full": xi_full, "xi_single": xi_single,
            "xi_m": _texture2d(ctx, corr.xi_m), "xi_n": _texture2d(ctx, corr.xi_n),
            "psi_full": psi_full, "psi_gm": _texture2d(ctx, corr.psi_gm), "psi_gn": _texture2d(ctx, corr.psi_gn),
            "im_table": _texture3d(ctx, table.reshape(na, nb * nc, nd, 3)),
            "tangent_tex": tangent, "coverage_tex": coverage, "detail_tex": detail,
        }
        if flyaway is not None:  # the three variants
            uniforms.update(flyaway_half_width=float(kernel_look.flyaway_half_width), fly_levels=flyaway[0][1])
            glow = pipeline.hair_glow(look) if pipeline.glow_on(self.features) else None
            uniforms.update(use_glow=int(glow is not None), glow_back=np.zeros(3) if glow is None else glow[0],
                            glow_forward=np.zeros(3) if glow is None else glow[1])
            uniforms.update(hairs_behind=int(self.features.hairs_behind))
            textures.update({f"fly_tex{v}": tex for v, (tex, _) in enumerate(flyaway)})
        assert len(textures) <= PEEL_UNITS[0], "a yarn entry's textures would share units with the atlases"
        return uniforms, textures

    # --- per frame --------------------------------------------------------------------------------------------------

    def render(self, frame: int | None = None, progress=None, camera: Camera | None = None, into=None,
               exposure: float = 0.0) -> pipeline.RenderResult:
        """Draw ``frame`` (default: the scene's ``render.frame``) through ``camera`` (default: the scene's; the
        viewer's orbit); timings per pass, as the CPU renderer's. With ``into`` (a moderngl framebuffer of the
        camera's size: the viewer's window) the frame is drawn there tone-mapped at ``exposure`` stops (``_display``)
        and not read back: the result's image is None."""
        if self.looks is None:
            raise RuntimeError("this GLRenderer was released (GLRenderer.release): make another to draw")
        scene, ctx = self.scene, self.ctx
        frame = self.cpu.frame_index(frame)
        timings, facts = {}, {"warnings": list(self.warnings), **self.setup_facts, "frame": frame}
        clock = [time.perf_counter()]

        def lap(name):
            ctx.finish()
            now = time.perf_counter()
            timings[name] = now - clock[0]
            if progress is not None:
                progress(name, now - clock[0])
            clock[0] = now

        if self._frame_side[0] != frame:
            self._release_frame_side()
            self._frame_side = (frame, self._frame_geometry(frame))
        lines, draws, polyline = self._frame_side[1]
        facts.update(curves=int(len(lines.entry)), points=int(len(lines.points)))
        camera = scene_camera(scene) if camera is None else camera
        w, h = camera.width, camera.height
        background = np.asarray(scene.background, np.float64)
        if len(lines.entry) == 0:
            lap("load")
            image = np.broadcast_to(background.astype(np.float32), (h, w, 3)).copy()
            if into is not None:
                self._display_array(image, into, exposure)
                image = None
            return pipeline.RenderResult(image, timings, facts)
        # the hair canopy at the polyline points, per light (pipeline.canopy_at_vertices); ones without it. It
        # depends on the frame's curves and the lights alone, so a viewer's orbit about a still frame reuses it
        # (83 ms a light on bench_render's 60K-point patch, BENCHMARKS.md stop 72)
        key = (frame, self.light_dir.tobytes())
        if self._light_side[0] != key:
            self._light_side = (key, {})
        kept = self._light_side[1]
        if not self.canopy:
            canopy = np.ones((len(self.light_dir), len(lines.points)))
        elif "canopy" in kept:
            canopy = kept["canopy"]
        else:
            canopy = kept["canopy"] = np.array([pipeline.canopy_at_vertices(lines, self.cpu.looks, d)
                                                for d in self.light_dir])
        canopy_tex = self._canopy_texture(lines, canopy) if self.canopy else ()
        lap("load")

        radius = np.array([self.cpu.looks[k].radius for k in lines.entry])
        lo, hi = lines.points.min(axis=0), lines.points.max(axis=0)
        size = scene.render.shadow_map_size
        # with two_blockers the lights' atlas has a second yarn layer (shadow_map's ``behind``)
        light_maps, light_atlas, *behind_atlas = self._shadow_atlas(
            draws, self.light_dir, size, np.zeros(len(self.light_dir)), lo, hi, radius.max(), lines.points,
            layers=2 if self.features.two_blockers else 1)
        if self.bounce and "bounce_light" not in kept:  # the read-back waits for the atlas: once per frame and lights
            maps = self._read_light_maps([light_atlas, *behind_atlas], light_maps)
            kept["bounce_light"] = self._bounce_light(lines, canopy, maps)
        bounce = self._bounce_texture(lines, camera, facts, *kept["bounce_light"]) if self.bounce else ()
        lobe_size = max(64, size // pipeline.LOBE_SHADOW_DIVISOR)
        angular = np.minimum(1.0 / np.sqrt(np.maximum(self.lobe_lambda, 1e-300)), pipeline.MAX_LOBE_ANGULAR_RADIUS)
        lobe_maps, lobe_atlas = self._shadow_atlas(draws, self.lobe_dir, lobe_size, angular, lo, hi, radius.max(),
                                                   lines.points)
        facts["ms_lights"] = int(len(self.ms_dir))
        lap("shadow")

        samples = min(scene.render.msaa, ctx.max_samples)
        if samples != scene.render.msaa:
            facts["warnings"].append(f"msaa {scene.render.msaa} is more than this GL driver's {ctx.max_samples} "
                                     f"samples: drawn with {samples}")
        def target(name, make):
            return self._target((w, h, samples), name, make)

        colour = target("colour", lambda: ctx.renderbuffer((w, h), 4, samples=samples, dtype="f4"))  # (α L, α)
        # (coverage, peel floor): the layer behind's mask
        front = target("front", lambda: ctx.texture((w, h), 4, samples=samples, dtype="f4"))
        # a texture: the flyaway layers' masks read it
        depth = target("depth", lambda: ctx.depth_texture((w, h), samples=samples))
        fbo = target("fbo", lambda: ctx.framebuffer(color_attachments=[colour, front], depth_attachment=depth))
        fbo.use()
        ctx.viewport = (0, 0, w, h)
        fbo.clear(0.0, 0.0, 0.0, 0.0, depth=1.0)
        _clear(ctx, front, (0.0, NO_YARN, 0.0, 0.0))  # no strip: no floor, nothing behind
        fbo.use()
        ctx.enable(ctx.DEPTH_TEST)
        near, far = self._depth_range(camera, lo, hi, radius.max())
        light_atlas.use(location=ATLAS_UNITS[0])
        lobe_atlas.use(location=ATLAS_UNITS[1])
        for tex in behind_atlas:
            tex.use(location=ATLAS_UNITS[8])
        self.cluster_weights.use(location=ATLAS_UNITS[2])
        for name, tex, unit in zip(("polyline", "curve_bounds"), polyline, ATLAS_UNITS[4:]):
            tex.use(location=unit)
            _set(self.regular, name, unit)
        _set(self.regular, "yarn_bounce", int(self.bounce))
        for tex in bounce[:1]:
            tex.use(location=ATLAS_UNITS[6])
            _set(self.regular, "bounce_tex", ATLAS_UNITS[6])
        fly_entries = [d for d in draws if "fly_tex0" in self.looks[d[0]][1]]
        for program in (self.regular, self.flyaway) if fly_entries else (self.regular,):
            _set(program, "hair_canopy", int(self.canopy))
            for tex in canopy_tex:
                tex.use(location=ATLAS_UNITS[7])
                _set(program, "canopy_tex", ATLAS_UNITS[7])
                _set(program, "canopy_rows", -(-len(lines.points) // POLYLINE_ROW))
            self._camera_uniforms(program, camera, near, far)
            _set(program, "image_height", int(h))
            _set(program, "samples", int(samples))
            _set(program, "sample_pattern", SAMPLE_PATTERNS[samples])
            self._light_uniforms(program, light_maps, lobe_maps)
            for name, unit in zip(("light_atlas", "lobe_atlas", "cluster_weights"), ATLAS_UNITS):
                _set(program, name, unit)
            _set(program, "two_blockers", int(self.features.two_blockers))
            _set(program, "behind_atlas", ATLAS_UNITS[8])
        _set(self.regular, "behind", 0)
        _set(self.regular, "front_floor", PEEL_UNITS[0])  # a unit of its own: samplers of two types may not share one
        for k, vao, count in draws:
            self._look_uniforms(self.regular, k)
            vao[0].render(ctx.LINES_ADJACENCY, vertices=count)
        behind = None  # with render.layers = 2: the strips behind the front ones (SHADING.md §6), (α L, α)
        if scene.render.layers == 2:
            behind = target("behind", lambda: ctx.renderbuffer((w, h), 4, samples=samples, dtype="f4"))
            behind_depth = target("behind_depth", lambda: ctx.depth_renderbuffer((w, h), samples=samples))
            behind_fbo = target("behind_fbo", lambda: ctx.framebuffer(color_attachments=[behind],
                                                                      depth_attachment=behind_depth))
            behind_fbo.use()
            behind_fbo.clear(0.0, 0.0, 0.0, 0.0, depth=1.0)
            front.use(location=PEEL_UNITS[0])
            _set(self.regular, "behind", 1)
            for k, vao, count in draws:
                self._look_uniforms(self.regular, k)
                vao[0].render(ctx.LINES_ADJACENCY, vertices=count)
        layers = []  # per flyaway layer, nearest first: its two targets
        if fly_entries:  # the flyaway layers over the regular one, peeled (the module docstring)
            _set(self.flyaway, "depth_tolerance", float(radius.max()))
            _set(self.flyaway, "regular_depth", PEEL_UNITS[0])
            _set(self.flyaway, "previous_layer", PEEL_UNITS[1])
            variants = self._variant_table(lines)
            variants.use(location=ATLAS_UNITS[3])
            _set(self.flyaway, "fly_variant", ATLAS_UNITS[3])
            _set(self.flyaway, "yarn_bounce", int(self.bounce and self.features.hair_bounce))
            for tex in bounce[1:]:  # the neighbours' light on the hairs (Features.hair_bounce)
                tex.use(location=ATLAS_UNITS[6])
                _set(self.flyaway, "bounce_tex", ATLAS_UNITS[6])
            # the previous layer's (depth, curve); the first reads none, but its unit must not hold the target it
            # draws into (a feedback loop): the front strips' texture stands in
            previous = front
            for layer in range(scene.render.hair_layers):
                targets = [target(f"fly{layer}_{i}", lambda: ctx.renderbuffer((w, h), 4, samples=samples, dtype="f4"))
                           for i in range(2)]
                # out_peel: (depth, curve)
                peeled = target(f"fly{layer}_peel", lambda: ctx.texture((w, h), 2, samples=samples, dtype="f4"))
                fly_depth = target(f"fly{layer}_depth", lambda: ctx.depth_renderbuffer((w, h), samples=samples))
                fly_fbo = target(f"fly{layer}_fbo", lambda: ctx.framebuffer(color_attachments=[*targets, peeled],
                                                                            depth_attachment=fly_depth))
                fly_fbo.use()
                fly_fbo.clear(0.0, 0.0, 0.0, 0.0, depth=1.0)
                _clear(ctx, peeled, (2.0, -1.0, 0.0, 0.0))  # no strip: nothing lies beyond it
                fly_fbo.use()
                depth.use(location=PEEL_UNITS[0])
                previous.use(location=PEEL_UNITS[1])
                _set(self.flyaway, "peel", int(layer > 0))
                for k, vao, count in fly_entries:
                    self._look_uniforms(self.flyaway, k)
                    _set(self.flyaway, "strip_half_width", self.looks[k][0]["flyaway_half_width"])
                    vao[3].render(ctx.LINES_ADJACENCY, vertices=count)
                layers.append(targets)
                previous = peeled
            variants.release()
        lap("shade")

        image = self._composite(colour, front, behind, layers, background, target, into, exposure)
        for obj in (light_atlas, *behind_atlas, lobe_atlas, *bounce, *canopy_tex):
            obj.release()
        if image is not None and not np.all(np.isfinite(image)):
            raise RuntimeError(NON_FINITE)
        lap("resolve")
        facts["residuals"] = {look.name: look.residuals for look in self.cpu.looks}
        return pipeline.RenderResult(image, timings, facts)

    def _read_light_maps(self, atlases, light_maps) -> list:
        """The lights' shadow maps as the CPU's ``shadow_map.ShadowMap`` (+inf where no yarn), read back from the light
        atlas drawn this frame (and its second yarn layer, ``atlases[1]``, with ``two_blockers``), each from its tile
        and light camera as ``light_maps`` (``_map_description``) gives them to ``shadow.glsl``: the yarn-level bounce
        looks the lights up on the CPU, in the maps the GPU drew, instead of drawing them again (``_bounce_texture``).
        GL's rows run upward and the descriptions' up is negated for it, so the tiles are used as read."""
        layers = []
        for atlas in atlases:
            layer = np.empty(atlas.size[::-1], np.float32)
            atlas.read_into(layer)
            np.putmask(layer, layer >= NO_YARN, np.inf)
            layers.append(layer)
        maps = []
        for m in light_maps:
            (x, y), size = m["tile"], m["size"]
            tiles = [layer[y:y + size, x:x + size] for layer in layers]
            maps.append(ShadowMap(np.stack([m["right"], m["up"], m["fwd"]]), m["origin"], m["texel"] * size, size,
                                  tiles[0], tiles[1] if len(tiles) > 1 else None))
        return maps

    def _bounce_light(self, lines, canopy, light_maps) -> tuple:
        """(the bounce's points ``at`` (``pipeline.bounce_vertices``), the lights' visibility there (L, len(at)) and
        the fraction at most one yarn blocks (L, len(at)), ``pipeline.Lights.beyond``): looked up in ``light_maps``,
        this frame's read back by ``_read_light_maps``, times the hair canopy ``canopy`` (L, P) at the points. It
        depends on the frame's curves and the lights alone (``render`` keeps it while they stay)."""
        at = pipeline.bounce_vertices(lines, self.cpu.looks)
        receivers = [pipeline.axis_receivers(lines, self.cpu.looks, at)]
        two = self.features.two_blockers
        found = [pipeline.map_visibility(sm, d, 0.0, receivers, two)[0] for sm, d in zip(light_maps, self.light_dir)]
        # with two blockers (V, V₂) per light, the canopy on V alone (pipeline.Renderer)
        vis = np.array([f[0] if two else f for f in found]).reshape(len(found), -1) * canopy[:, at]
        beyond = np.array([f[1] for f in found]).reshape(vis.shape) if two else np.ones_like(vis)
        return at, vis, beyond

    def _bounce_texture(self, lines, camera, facts, at, vis, beyond):
        """The yarn-level bounce at the frame's polyline points (``pipeline.frame_bounce`` from the lights' visibility
        ``vis`` and ``beyond`` at its points ``at``, ``_bounce_light``; the sums where ``bounce_on`` says) as
        textures of the points, point i at (i mod POLYLINE_ROW, i // POLYLINE_ROW): (bounce RGB, rest arc length)
        for ``regular.frag``, then (the neighbours' light arriving, rest arc length) for ``flyaway.frag``."""
        cpu = self.cpu
        solve = vertex_bounce if self.bounce_on == "cpu" else functools.partial(gpu_vertex_bounce, self.bounce_program)
        vertex, covered, arriving = pipeline.frame_bounce(lines, cpu.looks, camera, self.light_dir, self.light_e, at,
                                                          vis, beyond, solve)
        facts["yarn_bounce"] = pipeline.bounce_facts(vertex, covered)
        n = len(lines.points)
        textures = []
        for values in (vertex, arriving):
            data = np.zeros((-(-n // POLYLINE_ROW) * POLYLINE_ROW, 4), np.float32)
            data[:n, :3], data[:n, 3] = values, lines.rest
            textures.append(_texture2d(self.ctx, data.reshape(-1, POLYLINE_ROW, 4)))
        return tuple(textures)

    def _canopy_texture(self, lines, canopy):
        """The hair canopy ``canopy`` (L, P) at the frame's polyline points as a one-texture tuple for both passes:
        light l's point i at (i mod POLYLINE_ROW, l · rows + i // POLYLINE_ROW), (transmittance, rest arc length),
        rows = ⌈P / POLYLINE_ROW⌉."""
        n = len(lines.points)
        data = np.zeros((len(canopy), -(-n // POLYLINE_ROW) * POLYLINE_ROW, 2), np.float32)
        data[:, :n, 0], data[:, :n, 1] = canopy, lines.rest
        return (_texture2d(self.ctx, data.reshape(-1, POLYLINE_ROW, 2)),)

    def _frame_geometry(self, frame):
        """(polylines, ``_upload_segments``' draws, ``_polyline_textures`` or ()) of ``frame``: what ``render`` keeps
        while the frame stays (no draws or textures for a frame without yarns)."""
        lines = pipeline._polylines(self.scene, self.cpu.curves, frame, self.cpu.samples_per_segment)
        if len(lines.entry) == 0:
            return lines, [], ()
        tangent = vertex_tangents(lines.points, lines.offsets)
        polyline = _polyline_textures(self.ctx, lines, tangent) \
            if self.features.parallax or self.features.fiber_bend else ()
        return lines, self._upload_segments(lines, tangent), polyline

    def _release_frame_side(self):
        """Release the kept frame's vertex arrays, buffers and textures (``_frame_side``)."""
        if self._frame_side[1] is not None:
            _, draws, polyline = self._frame_side[1]
            for obj in (*polyline, *[o for _, arrays, _ in draws for o in arrays]):
                obj.release()
        self._frame_side = (None, None)

    def _upload_segments(self, lines, tangent):
        """One vertex array of segments with their neighbours (GL_LINES_ADJACENCY: previous point, the segment's two,
        next point; an end repeats its own) per yarn entry: [(entry, (vao, vbo, depth vao, flyaway vao), vertices)];
        ``tangent`` the points' vertex tangents (``vertex_tangents``)."""
        draws = []
        for k in np.unique(lines.entry):
            index = []
            for c in np.flatnonzero(lines.entry == k):
                first, last = lines.offsets[c], lines.offsets[c + 1] - 1
                a = np.arange(first, last)
                index.append(np.stack([np.maximum(a - 1, first), a, a + 1, np.minimum(a + 2, last)], axis=1).ravel())
            index = np.concatenate(index) if index else np.zeros(0, np.int64)
            curve_of = np.repeat(np.arange(len(lines.entry)), np.diff(lines.offsets))[index]
            record = np.zeros(len(index), dtype=[("p", "f4", 3), ("t", "f4", 3), ("s", "f4"), ("n", "f4", 3),
                                                 ("c", "i4"), ("i", "i4")])
            record["p"], record["t"], record["s"] = lines.points[index], tangent[index], lines.rest[index]
            record["n"], record["c"], record["i"] = lines.normal[index], curve_of, index
            vbo = self.ctx.buffer(record.tobytes())
            layout = [(vbo, "3f 3f 1f 3f 1i 1i", "in_position", "in_tangent", "in_arclength", "in_normal", "in_curve",
                       "in_index")]
            vao, depth_vao, fly_vao = (self.ctx.vertex_array(program, layout, skip_errors=True)
                                       for program in (self.regular, self.depth, self.flyaway))
            draws.append((int(k), (vao, vbo, depth_vao, fly_vao), len(index)))
        return draws

    def _look_uniforms(self, program, k):
        """Yarn entry k's uniforms and textures (``_upload_look``) on ``program``."""
        uniforms, textures = self.looks[k]
        for name, value in uniforms.items():
            _set(program, name, value)
        for unit, (name, tex) in enumerate(textures.items()):
            tex.use(location=unit)
            _set(program, name, unit)

    def _variant_table(self, lines):
        """The flyaway variant of every (period index, curve) a frame can show (``strip_shading.variant_of``, one
        definition for both renderers), as an 8-bit integer texture: column p + VARIANT_OFFSET, row = curve; the view
        phase moves u by less than a period, so indices from −2 cover every point."""
        from knitrun.render.strip_shading import variant_of

        periods = [float(self.cpu.looks[k].period) for k in lines.entry]
        lengths = [float(lines.rest[lines.offsets[c + 1] - 1]) for c in range(len(lines.entry))]
        width = max(int(math.floor(length / period)) for length, period in zip(lengths, periods)) + VARIANT_OFFSET + 3
        table = np.array([[variant_of(c, p - VARIANT_OFFSET) for p in range(width)] for c in range(len(lines.entry))],
                         np.uint8)
        return self.ctx.texture((width, len(lines.entry)), 1, table.tobytes(), dtype="u1")

    def _composite(self, colour, front, behind, layers, background, target, into=None, exposure=0.0):
        """The frame (h, w, 3) float32, row 0 at the top, by SHADING.md §6 from the multisampled targets: ``colour``
        (Σ w α L, s1 = Σ w α of the front strips), ``front`` (their coverage c1 in .r), ``behind`` (the strips behind
        them, (Σ_back w α L, Σ_back w α); None with one layer) and ``layers`` (per flyaway layer, nearest first, its
        (Σ w A L, Σ w A (1 − τ)) targets). Each target is resolved on the GPU and ``composite.frag`` composes them,
        the farthest flyaway layer first; one image is read back, or with ``into`` none: the frame is drawn there
        tone-mapped (``_display``) and None returned. ``target(name, make)``: the frame's kept targets
        (``_target``)."""
        ctx, program = self.ctx, self.composite
        (w, h), resolved = colour.size, []

        def resolve(source):
            tex = target(f"resolved{len(resolved)}", lambda: ctx.texture((w, h), 4, dtype="f4"))
            read, write = ctx.framebuffer(color_attachments=[source]), ctx.framebuffer(color_attachments=[tex])
            ctx.copy_framebuffer(write, read)
            read.release()
            write.release()
            resolved.append(tex)
            return tex

        flat = [resolve(colour), resolve(front)]
        flat.append(flat[1] if behind is None else resolve(behind))  # without it has_behind = 0: any texture serves
        for unit, (name, tex) in enumerate(zip(("regular", "front", "behind"), flat)):
            tex.use(location=unit)
            _set(program, name, unit)
        images = [target(f"image{i}", lambda: ctx.texture((w, h), 4, dtype="f4")) for i in range(2 if layers else 1)]
        fbos = [target(f"image{i}_fbo", lambda: ctx.framebuffer(color_attachments=[image]))
                for i, image in enumerate(images)]
        vao = ctx.vertex_array(program, [])
        ctx.disable(ctx.DEPTH_TEST)
        _set(program, "background", background)
        _set(program, "has_behind", int(behind is not None))
        _set(program, "stage", 0)
        fbos[0].use()
        vao.render(ctx.TRIANGLES, vertices=3)
        _set(program, "stage", 1)
        for name, unit in (("fly_radiance", 3), ("fly_cover", 4), ("previous", 5)):
            _set(program, name, unit)
        current = 0
        for targets in layers[::-1]:  # the K-th nearest first (SHADING.md §6)
            resolve(targets[0]).use(location=3)
            resolve(targets[1]).use(location=4)
            images[current].use(location=5)
            fbos[1 - current].use()
            vao.render(ctx.TRIANGLES, vertices=3)
            current = 1 - current
        if into is None:
            pixels = np.frombuffer(fbos[current].read(components=4, dtype="f4"), np.float32).reshape(h, w, 4)
            image = np.ascontiguousarray(pixels[::-1, :, :3])
        else:
            self._display(images[current], into, exposure)
            image = None
        ctx.enable(ctx.DEPTH_TEST)
        vao.release()
        return image

    def _target(self, size, name, make):
        """The frame target ``name`` for ``size`` = (w, h, samples), made by ``make()`` the first time and kept for the
        next frames of that size (every pass clears or overwrites what it draws into): making the multisampled
        buffers, their resolves and the composite's images anew took 0.29 s of a 1280 × 960 frame on llvmpipe
        (BENCHMARKS.md stop 74), and a GPU driver would allocate and free some hundred MB a frame. They are kept on
        the context, as the programs are (``_programs``): the renderers of one context draw one at a time (the
        viewer's, one per ablation), and each would otherwise hold its own ~1 GB at 1280 × 960. Another size releases
        them all."""
        kept_size, kept = getattr(self.ctx, "_knit_targets", (None, {}))
        if kept_size != size:
            release_targets(self.ctx)
            kept = {}
            self.ctx._knit_targets = (size, kept)
        if name not in kept:
            kept[name] = make()
        return kept[name]

    def _display(self, image, into, exposure):
        """Draw the linear frame ``image`` (a float texture, GL's rows upward) into the framebuffer ``into`` as
        ``data_formats.images.tonemap`` writes it (``composite.frag``'s stage 2; the 8-bit target rounds, within one
        level of NumPy's): what the viewer shows without reading the frame back, tone-mapping it on the CPU and
        uploading it again (152 ms a 1280 × 960 frame on llvmpipe, BENCHMARKS.md stop 74). A non-finite pixel raises
        RuntimeError, as ``render``'s read-back does (a four-byte flag the shader sets is read back)."""
        ctx, program = self.ctx, self.composite
        flag = ctx.buffer(np.zeros(1, np.uint32).tobytes())
        flag.bind_to_storage_buffer(0)
        vao = ctx.vertex_array(program, [])
        ctx.disable(ctx.DEPTH_TEST)
        image.use(location=5)
        _set(program, "previous", 5)
        _set(program, "stage", 2)
        _set(program, "exposure_scale", 2.0 ** float(exposure))
        into.use()
        ctx.viewport = (0, 0, *image.size)
        vao.render(ctx.TRIANGLES, vertices=3)
        ctx.memory_barrier()  # the shader's write to the flag, before the read-back of it
        bad = int(np.frombuffer(flag.read(), np.uint32)[0])
        vao.release()
        flag.release()
        if bad:
            raise RuntimeError(NON_FINITE)

    def _display_array(self, image, into, exposure):
        """``_display`` of an (h, w, 3) float32 frame, row 0 at the top (a frame with no yarn: the background)."""
        h, w = image.shape[:2]
        rgba = np.concatenate([image[::-1], np.ones((h, w, 1), np.float32)], axis=2)
        tex = self.ctx.texture((w, h), 4, np.ascontiguousarray(rgba).tobytes(), dtype="f4")
        self._display(tex, into, exposure)
        tex.release()

    @staticmethod
    def _depth_range(camera, lo, hi, radius_max):
        """(near, far) view depths that hold every yarn: the CPU's near (1e-3) and the farthest corner of the box."""
        corners = np.array([[x, y, z] for x in (lo[0], hi[0]) for y in (lo[1], hi[1]) for z in (lo[2], hi[2])])
        far = float(np.max(np.linalg.norm(corners - np.asarray(camera.position, float), axis=1))) + 2 * radius_max
        return 1e-3, max(far * 1.01, 2e-3)

    @staticmethod
    def _camera_uniforms(program, camera, near, far):
        fwd, right, up = camera.basis()
        for name, value in (("cam_position", np.asarray(camera.position, float)), ("cam_right", right),
                            ("cam_up", up), ("cam_fwd", fwd), ("ortho_height", float(camera.ortho_height)),
                            ("tan_half", math.tan(math.radians(camera.fov_deg) / 2)),
                            ("aspect", camera.width / camera.height), ("near_plane", near), ("far_plane", far)):
            _set(program, name, value)

    def _shadow_atlas(self, draws, directions, size, angular, lo, hi, radius_max, points, layers=1):
        """Render one shadow map per direction into the tiles of an atlas; returns (map descriptions, texture) and,
        with ``layers`` = 2, the atlas of the second yarn layer as a third value (``depth.frag``'s peel: shadow_map's
        ``behind``)."""
        ctx = self.ctx
        n = len(directions)
        grid = max(1, math.ceil(math.sqrt(n)))
        side = grid * size
        if side > ctx.info["GL_MAX_TEXTURE_SIZE"]:
            raise FormatError(f"{n} shadow maps of {size}² texels need a {side}² atlas, more than this GL driver's "
                              f"{ctx.info['GL_MAX_TEXTURE_SIZE']}: lower render.shadow_map_size")
        atlases = [ctx.texture((side, side) if n else (1, 1), 1, dtype="f4") for _ in range(layers)]
        maps = []
        if n == 0:
            for atlas in atlases:
                atlas.write(np.full(1, NO_YARN, np.float32).tobytes())
            return (maps, *atlases)
        floors = ctx.texture((side, side), 1, dtype="f4") if layers == 2 else None
        depth = ctx.depth_renderbuffer((side, side))
        program = self.depth
        for layer, atlas in enumerate(atlases):
            # the first layer (with its peel floors where a second follows), then the second peeled against them
            peel_floors = [floors] if layer == 0 and floors is not None else []
            fbo = ctx.framebuffer(color_attachments=[atlas] + peel_floors, depth_attachment=depth)
            fbo.use()
            ctx.viewport = (0, 0, side, side)
            fbo.clear(NO_YARN, NO_YARN, NO_YARN, NO_YARN, depth=1.0)
            ctx.enable(ctx.DEPTH_TEST)
            _set(program, "peel", layer)
            if layer:
                floors.use(location=ATLAS_UNITS[8])
                _set(program, "floor_atlas", ATLAS_UNITS[8])
            for i, d in enumerate(directions):
                cam, sphere = _light_camera(np.asarray(d, float), lo, hi, radius_max, size)
                gx, gy = i % grid, i // grid
                ctx.viewport = (gx * size, gy * size, size, size)
                self._camera_uniforms(program, cam, 0.5 * sphere, 3.5 * sphere)
                for k, vao, count in draws:
                    _set(program, "strip_half_width", float(self.cpu.looks[k].radius))
                    vao[2].render(ctx.LINES_ADJACENCY, vertices=count)
                if layer == 0:
                    maps.append(self._map_description(cam, sphere, points, angular[i], size, (gx * size, gy * size)))
            fbo.release()
        depth.release()
        if floors is not None:
            floors.release()
        return (maps, *atlases)

    @staticmethod
    def _map_description(cam, sphere, points, angular, size, tile):
        """shadow.glsl's ShadowMapInfo of the light camera ``cam`` (sphere radius ``sphere``) drawn into ``tile``."""
        fwd, right, up = cam.basis()
        d_min = float(np.min((points - cam.position) @ fwd))
        # GL's rows run upward, so texel row i of a tile is the map's row size − 1 − i (shadow_map.py counts rows
        # from the top): the map's up is given negated, and shadow.glsl's row from the top is GL's row
        return {"right": right, "up": -up, "fwd": fwd, "origin": np.asarray(cam.position, float),
                "texel": 2 * sphere / size, "d_min": d_min, "tan_angle": math.tan(float(angular)), "size": size,
                "tile": tile}

    def _light_uniforms(self, program, light_maps, lobe_maps):
        _set(program, "n_lights", len(self.light_dir))
        _set(program, "light_dir", self.light_dir)
        _set(program, "light_irradiance", self.light_e)
        for i, m in enumerate(light_maps):
            self._map_uniforms(program, f"light_map[{i}]", m)
        _set(program, "n_lobes", len(self.lobe_dir))
        _set(program, "lobe_dir", self.lobe_dir)
        _set(program, "lobe_lambda", self.lobe_lambda)
        _set(program, "lobe_weight", self.lobe_w)
        for j, m in enumerate(lobe_maps):
            self._map_uniforms(program, f"lobe_map[{j}]", m)
        _set(program, "n_clusters", len(self.ms_dir))
        _set(program, "cluster_dir", self.ms_dir)
        _set(program, "cluster_irradiance", self.ms_e)

    @staticmethod
    def _map_uniforms(program, prefix, m):
        for key in ("right", "up", "fwd", "origin"):
            _set(program, f"{prefix}.{key}", m[key])
        for key in ("texel", "d_min", "tan_angle"):
            _set(program, f"{prefix}.{key}", float(m[key]))
        _set(program, f"{prefix}.size", int(m["size"]))
        _set(program, f"{prefix}.tile", tuple(int(x) for x in m["tile"]))


def render(scene, packs=None, features: Features = Features(), samples_per_segment: int = 4, progress=None,
           use_cache: bool = True) -> pipeline.RenderResult:
    """One frame of ``scene`` on the GL backend (``pipeline.render``'s counterpart): timings include the set-up
    (``load``, ``srbf_fit``, ``gl_setup``)."""
    with GLRenderer(scene, packs, features, samples_per_segment, use_cache, progress) as renderer:
        result = renderer.render(progress=progress)
    setup = dict(renderer.setup_timings)
    setup["load"] = setup.get("load", 0.0) + result.timings.pop("load", 0.0)
    result.timings = {**setup, **result.timings}
    return result
