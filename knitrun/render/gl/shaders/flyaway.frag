// Strip renderer, GL backend: a flyaway pass (strip_shading.shade_flyaway), on the wider flyaway strips, once per
// flyaway layer. A fragment's depth is its own less the yarn radius; its sample mask keeps the samples where no
// regular strip is nearer than that (the regular pass's depth: the CPU's mask) and, from the second layer on
// (`peel`), where it lies beyond the previous layer's strip in the order (depth, curve), so that strips at one depth
// fall into successive layers; the depth test keeps the nearest strip of each sample among those: the layer-th
// nearest. Targets: A·L_fly and A·(1 − τ) per channel, τ the hair's forward fraction ā_f(θ_o^f), whose MSAA resolves
// are composited over the regular image, the farthest layer first, as C ← Σ w A L + (1 − min(1, Σ w A (1 − τ)))·C
// (SHADING.md §6); and the layer's (depth, curve) per sample, which the next layer peels beyond.

layout(location = 0) out vec4 out_radiance;
layout(location = 1) out vec4 out_cover;
layout(location = 2) out vec4 out_peel;  // (depth written, curve): what the next layer lies beyond

uniform float flyaway_half_width;
uniform float depth_tolerance;      // the largest regular yarn radius (pipeline: the flyaway mask's tolerance)
uniform sampler2D fly_tex0;         // the three variants: RGB premultiplied tangent, A coverage
uniform sampler2D fly_tex1;
uniform sampler2D fly_tex2;
uniform int fly_levels;
uniform usampler2D fly_variant;     // variant of (period index − VARIANT_OFFSET, curve): strip_shading.variant_of
uniform int use_glow;               // the body's glow on its hairs (Features.hair_glow; strip_shading.body_glow)
uniform vec3 glow_back;             // the body tube's R_Y and S_Y (yarn_bounce.tube_optics, the entry's colour)
uniform vec3 glow_forward;
uniform int hairs_behind;           // a share of the hairs seen over the body lie behind it (Features.hairs_behind)
uniform sampler2D coverage_tex;     // the regular strip's coverage (regular.frag's), for that share
uniform int texture_levels;
uniform sampler2DMS regular_depth;  // the regular pass's depth per sample
uniform sampler2DMS previous_layer; // the previous flyaway layer's out_peel per sample ((2, −1) where none)
uniform int peel;                   // 1 from the second flyaway layer on
const int VARIANT_OFFSET = 2;

vec4 fly_fetch(int layer, ivec2 texel, int level) {
    return layer == 0 ? texelFetch(fly_tex0, texel, level)
         : layer == 1 ? texelFetch(fly_tex1, texel, level) : texelFetch(fly_tex2, texel, level);
}

vec4 fly_bilinear(int layer, int level, float u, float v) {
    ivec2 size = textureSize(fly_tex0, level);
    int cols = size.x, rows = size.y;
    float x = u * float(cols) - 0.5;
    x = x - float(cols) * floor(x / float(cols));
    int j0 = min(int(floor(x)), cols - 1);
    int j1 = (j0 + 1) % cols;
    float fx = x - float(j0);
    float y = clamp((v + 1.0) * 0.5 * float(rows) - 0.5, 0.0, float(rows) - 1.0);
    int i0 = int(floor(y));
    int i1 = min(i0 + 1, rows - 1);
    float fy = y - float(i0);
    vec4 top = mix(fly_fetch(layer, ivec2(j0, i0), level), fly_fetch(layer, ivec2(j1, i0), level), fx);
    vec4 bottom = mix(fly_fetch(layer, ivec2(j0, i1), level), fly_fetch(layer, ivec2(j1, i1), level), fx);
    return mix(top, bottom, fy);
}

vec4 fly_sample(int layer, float level, float u, float v) {
    level = clamp(level, 0.0, float(fly_levels) - 1.0);
    int l0 = int(floor(level));
    int l1 = min(l0 + 1, fly_levels - 1);
    float f = level - float(l0);
    vec4 out_ = (1.0 - f) * fly_bilinear(layer, l0, u, v);
    if (f > 0.0)
        out_ += f * fly_bilinear(layer, l1, u, v);
    return out_;
}

