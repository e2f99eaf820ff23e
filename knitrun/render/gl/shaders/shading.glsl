// Strip renderer, GL backend: the shading model of data_formats/SHADING.md as knitrun/render/strip_shading.py
// implements it, in GLSL, function by function.
// Every function names the Python definition it follows; ASSET_PACK.md §3 gives the angles (θ = asin(ω·t),
// φ = φ_o − φ_i), §4.2–4.3 the table grids and interpolation, §8 the textures. Single precision throughout; the
// CPU renderer (float64) is the reference the tests compare against (tests/test_gl_render.py).
// The Python side prepends "#version", the constants of gl_constants() (D_F, D_B, the Gauss–Legendre nodes, the
// array bounds) and appends the pass's main().

const float PI = 3.14159265358979;
const float HALF_PI = 1.57079632679490;
const float INV_PI = 0.318309886183791;
const float INV_PI2 = 0.101321183642338;
const float SQRT_2PI = 2.50662827463100;

// ---- the fiber BCSDF's parameters (fiber_bcsdf.P_*) --------------------------------------------------------------

struct Params {
    vec3 a_r, a_tt, a_d;
    float beta_r, beta_tt, gamma_tt, alpha_r, alpha_tt;
};

// fiber_frame.wrap_angle: into [−π, π)
float wrap_angle(float x) { return mod(x + PI, 2.0 * PI) - PI; }

float clamped_asin(float x) { return asin(clamp(x, -1.0, 1.0)); }

// fiber_frame.azimuth_difference: φ = φ_o − φ_i about t
float azimuth_difference(vec3 t, vec3 wo, vec3 wi) {
    vec3 o = wo - dot(wo, t) * t;
    vec3 i = wi - dot(wi, t) * t;
    return atan(dot(cross(i, o), t), dot(i, o));
}

// tanh without overflow for large arguments
float safe_tanh(float x) {
    float e = exp(-2.0 * abs(x));
    return sign(x) * (1.0 - e) / (1.0 + e);
}

// ---- longitudinal lobes (fiber_bcsdf) -----------------------------------------------------------------------------

float gauss(float theta, float mu, float sigma) {
    float d = (theta - mu) / sigma;
    return exp(-0.5 * d * d);
}

// fiber_bcsdf.lobe_centre_at
float lobe_centre_at(float alpha, float sigma, float theta_o) {
    return clamp(2.0 * alpha - theta_o, -HALF_PI - 4.0 * sigma, HALF_PI + 4.0 * sigma);
}

// fiber_bcsdf.cos2_normaliser: Z = ∫ exp(−(θ − μ)²/2σ²) cos²θ dθ over the lobe's window μ ± 9σ clipped to
// [−π/2, π/2]; closed form when the window lies inside, else GL_NODES-point Gauss–Legendre over the clipped window
// (the CPU takes Faddeeva tails for 0.03 ≤ σ < 0.5: the same integral)
float cos2_normaliser(float mu, float sigma) {
    float lo = mu - LOBE_WINDOW * sigma, hi = mu + LOBE_WINDOW * sigma;
    if (lo >= -HALF_PI && hi <= HALF_PI)
        return 0.5 * SQRT_2PI * sigma * (1.0 + exp(-2.0 * sigma * sigma) * cos(2.0 * mu));
    lo = max(lo, -HALF_PI);
    hi = min(hi, HALF_PI);
    float half_len = 0.5 * (hi - lo), mid = 0.5 * (hi + lo), z = 0.0;
    for (int k = 0; k < GL_NODES; ++k) {
        float t = mid + half_len * GL_X[k];
        float c = cos(t);
        z += GL_W[k] * gauss(t, mu, sigma) * c * c;
    }
    return z * half_len;
}

float tt_logistic_scale(float gamma_tt) { return gamma_tt * 1.73205080756888 / PI; }

// fiber_bcsdf.logistic_trimmed
float logistic_trimmed(float x, float s) {
    float e = exp(-abs(x) / s);
    float norm = 1.0 - 2.0 / (1.0 + exp(PI / s));
    return e / (s * (1.0 + e) * (1.0 + e)) / norm;
}

// ---- dual scattering (knitrun/shading/dual_scattering.py) ----------------------------------------------------------

