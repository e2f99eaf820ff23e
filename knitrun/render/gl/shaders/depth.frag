// Strip renderer, GL backend: a yarn-level shadow map (knitrun/render/shadow_map.py): the view depth of the nearest
// strip seen from the light camera, one float per texel; the depth test keeps the nearest (linear depth). The first
// layer also writes its peel floor, the depth plus its strip's half-width (the yarn's radius); with ``peel`` the
// pass draws the second yarn layer (shadow_map's ``behind``, strip_raster.rasterize_behind): only fragments beyond
// the first layer's floor at their texel count, and a texel the first layer left empty keeps none.
in FragmentData {
    centroid vec3 position;
    centroid vec3 tangent;
    centroid float arclength;
    centroid float v;
    centroid vec3 normal;
    centroid float depth;
    flat vec2 segment_s;
    flat int curve;
    flat int segment;
} fin;

uniform float far_plane;
uniform float strip_half_width;
uniform int peel;
uniform sampler2D floor_atlas;  // the first layer's floors, texel = the fragment's atlas texel (peel only)
layout(location = 0) out float out_depth;
layout(location = 1) out float out_floor;

void main() {
    if (peel != 0 && fin.depth <= texelFetch(floor_atlas, ivec2(gl_FragCoord.xy), 0).r) discard;
    out_depth = fin.depth;
    out_floor = fin.depth + strip_half_width;
    gl_FragDepth = clamp(fin.depth / far_plane, 0.0, 1.0);
}