// strip_shading.behind_share: of the hairs seen over the body where its coverage is c, the share behind it
float behind_share(float c) {
    c = clamp(c, 0.0, 1.0);
    return (1.0 - c) / (2.0 - c);
}

// the fraction of the light from w that reaches a hair at v_strip past its own yarn, where the ray toward the light
// crosses the tube: τ_Y + (1 − τ_Y) a_f(θ_i)^(n_cross_rest·chord), averaged over HAIR_DEPTHS depths spread over lo…hi
vec3 through_own_yarn(float v_strip, float lo, float hi, vec3 t, vec3 n, vec3 b, vec3 w) {
    float wb = dot(w, b), wn = dot(w, n);
    float across = sqrt(wb * wb + wn * wn);
    if (across < DEGENERATE) return vec3(1.0);
    wb /= across;
    wn /= across;
    int i0, i1;
    float fr;
    axis_cell(clamped_asin(dot(t, w)), -HALF_PI, HALF_PI, textureSize(ds_table, 0).x, false, i0, i1, fr);
    vec3 a_f = clamp(ds_row(R_A_F, i0, i1, fr), 0.0, 1.0);
    vec3 through = vec3(0.0);
    for (int k = 0; k < HAIR_DEPTHS; ++k) {
        float z = lo + (hi - lo) * (float(k) + 0.5) / float(HAIR_DEPTHS);
        float toward = v_strip * wb + z * wn;
        float miss = v_strip * v_strip + z * z - toward * toward;
        through += (toward >= 0.0 || miss >= 1.0) ? vec3(1.0)
                 : gap + (1.0 - gap) * pow(max(a_f, vec3(1e-30)), vec3(n_cross_rest * sqrt(1.0 - miss)));
    }
    return through / float(HAIR_DEPTHS);
}

// strip_shading._hair_light: the fraction of the light from w reaching a hair at v_strip. Beside the body its own
// yarn's transmittance over the depths −d…d; over the body Ψ^Fiber_G (mean RGB) of the regular strip there for the
// share 1 − behind in front of it, and the transmittance over the depths −d…−√(1 − v²) for the share behind it
vec3 hair_light(bool on_body, float behind, float reach, float v_strip, vec3 t, vec3 n, vec3 b, vec3 w) {
    float depth = sqrt(max(reach * reach - v_strip * v_strip, 0.0));
    if (!on_body) return through_own_yarn(v_strip, -depth, depth, t, n, b, w);
    vec3 xi, xi_s, psi;
    corrections(v_strip, t, n, b, 0.0, w, false, false, xi, xi_s, psi);  // Ψ^Fiber_G alone
    vec3 light = vec3((1.0 - behind) * fiber_lit(psi));
    if (behind > 0.0)
        light += behind * through_own_yarn(v_strip, -depth, -sqrt(1.0 - v_strip * v_strip), t, n, b, w);
    return light;
}

// strip_shading._glow_between: weight × the body's glow averaged over HAIR_DEPTHS depths spread over lo…hi
vec3 glow_between(float v_strip, float wb, float wn, float cos_l, float lo, float hi, float weight, vec3 albedo) {
    vec3 glow = vec3(0.0);
    if (hi <= lo || weight <= 0.0) return glow;
    for (int k = 0; k < HAIR_DEPTHS; ++k) {
        float z = lo + (hi - lo) * (float(k) + 0.5) / float(HAIR_DEPTHS);
        float rho = sqrt(v_strip * v_strip + z * z);
        if (rho <= 1.0) continue;
        // yarn_bounce.lambert_pair: g(α) and g(π − α) from cos α
        float c = clamp((v_strip * wb + z * wn) / rho, -1.0, 1.0);
        float a = acos(c), s = sqrt(1.0 - c * c);
        float g = 0.25 * PI * (s + (PI - a) * c), g_forward = 0.25 * PI * (s - a * c);
        float share = weight * cos_l * INV_PI2 * 4.0 * asin(min(1.0 / rho, 1.0)) / (4.0 * PI) / float(HAIR_DEPTHS);
        glow += share * (glow_back * g + glow_forward * g_forward) * albedo;
    }
    return glow;
}

