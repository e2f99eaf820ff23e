// Strip renderer, GL backend: the yarn-level bounce at the polyline points (yarn_bounce._vertex_bounce, the model of
// the yarn_bounce module docstring), one invocation per receiving point, its sums its own. The inputs are the CPU's
// (yarn_bounce.BounceYarns, yarn_bounce.sender_segments: the segments sorted by the cell of their midpoint on a uniform
// grid of cell `cell`); the phase tables are read by the pack's trilinear rule (yarn_bounce.phase_at, axis_cell).
// Single precision throughout; gl_bounce.py holds the buffers' layouts.

layout(local_size_x = 64) in;

const float PI = 3.14159265358979;

layout(std430, binding = 0) readonly buffer ReceiverPoint { vec4 receiver_point[]; };      // xyz, rest arc length
layout(std430, binding = 1) readonly buffer ReceiverTangent { vec4 receiver_tangent[]; };  // xyz unit, curve
layout(std430, binding = 2) readonly buffer ReceiverView { vec4 receiver_view[]; };        // toward the camera
layout(std430, binding = 3) readonly buffer ReceiverAlbedo { vec4 receiver_scattered[]; }; // R_Y + S_Y (RGB)
layout(std430, binding = 4) readonly buffer Curves { vec4 curve_info[]; };                 // radius, phase table
layout(std430, binding = 5) readonly buffer SenderStart { vec4 sender_start[]; };          // xyz, length
layout(std430, binding = 6) readonly buffer SenderAxis { vec4 sender_axis[]; };            // unit xyz, radius
layout(std430, binding = 7) readonly buffer SenderMid { vec4 sender_mid[]; };              // xyz, rest of the midpoint
layout(std430, binding = 8) readonly buffer SenderTangent { vec4 sender_tangent[]; };      // xyz, curve
layout(std430, binding = 9) readonly buffer SenderLight { vec4 sender_light[]; };          // per (segment, light):
//                                                                    E V_d (RGB), the light's θ_i against the tangent
layout(std430, binding = 10) readonly buffer CellStart { int cell_start[]; };
layout(std430, binding = 11) readonly buffer Phase { float phase[]; };  // (K, PHASE_THETA, PHASE_THETA, PHASE_PHI, 3)
layout(std430, binding = 12) writeonly buffer Bounce { vec4 bounce[]; };      // B (RGB), covered fraction f
layout(std430, binding = 13) writeonly buffer Arriving { vec4 arriving[]; };  // I (RGB)

uniform int n_points;
uniform int n_lights;
uniform vec3 light_dir[MAX_LIGHTS];
uniform ivec3 dims;
uniform vec3 origin;
uniform float cell;
uniform float reach_radii;

float longitudinal(vec3 t, vec3 w) { return asin(clamp(dot(w, t), -1.0, 1.0)); }

float azimuth(vec3 t, vec3 wo, vec3 wi) {  // fiber_frame.azimuth_difference: φ_o − φ_i about t
    vec3 o = wo - dot(wo, t) * t, i = wi - dot(wi, t) * t;
    return atan(dot(cross(i, o), t), dot(i, o));
}

void cell_of(float x, float lo, float hi, int n, bool repeat, out int i0, out int i1, out float f) {
    float t = (x - lo) / (hi - lo) * float(n) - 0.5;
    if (repeat) {
        t = t - float(n) * floor(t / float(n));
        i0 = int(floor(t));
        if (i0 >= n) { i0 -= n; t -= float(n); }
        i1 = (i0 + 1) % n;
        f = t - float(i0);
        return;
    }
    t = clamp(t, 0.0, float(n) - 1.0);
    i0 = int(floor(t));
    i1 = min(i0 + 1, n - 1);
    f = t - float(i0);
}

float ph(int k, int a, int b, int c, int ch) {
    return phase[(((k * PHASE_THETA + a) * PHASE_THETA + b) * PHASE_PHI + c) * 3 + ch];
}

