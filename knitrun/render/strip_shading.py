"""Shading of the strip renderer's multisampled G-buffer (Huang et al. 2025 §4.3–4.5, eqs. 8–11 and 17): the model
of ``data_formats/SHADING.md``, which the GL backend (``knitrun/render/gl/shaders``) implements too.

Shading points
--------------
MSAA shades once per primitive per pixel (as a GPU does): the covered samples of a pixel are grouped by the curve
that covers them, and each group is one shading point with the attributes of its first sample and the weight
(samples in the group)/k. ``shading_points`` builds them from the rasterizer's visibility buffer
(``strip_raster.StripVisibility``) and interpolates the G-buffer attributes at them alone, in pixel order (pixel p
owns the points start[p]:start[p+1], so the resolve runs in parallel over pixels without races); an optional
per-sample mask drops samples (the flyaway layer's depth test against the regular layer).

Regular fibers (``shade_regular``), per point, angles by ``ASSET_PACK.md`` §3
----------------------------------------------------------------------------
t the yarn tangent (G-buffer), ω_o toward the camera, n = normalize(ω_o − (ω_o·t)t), b = n × t, u = s/period,
v ∈ [−1, 1]. Textures (trilinear, mip level from the pixel footprint): coverage c(u, v) is the point's alpha;
the coverage-premultiplied tangent gives the shading fiber tangent t_f (t where it vanishes), its component along t
scaled by the point's fiber bend (``fiber_bend``). Per directional light
(toward ω_i, irradiance E, yarn-level visibility V from the shadow map):

    yarn angles   θ_i, θ_o against t;  θ_d = (θ_o − θ_i)/2;  φ = φ_o − φ_i = −atan2(ω_i·b, ω_i·n)
    ξ           = ξ(v, θ_d, φ) (the pack's full table), or ξ_M(v, θ_d) ξ_N(v, φ) (its factors)
    Ψ^Fiber_G   = mean_RGB Ψ(v, θ_i, φ), or Ψ_{G,M}(v, θ_i) Ψ_{G,N}(v, φ); clamped to [0, 1]
    V_d         = V + (V₂ − V) τ_Y + (1 − V₂) τ_Y²                        light past the other yarns unscattered:
                  around them or between their fibers (τ_Y, ``yarn_look.gap_transmittance``; ``past_blockers``)
    D           = V_d · Ψ^Fiber_G                                         fraction lit directly
    n           = n_occluded + k n_rest,  k = (V₂ − V) + 2 (1 − V₂)       fibers toward the light when not lit
                  (n_rest: the count of the scattered rest, τ_Y + (1 − τ_Y) ā_f^{n_rest} = T_Y, the pack's yarn
                  transmittance; ``Look.n_cross_rest``, ``yarn_look``)
    DS          = DS(θ_i^f, θ_o^f, φ^f; n, D)                             ``dual_scattering.ds_kernel``, fiber frame
    L_o        += E · (ξ_s S + ξ (DS − S))                                S = D f cos θ_i^f, DS's single scattering;
                  ξ_s = ξ but for ξ closed apart on single and multiple scattering (``_corrections``)

with θ^f, φ^f against t_f, V₂ the fraction of the light that at most one yarn blocks (``Features.two_blockers``, the
default; ``past_blockers``, ``yarns_crossed``; with the ablation ``one_blocker`` V₂ = 1: V_d = V + (1 − V) τ_Y,
k = 1 − V). V_d (beyond Huang et al. 2025): the shadow map draws yarns as opaque tubes, but a sixth
of a beam crossing cotton1 meets no fiber, and without it the path-traced fibers in another yarn's shadow showed 2–3×
the strips' single scattering (BENCHMARKS.md, "Issue 13: light between a blocking yarn's fibers, and light that
neighbouring yarns scatter"). With ``bounce`` (the ablation ``yarn_bounce``, ``knitrun.render.yarn_bounce``) each
point adds the yarn-level light its neighbours scatter onto it, before the fiber-level detail. The detail
(``yarn_look.fiber_detail``) has two channels: the directional lights' terms and the bounce take the first (the AO
texture's contrast), the environment's lobes and cells the second (the AO inter-reflected with ρ_Y: crevices the sky
barely sees still get their walls' scattered light; BENCHMARKS.md, "Issue 13: … sub-yarn contrast", stop 52).
Tangent spread: a texel averages fibers whose tangents scatter; the length of its
premultiplied tangent gives their variance (``tangent_spread``, Toksvig 2005; ASSET_PACK.md §8), and every BCSDF
evaluation of the point (DS, I_M's R lobe, the multiple-scattering lights) uses the lobes widened by it for that
light's φ^f (``fiber_bcsdf.spread_params``). An empty (0, 1, 1, 3) full table selects the factors. An ablation
passes (1, 1, 3) factor tables of ones for ξ or Ψ (and n_occluded = 0 without Ψ^Fiber: no fiber of the yarn is assumed
between a visible fiber and the light). This is the bin average of what the bake divides by (ξ = ΣΨ_*/ΣΨ_DS over
the hits of a (v, θ_d, φ) bin, each hit lit directly iff no fiber lies toward the light), with Ψ^Yarn_G = V from the
yarn-level shadow map in place of the other yarns' fibers: Huang et al. 2025 eq. 11. Per SRBF lobe j (centre ω_j,
sharpness λ_j, weight W_j, visibility T̃_j from the lobe's shadow map, raised by the yarn-level inter-reflection of
``knitrun.render.interreflection`` when the pack has a hull albedo, per channel: T̃_j,c from the ρ_Y of channel c,
``channel_visibility``), eq. 17:

    L_o += W_j · T̃_j,c · ξ_s(ω_i = ω_j) · Ψ_{G,M} Ψ_{G,N}(ω_i = ω_j) · I_M(θ_o^f, θ_j^f, φ_j^f − φ_o^f, λ_j)

(I_M = the pack's I_M^{TT,D} table + the R lobe integrated per lookup, ``im_lookup.im_kernel``; the kernels read
the table as ``im_lookup.IMSlices``, interpolated at each lobe's λ once, ``im_slice_kernel``)

plus, beyond the paper, the environment's multiple scattering: eq. 17 has single scattering only (I_M integrates
f), which leaves a bright, highly scattering yarn (cotton: albedo 0.95) far too dark under an environment. Lobe j
carries irradiance E_j = W_j ∫G_j dω = W_j (2π/λ_j)(1 − e^{−2λ_j}), which ``knitrun.render.ms_lights`` spreads over
a dozen fixed cells of the sphere (each cell's light: E summed, direction and visibility T̃ averaged with luminance
weights), and each cell c acts as a distant light for the smooth DS terms, with D = T̃_c Ψ^Fiber_G and
n = n_occluded + (1 − T̃_c) n_cross, the count that passes all of T_Y (T̃ takes no τ_Y: the hull albedo ρ_Y of its
inter-reflection already holds what a blocker lets through, T_Y ≤ ρ_Y, so none of it is split out as direct):

    L_o += E_c · ξ · (D d_b f_back^direct + F_scatter) cos θ_c^f · T̃_c,c / T̃_c        (``ds_kernel`` terms; f
                                                                                  itself is in I_M)

(T̃_c,c / T̃_c: channel c's share of the light past the neighbours, ``channel_visibility`` of the mixed T̃_c.)

Flyaways (``shade_flyaway``): the variant of period ⌊s/period⌋ of curve c is ``variant_of(c, period)`` (a fixed
integer hash, stable over frames); alpha = the variant's coverage A(u, v) on the wider flyaway strip; the hair
tangent from its RGB; single scattering, L_o = Σ E V_d S f(ω_i, ω_o) cos θ_i + Σ_j W_j T̃_j S_j I_M (thin hairs: no
multiple-scattering terms), S = Ψ^Fiber_G(v_strip, ω_i) (mean RGB) where the hair lies over the yarn body
(|v_strip| ≤ 1, v_strip = v·h_fly/r) — a hair on the surface is shadowed like the surface fibers — and beyond it
the transmittance of the hair's own yarn toward ω_i, τ_Y + (1 − τ_Y) ā_f(θ_i)^{n_rest·ℓ} where the ray crosses the
tube on a chord ℓ diameters long, averaged over the depths the hair may have (``_hair_light``): without it a hair
below a yarn lit from above shone as if in the open (the straight yarn under the sky: the hairs below the body at
2.0× the reference's, BENCHMARKS.md "Issue 13: hairs in their own yarn's shadow"). Not every hair seen over the body
lies in front of it: the baked coverage A also holds the hairs behind it that show through its gaps (between the
plies, at its sparse edge), a share b = (1 − c)/(2 − c) of those seen where the regular coverage is c
(``behind_share``), and those take the own-yarn transmittance over the depths behind the body in place of
Ψ^Fiber_G (since stop 57): lit from behind they lie in the open, where Ψ^Fiber_G of the body's front is nearly 0,
and lit from the camera's side mostly in the body's shadow (BENCHMARKS.md, "Issue 13: hairs seen through the body").
A hair is not an opaque film: of the radiance behind it (the yarn body, or the background) it passes on its forward
fraction τ = ā_f(θ_o^f) (``dual_scattering.forward_fraction``; cotton ≈ 0.7), which a broad bright backdrop such as
the body sends on toward the camera as it receives it. Without τ a hair over the body replaces the body's multiply
scattered radiance by its own single scattering and darkens it, where in the path-traced reference hairs over the
body add light.

The body's glow on its hairs (``Features.hair_glow``, the default; ``body_glow``; GLSL ``body_glow``): a hair beside its
yarn's body (|v_strip| > 1), or over it (since stop 56; in front of it, and behind it with the share b since stop 57),
is also lit by the light the body scatters, which in front light is 42 % of what the path-traced reference shows beside
the body (light that needs both the R and the TT lobe: BENCHMARKS.md, "Issue 13: the flyaway draw"). The body is a
Lambertian tube (``yarn_bounce.lambert_pair``): lit by E at θ_L from its normal plane it sends toward a point at angle α
(in the normal plane) from the light the radiance E V cos θ_L (R_Y g(α) + S_Y g(π − α))/π²; a hair at distance ρ radii
from the axis sees the (infinite) tube over the solid angle Ω = 4 asin(1/ρ) and, taking its BCSDF's response to that
extended source as its albedo a = A_R + A_TT + A_D spread evenly over the sphere, returns L_b Ω/(4π) a toward the
camera, averaged over the depths the hair may have (as ``_hair_light``). V is the hair's own visibility of the light.
The bounce reads the pack's tube phase instead (``yarn_bounce``); here the pack's moved no patch and cost the lone
straight yarn 0.02× its floor (BENCHMARKS.md, stop 70).

The neighbours' light on the hairs (``Features.hair_bounce``, the default since knit's stop 70; ``hair_bounce``; GLSL
the same line in ``flyaway.frag``): the yarn-level bounce (``knitrun.render.yarn_bounce``) also gives, per polyline
point, the neighbouring yarns' light arriving there over all directions, I = Σ_j w_ij L_ji (the bounce before the
receiving tube's phase); a hair of the flyaway layer returns I a/(4π) toward the camera, a its albedo A_R + A_TT + A_D
spread evenly over the sphere (as for the body's glow), I interpolated along the curve by rest arc length. In the
reference the hairs carry a third of the light the example patches' yarns send each other (BENCHMARKS.md, stop 70).

Zinke's density factors d_f, d_b come with the look (``Look.d_f``, ``d_b``: ``dual_scattering.D_F``, ``D_B``); both
0 (``Features.multiple_scattering`` False) leave single scattering alone, the split that ``benchmarks/probe_split.py``
compares with the reference traced with one scattering event.

Resolve (``resolve``): C = Σ w α L + (1 − Σ w α)·background for the regular layer, then the flyaway layer over it:
C ← Σ w A L_fly + (1 − Σ w A (1 − τ))·C. All radiances linear RGB in the units of E and W.

Threads
-------
The shading kernels run ``prange`` over blocks of ``POINT_BLOCK`` points, each block with its own scratch arrays
(``ds_scratch`` and the rows of ``_N_VEC``), and copy the rows they read of arrays every thread shares (a point's
tangent, a light's direction) instead of taking views: Numba allocates an array per ``np.empty`` and bumps the
shared array's reference count with an atomic instruction per view, which cost as much as the shading itself
(BENCHMARKS.md, "An interactive strip renderer on 2 cores"). Outputs are written per point as before.

One signature
-------------
Each shading kernel is compiled for one signature whatever the scene and the ``Features``: a kind of light the scene
lacks is a structure of no rows and an off switch an empty array (``shading_inputs``), so its loop runs zero times.
Until stop 68 they came as None, which Numba types apart and prunes before it compiles: every combination of absent
inputs was a signature of its own, compiled anew (on 2 cores ~36 s a signature of either kernel with both kinds of
light, 9–17 s with the sun alone), so the default test run compiled ``shade_flyaway`` six times and ``shade_regular``
five (~310 s of it; BENCHMARKS.md, "Issue 13: … the test run (stop 67)" and "Issue 13: the shading kernels' one
signature, …(stop 68)"). A scene with one kind of light now compiles the other's terms too, once per machine: the
kernel cache serves every later scene.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit, prange

from data_formats.conventions import THETA_RANGE
from knitrun.render.camera import tan_half_fov
from knitrun.render.interreflection import channel_visibility
from knitrun.render.strip_raster import sample_attributes
from knitrun.render.texture_sampling import has_levels, mip_level, sample_mip
from knitrun.render.yarn_bounce import INV_PI2, lambert_pair
from knitrun.shading.dual_scattering import (K_F_BACK_DIRECT, K_F_DIRECT, K_F_SCATTER, K_TOTAL, ds_kernel,
                                             ds_scratch, forward_fraction)
from knitrun.shading.fiber_bcsdf import (N_CONTEXT, P_A_D, P_A_R, P_A_TT, context_into, evaluate, r_lobe_context_into,
                                         spread_params)
from knitrun.shading.fiber_frame import azimuth_difference, dot, longitudinal_angle
from knitrun.shading.im_lookup import im_slice_kernel
from knitrun.shading.table_lookup import axis_cell

DEGENERATE = 1e-6  # |ω_o × t| below this: the strip is edge-on (ASSET_PACK.md §3); the point is not drawn
HAIR_DEPTHS = 4  # depths averaged over by a hair's own-yarn shadow (``_hair_light``)
POINT_BLOCK = 256  # shading points per prange iteration: they share one set of scratch arrays
# rows of a block's (_N_VEC, 3) scratch in ``shade_regular``
_T, _WO, _N, _B, _TF, _TEX, _XI, _PSI, _SCRATCH, _IM, _W, _WO_L, _XI_S = range(13)
_N_VEC = 13
MAX_TANGENT_SPREAD = 0.5  # rad: cap on the tangent spread of a texel (a texel of opposed tangents, r → 0)


# --- shading points -------------------------------------------------------------------------------------------------

@njit(parallel=True, cache=True)
def _group_counts(curve, use, counts):
    height, width, k = curve.shape
    for i in prange(height):
        for j in range(width):
            n = 0
            for a in range(k):
                if not use[i, j, a]:
                    continue
                new = True
                for b in range(a):
                    if use[i, j, b] and curve[i, j, b] == curve[i, j, a]:
                        new = False
                        break
                if new:
                    n += 1
            counts[i * width + j] = n


@njit(parallel=True, cache=True)
def _group_fill(curve, use, depth, start, pattern, cam_pos, basis, tan_half, ortho_h, sample_of, weight, position,
                view_dir, footprint):
    height, width, k = curve.shape
    right, up, fwd = basis[0], basis[1], basis[2]
    for i in prange(height):
        for j in range(width):
            q = start[i * width + j]
            for a in range(k):
                if not use[i, j, a]:
                    continue
                new = True
                for b in range(a):
                    if use[i, j, b] and curve[i, j, b] == curve[i, j, a]:
                        new = False
                        break
                if not new:
                    continue
                same = 0
                for b in range(k):
                    if use[i, j, b] and curve[i, j, b] == curve[i, j, a]:
                        same += 1
                sample_of[q, 0], sample_of[q, 1], sample_of[q, 2] = i, j, a
                weight[q] = same / k
                sx = (2.0 * (j + pattern[a, 0]) - width) / height
                sy = 1.0 - 2.0 * (i + pattern[a, 1]) / height
                d = depth[i, j, a]
                if ortho_h > 0.0:
                    for c in range(3):
                        position[q, c] = cam_pos[c] + 0.5 * ortho_h * (sx * right[c] + sy * up[c]) + d * fwd[c]
                        view_dir[q, c] = -fwd[c]
                    footprint[q] = ortho_h / height
                else:
                    rx = fwd[0] + tan_half * (sx * right[0] + sy * up[0])
                    ry = fwd[1] + tan_half * (sx * right[1] + sy * up[1])
                    rz = fwd[2] + tan_half * (sx * right[2] + sy * up[2])
                    norm = math.sqrt(rx ** 2 + ry ** 2 + rz ** 2)
                    position[q, 0] = cam_pos[0] + d * rx / norm
                    position[q, 1] = cam_pos[1] + d * ry / norm
                    position[q, 2] = cam_pos[2] + d * rz / norm
                    view_dir[q, 0], view_dir[q, 1], view_dir[q, 2] = -rx / norm, -ry / norm, -rz / norm
                    footprint[q] = 2.0 * d * tan_half / height
                q += 1


def shading_points(vis, camera, mask=None):
    """Group the covered samples of a ``strip_raster.StripVisibility`` into shading points (module docstring).
    Returns a dict of arrays: ``start`` (H·W + 1,), ``weight`` (N,), ``position`` (N, 3) world,
    ``view_dir`` (N, 3) unit toward the camera, ``footprint`` (N,) pixel size at the point (scene units), and the
    G-buffer attributes ``curve``, ``yarn``, ``segment``, ``arclength``, ``v``, ``tangent`` (float64) of each point's
    sample (``strip_raster.sample_attributes``, evaluated at the points alone)."""
    use = vis.coverage if mask is None else (vis.coverage & mask)
    height, width, _ = use.shape
    counts = np.empty(height * width, np.int64)
    _group_counts(vis.curve, use, counts)
    start = np.zeros(height * width + 1, np.int64)
    np.cumsum(counts, out=start[1:])
    n = int(start[-1])
    pixel_sample = np.empty((n, 3), np.int64)
    weight, footprint = np.empty(n), np.empty(n)
    position, view_dir = np.empty((n, 3)), np.empty((n, 3))
    fwd, right, up = camera.basis()
    _group_fill(vis.curve, use, vis.depth, start, np.asarray(vis.pattern, np.float64),
                np.asarray(camera.position, np.float64), np.stack([right, up, fwd]),
                tan_half_fov(camera), float(camera.ortho_height), pixel_sample, weight,
                position, view_dir, footprint)
    i, j, a = pixel_sample.T
    points = {"start": start, "weight": weight, "position": position,
              "view_dir": view_dir, "footprint": footprint}
    points.update(sample_attributes(vis, i, j, a), curve=vis.curve[i, j, a])
    points["tangent"] = points["tangent"].astype(np.float64)
    return points


def no_shading_points(pixels: int):
    """``shading_points``' dict for a frame of ``pixels`` pixels that has no shading point, with the dtypes it has
    for a frame that has some (``pipeline.Renderer.compile_shading`` compiles the kernels on it)."""
    return {"start": np.zeros(pixels + 1, np.int64), "weight": np.empty(0), "position": np.empty((0, 3)),
            "view_dir": np.empty((0, 3)), "footprint": np.empty(0), "yarn": np.empty(0, np.int32),
            "segment": np.empty(0, np.int32), "arclength": np.empty(0, np.float32), "v": np.empty(0, np.float32),
            "tangent": np.empty((0, 3)), "curve": np.empty(0, np.int32)}


# --- the strip frame (ASSET_PACK.md §3) ---------------------------------------------------------------------------

@njit(cache=True)
def _strip_frame(t, wo, n, b):
    """n, b of the strip at unit tangent t seen from ω_o; False when edge-on."""
    c = dot(wo, t)
    for k in range(3):
        n[k] = wo[k] - c * t[k]
    norm = math.sqrt(dot(n, n))
    if norm < DEGENERATE:
        return False
    for k in range(3):
        n[k] /= norm
    b[0] = n[1] * t[2] - n[2] * t[1]
    b[1] = n[2] * t[0] - n[0] * t[2]
    b[2] = n[0] * t[1] - n[1] * t[0]
    return True


@njit(cache=True)
def _strip_angles(w, t, n, b):
    """(θ, φ) by which the pack's tables are indexed for a light direction ω (ASSET_PACK.md §3): θ = asin(ω·t) and
    the table axis φ = φ_o − φ_i = −atan2(ω·b, ω·n) (azimuths measured from n toward b; the view's is 0)."""
    return longitudinal_angle(t, w), -math.atan2(dot(w, b), dot(w, n))


@njit(cache=True)
def _table_v(tab, v, x, lo, hi, repeat, out):
    """out[:3] = bilinear lookup of a (N_v, N_x, 3) table at (v, x); v over [−1, 1] clamps."""
    a0, a1, fa = axis_cell(v, -1.0, 1.0, tab.shape[0], False)
    b0, b1, fb = axis_cell(x, lo, hi, tab.shape[1], repeat)
    for ch in range(3):
        out[ch] = ((1.0 - fa) * ((1.0 - fb) * tab[a0, b0, ch] + fb * tab[a0, b1, ch])
                   + fa * ((1.0 - fb) * tab[a1, b0, ch] + fb * tab[a1, b1, ch]))


@njit(cache=True)
def _table_v3(tab, v, theta, phi, out):
    """out[:3] = trilinear lookup of a (N_v, N_theta, N_phi, 3) table at (v, θ, φ) (§4.3: v, θ clamp, φ repeats)."""
    a0, a1, fa = axis_cell(v, -1.0, 1.0, tab.shape[0], False)
    b0, b1, fb = axis_cell(theta, THETA_RANGE[0], THETA_RANGE[1], tab.shape[1], False)
    c0, c1, fc = axis_cell(phi, -math.pi, math.pi, tab.shape[2], True)
    for ch in range(3):
        lo = ((1.0 - fb) * ((1.0 - fc) * tab[a0, b0, c0, ch] + fc * tab[a0, b0, c1, ch])
              + fb * ((1.0 - fc) * tab[a0, b1, c0, ch] + fc * tab[a0, b1, c1, ch]))
        hi = ((1.0 - fb) * ((1.0 - fc) * tab[a1, b0, c0, ch] + fc * tab[a1, b0, c1, ch])
              + fb * ((1.0 - fc) * tab[a1, b1, c0, ch] + fc * tab[a1, b1, c1, ch]))
        out[ch] = (1.0 - fa) * lo + fa * hi


@njit(cache=True)
def _table_v4(tab, v, theta_i, theta_o, phi, out):
    """out[:3] = quadrilinear lookup of a (N_v, N_θ, N_θ, N_φ, 3) table at (v, θ_i, θ_o, φ) (§4.3: v, θ clamp, φ
    repeats)."""
    a0, a1, fa = axis_cell(v, -1.0, 1.0, tab.shape[0], False)
    b0, b1, fb = axis_cell(theta_i, THETA_RANGE[0], THETA_RANGE[1], tab.shape[1], False)
    c0, c1, fc = axis_cell(theta_o, THETA_RANGE[0], THETA_RANGE[1], tab.shape[2], False)
    d0, d1, fd = axis_cell(phi, -math.pi, math.pi, tab.shape[3], True)
    for ch in range(3):
        total = 0.0
        for a, wa in ((a0, 1.0 - fa), (a1, fa)):
            for b, wb in ((b0, 1.0 - fb), (b1, fb)):
                for c, wc in ((c0, 1.0 - fc), (c1, fc)):
                    w = wa * wb * wc
                    total += w * ((1.0 - fd) * tab[a, b, c, d0, ch] + fd * tab[a, b, c, d1, ch])
        out[ch] = total


@njit(cache=True)
def _factored_or_full(full, m_tab, n_tab, v, theta, phi, out, scratch):
    """A correction or shadowing value: the full table when it has cells (``full.shape[0] > 0``), else the product
    of the factor lookups (ASSET_PACK.md §6–7)."""
    if full.shape[0] > 0:
        _table_v3(full, v, theta, phi, out)
        return
    _table_v(m_tab, v, theta, THETA_RANGE[0], THETA_RANGE[1], False, out)
    _table_v(n_tab, v, phi, -math.pi, math.pi, True, scratch)
    for ch in range(3):
        out[ch] *= scratch[ch]


@njit(cache=True, inline='always')
def _corrections(tables, v, t, n, b, theta_o, w, xi, xi_s, psi, scratch, single=True, multiple=True):
    """ξ into ``xi``, the ξ of single scattering into ``xi_s`` and Ψ^Fiber_G(v, θ_i, φ) into ``psi`` (``tables``:
    ``shading_inputs.Corrections``) for light direction ω = ``w`` seen from θ_o (θ_i and φ by ``_strip_angles``):
    ξ(v, θ_i, θ_o, φ) from the view-closed table when it has cells, else ξ(v, θ_d, φ) with θ_d = (θ_o − θ_i)/2; the
    same from the single-scattering tables where they have cells (ξ closed apart on single and multiple scattering,
    ``xi`` then being multiple scattering's), else ``xi_s`` = ``xi``. A term that uses one of the two asks for it
    alone (``single``, ``multiple``): the other is then not looked up and its output is left as it was (the sky's
    lobes are single scattering, its cells multiple: one 4-D lookup each instead of two)."""
    theta_i, phi = _strip_angles(w, t, n, b)
    theta_d = 0.5 * (theta_o - theta_i)
    apart = tables.xi_single_view.shape[0] > 0 or tables.xi_single.shape[0] > 0
    if multiple or not apart:
        if tables.xi_view.shape[0] > 0:
            _table_v4(tables.xi_view, v, theta_i, theta_o, phi, xi)
        else:
            _factored_or_full(tables.xi_full, tables.xi_m, tables.xi_n, v, theta_d, phi, xi, scratch)
    if single:
        if tables.xi_single_view.shape[0] > 0:
            _table_v4(tables.xi_single_view, v, theta_i, theta_o, phi, xi_s)
        elif tables.xi_single.shape[0] > 0:
            _table_v3(tables.xi_single, v, theta_d, phi, xi_s)
        else:
            xi_s[0], xi_s[1], xi_s[2] = xi[0], xi[1], xi[2]
    _factored_or_full(tables.psi_full, tables.psi_gm, tables.psi_gn, v, theta_i, phi, psi, scratch)


@njit(cache=True)
def past_blockers(visibility, beyond, gap):
    """The fraction of a directional light that reaches a point unscattered at yarn level: past the other yarns
    (``visibility`` V, the shadow map's, which treats them as opaque tubes) or between their fibers, the gap
    transmittance τ_Y (``yarn_look.gap_transmittance``) for each yarn crossed: V + (V₂ − V) τ_Y + (1 − V₂) τ_Y²,
    V₂ = ``beyond`` the fraction that at most one yarn blocks (``Features.two_blockers``; 1: every blocked ray
    crosses one yarn, V + (1 − V) τ_Y)."""
    return visibility + (beyond - visibility) * gap + (1.0 - beyond) * gap * gap


@njit(cache=True, inline="always")
def _beyond(lights, light, q):
    """V₂ of point q toward light ``light``: ``lights.beyond`` where counted, else 1 (``shading_inputs.Lights``)."""
    return lights.beyond[light, q] if lights.beyond.shape[1] > 0 else 1.0


@njit(cache=True)
def yarns_crossed(visibility, beyond):
    """The mean number of other yarns a directional light crosses to reach a point: (V₂ − V) + 2 (1 − V₂)
    (``past_blockers``; 1 − V when V₂ = 1)."""
    return 2.0 - visibility - beyond


@njit(cache=True)
def _fiber_lit(psi):
    """The fraction of a point's fibers lit directly at fiber level: mean RGB Ψ^Fiber_G clamped to [0, 1]."""
    return min(max((psi[0] + psi[1] + psi[2]) / 3.0, 0.0), 1.0)


MIN_ALONG = 0.05  # floor of the fiber bend's scale: inside a bend tighter than the radius the fibers would fold


@njit(cache=True)
def fiber_bend(curvature, stretch, q, radius, v, n, b):
    """The fiber bend of point q (beyond Huang et al. 2025; SHADING.md §2): the scale a of the fibers' tangent along
    the yarn where its curve bends and stretches. The reference sweeps the straight procedural yarn along the curve
    (``knitbake.fibers.fiber_sweep``): a fiber at offset o from the axis (in the normal plane of a
    rotation-minimising frame) at rest arc length σ lies at c(σ) + o(σ), whose derivative is λ (1 − κ·o) t + o′(σ),
    o′ the twist of the straight yarn, λ the stretch and κ the curvature vector (``curvature[q]``, ``stretch[q]``:
    ``pipeline.segment_bend``). The textures hold the straight yarn at rest (a = 1), so a = max(λ (1 − κ·o),
    ``MIN_ALONG``) with o = r (v b + √(1 − v²) n), the tube surface the camera sees at v in the strip frame (n, b):
    on the outside of a bend (κ·o < 0) and on a stretched yarn the fibers turn toward the yarn's tangent, on the
    inside away from it."""
    depth = math.sqrt(max(0.0, 1.0 - v * v))
    k_dot_o = 0.0
    for k in range(3):
        k_dot_o += curvature[q, k] * radius * (v * b[k] + depth * n[k])
    return max(stretch[q] * (1.0 - k_dot_o), MIN_ALONG)


@njit(cache=True)
def _texture_tangent(tex, t, n, b, tf, along):
    """World fiber tangent from a coverage-premultiplied strip-frame vector, its component along t scaled by
    ``along`` (``fiber_bend``; 1 for hairs); t where it vanishes."""
    for k in range(3):
        tf[k] = along * tex[0] * t[k] + tex[1] * b[k] + tex[2] * n[k]
    norm = math.sqrt(dot(tf, tf))
    if norm < 1e-6:
        tf[0], tf[1], tf[2] = t[0], t[1], t[2]
        return False
    for k in range(3):
        tf[k] /= norm
    return True


@njit(cache=True)
def tangent_spread(tex, coverage):
    """Variance (rad², per axis normal to the mean) of the fiber tangents a texel averages, from the length of its
    coverage-premultiplied mean tangent (Toksvig 2005): r = |T|/coverage ∈ [0, 1], spread² = (1 − r)/r (for small
    tilts r ≈ 1 − spread²), at most ``MAX_TANGENT_SPREAD``². 0 where nothing is covered."""
    if coverage <= 1e-6:
        return 0.0
    r = min(math.sqrt(dot(tex, tex)) / coverage, 1.0)
    if r <= 0.0:
        return MAX_TANGENT_SPREAD * MAX_TANGENT_SPREAD
    return min((1.0 - r) / r, MAX_TANGENT_SPREAD * MAX_TANGENT_SPREAD)


@njit(cache=True, inline='always')
def _begin_point(q, points, period, t, wo, n, b, rgb, alpha):
    """Clear point q's output, copy its tangent and view direction into t, wo (``_copy_row``) and set up its strip
    frame (n, b); returns (drawn, u, v), drawn False when edge-on."""
    _copy_row(points.tangent, q, t)
    _copy_row(points.view_dir, q, wo)
    rgb[q, :] = 0.0
    alpha[q] = 0.0
    if not _strip_frame(t, wo, n, b):
        return False, 0.0, 0.0
    return True, points.arclength[q] / period, min(max(points.v[q], -1.0), 1.0)


# --- regular fibers --------------------------------------------------------------------------------------------------

@njit(parallel=True, cache=True)
def shade_regular(idx, points, look, corrections, tangent, coverage, detail, lights, lobes, ms, im, bounce, rgb,
                  alpha):
    """Shade the points ``idx`` (indices into ``points``) of one yarn; writes rgb[idx], alpha[idx]. ``points``,
    ``look``, ``corrections`` (ξ, Ψ^Fiber), the textures ``tangent``, ``coverage`` and ``detail``, ``lights``
    (directional), ``lobes`` (SRBF), ``ms`` (the environment's multiple-scattering lights, module docstring) and
    ``im``: the named tuples of ``knitrun.render.shading_inputs``. A kind of light the scene lacks comes as a tuple
    of no rows (``no_lights``, ``no_lobes``: no directional light, no environment), never None: one signature serves
    every scene and every ``Features``, so the kernel compiles once (module docstring, "One signature"). ``bounce``
    (N, 3): the yarn-level radiance the neighbouring yarns scatter onto each point (``knitrun.render.yarn_bounce``),
    or (0, 3) (``shading_inputs.no_rows``): none."""
    params, ds, period = look.params, look.ds, look.period
    n_occluded, n_cross, d_f, d_b = look.n_occluded, look.n_cross, look.d_f, look.d_b
    n_cross_rest, gap = look.n_cross_rest, look.gap
    texel_u = period / tangent.cols[0, 0]
    texel_v = 2.0 * look.radius / tangent.rows[0, 0]
    for block in prange((idx.shape[0] + POINT_BLOCK - 1) // POINT_BLOCK):
        # scratch owned by this block of points (module docstring, "Threads")
        vec = np.empty((_N_VEC, 3))
        t, wo, n, b, tf, tex = vec[_T], vec[_WO], vec[_N], vec[_B], vec[_TF], vec[_TEX]
        xi, psi, scratch, i_m, w, xi_s = vec[_XI], vec[_PSI], vec[_SCRATCH], vec[_IM], vec[_W], vec[_XI_S]
        cov, fiber_detail, ambient = np.empty(1), np.empty(2), np.empty(3)
        comp, ds_work = ds_scratch()
        wide, ctx = np.empty(params.shape[0]), np.empty(N_CONTEXT)
        for m in range(block * POINT_BLOCK, min(idx.shape[0], (block + 1) * POINT_BLOCK)):
            q = idx[m]
            drawn, u, v = _begin_point(q, points, period, t, wo, n, b, rgb, alpha)
            if not drawn:
                continue
            level = mip_level(points.footprint[q], texel_u, texel_v)
            sample_mip(coverage, 0, level, u, v, cov)
            sample_mip(tangent, 0, level, u, v, tex)
            alpha[q] = min(max(cov[0], 0.0), 1.0)
            sample_mip(detail, 0, level, u, v, fiber_detail)  # the directional lights' and the environment's
            along = fiber_bend(points.curvature, points.stretch, q, look.radius, v, n, b)
            _texture_tangent(tex, t, n, b, tf, along)
            spread2 = tangent_spread(tex, cov[0])
            theta_o = longitudinal_angle(t, wo)
            theta_o_f = longitudinal_angle(tf, wo)
            xi[:] = 1.0
            psi[:] = 1.0
            for light in range(lights.direction.shape[0]):
                _copy_row(lights.direction, light, w)
                _corrections(corrections, v, t, n, b, theta_o, w, xi, xi_s, psi, scratch)
                fiber_lit = _fiber_lit(psi)
                vis, beyond = lights.visibility[light, q], _beyond(lights, light, q)
                n_front = n_occluded + yarns_crossed(vis, beyond) * n_cross_rest
                lit = past_blockers(vis, beyond, gap) * fiber_lit
                phi_f = azimuth_difference(tf, wo, w)
                spread_params(params, spread2, phi_f, wide)
                theta_i_f = longitudinal_angle(tf, w)
                ds_kernel(wide, ds, theta_i_f, theta_o_f, phi_f, n_front, d_f, d_b, lit, comp, ds_work)
                cos_i = math.cos(theta_i_f)
                for ch in range(3):
                    # D f cos θ_i, single scattering (``dual_scattering``: F_direct = D (f + d_b f_back^direct))
                    single = (comp[K_F_DIRECT, ch] - lit * d_b * comp[K_F_BACK_DIRECT, ch]) * cos_i
                    rgb[q, ch] += lights.irradiance[light, ch] * (
                        xi_s[ch] * single + xi[ch] * (comp[K_TOTAL, ch] - single))
            ambient[0], ambient[1], ambient[2] = rgb[q, 0], rgb[q, 1], rgb[q, 2]  # the environment's terms: below
            for j in range(lobes.direction.shape[0]):
                vis = lobes.visibility[j, q]
                if vis <= 0.0:  # the lobe is blocked here: its term is zero, skip its lookups
                    continue
                _copy_row(lobes.direction, j, w)
                _corrections(corrections, v, t, n, b, theta_o, w, xi, xi_s, psi, scratch, multiple=False)
                theta_j_f = longitudinal_angle(tf, w)
                phi_f = azimuth_difference(tf, wo, w)
                spread_params(params, spread2, phi_f, wide)
                # the R lobe of the fiber-frame view, for I_M's R rule
                r_lobe_context_into(wide, math.sin(theta_o_f), ctx)
                im_slice_kernel(im, j, wide, ctx, theta_o_f, theta_j_f, -phi_f, lobes.sharpness[j], i_m)
                for ch in range(3):  # single scattering, each channel's inter-reflected visibility
                    vis_ch = channel_visibility(vis, lobes.albedo[0], lobes.albedo[1 + ch])
                    rgb[q, ch] += lobes.weight[j, ch] * vis_ch * xi_s[ch] * psi[ch] * i_m[ch]
            for c in range(ms.direction.shape[0]):  # multiple scattering: cells of the sky as distant lights
                _copy_row(ms.direction, c, w)
                _corrections(corrections, v, t, n, b, theta_o, w, xi, xi_s, psi, scratch, single=False)
                vis = ms.visibility[c, q]
                lit = vis * _fiber_lit(psi)
                theta_c_f = longitudinal_angle(tf, w)
                phi_f = azimuth_difference(tf, wo, w)
                spread_params(params, spread2, phi_f, wide)
                ds_kernel(wide, ds, theta_c_f, theta_o_f, phi_f, n_occluded + (1.0 - vis) * n_cross, d_f, d_b, lit,
                          comp, ds_work, False)  # f itself is in the lobes' I_M
                cos_c = math.cos(theta_c_f)
                for ch in range(3):
                    multiple = (lit * d_b * comp[K_F_BACK_DIRECT, ch] + comp[K_F_SCATTER, ch]) * cos_c
                    # the channel's share of the light past the neighbours (``interreflection`` docstring)
                    tint = channel_visibility(vis, lobes.albedo[0], lobes.albedo[1 + ch]) / vis if vis > 0.0 \
                        else 1.0
                    rgb[q, ch] += ms.irradiance[c, ch] * xi[ch] * multiple * tint
            for ch in range(3):
                ambient[ch] = rgb[q, ch] - ambient[ch]
            if bounce.shape[0] > 0:  # light the neighbouring yarns scatter onto this one (``yarn_bounce``)
                for ch in range(3):
                    rgb[q, ch] += bounce[q, ch]
            for ch in range(3):
                rgb[q, ch] = (rgb[q, ch] - ambient[ch]) * fiber_detail[0] + ambient[ch] * fiber_detail[1]


@njit(cache=True, inline='always')
def _copy_row(src, i, out):
    """out[:3] = src[i, :3], copied: a view of an array every thread reads would bump its reference count with an
    atomic instruction per call (module docstring, "Threads")."""
    out[0], out[1], out[2] = src[i, 0], src[i, 1], src[i, 2]


# --- flyaways --------------------------------------------------------------------------------------------------------

@njit(cache=True)
def variant_of(curve, period_index):
    """Flyaway texture variant (0, 1, 2) of one period of one curve: a fixed 64-bit integer hash (splitmix64's
    finaliser) of the pair, stable over frames and thread counts."""
    x = np.uint64(curve) * np.uint64(0x9E3779B97F4A7C15) + np.uint64(period_index & 0xFFFFFFFFFFFF)
    x = (x ^ (x >> np.uint64(30))) * np.uint64(0xBF58476D1CE4E5B9)
    x = (x ^ (x >> np.uint64(27))) * np.uint64(0x94D049BB133111EB)
    x = x ^ (x >> np.uint64(31))
    return int(x % np.uint64(3))


@njit(cache=True, inline='always')
def _hair_texel(q, points, period, flyaway, texel_u, texel_v, t, wo, n, b, tf, texel):
    """Point q of the flyaway layer: its tangent and view direction into t, wo, its strip frame (n, b), the texel of
    its period's variant (``variant_of``) into ``texel`` (RGBA) and the hair tangent from it into tf. Returns (drawn,
    v): drawn False where the strip is edge-on or the texel has no tangent (nothing to draw there)."""
    _copy_row(points.tangent, q, t)
    _copy_row(points.view_dir, q, wo)
    if not _strip_frame(t, wo, n, b):
        return False, 0.0
    u, v = points.arclength[q] / period, min(max(points.v[q], -1.0), 1.0)
    sample_mip(flyaway, variant_of(points.curve[q], int(math.floor(u))),
               mip_level(points.footprint[q], texel_u, texel_v), u, v, texel)
    return _texture_tangent(texel, t, n, b, tf, 1.0), v


@njit(parallel=True, cache=True)
def flyaway_coverage(idx, points, look, flyaway, alpha):
    """alpha[idx]: the coverage ``shade_flyaway`` gives the flyaway-layer points ``idx`` of one yarn, without shading
    them. The renderer drops the points of zero coverage before their shadow lookups and shading: they add nothing
    to the image (``resolve``), and where the hair texture is magnified most of the layer's points are such."""
    texel_u = look.period / flyaway.cols[0, 0]
    texel_v = 2.0 * look.flyaway_half_width / flyaway.rows[0, 0]
    for block in prange((idx.shape[0] + POINT_BLOCK - 1) // POINT_BLOCK):
        vec = np.empty((_N_VEC, 3))  # scratch owned by this block of points
        texel = np.empty(4)
        for m in range(block * POINT_BLOCK, min(idx.shape[0], (block + 1) * POINT_BLOCK)):
            q = idx[m]
            drawn, _ = _hair_texel(q, points, look.period, flyaway, texel_u, texel_v, vec[_T], vec[_WO], vec[_N],
                                   vec[_B], vec[_TF], texel)
            alpha[q] = min(max(texel[3], 0.0), 1.0) if drawn else 0.0


@njit(cache=True)
def cylinder_solid_angle(rho):
    """Solid angle (sr) of an infinite cylinder of radius 1 seen from a point ρ ≥ 1 from its axis: the strip of
    half-angle asin(1/ρ) about the axis direction, integrated over every elevation along it, 4 asin(1/ρ) (2π at the
    surface, 4/ρ far away)."""
    return 4.0 * math.asin(min(1.0 / rho, 1.0))


@njit(cache=True)
def behind_share(coverage):
    """The share of the hairs seen at a point over a yarn's body (regular coverage c there, in [0, 1]) that lie
    behind the body. The hair layer is as dense behind the body as in front of it, and its baked coverage counts
    every hair the camera sees through the regular fibers (``knitbake.stages.textures``): all of those in front, and
    of those behind the fraction 1 − c that the body's gaps let through. So (1 − c)/(2 − c): none where the body is
    opaque, half where it is empty."""
    c = min(max(coverage, 0.0), 1.0)
    return (1.0 - c) / (2.0 - c)


@njit(cache=True)
def body_glow(tube, albedo, reach, v, behind, n, b, w, out):
    """out[:3] = the radiance toward the camera, per unit irradiance and visibility of a directional light from ``w``,
    that a hair at strip coordinate ``v`` (yarn radii from the axis, along b) returns of the light its own yarn's body
    scatters onto it (module docstring, "The body's glow on its hairs"), averaged over ``HAIR_DEPTHS`` depths z
    (along n, toward the camera) within ``reach`` radii: beside the body (|v| > 1) over −d…d, d = √(reach² − v²); over
    it (|v| ≤ 1) over the front part √(1 − v²)…d with weight 1 − ``behind`` and the back part −d…−√(1 − v²) with
    weight ``behind`` (``behind_share``: hairs behind the body are seen through its gaps). ``tube`` (2, 3): the body's
    R_Y and S_Y (``yarn_bounce.tube_optics``), ``albedo`` (3,): the hair's A_R + A_TT + A_D; n, b the strip frame."""
    out[0] = out[1] = out[2] = 0.0
    wb, wn = dot(w, b), dot(w, n)
    cos_l = math.sqrt(wb * wb + wn * wn)  # cos θ_L: the light's part normal to the yarn
    if cos_l < DEGENERATE:
        return
    wb, wn = wb / cos_l, wn / cos_l
    depth = math.sqrt(max(reach * reach - v * v, 0.0))
    if abs(v) > 1.0:
        _glow_between(tube, albedo, v, wb, wn, cos_l, -depth, depth, 1.0, out)
        return
    surface = math.sqrt(1.0 - v * v)
    _glow_between(tube, albedo, v, wb, wn, cos_l, surface, depth, 1.0 - behind, out)
    _glow_between(tube, albedo, v, wb, wn, cos_l, -depth, -surface, behind, out)


@njit(cache=True, inline='always')
def _glow_between(tube, albedo, v, wb, wn, cos_l, lo, hi, weight, out):
    """Adds to out[:3] ``weight`` times ``body_glow``'s mean over ``HAIR_DEPTHS`` depths spread evenly over
    lo…hi (nothing where the interval is empty or the weight is 0); (wb, wn): the light's unit part normal to t."""
    if hi <= lo or weight <= 0.0:
        return
    for k in range(HAIR_DEPTHS):
        z = lo + (hi - lo) * (k + 0.5) / HAIR_DEPTHS
        rho = math.sqrt(v * v + z * z)
        if rho <= 1.0:
            continue
        g, g_forward = lambert_pair((v * wb + z * wn) / rho)
        share = weight * cos_l * INV_PI2 * cylinder_solid_angle(rho) / (4.0 * math.pi) / HAIR_DEPTHS
        for ch in range(3):
            out[ch] += share * (tube[0, ch] * g + tube[1, ch] * g_forward) * albedo[ch]


def hair_bounce(arriving, params) -> np.ndarray:
    """(N, 3): the radiance toward the camera that hairs return of the neighbouring yarns' light ``arriving`` (N, 3),
    I of ``yarn_bounce.vertex_bounce`` at the hairs' points, for the BCSDF ``params`` of their yarn (module docstring,
    "The neighbours' light on the hairs"): I (A_R + A_TT + A_D)/(4π)."""
    albedo = params[P_A_R:P_A_R + 3] + params[P_A_TT:P_A_TT + 3] + params[P_A_D:P_A_D + 3]
    return np.asarray(arriving, np.float64) * albedo / (4.0 * math.pi)


@njit(parallel=True, cache=True)
def shade_flyaway(idx, points, look, corrections, flyaway, coverage, lights, glow, lobes, im, rgb, alpha, transmit):
    """Shade the flyaway-layer points ``idx`` of one yarn (the named tuples of ``knitrun.render.shading_inputs``;
    ``flyaway``: its three texture variants); writes rgb[idx], alpha[idx] and transmit[idx] (RGB, the hair's
    forward fraction ā_f(θ_o): what it passes on of the radiance behind it). A kind of light the scene lacks comes as
    a tuple of no rows, as in ``shade_regular`` (one signature for every scene and ``Features``). ``glow`` (2, 3): the
    body's R_Y and S_Y for its glow on the hairs under the directional lights (``body_glow``), or (0, 3)
    (``shading_inputs.no_rows``): none (``Features.hair_glow`` off, or a pack without ρ_Y and T_Y). ``coverage``: the
    regular strip's coverage texture (``shade_regular``'s), read at a hair over the body (|v_strip| ≤ 1, at the hair's
    own u, mip level from the regular texels) for the share of the hairs seen there that lie behind the body
    (``behind_share``), or a stack of no level (``texture_sampling.no_texture``): every hair seen over the body lies
    in front of it (``Features.hairs_behind`` off)."""
    params, ds, period = look.params, look.ds, look.period
    half_width, radius, n_rest, gap = look.flyaway_half_width, look.radius, look.n_cross_rest, look.gap
    reach = half_width / radius  # the hair layer's half-width in yarn radii
    texel_u = period / flyaway.cols[0, 0]
    texel_v = 2.0 * half_width / flyaway.rows[0, 0]
    for block in prange((idx.shape[0] + POINT_BLOCK - 1) // POINT_BLOCK):
        vec = np.empty((_N_VEC, 3))  # scratch owned by this block of points
        cov = np.empty(1)
        t, wo, n, b, tf, ny = vec[_T], vec[_WO], vec[_N], vec[_B], vec[_TF], vec[_TEX]
        f, wl, psi, scratch, w, wo_l = vec[_XI], vec[_IM], vec[_PSI], vec[_SCRATCH], vec[_W], vec[_WO_L]
        texel, hair_albedo = np.empty(4), np.empty(3)
        wide, ctx = np.empty(params.shape[0]), np.empty(N_CONTEXT)
        for m in range(block * POINT_BLOCK, min(idx.shape[0], (block + 1) * POINT_BLOCK)):
            q = idx[m]
            rgb[q, :] = 0.0
            alpha[q] = 0.0
            drawn, v = _hair_texel(q, points, period, flyaway, texel_u, texel_v, t, wo, n, b, tf, texel)
            if not drawn:
                continue
            alpha[q] = min(max(texel[3], 0.0), 1.0)
            theta_o_f = longitudinal_angle(tf, wo)
            forward_fraction(ds, theta_o_f, scratch)
            transmit[q, 0], transmit[q, 1], transmit[q, 2] = scratch[0], scratch[1], scratch[2]
            # local fiber frame: x along tf, y toward the camera in the normal plane, z = x × y
            if not _strip_frame(tf, wo, ny, b):
                continue
            wo_l[0], wo_l[1], wo_l[2] = dot(wo, tf), dot(wo, ny), 0.0
            spread2 = tangent_spread(texel[:3], texel[3])
            # over the regular strip (|v| ≤ 1 in its units) a hair in front of the body lies on the yarn's surface
            # fibers, and the fiber-level shadowing of that strip point applies to it; one behind the body or beside it
            # sticks out, and its own yarn shadows it where the ray toward the light crosses the yarn (``_hair_light``)
            v_strip = v * half_width / radius
            on_body = abs(v_strip) <= 1.0
            behind = 0.0  # the share of the hairs seen here that lie behind the body (``behind_share``)
            if on_body:
                if has_levels(coverage):
                    level = mip_level(points.footprint[q], period / coverage.cols[0, 0],
                                      2.0 * radius / coverage.rows[0, 0])
                    sample_mip(coverage, 0, level, points.arclength[q] / period, v_strip, cov)
                    behind = behind_share(cov[0])
            for light in range(lights.direction.shape[0]):
                _copy_row(lights.direction, light, w)
                wl[0], wl[1], wl[2] = dot(w, tf), dot(w, ny), -dot(w, b)
                spread_params(params, spread2, azimuth_difference(tf, wo, w), wide)
                context_into(wide, wo_l, ctx, False)
                evaluate(wide, ctx, wl, f)
                cos_i = math.sqrt(max(0.0, 1.0 - wl[0] * wl[0]))
                _hair_light(on_body, behind, corrections, ds, n_rest, gap, reach, v_strip, t, n, b, w, psi, scratch)
                lit = past_blockers(lights.visibility[light, q], _beyond(lights, light, q), gap) * cos_i
                for ch in range(3):
                    rgb[q, ch] += lights.irradiance[light, ch] * lit * psi[ch] * f[ch]
                if glow.shape[0] > 0:  # the body's glow (``body_glow``), lit as the hair is
                    for ch in range(3):
                        hair_albedo[ch] = params[P_A_R + ch] + params[P_A_TT + ch] + params[P_A_D + ch]
                    body_glow(glow, hair_albedo, reach, v_strip, behind, n, b, w, f)
                    body_lit = past_blockers(lights.visibility[light, q], _beyond(lights, light, q), gap)
                    for ch in range(3):
                        rgb[q, ch] += lights.irradiance[light, ch] * body_lit * f[ch]
            for j in range(lobes.direction.shape[0]):
                if lobes.visibility[j, q] <= 0.0:  # blocked: a zero term
                    continue
                _copy_row(lobes.direction, j, w)
                phi_f = azimuth_difference(tf, wo, w)
                spread_params(params, spread2, phi_f, wide)
                r_lobe_context_into(wide, wo_l[0], ctx)
                im_slice_kernel(im, j, wide, ctx, theta_o_f, longitudinal_angle(tf, w), -phi_f,
                                lobes.sharpness[j], f)
                _hair_light(on_body, behind, corrections, ds, n_rest, gap, reach, v_strip, t, n, b, w, psi, scratch)
                for ch in range(3):  # each channel's inter-reflected visibility (``channel_visibility``)
                    vis = channel_visibility(lobes.visibility[j, q], lobes.albedo[0], lobes.albedo[1 + ch])
                    rgb[q, ch] += lobes.weight[j, ch] * vis * psi[ch] * f[ch]


@njit(cache=True, inline='always')
def _hair_light(on_body, behind, tables, ds, n_rest, gap, reach, v, t, n, b, wi, out, scratch):
    """out[:3] = the fraction of the light from ω_i that reaches a hair at strip coordinate v (yarn radii from the
    axis, along b) of a yarn with axis tangent t (strip frame n, b). The strip does not say how far in front of or
    behind the axis the hair lies, so the fraction is a mean over the depths z it may have (|(v, z)| ≤ ``reach``
    radii). Beside the body (|v| > 1) the hair sticks out of its own yarn, which shadows it where the ray toward the
    light crosses the tube: the mean over ``HAIR_DEPTHS`` depths spread evenly over −d…d, d = √(reach² − v²). Over the
    body (``on_body``) a hair in front of it lies on its surface fibers and takes Ψ^Fiber_G (mean RGB, clamped to
    [0, 1]) of the regular strip there, with weight 1 − ``behind``; one behind it (seen through the body's gaps,
    ``behind_share``) takes, with weight ``behind``, the same crossing mean over the depths −d…−√(1 − v²) (lit from
    behind, it lies in the open; from the front, in the body's shadow). The crossing: in the cross-section (b, n),
    with ŵ the unit part of ω_i normal to t, a ray from p = (v, z) heading toward the axis (p·ŵ < 0) passes it at
    distance √(|p|² − (p·ŵ)²); where that is below 1 the fraction τ_Y = ``gap`` passes between the fibers and the
    rest meets n_rest·ℓ fibers (``Look.n_cross_rest``), ℓ = √(1 − distance²) its chord over the diameter: it keeps
    τ_Y + (1 − τ_Y) ā_f(θ_i)^{n_rest·ℓ} per channel (module docstring; at ℓ = 1 the yarn's transmittance T_Y)."""
    depth = math.sqrt(max(reach * reach - v * v, 0.0))
    surface, share, lo, hi = 0.0, 1.0, -depth, depth
    if on_body:
        theta_i, phi = _strip_angles(wi, t, n, b)
        _factored_or_full(tables.psi_full, tables.psi_gm, tables.psi_gn, v, theta_i, phi, out, scratch)
        surface = (1.0 - behind) * _fiber_lit(out)
        share, hi = behind, -math.sqrt(1.0 - v * v)
    out[0] = out[1] = out[2] = surface
    if share <= 0.0:
        return
    wb, wn = dot(wi, b), dot(wi, n)
    across = math.sqrt(wb * wb + wn * wn)
    if across < DEGENERATE:  # light along the yarn: the ray never nears the axis
        for ch in range(3):
            out[ch] += share
        return
    wb, wn = wb / across, wn / across
    forward_fraction(ds, longitudinal_angle(t, wi), scratch)
    for k in range(HAIR_DEPTHS):
        z = lo + (hi - lo) * (k + 0.5) / HAIR_DEPTHS
        toward = v * wb + z * wn
        miss = v * v + z * z - toward * toward
        if toward >= 0.0 or miss >= 1.0:
            for ch in range(3):
                out[ch] += share / HAIR_DEPTHS
            continue
        count = n_rest * math.sqrt(1.0 - miss)
        for ch in range(3):
            out[ch] += share * (gap + (1.0 - gap) * scratch[ch] ** count) / HAIR_DEPTHS


# --- resolve ---------------------------------------------------------------------------------------------------------

def resolve(start, weight, rgb, alpha, transmit, under, out):
    """out[p] = Σ_points w α L + (1 − min(1, Σ w α (1 − τ)))·under[p] over the points of pixel p (flattened H·W,
    RGB); τ = ``transmit`` (N, 3), the fraction of the radiance behind a point that it passes on (0: opaque).
    ``start`` (H·W + 1,) the points of each pixel, or (L, H·W + 1) those of L layers, the nearest first: composited
    back to front, each over the one behind. ``under`` may be ``out`` (each pixel reads its own row before writing
    it): the layers composite in place."""
    _resolve(np.atleast_2d(start), weight, rgb, alpha, transmit, under, out)


@njit(parallel=True, cache=True)
def _resolve(starts, weight, rgb, alpha, transmit, under, out):
    """``resolve`` over (L, H·W + 1) ``starts``."""
    for p in prange(out.shape[0]):
        for ch in range(3):  # scalar sums per channel: no per-pixel scratch array (1.2M pixels a frame)
            value = under[p, ch]
            for layer in range(starts.shape[0] - 1, -1, -1):
                acc, cov = 0.0, 0.0
                for q in range(starts[layer, p], starts[layer, p + 1]):
                    a = weight[q] * alpha[q]
                    acc += a * rgb[q, ch]
                    cov += a * (1.0 - transmit[q, ch])
                value = acc + (1.0 - min(cov, 1.0)) * value
            out[p, ch] = value


@njit(parallel=True, cache=True)
def resolve_behind(front_start, front_weight, front_alpha, back_start, back_weight, back_rgb, back_alpha, background,
                   out):
    """out[p] (H·W, 3): what the front layer of regular points lets through at pixel p, for ``resolve`` to draw the
    front over. The front's points cover the fraction c1 = Σ w of the pixel's samples with s1 = Σ w α; the back layer
    (depth-peeled: it has samples only where the front has) over the background, averaged over those samples, is
    X = (Σ w₂ α₂ L₂ + (c1 − Σ w₂ α₂)·bg)/c1; through the front's transparent part T1 = c1 − s1 shows X and through
    the rest of the pixel the background: out = (T1·X + (1 − c1)·bg)/(1 − s1), so ``resolve`` gives
    Σ w α L + T1·X + (1 − c1)·bg. The background where the front is opaque (s1 = 1)."""
    for p in prange(out.shape[0]):
        c1, s1 = 0.0, 0.0
        for q in range(front_start[p], front_start[p + 1]):
            c1 += front_weight[q]
            s1 += front_weight[q] * front_alpha[q]
        open_ = 1.0 - s1
        for ch in range(3):  # scalar sums per channel, as ``resolve``
            if open_ <= 1e-9 or c1 <= 0.0:
                out[p, ch] = background[ch]
                continue
            acc, cov = 0.0, 0.0
            for q in range(back_start[p], back_start[p + 1]):
                a = back_weight[q] * back_alpha[q]
                acc += a * back_rgb[q, ch]
                cov += a
            x = (acc + (c1 - cov) * background[ch]) / c1
            out[p, ch] = ((c1 - s1) * x + (1.0 - c1) * background[ch]) / open_