float tt_cdf(float x, float s) {
    float t = safe_tanh(0.5 * PI / s);
    return 0.5 * (safe_tanh(0.5 * x / s) + t) / t;
}

float n_tt_global(float phi, float gamma_tt) {
    float s = tt_logistic_scale(gamma_tt);
    float c = wrap_angle(phi - PI);
    float lo = c - HALF_PI, hi = c + HALF_PI, mass;
    if (hi > PI)
        mass = 1.0 - tt_cdf(lo, s) + tt_cdf(hi - 2.0 * PI, s);
    else if (lo < -PI)
        mass = tt_cdf(hi, s) + 1.0 - tt_cdf(lo + 2.0 * PI, s);
    else
        mass = tt_cdf(hi, s) - tt_cdf(lo, s);
    return max(mass, 0.0) * INV_PI;
}

float n_back(float phi) { return abs(wrap_angle(phi)) < HALF_PI ? INV_PI : 0.0; }
float n_back_global(float phi) { return (PI - abs(wrap_angle(phi))) * INV_PI2; }

// dual_scattering._lobe: M(α, w) centred by lobe_centre_at, normalised over cos²θ_i
float ds_lobe(float theta_i, float theta_o, float alpha, float width) {
    float sigma = 2.0 * max(width, WIDTH_FLOOR);
    float mu = lobe_centre_at(alpha, sigma, theta_o);
    float g = gauss(theta_i, mu, sigma);
    return g > 0.0 ? g / cos2_normaliser(mu, sigma) : 0.0;
}

// ---- table lookups (table_lookup.axis_cell, ASSET_PACK.md §4.3) ------------------------------------------------------

