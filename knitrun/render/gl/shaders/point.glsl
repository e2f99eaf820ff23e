// Strip renderer, GL backend: a fragment's shading point, shared by the regular and flyaway passes: the attributes
// at the sample where the CPU renderer shades (SHADING.md §1), the strip frame, the view phase, the pixel footprint.

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

// the camera (as in strip.geom)
uniform vec3 cam_position;
uniform vec3 cam_fwd;
uniform float ortho_height;
uniform float tan_half;
uniform int image_height;
uniform float far_plane;
uniform int samples;              // MSAA samples of the framebuffer
uniform vec2 sample_pattern[16];  // the CPU's sample positions in the pixel (x right, y down), strip_raster's
uniform float period;             // texture period (scene units)
uniform float twist_sign;

struct StripPoint {
    vec3 position, t, n, b, wo;
    float s, u, v, depth, footprint;  // s: the rest arc length; u: the texture coordinate (the view phase's)
    bool drawn;  // false when edge-on (|ω_o − (ω_o·t)t| < DEGENERATE)
    int segment;  // the polyline segment (its first point) the point's attributes come from
};

// the strip frame of tangent t seen from wo (strip_shading._strip_frame)
void strip_frame(inout StripPoint p) {
    vec3 n = p.wo - dot(p.wo, p.t) * p.t;
    p.drawn = length(n) >= DEGENERATE;
    p.n = p.drawn ? normalize(n) : n;
    p.b = cross(p.n, p.t);
}

// the texture coordinate u of rest arc length s, seen from the azimuth of the yarn frame's normal N
// (pipeline.view_phase_arclength)
float view_phase_u(vec3 t, vec3 wo, vec3 normal, float s) {
    vec3 yn = normal - dot(normal, t) * t;
    yn = length(yn) > 1e-9 ? normalize(yn) : normal;
    float gamma = atan(dot(wo, cross(t, yn)), dot(wo, yn));
    return (s - twist_sign * gamma / (2.0 * PI) * period) / period;
}

StripPoint strip_point() {
    StripPoint p;
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
    p.position = found ? interpolateAtOffset(fin.position, offset) : fin.position;
    p.t = normalize(found ? interpolateAtOffset(fin.tangent, offset) : fin.tangent);
    float arclength = found ? interpolateAtOffset(fin.arclength, offset) : fin.arclength;
    p.v = clamp(found ? interpolateAtOffset(fin.v, offset) : fin.v, -1.0, 1.0);
    vec3 normal = found ? interpolateAtOffset(fin.normal, offset) : fin.normal;
    p.depth = found ? interpolateAtOffset(fin.depth, offset) : fin.depth;
    p.wo = ortho_height > 0.0 ? -cam_fwd : normalize(cam_position - p.position);
    p.footprint = ortho_height > 0.0 ? ortho_height / float(image_height)
                                     : 2.0 * p.depth * tan_half / float(image_height);
    strip_frame(p);
    p.s = arclength;
    p.u = view_phase_u(p.t, p.wo, normal, arclength);
    p.segment = fin.segment;
    return p;
}
