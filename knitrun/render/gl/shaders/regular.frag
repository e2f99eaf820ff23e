// Strip renderer, GL backend: the regular-fiber pass (strip_shading.shade_regular and the pipeline's view phase),
// one fragment per pixel and primitive, writing (α·L, α) per sample; the MSAA resolves of it and of out_front give
// Σ w α L, Σ w α and the front strips' coverage c1, from which gl_renderer composes SHADING.md §6's resolve. Drawn
// twice with render.layers = 2: the front strips (the depth test keeps the nearest), then with ``behind`` the
// strips behind them (strip_raster.rasterize_behind: the sample mask keeps the samples where the fragment lies more
// than the front strip's radius behind it, its floor in out_front, and the depth test the nearest of those).

layout(location = 0) out vec4 out_colour;
layout(location = 1) out vec4 out_front;  // front pass: (1, the peel floor: view depth + radius, 0, 0)
uniform int behind;                       // 1: the pass of the strips behind the front ones
uniform sampler2DMS front_floor;          // the front pass's out_front per sample ((0, 3e38) where no strip)

// the regular-fiber textures of the entry
uniform sampler2D tangent_tex;   // coverage-premultiplied strip-frame tangent (t, b, n), mip chain of the pack
uniform sampler2D coverage_tex;
uniform int texture_levels;
uniform sampler2D detail_tex;    // fiber-level detail: directional, environment (yarn_look.fiber_detail), or ones
uniform int detail_levels;
uniform int surface_shadows;     // Features.surface_shadows: lights looked up on the tube surface seen
// the axial parallax (Features.parallax; pipeline.parallax_shift): the frame's polylines, POLYLINE_ROW points a row,
// per point three texels (x, y, z, rest arc length), (vertex tangent, 0), (yarn frame's N, 0); per curve one texel
// (its first point, its last point)
uniform int parallax;
uniform int fiber_bend;          // Features.fiber_bend: the same polyline texture gives the bend and stretch
uniform sampler2D polyline;
uniform sampler2D curve_bounds;
vec4 polyline_at(int i, int k) {
    return texelFetch(polyline, ivec2(3 * (i % POLYLINE_ROW) + k, i / POLYLINE_ROW), 0);
}

float segment_length(int j) {
    return distance(polyline_at(j, 0).xyz, polyline_at(j + 1, 0).xyz);
}

// move ``at`` (current length from point j along its segment of length len) onto the segment it falls in, at most
// PARALLAX_STEPS segments each way (the CPU walks on to the curve's ends, lo and hi)
void walk(inout float at, inout int j, inout float len, int lo, int hi) {
    for (int k = 0; k < PARALLAX_STEPS && at > len && j + 1 < hi; ++k) {
        at -= len;
        j += 1;
        len = segment_length(j);
    }
    for (int k = 0; k < PARALLAX_STEPS && at < 0.0 && j > lo; ++k) {
        j -= 1;
        len = segment_length(j);
        at += len;
    }
}

// the regular point read further along its curve where the ray meets the tube (pipeline.parallax_shift): the shift
// δ by PARALLAX_PASSES Newton steps on R(δ) = e·(c(s + δ) − c(s)) − h tan θ'_o (e·t'), walked in current length: its
// tangent turned by the vertex tangents' change, its rest arc length, strip frame and view phase there.
// A fragment's sample may lie past its own segment's end (strip_point extends a segment's attributes to its
// neighbours), where the CPU shades the neighbour's triangle: the point is first found on the segment it lies on.
void axial_parallax(inout StripPoint sp) {
    vec2 bounds = texelFetch(curve_bounds, ivec2(fin.curve % POLYLINE_ROW, fin.curve / POLYLINE_ROW), 0).xy;
    int lo = int(bounds.x), hi = int(bounds.y), j = fin.segment;
    vec3 e = sp.t - dot(sp.t, sp.wo) * sp.wo;  // the yarn's direction in the image
    if (j >= hi || !(length(e) > 0.0))
        return;
    e = normalize(e);
    vec4 a = polyline_at(j, 0), b = polyline_at(j + 1, 0);
    float d_rest = b.w - a.w, len = distance(a.xyz, b.xyz);
    float at = d_rest > 0.0 ? (sp.s - a.w) / d_rest * len : 0.0;
    walk(at, j, len, lo, hi);
    int i = j;
    float len_i = len, f0 = len > 0.0 ? clamp(at / len, 0.0, 1.0) : 0.0;
    vec3 h = mix(polyline_at(i, 1).xyz, polyline_at(i + 1, 1).xyz, f0);
    float start = dot(e, mix(polyline_at(i, 0).xyz, polyline_at(i + 1, 0).xyz, f0));
    float height = radius * sqrt(max(0.0, 1.0 - sp.v * sp.v));
    float max_shift = height * PARALLAX_MAX_SIN / sqrt(1.0 - PARALLAX_MAX_SIN * PARALLAX_MAX_SIN);
    vec3 t = sp.t;
    float shift = 0.0, seen = 0.0, f = f0;
    for (int pass = 0; pass < PARALLAX_PASSES; ++pass) {
        float sin_o = clamp(dot(t, sp.wo), -PARALLAX_MAX_SIN, PARALLAX_MAX_SIN), slope = dot(t, e);
        float residual = seen - height * sin_o / sqrt(1.0 - sin_o * sin_o) * slope;
        shift = clamp(shift - residual / max(slope, PARALLAX_MIN_SLOPE), -max_shift, max_shift);
        j = i;
        len = len_i;
        at = f0 * len + shift;
        walk(at, j, len, lo, hi);
        f = len > 0.0 ? clamp(at / len, 0.0, 1.0) : 0.0;
        seen = dot(e, mix(polyline_at(j, 0).xyz, polyline_at(j + 1, 0).xyz, f)) - start;
        vec3 m = sp.t + mix(polyline_at(j, 1).xyz, polyline_at(j + 1, 1).xyz, f) - h;
        t = length(m) > 0.0 ? normalize(m) : sp.t;
    }
    sp.t = t;
    vec4 pj = polyline_at(j, 0), pk = polyline_at(j + 1, 0);
    sp.s = pj.w + f * (pk.w - pj.w);
    sp.segment = j;
    strip_frame(sp);
    sp.u = view_phase_u(sp.t, sp.wo, mix(polyline_at(j, 2).xyz, polyline_at(j + 1, 2).xyz, f), sp.s);
}

