// Strip renderer, GL backend: segment (a, b) (with its neighbouring points) → the camera-facing quad p_a ∓ r b_a, p_b ∓ r b_b of
// knitrun/render/strip_raster.py (b_i = normalize(ω_o × t_i), ω_o toward the camera from p_i, −fwd when
// orthographic; v = −1 on the −b edge, +1 on the +b edge). Skipped like there: a zero-length segment, or an end
// where |ω_o × t| < 1e-6. The camera is given by its basis (camera.py): view coordinates of p are
// (right, up', fwd)·(p − position); clip coordinates follow the pinhole or orthographic projection, and the view
// depth travels to the fragment shader, which writes it (linear) as the depth.
layout(lines_adjacency) in;  // previous point, the segment (a, b), next point
layout(triangle_strip, max_vertices = 4) out;

in VertexData {
    vec3 position;
    vec3 tangent;
    float arclength;
    vec3 normal;
    flat int curve;
    flat int index;
} vin[];

out FragmentData {
    centroid vec3 position;    // world
    centroid vec3 tangent;     // interpolated vertex tangent (renormalised in the fragment shader)
    centroid float arclength;  // rest arc length
    centroid float v;          // across the strip, [-1, 1]
    centroid vec3 normal;      // the yarn frame's normal N
    centroid float depth;      // view depth (pinhole: distance from the camera, as strip_raster)
    flat vec2 segment_s;  // rest arc lengths from the previous point to the next (ascending): the curve around here
    flat int curve;
    flat int segment;     // the segment's first point among the frame's polyline points (strip_raster's segment)
} gout;

uniform vec3 cam_position;
uniform vec3 cam_right;
uniform vec3 cam_up;
uniform vec3 cam_fwd;
uniform float ortho_height;   // > 0: orthographic
uniform float tan_half;       // pinhole tan(fov/2)
uniform float aspect;         // width / height
uniform float near_plane;
uniform float far_plane;
uniform float strip_half_width;  // of the yarn entry drawn: its radius, or its flyaway strip's half-width

const float DEGENERATE_SIN = 1e-6;

vec4 clip_of(vec3 p) {
    vec3 d = p - cam_position;
    float x = dot(d, cam_right), y = dot(d, cam_up), z = dot(d, cam_fwd);
    float n = near_plane, f = far_plane;
    if (ortho_height > 0.0)
        return vec4(2.0 * x / (ortho_height * aspect), 2.0 * y / ortho_height, 2.0 * (z - n) / (f - n) - 1.0, 1.0);
    // the standard perspective clip z (linear in the vertex, so near-plane clipping is exact); the depth test uses
    // the linear depth the fragment shader writes
    return vec4(x / (tan_half * aspect), y / tan_half, ((f + n) * z - 2.0 * f * n) / (f - n), z);
}

bool half_width_dir(vec3 p, vec3 t, out vec3 b) {
    vec3 wo = ortho_height > 0.0 ? -cam_fwd : normalize(cam_position - p);
    vec3 c = cross(wo, t);
    float s = length(c);
    if (!(s >= DEGENERATE_SIN))
        return false;
    b = c / s;
    return true;
}

void emit(int i, vec3 b, float v) {
    vec3 p = vin[i].position + strip_half_width * v * b;
    gout.position = p;
    gout.tangent = vin[i].tangent;
    gout.arclength = vin[i].arclength;
    gout.v = v;
    gout.normal = vin[i].normal;
    gout.depth = ortho_height > 0.0 ? dot(p - cam_position, cam_fwd) : length(p - cam_position);
    gout.segment_s = vec2(min(vin[0].arclength, vin[3].arclength), max(vin[0].arclength, vin[3].arclength));
    gout.curve = vin[1].curve;
    gout.segment = vin[1].index;
    gl_Position = clip_of(p);
    EmitVertex();
}

void main() {
    if (distance(vin[1].position, vin[2].position) == 0.0)
        return;
    vec3 ba, bb;
    if (!half_width_dir(vin[1].position, vin[1].tangent, ba) || !half_width_dir(vin[2].position, vin[2].tangent, bb))
        return;
    // the triangles (a+, a−, b+) and (a−, b+, b−): the quad split along a− b+ as strip_raster splits it, so that a
    // quad that is not a parallelogram (a bend) interpolates its attributes as there
    emit(1, ba, 1.0);
    emit(1, ba, -1.0);
    emit(2, bb, 1.0);
    emit(2, bb, -1.0);
    EndPrimitive();
}