// strip_shading.body_glow: the radiance toward the camera, per unit irradiance and visibility of a directional light
// from w, that a hair at v_strip returns of the light its own yarn's body scatters onto it: the tube's phase
// (R_Y g(α) + S_Y g(π − α))/π² at the hair times the tube's solid angle 4 asin(1/ρ) over 4π times the hair's albedo,
// averaged over HAIR_DEPTHS depths within the hair layer's reach; over the body (|v_strip| ≤ 1) over those in front
// of it with weight 1 − behind and those behind it with weight behind (SHADING.md §6)
vec3 body_glow(float reach, float v_strip, float behind, vec3 n, vec3 b, vec3 w, vec3 albedo) {
    float wb = dot(w, b), wn = dot(w, n);
    float cos_l = sqrt(wb * wb + wn * wn);
    if (cos_l < DEGENERATE) return vec3(0.0);
    wb /= cos_l;
    wn /= cos_l;
    float depth = sqrt(max(reach * reach - v_strip * v_strip, 0.0));
    if (abs(v_strip) > 1.0) return glow_between(v_strip, wb, wn, cos_l, -depth, depth, 1.0, albedo);
    float surface = sqrt(1.0 - v_strip * v_strip);
    return glow_between(v_strip, wb, wn, cos_l, surface, depth, 1.0 - behind, albedo)
         + glow_between(v_strip, wb, wn, cos_l, -depth, -surface, behind, albedo);
}

