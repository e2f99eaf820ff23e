// Strip renderer, GL backend: the regular-fiber pass (strip_shading.shade_regular and the pipeline's view phase),
// one fragment per pixel and primitive; the MSAA resolve averages the samples of
// α·L + (1 − α)·background, which is the CPU renderer's resolve Σ w α L + (1 − Σ w α)·background.

in FragmentData {
    centroid vec3 position;
    centroid vec3 tangent;
    centroid float arclength;
    centroid float v;
    centroid vec3 normal;
    centroid float depth;
    flat vec2 segment_s;
    flat int curve;
} fin;

out vec4 out_colour;

// the camera (as in strip.geom)
uniform vec3 cam_position;
uniform vec3 cam_fwd;
uniform float ortho_height;
uniform float tan_half;
uniform int image_height;
uniform float far_plane;
uniform vec3 background;
uniform int samples;          // MSAA samples of the framebuffer
uniform vec2 sample_pattern[16];  // the CPU's sample positions in the pixel (x right, y down), strip_raster's

// the yarn entry drawn (strip_shading's Look)
uniform float p_a_r[3];
uniform float p_a_tt[3];
uniform float p_a_d[3];
uniform float p_beta_r;
uniform float p_beta_tt;
uniform float p_gamma_tt;
uniform float p_alpha_r;
uniform float p_alpha_tt;
uniform float period;
uniform float radius;
uniform float n_occluded;
uniform float n_cross;
uniform float twist_sign;
uniform float yarn_albedo;     // ρ_Y of the yarn-level inter-reflection, 0 without it
uniform float shadow_bias;     // SHADOW_BIAS_RADII · radius
uniform sampler2D tangent_tex;   // coverage-premultiplied strip-frame tangent (t, b, n), mip chain of the pack
uniform sampler2D coverage_tex;
uniform int texture_levels;

// directional lights
uniform int n_lights;
uniform vec3 light_dir[MAX_LIGHTS];
uniform vec3 light_irradiance[MAX_LIGHTS];
uniform ShadowMapInfo light_map[MAX_LIGHTS];
uniform sampler2D light_atlas;

// SRBF lobes and the multiple-scattering clusters (pipeline.ms_clusters: weights (C, J) in a texture)
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

