// Strip renderer, GL backend: the resolve of SHADING.md §6 on the resolved (one sample a pixel) targets, one pixel
// per fragment. Stage 0: the regular strips over the background, C = Σ w α L + (c1 − s1)·X + (1 − c1)·background,
// X the layer behind (with render.layers = 2) over the background averaged over the samples the front covers, the
// background without it. Stage 1: one flyaway layer over the image so far, C ← Σ w A L + (1 − min(1, Σ w A (1 − τ)))·C
// (gl_renderer._composite draws them the farthest first). Stage 2, for a window (gl_renderer._display): the image so
// far tone-mapped as data_formats.images.tonemap writes PNGs (2^exposure, clipped to [0, 1], the sRGB curve; the 8-bit
// target rounds), a non-finite pixel drawn black and flagged in `finite_flag` for the renderer to raise on.

layout(location = 0) out vec4 out_colour;
uniform int stage;
uniform vec3 background;
uniform int has_behind;
uniform sampler2D regular;       // (Σ w α L, s1 = Σ w α) of the front strips
uniform sampler2D front;         // c1, the front strips' coverage, in .r
uniform sampler2D behind;        // (Σ_back w α L, Σ_back w α) of the strips behind
uniform sampler2D fly_radiance;  // Σ w A L of a flyaway layer
uniform sampler2D fly_cover;     // Σ w A (1 − τ)
uniform sampler2D previous;      // the image so far
uniform float exposure_scale;    // stage 2: 2^exposure
layout(std430, binding = 0) buffer Flag { uint finite_flag; };  // stage 2: 1 once a pixel was not finite

vec3 srgb(vec3 linear) {
    vec3 x = clamp(linear * exposure_scale, 0.0, 1.0);
    return mix(1.055 * pow(x, vec3(1.0 / 2.4)) - 0.055, 12.92 * x, lessThanEqual(x, vec3(0.0031308)));
}

void main() {
    ivec2 p = ivec2(gl_FragCoord.xy);
    if (stage == 0) {
        vec4 reg = texelFetch(regular, p, 0);
        float c1 = texelFetch(front, p, 0).r;
        vec3 x = background;
        if (has_behind != 0 && c1 > 0.0) {
            vec4 back = texelFetch(behind, p, 0);
            x = (back.rgb + (c1 - back.a) * background) / c1;
        }
        out_colour = vec4(reg.rgb + (c1 - reg.a) * x + (1.0 - c1) * background, 1.0);
    } else if (stage == 2) {
        vec3 c = texelFetch(previous, p, 0).rgb;
        if (any(isnan(c)) || any(isinf(c))) {
            atomicOr(finite_flag, 1u);
            c = vec3(0.0);
        }
        out_colour = vec4(srgb(c), 1.0);
    } else {
        vec3 cover = min(texelFetch(fly_cover, p, 0).rgb, vec3(1.0));
        out_colour = vec4(texelFetch(fly_radiance, p, 0).rgb + (1.0 - cover) * texelFetch(previous, p, 0).rgb, 1.0);
    }
}
