// Strip renderer, GL backend: what the regular and flyaway passes share about the yarn entry drawn (strip_shading's
// Look) and the lights (SHADING.md §3–§5).

// the yarn entry drawn (strip_shading's Look)
uniform float p_a_r[3];
uniform float p_a_tt[3];
uniform float p_a_d[3];
uniform float p_beta_r;
uniform float p_beta_tt;
uniform float p_gamma_tt;
uniform float p_alpha_r;
uniform float p_alpha_tt;
uniform float radius;
uniform float n_occluded;
uniform float n_cross;
uniform float n_cross_rest;    // n_cross with τ_Y split out (directional lights, hairs; SHADING.md §3)
uniform float gap;             // τ_Y: light past a blocking yarn between its fibers (yarn_look.gap_transmittance)
uniform float yarn_albedo;     // ρ_Y's luminance: the yarn-level inter-reflection's ρ, 0 without it
uniform vec3 yarn_albedo_rgb;  // ρ_Y per channel (zeros without it): each channel's visibility (channel_visibility)
uniform float shadow_bias;     // SHADOW_BIAS_RADII · radius

// directional lights
uniform int n_lights;
uniform vec3 light_dir[MAX_LIGHTS];
uniform vec3 light_irradiance[MAX_LIGHTS];
uniform ShadowMapInfo light_map[MAX_LIGHTS];
uniform sampler2D light_atlas;
// Features.two_blockers: the maps' second yarn layer, tiles as light_atlas's (depth.frag's peel)
uniform int two_blockers;
uniform sampler2D behind_atlas;
// the hair canopy (Features.hair_canopy; pipeline.canopy_at_vertices, computed on the CPU): per light and polyline
// point one texel (transmittance, rest arc length), light l's points from row l · canopy_rows, POLYLINE_ROW a row
uniform int hair_canopy;
uniform int canopy_rows;
uniform sampler2D canopy_tex;

// SRBF lobes and the multiple-scattering lights, cells of the sky (ms_lights.ms_cells: weights (C, J) in a texture)
uniform int n_lobes;
uniform vec3 lobe_dir[MAX_LOBES];
uniform float lobe_lambda[MAX_LOBES];
uniform vec3 lobe_weight[MAX_LOBES];
uniform ShadowMapInfo lobe_map[MAX_LOBES];
uniform sampler2D lobe_atlas;
uniform int n_clusters;
uniform vec3 cluster_dir[MAX_LOBES];
uniform vec3 cluster_irradiance[MAX_LOBES];
uniform sampler2D cluster_weights;

Params yarn_params() {
    return Params(vec3(p_a_r[0], p_a_r[1], p_a_r[2]), vec3(p_a_tt[0], p_a_tt[1], p_a_tt[2]),
                  vec3(p_a_d[0], p_a_d[1], p_a_d[2]), p_beta_r, p_beta_tt, p_gamma_tt, p_alpha_r, p_alpha_tt);
}

// strip_shading.past_blockers: a directional light's light past the other yarns unscattered,
// V + (V₂ − V) τ_Y + (1 − V₂) τ_Y², V₂ the fraction at most one yarn blocks (1 without two_blockers)
float past_blockers(float vis, float beyond) {
    return vis + (beyond - vis) * gap + (1.0 - beyond) * gap * gap;
}

// V₂ of light l at a receiver of that bias: PCSS on the second yarn layer with two_blockers, else 1
float light_beyond(int l, vec3 position, float bias) {
    return two_blockers != 0 ? pcss(behind_atlas, light_map[l], position, bias, PCF_RADIUS) : 1.0;
}

// light l's hair canopy interpolated by rest arc length s along segment i, as yarn_bounce.bounce_at_points; 1
// without the canopy
float canopy_at(int l, int i, float s) {
    if (hair_canopy == 0) return 1.0;
    int row = l * canopy_rows;
    vec2 a = texelFetch(canopy_tex, ivec2(i % POLYLINE_ROW, row + i / POLYLINE_ROW), 0).rg;
    vec2 b = texelFetch(canopy_tex, ivec2((i + 1) % POLYLINE_ROW, row + (i + 1) / POLYLINE_ROW), 0).rg;
    float ds = b.y - a.y;
    return mix(a.x, b.x, ds > 0.0 ? clamp((s - a.y) / ds, 0.0, 1.0) : 0.0);
}

// the yarn-level bounce (Features.yarn_bounce; pipeline.frame_bounce, computed on the CPU): per polyline point one
// texel (RGB, rest arc length), POLYLINE_ROW points a row; the regular pass reads the bounce radiance, the flyaway
// pass the neighbours' light arriving (Features.hair_bounce)
uniform int yarn_bounce;
uniform sampler2D bounce_tex;

// yarn_bounce.bounce_at_points: bounce_tex interpolated by rest arc length s along segment i (its first point)
vec3 bounce_at(int i, float s) {
    vec4 a = texelFetch(bounce_tex, ivec2(i % POLYLINE_ROW, i / POLYLINE_ROW), 0);
    vec4 b = texelFetch(bounce_tex, ivec2((i + 1) % POLYLINE_ROW, (i + 1) / POLYLINE_ROW), 0);
    float ds = b.w - a.w;
    return mix(a.rgb, b.rgb, ds > 0.0 ? clamp((s - a.w) / ds, 0.0, 1.0) : 0.0);
}

// interreflection.channel_visibility: V'_c of the visibility whose V' (inter-reflected with yarn_albedo) is vp
vec3 channel_visibility(float vp) {
    float r = clamp(yarn_albedo, 0.0, 1.0);
    vec3 rc = clamp(yarn_albedo_rgb, 0.0, 1.0);
    vp = clamp(vp, 0.0, 1.0);
    if (r <= 0.0 || r >= 1.0) return vec3(vp);
    float v = min(vp * (1.0 - r) / (1.0 - r * vp), 1.0);
    vec3 den = 1.0 - rc * (1.0 - v);
    return min(vec3(den.x > 0.0 ? v / den.x : 1.0, den.y > 0.0 ? v / den.y : 1.0, den.z > 0.0 ? v / den.z : 1.0),
               vec3(1.0));
}

// T̃_j: lobe j's PCSS visibility at a receiver of that bias, raised by the yarn-level inter-reflection
// (interreflection.interreflected_visibility)
float lobe_visibility(int j, vec3 position, float bias) {
    float vis = pcss(lobe_atlas, lobe_map[j], position, bias, PCF_RADIUS);
    if (yarn_albedo > 0.0) {
        float den = 1.0 - yarn_albedo * (1.0 - vis);
        vis = den > 0.0 ? vis / den : 1.0;
    }
    return vis;
}