// strip_shading.fiber_bend (pipeline.segment_bend): the scale a = max(λ (1 − κ·o), MIN_ALONG) of the fibers' tangent
// along the yarn on the point's segment j: κ = (t_{j+1} − t_j)/L_j from the vertex tangents, λ = L_j/(σ_{j+1} − σ_j),
// o = r (v b + √(1 − v²) n) the tube surface seen; 1 on a closed curve's closing segment and on a degenerate segment.
// Without the parallax the segment is the fragment's own (the CPU's is the one its sample lies on: they differ at a
// joint, by a sample)
float along_scale(StripPoint sp) {
    vec2 bounds = texelFetch(curve_bounds, ivec2(fin.curve % POLYLINE_ROW, fin.curve / POLYLINE_ROW), 0).xy;
    int j = sp.segment;
    if (j >= int(bounds.y))
        return 1.0;
    vec4 a = polyline_at(j, 0), b = polyline_at(j + 1, 0);
    float len = distance(a.xyz, b.xyz), d_rest = b.w - a.w;
    if (!(len > 0.0) || !(d_rest > 0.0))
        return 1.0;
    vec3 kappa = (polyline_at(j + 1, 1).xyz - polyline_at(j, 1).xyz) / len;
    vec3 o = radius * (sp.v * sp.b + sqrt(max(0.0, 1.0 - sp.v * sp.v)) * sp.n);
    return max(len / d_rest * (1.0 - dot(kappa, o)), MIN_ALONG);
}