void main() {
    StripPoint sp = strip_point();
    float written = clamp((fin.depth - depth_tolerance) / far_plane, 0.0, 1.0);
    gl_FragDepth = written;
    int mask = 0;  // the samples where this strip may be the layer's (the header)
    for (int s = 0; s < samples; ++s) {
        bool kept = written < texelFetch(regular_depth, ivec2(gl_FragCoord.xy), s).r;
        if (peel != 0) {
            vec2 previous = texelFetch(previous_layer, ivec2(gl_FragCoord.xy), s).rg;
            kept = kept && (written > previous.x || (written == previous.x && float(fin.curve) > previous.y));
        }
        if (kept) mask |= 1 << s;
    }
    gl_SampleMask[0] = mask;
    out_peel = vec4(written, float(fin.curve), 0.0, 0.0);
    out_radiance = vec4(0.0);
    out_cover = vec4(0.0);
    if (!sp.drawn) return;
    ivec2 size0 = textureSize(fly_tex0, 0);
    int period_index = int(floor(sp.u));
    ivec2 vsize = textureSize(fly_variant, 0);
    int column = clamp(period_index + VARIANT_OFFSET, 0, vsize.x - 1);
    int layer = int(texelFetch(fly_variant, ivec2(column, fin.curve), 0).r);
    float level = mip_level(sp.footprint, period / float(size0.x), 2.0 * flyaway_half_width / float(size0.y));
    vec4 texel = fly_sample(layer, level, sp.u, sp.v);
    vec3 tf = texel.x * sp.t + texel.y * sp.b + texel.z * sp.n;
    if (length(tf) < 1e-6) return;
    tf = normalize(tf);
    float alpha = clamp(texel.a, 0.0, 1.0);
    float theta_o_f = clamped_asin(dot(tf, sp.wo));
    // forward fraction τ = ā_f(θ_o^f) (dual_scattering.forward_fraction)
    int i0, i1;
    float fr;
    axis_cell(theta_o_f, -HALF_PI, HALF_PI, textureSize(ds_table, 0).x, false, i0, i1, fr);
    vec3 tau = clamp(ds_row(R_A_F, i0, i1, fr), 0.0, 1.0);
    out_cover = vec4(alpha * (1.0 - tau), 1.0);
    Params p = yarn_params();
    // strip_shading.hair_bounce: the neighbouring yarns' light arriving here, returned evenly over the sphere
    vec3 rgb = yarn_bounce != 0 ? bounce_at(fin.segment, sp.s) * (p.a_r + p.a_tt + p.a_d) / (4.0 * PI) : vec3(0.0);
    out_radiance = vec4(alpha * rgb, 1.0);
    // the hair's own frame: x along t_f, y toward the camera in its normal plane; a hair seen end-on covers but
    // scatters nothing toward the camera
    vec3 ny = sp.wo - dot(sp.wo, tf) * tf;
    if (!(length(ny) >= DEGENERATE)) return;
    float spread2 = tangent_spread(texel.rgb, texel.a);
    float v_strip = sp.v * flyaway_half_width / radius;
    bool on_body = abs(v_strip) <= 1.0;
    float reach = flyaway_half_width / radius;
    float behind = 0.0;  // the share of the hairs seen here that lie behind the body (behind_share)
    if (on_body && hairs_behind != 0) {
        ivec2 body0 = textureSize(coverage_tex, 0);
        float body_level = mip_level(sp.footprint, period / float(body0.x), 2.0 * radius / float(body0.y));
        behind = behind_share(sample_mip(coverage_tex, texture_levels, body_level, sp.u, v_strip).r);
    }
    // the lights are looked up at the strip point, biased per light by how far it lies behind its own yarn's strip
    // (pipeline.strip_receivers with flyaway): its own yarn's shadow is hair_light's, not the map's
    vec3 half_width = cross(sp.wo, sp.t);
    vec3 offset = length(half_width) > 0.0 ? flyaway_half_width * sp.v * normalize(half_width) : vec3(0.0);
    for (int l = 0; l < n_lights; ++l) {
        vec3 w = light_dir[l];
        float phi_f = azimuth_difference(tf, sp.wo, w);
        float theta_i_f = clamped_asin(dot(tf, w));
        vec3 f = bcsdf_single(spread_params(p, spread2, phi_f), theta_i_f, theta_o_f, phi_f);
        float bias = shadow_bias + own_strip_depth(offset, sp.t, w);
        float lit = past_blockers(pcss(light_atlas, light_map[l], sp.position, bias, PCF_RADIUS)
                                  * canopy_at(l, fin.segment, sp.s), light_beyond(l, sp.position, bias));
        rgb += light_irradiance[l] * lit * hair_light(on_body, behind, reach, v_strip, sp.t, sp.n, sp.b, w) * f
             * cos(theta_i_f);
        if (use_glow != 0)  // the body's glow, lit as the hair is
            rgb += light_irradiance[l] * lit * body_glow(reach, v_strip, behind, sp.n, sp.b, w, p.a_r + p.a_tt + p.a_d);
    }
    for (int j = 0; j < n_lobes; ++j) {
        float vis = lobe_visibility(j, sp.position, shadow_bias + own_strip_depth(offset, sp.t, lobe_dir[j]));
        if (vis <= 0.0) continue;
        vec3 w = lobe_dir[j];
        float phi_f = azimuth_difference(tf, sp.wo, w);
        Params wide = spread_params(p, spread2, phi_f);
        float sigma_r = 2.0 * wide.beta_r;
        float mu_r = lobe_centre_at(wide.alpha_r, sigma_r, theta_o_f);
        vec3 i_m = im_kernel(wide, mu_r, sigma_r, cos2_normaliser(mu_r, sigma_r), theta_o_f, clamped_asin(dot(tf, w)),
                             -phi_f, lobe_lambda[j]);
        rgb += lobe_weight[j] * channel_visibility(vis)
             * hair_light(on_body, behind, reach, v_strip, sp.t, sp.n, sp.b, w) * i_m;
    }
    out_radiance = vec4(alpha * rgb, 1.0);
}
