// Strip renderer, GL backend: a yarn-level shadow map (knitrun/render/shadow_map.py): the view depth of the nearest
// strip seen from the light camera, one float per texel; the depth test keeps the nearest (linear depth).
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
out float out_depth;

void main() {
    out_depth = fin.depth;
    gl_FragDepth = clamp(fin.depth / far_plane, 0.0, 1.0);
}
