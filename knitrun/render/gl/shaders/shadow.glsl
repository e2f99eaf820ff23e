// Strip renderer, GL backend: yarn-level visibility from a shadow map by PCSS, knitrun/render/shadow_map.py's
// _pcss line by line. Maps are tiles of an atlas texture (one per light kind); map k covers texels
// [origin_k, origin_k + size_k)² of its atlas. A texel no yarn covers, and any fetch outside the tile, reads
// NO_YARN (lit).

struct ShadowMapInfo {
    vec3 right, up, fwd;  // the light camera's view rows
    vec3 origin;          // its position
    float texel;          // scene units per texel
    float d_min;          // the nearest depth of the map
    float tan_angle;      // tan of the light's angular radius (0: a delta light)
    int size;             // texels per side
    ivec2 tile;           // the tile's first texel in the atlas
};

float atlas_fetch(sampler2D atlas, ShadowMapInfo m, int i, int j) {
    if (i < 0 || j < 0 || i >= m.size || j >= m.size) return NO_YARN;
    return texelFetch(atlas, m.tile + ivec2(j, i), 0).r;
}

float atlas_lit(sampler2D atlas, ShadowMapInfo m, int i, int j, float threshold) {
    return atlas_fetch(atlas, m, i, j) >= threshold ? 1.0 : 0.0;
}

float pcss(sampler2D atlas, ShadowMapInfo m, vec3 position, float bias, float pcf_radius) {
    vec3 d = position - m.origin;
    float x = dot(m.right, d), y = dot(m.up, d), z = dot(m.fwd, d);
    float size = float(m.size);
    float u = x / m.texel + 0.5 * size, w = 0.5 * size - y / m.texel;
    float reach = MAX_FILTER_TEXELS + 2.0;
    if (!(abs(z) < 1e30 && -reach < u && u < size + reach && -reach < w && w < size + reach))
        return 1.0;
    float threshold = z - bias;
    float r = min(max(pcf_radius, (z - m.d_min) * m.tan_angle / m.texel), MAX_FILTER_TEXELS);
    int n = min(MAX_TAPS, int(ceil(2.0 * r)) + 1);
    int found = 0;
    float total = 0.0;
    for (int a = 0; a < n; ++a)
        for (int b = 0; b < n; ++b) {
            float tu = u - r + (n > 1 ? 2.0 * r * float(a) / float(n - 1) : r);
            float tw = w - r + (n > 1 ? 2.0 * r * float(b) / float(n - 1) : r);
            float dd = atlas_fetch(atlas, m, int(floor(tw)), int(floor(tu)));
            if (dd < threshold) { found += 1; total += dd; }
        }
    if (found == 0) return 1.0;
    r = min(max(pcf_radius, (z - total / float(found)) * m.tan_angle / m.texel), MAX_FILTER_TEXELS);
    n = min(MAX_TAPS, max(1, int(ceil(2.0 * r))));
    float lit = 0.0;
    for (int a = 0; a < n; ++a)
        for (int b = 0; b < n; ++b) {
            float fu = u - r + 2.0 * r * (float(a) + 0.5) / float(n) - 0.5;
            float fw = w - r + 2.0 * r * (float(b) + 0.5) / float(n) - 0.5;
            int j = int(floor(fu)), i = int(floor(fw));
            float su = fu - float(j), sw = fw - float(i);
            float top = (1.0 - su) * atlas_lit(atlas, m, i, j, threshold) + su * atlas_lit(atlas, m, i, j + 1, threshold);
            float bottom = (1.0 - su) * atlas_lit(atlas, m, i + 1, j, threshold)
                         + su * atlas_lit(atlas, m, i + 1, j + 1, threshold);
            lit += (1.0 - sw) * top + sw * bottom;
        }
    return clamp(lit / float(n * n), 0.0, 1.0);
}

// shadow_map.own_strip_depth: how far toward the light d a receiver o off its yarn's axis (tangent t, unit) lies behind
// the strip the map draws its yarn as; 0 where the strip lies beyond it; capped at OWN_STRIP_MAX |o|
float own_strip_depth(vec3 o, vec3 t, vec3 d) {
    float c = dot(t, d);
    float toward = -(dot(o, d) - dot(o, t) * c);
    float cap = OWN_STRIP_MAX * length(o);
    float den = 1.0 - c * c;
    return clamp(den > 1e-12 ? toward / den : (toward > 0.0 ? cap : 0.0), 0.0, cap);
}