void main() {
    // shaded where the CPU renderer shades it: at the first sample of its pattern (strip_raster.SAMPLE_PATTERNS, y
    // down) on this curve's strip, the CPU shading a pixel once per curve (|v| ≤ 1 and the rest arc length between
    // the segment's neighbouring points, this segment's attributes extended to it); the centroid of the covered
    // samples when none is (the driver's sample positions are not the CPU's)
    vec2 offset = vec2(0.0);
    bool found = false;
    for (int k = 0; k < samples && !found; ++k) {
        vec2 o = vec2(sample_pattern[k].x - 0.5, 0.5 - sample_pattern[k].y);
        float sk = interpolateAtOffset(fin.arclength, o), vk = interpolateAtOffset(fin.v, o);
        if (abs(vk) <= 1.0 && sk >= fin.segment_s.x && sk <= fin.segment_s.y) {
            offset = o;
            found = true;
        }
    }
    vec3 position = found ? interpolateAtOffset(fin.position, offset) : fin.position;
    vec3 t = normalize(found ? interpolateAtOffset(fin.tangent, offset) : fin.tangent);
    float arclength = found ? interpolateAtOffset(fin.arclength, offset) : fin.arclength;
    float v = clamp(found ? interpolateAtOffset(fin.v, offset) : fin.v, -1.0, 1.0);
    vec3 normal = found ? interpolateAtOffset(fin.normal, offset) : fin.normal;
    float depth = found ? interpolateAtOffset(fin.depth, offset) : fin.depth;
    vec3 wo = ortho_height > 0.0 ? -cam_fwd : normalize(cam_position - position);
    gl_FragDepth = clamp(fin.depth / far_plane, 0.0, 1.0);
    // strip frame (strip_shading._strip_frame); an edge-on point is not drawn: the background shows
    vec3 n = wo - dot(wo, t) * t;
    if (!(length(n) >= DEGENERATE)) { out_colour = vec4(background, 1.0); return; }
    n = normalize(n);
    vec3 b = cross(n, t);
    // the view phase (pipeline.view_phase_arclength)
    vec3 yn = normal - dot(normal, t) * t;
    yn = length(yn) > 1e-9 ? normalize(yn) : normal;
    float gamma = atan(dot(wo, cross(t, yn)), dot(wo, yn));
    float u = (arclength - twist_sign * gamma / (2.0 * PI) * period) / period;
    // textures
    float footprint = ortho_height > 0.0 ? ortho_height / float(image_height)
                                         : 2.0 * depth * tan_half / float(image_height);
    ivec2 size0 = textureSize(tangent_tex, 0);
    float level = mip_level(footprint, period / float(size0.x), 2.0 * radius / float(size0.y));
    float cov = sample_mip(coverage_tex, texture_levels, level, u, v).r;
    vec3 tex = sample_mip(tangent_tex, texture_levels, level, u, v).rgb;
    float alpha = clamp(cov, 0.0, 1.0);
    vec3 tf = tex.x * t + tex.y * b + tex.z * n;
    tf = length(tf) < 1e-6 ? t : normalize(tf);
    float spread2 = tangent_spread(tex, cov);
    float theta_o = clamped_asin(dot(t, wo));
    float theta_o_f = clamped_asin(dot(tf, wo));
    Params p = Params(vec3(p_a_r[0], p_a_r[1], p_a_r[2]), vec3(p_a_tt[0], p_a_tt[1], p_a_tt[2]),
                      vec3(p_a_d[0], p_a_d[1], p_a_d[2]), p_beta_r, p_beta_tt, p_gamma_tt, p_alpha_r, p_alpha_tt);
    vec3 rgb = vec3(0.0), xi, psi, total, back_direct, f_scatter;
    for (int l = 0; l < n_lights; ++l) {
        vec3 w = light_dir[l];
        corrections(v, t, n, b, theta_o, w, xi, psi);
        float vis = pcss(light_atlas, light_map[l], position, shadow_bias, PCF_RADIUS);
        float phi_f = azimuth_difference(tf, wo, w);
        ds_kernel(spread_params(p, spread2, phi_f), clamped_asin(dot(tf, w)), theta_o_f, phi_f,
                  n_occluded + (1.0 - vis) * n_cross, vis * fiber_lit(psi), true, total, back_direct, f_scatter);
        rgb += light_irradiance[l] * xi * total;
    }
    float lobe_vis[MAX_LOBES];
    for (int j = 0; j < n_lobes; ++j) {
        float vis = pcss(lobe_atlas, lobe_map[j], position, shadow_bias, PCF_RADIUS);
        if (yarn_albedo > 0.0) {  // interreflection.interreflected_visibility
            float den = 1.0 - yarn_albedo * (1.0 - vis);
            vis = den > 0.0 ? vis / den : 1.0;
        }
        lobe_vis[j] = vis;
        if (vis <= 0.0) continue;
        vec3 w = lobe_dir[j];
        corrections(v, t, n, b, theta_o, w, xi, psi);
        float theta_j_f = clamped_asin(dot(tf, w));
        float phi_f = azimuth_difference(tf, wo, w);
        Params wide = spread_params(p, spread2, phi_f);
        float sigma_r = 2.0 * wide.beta_r;
        float mu_r = lobe_centre_at(wide.alpha_r, sigma_r, theta_o_f);
        vec3 i_m = im_kernel(wide, mu_r, sigma_r, cos2_normaliser(mu_r, sigma_r), theta_o_f, theta_j_f, -phi_f,
                             lobe_lambda[j]);
        rgb += lobe_weight[j] * vis * xi * psi * i_m;
    }
    for (int c = 0; c < n_clusters; ++c) {
        vec3 w = cluster_dir[c];
        corrections(v, t, n, b, theta_o, w, xi, psi);
        float vis = 0.0;
        for (int j = 0; j < n_lobes; ++j)
            vis += texelFetch(cluster_weights, ivec2(j, c), 0).r * lobe_vis[j];
        float lit = vis * fiber_lit(psi);
        float theta_c_f = clamped_asin(dot(tf, w));
        float phi_f = azimuth_difference(tf, wo, w);
        ds_kernel(spread_params(p, spread2, phi_f), theta_c_f, theta_o_f, phi_f, n_occluded + (1.0 - vis) * n_cross,
                  lit, false, total, back_direct, f_scatter);
        rgb += cluster_irradiance[c] * xi * (lit * D_B * back_direct + f_scatter) * cos(theta_c_f);
    }
    out_colour = vec4(alpha * rgb + (1.0 - alpha) * background, 1.0);
}