vec3 phase_at(int k, float theta_i, float theta_o, float phi) {
    int a0, a1, b0, b1, c0, c1;
    float fa, fb, fc;
    cell_of(theta_i, -0.5 * PI, 0.5 * PI, PHASE_THETA, false, a0, a1, fa);
    cell_of(theta_o, -0.5 * PI, 0.5 * PI, PHASE_THETA, false, b0, b1, fb);
    cell_of(phi, -PI, PI, PHASE_PHI, true, c0, c1, fc);
    vec3 out_;
    for (int ch = 0; ch < 3; ch++) {
        float lo = (1.0 - fb) * ((1.0 - fc) * ph(k, a0, b0, c0, ch) + fc * ph(k, a0, b0, c1, ch)) +
                   fb * ((1.0 - fc) * ph(k, a0, b1, c0, ch) + fc * ph(k, a0, b1, c1, ch));
        float hi = (1.0 - fb) * ((1.0 - fc) * ph(k, a1, b0, c0, ch) + fc * ph(k, a1, b0, c1, ch)) +
                   fb * ((1.0 - fc) * ph(k, a1, b1, c0, ch) + fc * ph(k, a1, b1, c1, ch));
        out_[ch] = (1.0 - fa) * lo + fa * hi;
    }
    return out_;
}

float strip_solid_angle(vec3 x, vec3 u, float len, float width, float nearest) {  // yarn_bounce._strip_solid_angle
    float s_a = -dot(x, u);
    float h = max(length(-x - s_a * u), nearest);
    float s_b = s_a + len;
    return width / h * (s_b / sqrt(h * h + s_b * s_b) - s_a / sqrt(h * h + s_a * s_a));
}

void main() {
    int i = int(gl_GlobalInvocationID.x);
    if (i >= n_points) return;
    vec3 x = receiver_point[i].xyz;
    float rest = receiver_point[i].w;
    vec3 ti = receiver_tangent[i].xyz;
    int c = int(receiver_tangent[i].w);
    vec3 view = receiver_view[i].xyz;
    float reach = reach_radii * curve_info[c].x;
    int received = int(curve_info[c].y);
    float theta_view = longitudinal(ti, view);
    ivec3 g = ivec3(floor((x - origin) / cell));
    float total = 0.0;
    vec3 s = vec3(0.0), a = vec3(0.0);
    for (int ci = max(g.x - 1, 0); ci < min(g.x + 2, dims.x); ci++)
    for (int cj = max(g.y - 1, 0); cj < min(g.y + 2, dims.y); cj++)
    for (int ck = max(g.z - 1, 0); ck < min(g.z + 2, dims.z); ck++) {
        int key = (ci * dims.y + cj) * dims.z + ck;
        for (int m = cell_start[key]; m < cell_start[key + 1]; m++) {
            int cn = int(sender_tangent[m].w);
            if (cn == c && abs(sender_mid[m].w - rest) < reach) continue;  // this yarn itself: the tables' part
            vec3 d = x - sender_mid[m].xyz;  // from the neighbour to the receiver
            float dist = length(d);
            float len = sender_start[m].w;
            if (dist > reach || dist <= 0.0 || len <= 0.0) continue;
            float rn = sender_axis[m].w;
            float w = strip_solid_angle(x - sender_start[m].xyz, sender_axis[m].xyz, len, 2.0 * rn,
                                        CONTACT_RADII * rn);
            if (!(w > 0.0)) continue;
            total += w;
            vec3 away = d / dist;
            vec3 seen = phase_at(received, longitudinal(ti, -away), theta_view, azimuth(ti, view, -away));
            vec3 tj = sender_tangent[m].xyz;
            int sent = int(curve_info[cn].y);
            float theta_d = longitudinal(tj, away);
            for (int l = 0; l < n_lights; l++) {
                vec4 light = sender_light[m * n_lights + l];
                vec3 e = w * light.rgb * phase_at(sent, light.w, theta_d, azimuth(tj, away, light_dir[l]));
                a += e;
                s += e * seen;
            }
        }
    }
    if (total <= 0.0) {
        bounce[i] = vec4(0.0);
        arriving[i] = vec4(0.0);
        return;
    }
    float q = total / (4.0 * PI);
    float f = q < 1e-3 ? q * (1.0 - q * (0.5 - q / 6.0)) : 1.0 - exp(-q);  // −expm1(−q), accurate in single precision
    float share = 4.0 * PI * f / total;
    vec3 k = share / max(1.0 - clamp(receiver_scattered[i].rgb, 0.0, 1.0) * f, vec3(1e-6));
    bounce[i] = vec4(s * k, f);
    arriving[i] = vec4(a * k, 0.0);
}