void main() {
    StripPoint sp = strip_point();
    float bounce_s = sp.s;  // the bounce and the canopy are read where the point lies, before the parallax (as on
                            // the CPU)
    vec3 raster_t = sp.t;  // and the lights' bias takes the rasterizer's tangent (pipeline.strip_receivers)
    if (parallax != 0 && sp.drawn)
        axial_parallax(sp);
    gl_FragDepth = clamp(fin.depth / far_plane, 0.0, 1.0);
    out_front = vec4(1.0, fin.depth + radius, 0.0, 0.0);
    int mask = -1;  // every sample the strip covers; behind the front strips, those beyond their floor
    if (behind != 0) {
        mask = 0;
        for (int s = 0; s < samples; ++s)
            if (fin.depth > texelFetch(front_floor, ivec2(gl_FragCoord.xy), s).g) mask |= 1 << s;
    }
    gl_SampleMask[0] = mask;  // written on every path (else undefined)
    out_colour = vec4(0.0);
    if (!sp.drawn) return;  // edge-on: not drawn, what lies behind shows
    vec3 t = sp.t, n = sp.n, b = sp.b, wo = sp.wo;
    float u = sp.u, v = sp.v;
    // textures
    ivec2 size0 = textureSize(tangent_tex, 0);
    float level = mip_level(sp.footprint, period / float(size0.x), 2.0 * radius / float(size0.y));
    float cov = sample_mip(coverage_tex, texture_levels, level, u, v).r;
    vec3 tex = sample_mip(tangent_tex, texture_levels, level, u, v).rgb;
    float alpha = clamp(cov, 0.0, 1.0);
    float along = fiber_bend != 0 ? along_scale(sp) : 1.0;
    vec3 tf = along * tex.x * t + tex.y * b + tex.z * n;
    tf = length(tf) < 1e-6 ? t : normalize(tf);
    float spread2 = tangent_spread(tex, cov);
    float theta_o = clamped_asin(dot(t, wo));
    float theta_o_f = clamped_asin(dot(tf, wo));
    // where the lights are looked up: the strip point, or the tube surface seen there (pipeline.strip_receivers)
    // biased per light by how far it lies behind its own strip (pipeline.strip_receivers, pipeline.receiver_bias):
    // its offset from the axis, v r along the strip's half-width direction and the surface's height
    vec3 surface = surface_shadows != 0 ? radius * sqrt(max(1.0 - v * v, 0.0)) * wo : vec3(0.0);
    vec3 half_width = cross(wo, raster_t);
    vec3 offset = surface + (length(half_width) > 0.0 ? radius * v * normalize(half_width) : vec3(0.0));
    vec3 receiver = sp.position + surface;
    Params p = yarn_params();
    vec3 rgb = vec3(0.0), ambient = vec3(0.0);  // directional, environment
    vec3 xi, xi_s, psi, total, back_direct, f_scatter, single;
    for (int l = 0; l < n_lights; ++l) {
        vec3 w = light_dir[l];
        corrections(v, t, n, b, theta_o, w, true, true, xi, xi_s, psi);
        float bias = shadow_bias + own_strip_depth(offset, raster_t, w);
        // the canopy dims V alone (pipeline.Renderer): what it keeps off passes the bodies as under one blocker
        float vis = pcss(light_atlas, light_map[l], receiver, bias, PCF_RADIUS) * canopy_at(l, fin.segment, bounce_s);
        float beyond = light_beyond(l, receiver, bias);
        float phi_f = azimuth_difference(tf, wo, w);
        // strip_shading.yarns_crossed: (V₂ − V) + 2 (1 − V₂) yarns between the point and the light
        ds_kernel(spread_params(p, spread2, phi_f), clamped_asin(dot(tf, w)), theta_o_f, phi_f,
                  n_occluded + (2.0 - vis - beyond) * n_cross_rest, past_blockers(vis, beyond) * fiber_lit(psi), true,
                  total, back_direct, f_scatter, single);
        // single scattering (D f cos θ_i) by its ξ, the rest by multiple scattering's (strip_shading.shade_regular)
        rgb += light_irradiance[l] * (xi_s * single + xi * (total - single));
    }
    float lobe_vis[MAX_LOBES];
    for (int j = 0; j < n_lobes; ++j) {
        float vis = lobe_visibility(j, receiver, shadow_bias + own_strip_depth(offset, raster_t, lobe_dir[j]));
        lobe_vis[j] = vis;
        if (vis <= 0.0) continue;
        vec3 w = lobe_dir[j];
        corrections(v, t, n, b, theta_o, w, true, false, xi, xi_s, psi);
        float theta_j_f = clamped_asin(dot(tf, w));
        float phi_f = azimuth_difference(tf, wo, w);
        Params wide = spread_params(p, spread2, phi_f);
        float sigma_r = 2.0 * wide.beta_r;
        float mu_r = lobe_centre_at(wide.alpha_r, sigma_r, theta_o_f);
        vec3 i_m = im_kernel(wide, mu_r, sigma_r, cos2_normaliser(mu_r, sigma_r), theta_o_f, theta_j_f, -phi_f,
                             lobe_lambda[j]);
        ambient += lobe_weight[j] * channel_visibility(vis) * xi_s * psi * i_m;  // single scattering
    }
    for (int c = 0; c < n_clusters; ++c) {
        vec3 w = cluster_dir[c];
        corrections(v, t, n, b, theta_o, w, false, true, xi, xi_s, psi);
        float vis = 0.0;
        for (int j = 0; j < n_lobes; ++j)
            vis += texelFetch(cluster_weights, ivec2(j, c), 0).r * lobe_vis[j];
        float lit = vis * fiber_lit(psi);
        float theta_c_f = clamped_asin(dot(tf, w));
        float phi_f = azimuth_difference(tf, wo, w);
        ds_kernel(spread_params(p, spread2, phi_f), theta_c_f, theta_o_f, phi_f, n_occluded + (1.0 - vis) * n_cross,
                  lit, false, total, back_direct, f_scatter, single);
        // the channel's share of the light past the neighbours (interreflection's docstring)
        vec3 tint = vis > 0.0 ? channel_visibility(vis) / vis : vec3(1.0);
        ambient += cluster_irradiance[c] * xi * (lit * D_B * back_direct + f_scatter) * cos(theta_c_f) * tint;
    }
    if (yarn_bounce != 0)
        rgb += bounce_at(fin.segment, bounce_s);
    vec2 detail = sample_mip(detail_tex, detail_levels, level, u, v).rg;
    rgb = rgb * detail.r + ambient * detail.g;
    out_colour = vec4(alpha * rgb, alpha);
}