void axis_cell(float x, float lo, float hi, int n, bool repeat_axis, out int i0, out int i1, out float f) {
    float t = (x - lo) / (hi - lo) * float(n) - 0.5;
    if (repeat_axis) {
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

// the runtime DS tables (dual_scattering.pack_tables: rows a_f, beta_f, A_b, Delta_b, sigma_b over θ), one texel row
// each of ds_table
uniform sampler2D ds_table;
const int R_A_F = 0, R_BETA_F = 1, R_A_BACK = 2, R_DELTA_B = 3, R_SIGMA_B = 4;

vec3 ds_row(int row, int i0, int i1, float f) {
    return mix(texelFetch(ds_table, ivec2(i0, row), 0).rgb, texelFetch(ds_table, ivec2(i1, row), 0).rgb, f);
}

// fiber_bcsdf.evaluate for the view (sin θ_o, cos θ_o, 0) and light (θ_i, φ), as dual_scattering.ds_kernel calls it
vec3 bcsdf_single(Params p, float theta_i, float theta_o, float phi) {
    float sigma_r = 2.0 * p.beta_r, sigma_tt = 2.0 * p.beta_tt;
    float mu_r = lobe_centre_at(p.alpha_r, sigma_r, theta_o), mu_tt = lobe_centre_at(p.alpha_tt, sigma_tt, theta_o);
    float m_r = gauss(theta_i, mu_r, sigma_r) / cos2_normaliser(mu_r, sigma_r);
    float m_tt = gauss(theta_i, mu_tt, sigma_tt) / cos2_normaliser(mu_tt, sigma_tt);
    float n_tt = logistic_trimmed(wrap_angle(wrap_angle(phi) - PI), tt_logistic_scale(p.gamma_tt));
    return p.a_r * m_r * (0.5 * INV_PI) + p.a_tt * m_tt * n_tt + p.a_d * INV_PI2;
}

// dual_scattering.ds_kernel: L_o/E (total), f_back^direct and F_scatter (its rows K_TOTAL, K_F_BACK_DIRECT,
// K_F_SCATTER) and the single scattering in the total, direct f cos θ_i (strip_shading.shade_regular's ``single``);
// with_single false leaves f out
void ds_kernel(Params p, float theta_i, float theta_o, float phi, float n_front, float direct, bool with_single,
               out vec3 total, out vec3 back_direct, out vec3 f_scatter, out vec3 single) {
    int i0, i1;
    float fr;
    axis_cell(theta_i, -HALF_PI, HALF_PI, textureSize(ds_table, 0).x, false, i0, i1, fr);
    theta_o = clamped_asin(sin(theta_o));
    float cos_i = cos(theta_i);
    vec3 f_single = vec3(0.0);
    if (direct > 0.0 && with_single)
        f_single = bcsdf_single(p, theta_i, theta_o, phi);
    float n_r_g = 0.5 * INV_PI;
    float n_tt_g = n_tt_global(phi, p.gamma_tt);
    float nb = n_back(phi), nb_g = n_back_global(phi);
    vec3 a_f = ds_row(R_A_F, i0, i1, fr), beta_f = ds_row(R_BETA_F, i0, i1, fr);
    vec3 a_back = ds_row(R_A_BACK, i0, i1, fr), delta_b = ds_row(R_DELTA_B, i0, i1, fr);
    vec3 sigma_b = ds_row(R_SIGMA_B, i0, i1, fr);
    for (int ch = 0; ch < 3; ++ch) {
        float af = clamp(a_f[ch], 0.0, 1.0);
        float t_f = D_F * (n_front > 0.0 ? pow(af, n_front) : 1.0);
        float s2 = n_front * beta_f[ch] * beta_f[ch];
        float bd = nb > 0.0 ? a_back[ch] * ds_lobe(theta_i, theta_o, delta_b[ch], sigma_b[ch]) * nb : 0.0;
        float bs = 0.0, ss = 0.0;
        if (direct < 1.0) {
            bs = a_back[ch] * ds_lobe(theta_i, theta_o, delta_b[ch], sqrt(sigma_b[ch] * sigma_b[ch] + s2)) * nb_g;
            ss = p.a_r[ch] * ds_lobe(theta_i, theta_o, p.alpha_r, sqrt(p.beta_r * p.beta_r + s2)) * n_r_g
               + p.a_tt[ch] * n_tt_g * ds_lobe(theta_i, theta_o, p.alpha_tt, sqrt(p.beta_tt * p.beta_tt + s2))
               + p.a_d[ch] * INV_PI2;
        }
        float fd = direct * (f_single[ch] + D_B * bd);
        float fs = (1.0 - direct) * t_f * (ss + D_B * bs);
        back_direct[ch] = bd;
        f_scatter[ch] = fs;
        total[ch] = (fd + fs) * cos_i;
        single[ch] = direct * f_single[ch] * cos_i;
    }
}

// fiber_bcsdf.spread_params: widths widened by a tangent spread (rad²) seen at azimuth difference φ
Params spread_params(Params p, float spread2, float phi) {
    float c = cos(0.5 * phi);
    float grow = spread2 * c * c;
    p.beta_r = sqrt(p.beta_r * p.beta_r + grow);
    p.beta_tt = sqrt(p.beta_tt * p.beta_tt + grow);
    return p;
}

// ---- I_M (knitrun/shading/im_lookup.py) ------------------------------------------------------------------------------

// im_lookup.i0e: e^{−x} I_0(x), x ≥ 0
float i0e(float x) {
    if (x <= 20.0) {
        float q = 0.25 * x * x, term = 1.0, total = 1.0;
        for (int k = 1; k < 200; ++k) {
            term *= q / float(k * k);
            total += term;
            if (term <= 1e-9 * total) break;
        }
        return total * exp(-x);
    }
    float term = 1.0, total = 1.0;
    for (int k = 1; k < 200; ++k) {
        if (!(term > 1e-9 * total && float(k) < 2.0 * x)) break;
        term *= float((2 * k - 1) * (2 * k - 1)) / (float(k) * 8.0 * x);
        total += term;
    }
    return total / sqrt(2.0 * PI * x);
}

// im_lookup._r_integrand: the R rule's integrand at θ_i = t without 1/Z_R
float r_integrand(float t, float mu, float sigma, float theta_j, float cos_j, float lam) {
    float ct = cos(t);
    float sh = sin(0.5 * (t - theta_j));  // cos(t − θ_j) − 1 = −2 sin²(·/2), exact for small angles
    float d = (t - mu) / sigma;
    return exp(-0.5 * d * d - 2.0 * lam * sh * sh) * ct * ct * i0e(lam * max(ct, 0.0) * cos_j);
}

// im_lookup.r_lobe_integral: I_M^R / A_R for the R lobe (μ, σ, Z) of the view
float r_lobe_integral(float mu, float sigma, float z, float theta_j, float lam) {
    if ((mu - theta_j) * (mu - theta_j) > -log(R_NEGLIGIBLE * z / PI) * (2.0 * sigma * sigma + PI * PI / (2.0 * lam)))
        return 0.0;
    float precision_ = 1.0 / (sigma * sigma) + lam;
    float centre = (mu / (sigma * sigma) + lam * theta_j) / precision_;
    float sd = 1.0 / sqrt(precision_);
    float cos_j = max(cos(theta_j), 0.0), total = 0.0;
    if (-HALF_PI <= centre - R_HERMITE_REACH * sd && centre + R_HERMITE_REACH * sd <= HALF_PI) {
        float scale = sqrt(2.0) * sd;  // Gauss–Hermite for the product Gaussian inside the domain
        for (int q = 0; q < R_HERMITE_NODES; ++q)
            total += RH_W[q] * r_integrand(centre + scale * RH_X[q], mu, sigma, theta_j, cos_j, lam);
        return scale * total / z;
    }
    float lo = max(-HALF_PI, centre - R_WINDOW * sd), hi = min(HALF_PI, centre + R_WINDOW * sd);
    if (hi <= lo) return 0.0;
    float half_len = 0.5 * (hi - lo), mid = 0.5 * (hi + lo);
    for (int q = 0; q < R_NODES; ++q)
        total += R_W[q] * r_integrand(mid + half_len * R_X[q], mu, sigma, theta_j, cos_j, lam);
    return half_len * total / z;
}

// the I_M^{TT,D} table (N_a, N_b, N_c, N_d, 3) as a 3-D texture: texel (d, b·N_c + c, a); per axis its range, wrap,
// size and code (im_lookup.AXIS_CODES: 0 θ_o, 1 θ_j, 2 |Δφ|, 3 log10 λ)
uniform sampler3D im_table;
uniform float im_lo[4];
uniform float im_hi[4];
uniform int im_repeat[4];
uniform int im_size[4];
uniform int im_code[4];

void im_axis(int axis, float theta_o, float theta_j, float dphi, float lam, out int i0, out int i1, out float f) {
    int code = im_code[axis];
    float x = code == 0 ? theta_o : code == 1 ? theta_j : code == 2 ? abs(mod(dphi + PI, 2.0 * PI) - PI) : log(lam) / log(10.0);
    axis_cell(x, im_lo[axis], im_hi[axis], im_size[axis], im_repeat[axis] != 0, i0, i1, f);
}

// im_lookup.im_kernel: the table by multilinear interpolation plus A_R times the R rule
vec3 im_kernel(Params p, float mu_r, float sigma_r, float z_r, float theta_o, float theta_j, float dphi, float lam) {
    int a[2], b[2], c[2], d[2];
    float fa, fb, fc, fd;
    im_axis(0, theta_o, theta_j, dphi, lam, a[0], a[1], fa);
    im_axis(1, theta_o, theta_j, dphi, lam, b[0], b[1], fb);
    im_axis(2, theta_o, theta_j, dphi, lam, c[0], c[1], fc);
    im_axis(3, theta_o, theta_j, dphi, lam, d[0], d[1], fd);
    vec3 out_ = vec3(0.0);
    for (int bits = 0; bits < 16; ++bits) {
        float w = ((bits & 1) != 0 ? fa : 1.0 - fa) * ((bits & 2) != 0 ? fb : 1.0 - fb)
                * ((bits & 4) != 0 ? fc : 1.0 - fc) * ((bits & 8) != 0 ? fd : 1.0 - fd);
        if (w > 0.0) {
            int ia = a[(bits & 1) != 0 ? 1 : 0], ib = b[(bits & 2) != 0 ? 1 : 0];
            int ic = c[(bits & 4) != 0 ? 1 : 0], id = d[(bits & 8) != 0 ? 1 : 0];
            out_ += w * texelFetch(im_table, ivec3(id, ib * im_size[2] + ic, ia), 0).rgb;
        }
    }
    if (p.a_r.r > 0.0 || p.a_r.g > 0.0 || p.a_r.b > 0.0)
        out_ += p.a_r * r_lobe_integral(mu_r, sigma_r, z_r, clamp(theta_j, -HALF_PI, HALF_PI), lam);
    return out_;
}

// ---- corrections ξ and Ψ^Fiber (strip_shading._corrections, ASSET_PACK.md §6–7) ------------------------------------

// a full table (N_v, N_θ, N_φ, 3) as a 3-D texture, texel (φ, θ, v)
vec3 table_v3(sampler3D tab, float v, float theta, float phi) {
    ivec3 size = textureSize(tab, 0);
    int a0, a1, b0, b1, c0, c1;
    float fa, fb, fc;
    axis_cell(v, -1.0, 1.0, size.z, false, a0, a1, fa);
    axis_cell(theta, -HALF_PI, HALF_PI, size.y, false, b0, b1, fb);
    axis_cell(phi, -PI, PI, size.x, true, c0, c1, fc);
    vec3 lo = mix(mix(texelFetch(tab, ivec3(c0, b0, a0), 0).rgb, texelFetch(tab, ivec3(c1, b0, a0), 0).rgb, fc),
                  mix(texelFetch(tab, ivec3(c0, b1, a0), 0).rgb, texelFetch(tab, ivec3(c1, b1, a0), 0).rgb, fc), fb);
    vec3 hi = mix(mix(texelFetch(tab, ivec3(c0, b0, a1), 0).rgb, texelFetch(tab, ivec3(c1, b0, a1), 0).rgb, fc),
                  mix(texelFetch(tab, ivec3(c0, b1, a1), 0).rgb, texelFetch(tab, ivec3(c1, b1, a1), 0).rgb, fc), fb);
    return mix(lo, hi, fa);
}

// a factor table (N_v, N_x, 3) as a 2-D texture, texel (x, v)
vec3 table_v(sampler2D tab, float v, float x, float lo, float hi, bool repeat_axis) {
    ivec2 size = textureSize(tab, 0);
    int a0, a1, b0, b1;
    float fa, fb;
    axis_cell(v, -1.0, 1.0, size.y, false, a0, a1, fa);
    axis_cell(x, lo, hi, size.x, repeat_axis, b0, b1, fb);
    return mix(mix(texelFetch(tab, ivec2(b0, a0), 0).rgb, texelFetch(tab, ivec2(b1, a0), 0).rgb, fb),
               mix(texelFetch(tab, ivec2(b0, a1), 0).rgb, texelFetch(tab, ivec2(b1, a1), 0).rgb, fb), fa);
}

// the view-closed ξ (N_v, N_θ, N_θ, N_φ, 3) on axes (v, θ_i, θ_o, φ) as a 3-D texture: texel (φ, θ_i·N_θ + θ_o, v)
vec3 table_v4(sampler3D tab, int n_theta, float v, float theta_i, float theta_o, float phi) {
    ivec3 size = textureSize(tab, 0);
    int a[2], b[2], c[2], d[2];
    float fa, fb, fc, fd;
    axis_cell(v, -1.0, 1.0, size.z, false, a[0], a[1], fa);
    axis_cell(theta_i, -HALF_PI, HALF_PI, n_theta, false, b[0], b[1], fb);
    axis_cell(theta_o, -HALF_PI, HALF_PI, n_theta, false, c[0], c[1], fc);
    axis_cell(phi, -PI, PI, size.x, true, d[0], d[1], fd);
    vec3 out_ = vec3(0.0);
    for (int bits = 0; bits < 16; ++bits) {
        float w = ((bits & 1) != 0 ? fa : 1.0 - fa) * ((bits & 2) != 0 ? fb : 1.0 - fb)
                * ((bits & 4) != 0 ? fc : 1.0 - fc) * ((bits & 8) != 0 ? fd : 1.0 - fd);
        int ia = a[(bits & 1) != 0 ? 1 : 0], ib = b[(bits & 2) != 0 ? 1 : 0];
        int ic = c[(bits & 4) != 0 ? 1 : 0], id = d[(bits & 8) != 0 ? 1 : 0];
        out_ += w * texelFetch(tab, ivec3(id, ib * n_theta + ic, ia), 0).rgb;
    }
    return out_;
}

uniform sampler3D xi_view;
uniform int use_xi_view;
uniform int xi_view_n_theta;
uniform sampler3D xi_full;
uniform sampler2D xi_m;
uniform sampler2D xi_n;
uniform sampler3D psi_full;
uniform sampler2D psi_gm;
uniform sampler2D psi_gn;
uniform int use_xi_full;
uniform int use_psi_full;
// ξ of single scattering (ξ closed apart, Features.split_xi): xi_single_kind 0 none (ξ serves both), 1 a full table
// (v, θ_d, φ) as xi_full, 2 a view-closed one (v, θ_i, θ_o, φ) as xi_view, on xi_single_n_theta θ cells
uniform sampler3D xi_single;
uniform int xi_single_kind;
uniform int xi_single_n_theta;

// strip_shading._corrections: ξ(v, θ_i, θ_o, φ) (view-closed) or ξ(v, θ_d, φ), the ξ of single scattering (xi_s: the
// same from the single-scattering table where there is one, xi then being multiple scattering's; else xi) and
// Ψ^Fiber_G(v, θ_i, φ) toward w, θ_i and φ against the strip frame; a term asks for the ξ it uses (single, multiple),
// the other is not looked up (left at 0)
void corrections(float v, vec3 t, vec3 n, vec3 b, float theta_o, vec3 w, bool single, bool multiple, out vec3 xi,
                 out vec3 xi_s, out vec3 psi) {
    float theta_i = clamped_asin(dot(w, t));
    float phi = -atan(dot(w, b), dot(w, n));
    float theta_d = 0.5 * (theta_o - theta_i);
    xi = vec3(0.0);
    xi_s = vec3(0.0);
    if (multiple || (single && xi_single_kind == 0)) {
        if (use_xi_view != 0)
            xi = table_v4(xi_view, xi_view_n_theta, v, theta_i, theta_o, phi);
        else
            xi = use_xi_full != 0 ? table_v3(xi_full, v, theta_d, phi)
                                  : table_v(xi_m, v, theta_d, -HALF_PI, HALF_PI, false)
                                    * table_v(xi_n, v, phi, -PI, PI, true);
    }
    if (single) {
        if (xi_single_kind == 2)
            xi_s = table_v4(xi_single, xi_single_n_theta, v, theta_i, theta_o, phi);
        else if (xi_single_kind == 1)
            xi_s = table_v3(xi_single, v, theta_d, phi);
        else
            xi_s = xi;
    }
    psi = use_psi_full != 0 ? table_v3(psi_full, v, theta_i, phi)
                            : table_v(psi_gm, v, theta_i, -HALF_PI, HALF_PI, false) * table_v(psi_gn, v, phi, -PI, PI, true);
}

float fiber_lit(vec3 psi) { return clamp((psi.r + psi.g + psi.b) / 3.0, 0.0, 1.0); }

// ---- textures (texture_sampling.sample_mip: u repeats, v clamps, trilinear between stored levels) --------------------

vec4 bilinear(sampler2D tex, int level, float u, float v) {
    ivec2 size = textureSize(tex, level);
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
    vec4 top = mix(texelFetch(tex, ivec2(j0, i0), level), texelFetch(tex, ivec2(j1, i0), level), fx);
    vec4 bottom = mix(texelFetch(tex, ivec2(j0, i1), level), texelFetch(tex, ivec2(j1, i1), level), fx);
    return mix(top, bottom, fy);
}

vec4 sample_mip(sampler2D tex, int levels, float level, float u, float v) {
    level = clamp(level, 0.0, float(levels) - 1.0);
    int l0 = int(floor(level));
    int l1 = min(l0 + 1, levels - 1);
    float f = level - float(l0);
    vec4 out_ = (1.0 - f) * bilinear(tex, l0, u, v);
    if (f > 0.0)
        out_ += f * bilinear(tex, l1, u, v);
    return out_;
}

// texture_sampling.mip_level
float mip_level(float footprint, float texel_u, float texel_v) {
    float ratio = max(footprint / texel_u, footprint / texel_v);
    return ratio > 1.0 ? log2(ratio) : 0.0;
}

// strip_shading.tangent_spread (Toksvig 2005), capped at MAX_TANGENT_SPREAD²
float tangent_spread(vec3 tex, float coverage) {
    if (coverage <= 1e-6) return 0.0;
    float r = min(length(tex) / coverage, 1.0);
    float cap = MAX_TANGENT_SPREAD * MAX_TANGENT_SPREAD;
    if (r <= 0.0) return cap;
    return min((1.0 - r) / r, cap);
}
