"""Knot interpolation and per-face Gauss-Newton: deformed stitch-mesh vertices → yarn control points of every face
(Huang et al. 2025 §3.2 and §5.2). Numba kernels, one face per thread (``prange`` over chunks of faces); every face
reads the shared vertices and writes only its own outputs.

Per face, per frame
-------------------
1. **Frame.** Centroid c (vertex mean), normal n (Newell's formula, robust for non-planar faces; the rest normal when
   the face has no area), e1 = the course direction (TR − TL) + (BR − BL) projected off n, e2 = n × e1. Vertices,
   boundary points and knot points are expressed in this frame (u, v, z). The rest face gets the same frame.
2. **Deformation gradient** (2-D): F = argmin Σ_i |x_i − F X_i|² over the face's vertices (x deformed, X rest,
   both centred), F = (Σ x Xᵀ)(Σ X Xᵀ)⁻¹. R = the rotation of F's polar decomposition. F's shear sets how much of
   the template's shear shape (knot shifts, lift changes; ``stitch_templates``, "Shear shape") the face takes.
3. **Knot centres** x_k = (R + β (F − R)) X_k: the spacing blend d = d_0 + β (d_1 − d_0) of §6.1 applied to every knot
   offset from the centroid (d_0 = R X_k, the rest spacing turned with the face; d_1 = F X_k, the interpolated one).
   β = 1 (default) interpolates knots uniformly; β = 0 keeps their rest spacing. On a sheared face X_k first moves by
   the template's shear shape, w⁺ ΔX⁺_k + w⁻ ΔX⁻_k (``shear_weights``).
4. **Boundary points** (template points on edges) are interpolated along their edge, in 3-D, from the edge's two
   vertices: the same point for both faces of the edge. They are fixed.
5. **Unknowns** Θ = (θ1, θ2, l1, l2): the two knots' tilt angles (direction d = (cos θ, sin θ) in the (e1, e2) plane)
   and half-lengths. Eq. 1-2 give every knot point from Θ (``stitch_templates``), so eq. 4 holds by construction.
   Initial guess ("uniform interpolation"): each knot's rest axis c0 − c1 mapped by F.
6. **Energy** (eqs. 3, 5, 6) over the face's own yarn pieces (polylines of template points, boundary points at their
   ends), with positions in the face frame in 3-D (knot points at their lift z, step 8; boundary points at their own):
   E = Σ_segments w_length ((L − L_0)/h)² + Σ_interior points w_angle (cos − cos_0)², L the segment length, cos the
   cosine between consecutive segments, L_0 and cos_0 those of the rest template of this face. h is the mesh's
   ``length_scale`` (the median rest length of its faces' top edges, one stitch width): lengths are measured in
   stitch widths, so results do not depend on the unit of the mesh, and w_length = 100, w_angle = 1 (the paper's
   values) price a length change of a tenth of a stitch width like a change of 1 in a cosine (a 90° bend).
   Residuals r = √w (L − L_0)/h and √w (cos − cos_0):
   r² = E_i, the sign kept so r is smooth. Lengths are |e| = sqrt(e·e + (1e-9 h)²), so a collapsed segment has a
   finite Jacobian.
7. **Gauss-Newton with Levenberg damping**: A = Σ J Jᵀ, b = −Σ J r (J = ∂r/∂Θ, analytic), solve
   (A + λ μ S⁻²) ΔΘ = b by a hand-written 4×4 LDLᵀ, S = diag(1, 1, h, h), μ = tr(S A S)/4: damping isotropic in
   (θ1, θ2, l1/h, l2/h), so it does not depend on the mesh's unit. The step is accepted only if it lowers E (then
   λ ← λ/10), else λ ← 10 λ and the step is solved again (at most ``MAX_TRIES`` times), so E never increases.
   ``iterations`` (default 3) counts accepted-or-abandoned steps; λ starts at ``LAMBDA0`` = 1e-2 for every face:
   on random stretch and shear this small first damping gives E_3 closer to the converged energy than plain
   Gauss-Newton, whose full first step overshoots on strongly deformed faces (figures in BENCHMARKS.md).
8. **Output**: knot points c + u e1 + v e2 + z n (z = s r, with the face's shear lifts), boundary points the exact
   3-D edge points.

Modes: ``iterations = 0`` is "knot interpolation without optimisation" (Fig. 9 middle); ``naive = True`` maps every
rest template point by x = F X (boundary points still on their edges): "naive interpolation of control points".
Degenerate input never produces NaN from finite vertices: zero-area, inverted and non-planar faces get a valid frame,
and a face whose result is not finite falls back to its initial guess, then to its rest shape turned by R.

Layout (speed): each chunk of faces copies the templates, and each face its vertices and its row of the rest array
(``REST_SIZE`` floats: ``R_XY`` rest 2-D vertices, ``R_MINV`` (Σ X Xᵀ)⁻¹, ``R_KNOTS`` x, y, θ_0, l_0 per knot,
``R_NORMAL``, ``R_SHEAR`` the template's knot shifts under shear (Δx, Δy per knot, one way then the other, in the
rest frame), ``R_TARGETS`` the rest value of every residual: segment lengths then cosines), into thread-local
arrays before calling the helpers: Numba reference-counts every array passed to a function, and counting shared
arrays from two threads costs more than the solve. A face's points live in a workspace ``ws`` (point, ``W_*``
column) and its residuals with their Jacobian rows in ``rj`` (residual, [r, ∂r/∂θ1, ∂r/∂θ2, ∂r/∂l1, ∂r/∂l2]).
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit, prange

from data_formats.numba_setup import FASTMATH
from knitrun.sim.stitch_templates import (F_A, F_C, F_DS_NEG, F_DS_POS, F_KNOTS, F_S, F_SHEAR, F_T, I_KNOT, I_PIECES,
                                          I_V0, I_V1, MAX_ANGLES, MAX_POINTS, MAX_SEGMENTS, N_UNKNOWNS)

MAX_TRIES = 8  # damped solves per iteration before giving up on the iteration
LAMBDA0 = 1e-2  # initial Levenberg damping (relative to tr(S A S)/4, see damped_solve)
LAMBDA_MIN = 1e-9
EPS_LENGTH = 1e-9  # length smoothing, in units of length_scale
MAX_RESIDUALS = MAX_SEGMENTS + MAX_ANGLES
P_RADIUS, P_SCALE, P_W_ANGLE, P_W_LENGTH, P_BETA = range(5)  # layout of the ``params`` vector
R_XY, R_MINV, R_KNOTS, R_NORMAL, R_SHEAR, R_TARGETS = 0, 10, 14, 22, 25, 33  # layout of a face's rest row
REST_SIZE = R_TARGETS + MAX_RESIDUALS
W_X, W_DTH, W_DLN, W_SEG = 0, 3, 5, 7  # workspace columns: point (3), ∂/∂θ (2), ∂/∂l (2), segment unit + 1/L (4)
W_SIZE = 11


@njit(cache=True, fastmath=FASTMATH)
def gather_face(vertices, face_offsets, face_vertices, f, v):
    """Copy face f's vertex positions, in the face's slot order, into ``v[:nv]``; returns nv."""
    start = face_offsets[f]
    nv = face_offsets[f + 1] - start
    for i in range(nv):
        for k in range(3):
            v[i, k] = vertices[face_vertices[start + i], k]
    return nv


@njit(cache=True, fastmath=FASTMATH)
def face_frame(v, nv, fallback_normal, frame):
    """frame[0] = centroid, frame[1] = e1, frame[2] = e2, frame[3] = n of the face with vertices ``v[:nv]`` in the
    documented slot order (module docstring, step 1); ``fallback_normal`` where the face has no area."""
    for k in range(3):
        frame[0, k] = 0.0
        for i in range(nv):
            frame[0, k] += v[i, k]
        frame[0, k] /= nv
    nx = ny = nz = spread = 0.0
    for i in range(nv):
        j = (i + 1) % nv
        ax, ay, az = v[i, 0] - frame[0, 0], v[i, 1] - frame[0, 1], v[i, 2] - frame[0, 2]
        bx, by, bz = v[j, 0] - frame[0, 0], v[j, 1] - frame[0, 1], v[j, 2] - frame[0, 2]
        nx += ay * bz - az * by
        ny += az * bx - ax * bz
        nz += ax * by - ay * bx
        spread += ax * ax + ay * ay + az * az
    norm = math.sqrt(nx * nx + ny * ny + nz * nz)
    if not norm > 1e-12 * spread + 1e-300:
        nx, ny, nz = fallback_normal[0], fallback_normal[1], fallback_normal[2]
        norm = math.sqrt(nx * nx + ny * ny + nz * nz)
    nx, ny, nz = nx / norm, ny / norm, nz / norm
    b = nv - 3
    dx = v[b + 1, 0] - v[b + 2, 0] + v[b, 0] - v[0, 0]  # (TR − TL) + (BR − BL)
    dy = v[b + 1, 1] - v[b + 2, 1] + v[b, 1] - v[0, 1]
    dz = v[b + 1, 2] - v[b + 2, 2] + v[b, 2] - v[0, 2]
    dn = dx * nx + dy * ny + dz * nz
    dx, dy, dz = dx - dn * nx, dy - dn * ny, dz - dn * nz
    dl = math.sqrt(dx * dx + dy * dy + dz * dz)
    if not dl > 1e-9 * math.sqrt(spread) + 1e-300:  # no course direction: any direction in the plane
        dx, dy, dz = (1.0, 0.0, 0.0) if abs(nx) < 0.9 else (0.0, 1.0, 0.0)
        dn = dx * nx + dy * ny + dz * nz
        dx, dy, dz = dx - dn * nx, dy - dn * ny, dz - dn * nz
        dl = math.sqrt(dx * dx + dy * dy + dz * dz)
    frame[1, 0], frame[1, 1], frame[1, 2] = dx / dl, dy / dl, dz / dl
    frame[3, 0], frame[3, 1], frame[3, 2] = nx, ny, nz
    frame[2, 0] = ny * frame[1, 2] - nz * frame[1, 1]
    frame[2, 1] = nz * frame[1, 0] - nx * frame[1, 2]
    frame[2, 2] = nx * frame[1, 1] - ny * frame[1, 0]


@njit(cache=True, fastmath=FASTMATH)
def ruled_point(xy, nv, u, v):
    """M(u, v) of the face with 2-D vertices ``xy[:nv]`` (``stitch_templates`` module docstring)."""
    b = nv - 3
    tx = (1.0 - u) * xy[b + 2, 0] + u * xy[b + 1, 0]
    ty = (1.0 - u) * xy[b + 2, 1] + u * xy[b + 1, 1]
    if b == 0:
        bx, by = xy[0, 0], xy[0, 1]
    else:
        k = min(int(math.floor(u * b)), b - 1)
        s = u * b - k
        bx = (1.0 - s) * xy[k, 0] + s * xy[k + 1, 0]
        by = (1.0 - s) * xy[k, 1] + s * xy[k + 1, 1]
    return (1.0 - v) * bx + v * tx, (1.0 - v) * by + v * ty


@njit(cache=True, fastmath=FASTMATH)
def boundary_points(v, code, ti, tf, frame, ws):
    """Local coordinates (u, v, z) of the face's boundary points, interpolated in 3-D along their edges, into
    ``ws[i, W_X:W_X+3]``; their Θ-derivatives are zero."""
    n_points = ti[code, I_PIECES, 1 + ti[code, I_PIECES, 0]]
    for i in range(n_points):
        if ti[code, I_KNOT, i] < 0:
            t, a, b = tf[code, F_T, i], ti[code, I_V0, i], ti[code, I_V1, i]
            for k in range(3):
                ws[i, W_X + k] = 0.0
            for c in range(3):
                p = (1.0 - t) * v[a, c] + t * v[b, c] - frame[0, c]
                for k in range(3):
                    ws[i, W_X + k] += p * frame[1 + k, c]
            for k in range(W_DTH, W_SEG):
                ws[i, k] = 0.0


@njit(cache=True, fastmath=FASTMATH)
def knot_points(theta, knots, code, ti, tf, radius, ws):
    """Eq. 1: in-plane positions of the knot points of stitch type ``code`` for Θ = ``theta`` (θ1, θ2, l1, l2) and
    knot centres ``knots`` (2, 2), with their derivatives w.r.t. their own knot's θ and l, into ``ws`` (their lifts,
    ``knot_lifts``, and boundary points are left as they are)."""
    n_points = ti[code, I_PIECES, 1 + ti[code, I_PIECES, 0]]
    c0, s0, c1, s1 = math.cos(theta[0]), math.sin(theta[0]), math.cos(theta[1]), math.sin(theta[1])
    for i in range(n_points):
        j = ti[code, I_KNOT, i]
        if j < 0:
            continue
        ct, st = (c0, s0) if j == 0 else (c1, s1)
        a = tf[code, F_A, i]
        al, cr = a * theta[2 + j], tf[code, F_C, i] * radius
        ws[i, W_X] = knots[j, 0] + al * ct + cr * st
        ws[i, W_X + 1] = knots[j, 1] + al * st - cr * ct
        ws[i, W_DTH], ws[i, W_DTH + 1] = -al * st + cr * ct, al * ct + cr * st
        ws[i, W_DLN], ws[i, W_DLN + 1] = a * ct, a * st


@njit(cache=True, fastmath=FASTMATH)
def face_shear(fmat):
    """Shear κ = C₁₂/√(C₁₁C₂₂), C = FᵀF, of a face with deformation gradient ``fmat`` (2, 2) in its (course, wale)
    frame: the cosine of the angle between the deformed course and wale directions (0 at rest, under stretch and
    rotation; F = [[1, γ], [0, 1]] gives γ/√(1 + γ²)); 0 for a face collapsed along an axis."""
    c11 = fmat[0, 0] * fmat[0, 0] + fmat[1, 0] * fmat[1, 0]
    c22 = fmat[0, 1] * fmat[0, 1] + fmat[1, 1] * fmat[1, 1]
    c12 = fmat[0, 0] * fmat[0, 1] + fmat[1, 0] * fmat[1, 1]
    kappa = c12 / math.sqrt(c11 * c22) if c11 * c22 > 0.0 else 0.0
    return kappa if abs(kappa) <= 1.0 else 0.0


@njit(cache=True, fastmath=FASTMATH)
def shear_weights(fmat, kappa_ref):
    """(w⁺, w⁻) = (κ/κ_ref, −κ/κ_ref) clamped to [0, 1] of a face's shear κ (``face_shear``) for a template shear
    shape relaxed at ``kappa_ref`` (``stitch_templates``, "Shear shape"); (0, 0) without one (κ_ref = 0)."""
    if not kappa_ref > 0.0:
        return 0.0, 0.0
    w = face_shear(fmat) / kappa_ref
    return min(max(w, 0.0), 1.0), min(max(-w, 0.0), 1.0)


@njit(cache=True, fastmath=FASTMATH)
def knot_lifts(code, ti, tf, radius, w_pos, w_neg, ws):
    """Eq. 2: the lift z = (s + w⁺Δs⁺ + w⁻Δs⁻)·r of every knot point of stitch type ``code`` into ``ws``; it does not
    depend on Θ, so a face sets it once (``face_setup``)."""
    n_points = ti[code, I_PIECES, 1 + ti[code, I_PIECES, 0]]
    for i in range(n_points):
        if ti[code, I_KNOT, i] >= 0:
            ws[i, W_X + 2] = (tf[code, F_S, i] + w_pos * tf[code, F_DS_POS, i] + w_neg * tf[code, F_DS_NEG, i]) * radius


@njit(cache=True, fastmath=FASTMATH)
def residuals(code, ti, ws, targets, s_len, s_ang, inv_h, eps, rj, want_jac):
    """Residuals (eqs. 5-6) of the points in ``ws`` of a face of type ``code``, into ``rj[:, 0]``: length residuals
    s_len (L − target)·inv_h of all segments first (piece by piece), then angle residuals s_ang (cos − target) of
    all interior points; with ``want_jac`` also their Θ-Jacobian rows into ``rj[:, 1:5]``. Returns E = Σ r².
    With zero targets, unit weights and inv_h = 1 the residuals are the raw lengths and cosines."""
    n_pieces = ti[code, I_PIECES, 0]
    n_seg = ti[code, I_PIECES, 1 + n_pieces] - n_pieces
    si, ai = 0, n_seg
    energy = 0.0
    for q in range(n_pieces):
        i0, i1 = ti[code, I_PIECES, 1 + q], ti[code, I_PIECES, 2 + q]
        for i in range(i0, i1 - 1):
            ex, ey, ez = ws[i + 1, 0] - ws[i, 0], ws[i + 1, 1] - ws[i, 1], ws[i + 1, 2] - ws[i, 2]
            length = math.sqrt(ex * ex + ey * ey + ez * ez + eps * eps)
            inv = 1.0 / length
            ws[i, W_SEG], ws[i, W_SEG + 1], ws[i, W_SEG + 2], ws[i, W_SEG + 3] = ex * inv, ey * inv, ez * inv, inv
            r = s_len * (length - targets[si]) * inv_h
            rj[si, 0] = r
            energy += r * r
            if want_jac:
                for k in range(1, 1 + N_UNKNOWNS):
                    rj[si, k] = 0.0
                wx, wy = s_len * inv_h * ws[i, W_SEG], s_len * inv_h * ws[i, W_SEG + 1]
                for p, sign in ((i, -1.0), (i + 1, 1.0)):  # r row += w · ∂x_p/∂Θ, p's own knot only
                    j = ti[code, I_KNOT, p]
                    if j >= 0:
                        rj[si, 1 + j] += sign * (wx * ws[p, W_DTH] + wy * ws[p, W_DTH + 1])
                        rj[si, 3 + j] += sign * (wx * ws[p, W_DLN] + wy * ws[p, W_DLN + 1])
            si += 1
        for i in range(i0, i1 - 2):
            cos = ws[i, W_SEG] * ws[i + 1, W_SEG] + ws[i, W_SEG + 1] * ws[i + 1, W_SEG + 1] \
                + ws[i, W_SEG + 2] * ws[i + 1, W_SEG + 2]
            r = s_ang * (cos - targets[ai])
            rj[ai, 0] = r
            energy += r * r
            if want_jac:
                for k in range(1, 1 + N_UNKNOWNS):
                    rj[ai, k] = 0.0
                inv1, inv2 = s_ang * ws[i, W_SEG + 3], s_ang * ws[i + 1, W_SEG + 3]
                g1x = (ws[i + 1, W_SEG] - cos * ws[i, W_SEG]) * inv1  # ∂cos/∂e1 (xy; z derivatives vanish)
                g1y = (ws[i + 1, W_SEG + 1] - cos * ws[i, W_SEG + 1]) * inv1
                g2x = (ws[i, W_SEG] - cos * ws[i + 1, W_SEG]) * inv2  # ∂cos/∂e2
                g2y = (ws[i, W_SEG + 1] - cos * ws[i + 1, W_SEG + 1]) * inv2
                for p, wx, wy in ((i, -g1x, -g1y), (i + 1, g1x - g2x, g1y - g2y), (i + 2, g2x, g2y)):
                    j = ti[code, I_KNOT, p]
                    if j >= 0:
                        rj[ai, 1 + j] += wx * ws[p, W_DTH] + wy * ws[p, W_DTH + 1]
                        rj[ai, 3 + j] += wx * ws[p, W_DLN] + wy * ws[p, W_DLN + 1]
            ai += 1
    return energy


@njit(cache=True, fastmath=FASTMATH)
def damped_solve(a, g, lam, h, lw, delta):
    """Solve (A + λ μ S⁻²) δ = −g by LDLᵀ (``lw`` 4×4 scratch) for a symmetric positive semi-definite 4×4 A, with
    S = diag(1, 1, h, h) and μ = tr(S A S)/4: isotropic Levenberg damping of the unknowns (θ1, θ2, l1/h, l2/h).
    Returns False (δ undefined) if a pivot is not positive and finite."""
    n = N_UNKNOWNS
    mu = 0.25 * (a[0, 0] + a[1, 1] + h * h * (a[2, 2] + a[3, 3]))
    floor = 1e-12 * mu + 1e-300
    for i in range(n):
        for j in range(i + 1):
            s = a[i, j]
            if i == j:
                s += lam * mu if i < 2 else lam * mu / (h * h)
            for k in range(j):
                s -= lw[i, k] * lw[j, k] * lw[k, k]
            if i == j:
                if not (s > floor * (1.0 if i < 2 else 1.0 / (h * h)) and s < math.inf):
                    return False
                lw[i, i] = s
            else:
                lw[i, j] = s / lw[j, j]
    for i in range(n):  # L y = −g
        s = -g[i]
        for k in range(i):
            s -= lw[i, k] * delta[k]
        delta[i] = s
    for i in range(n):  # D z = y
        delta[i] /= lw[i, i]
    for i in range(n - 1, -1, -1):  # Lᵀ δ = z
        s = delta[i]
        for k in range(i + 1, n):
            s -= lw[k, i] * delta[k]
        delta[i] = s
    for i in range(n):
        if not abs(delta[i]) < math.inf:
            return False
    return True


@njit(cache=True, fastmath=FASTMATH)
def normal_equations(rows, n_res, a, g):
    """A = Σ J Jᵀ and g = Σ J r over the first ``n_res`` rows [r, J] of ``rows`` (one pass, sums in registers)."""
    a00 = a10 = a11 = a20 = a21 = a22 = a30 = a31 = a32 = a33 = g0 = g1 = g2 = g3 = 0.0
    for k in range(n_res):
        r, j0, j1, j2, j3 = rows[k, 0], rows[k, 1], rows[k, 2], rows[k, 3], rows[k, 4]
        a00 += j0 * j0
        a10 += j1 * j0
        a11 += j1 * j1
        a20 += j2 * j0
        a21 += j2 * j1
        a22 += j2 * j2
        a30 += j3 * j0
        a31 += j3 * j1
        a32 += j3 * j2
        a33 += j3 * j3
        g0 += j0 * r
        g1 += j1 * r
        g2 += j2 * r
        g3 += j3 * r
    a[0, 0], a[1, 1], a[2, 2], a[3, 3] = a00, a11, a22, a33
    a[1, 0] = a[0, 1] = a10
    a[2, 0] = a[0, 2] = a20
    a[2, 1] = a[1, 2] = a21
    a[3, 0] = a[0, 3] = a30
    a[3, 1] = a[1, 3] = a31
    a[3, 2] = a[2, 3] = a32
    g[0], g[1], g[2], g[3] = g0, g1, g2, g3


@njit(cache=True, fastmath=FASTMATH)
def _all_finite(x, n):
    for i in range(n):
        if not abs(x[i]) < math.inf:
            return False
    return True


@njit(cache=True, fastmath=FASTMATH)
def gauss_newton(theta, knots, code, ti, tf, radius, targets, weights, iterations, ws, rj, mats, history):
    """Damped Gauss-Newton on Θ (in place) for ``iterations`` iterations (module docstring, step 7); ``weights`` =
    (s_len, s_ang, inv_h, eps); history[k] = E after k iterations (non-increasing). ``rj`` holds two buffers (current,
    trial); ``mats`` (3, 4, 4): A, the LDLᵀ scratch, and rows g, δ, trial Θ. Leaves the points of Θ in ``ws``."""
    s_len, s_ang, inv_h, eps = weights[0], weights[1], weights[2], weights[3]
    a, lw, vec = mats[0], mats[1], mats[2]
    knot_points(theta, knots, code, ti, tf, radius, ws)
    energy = residuals(code, ti, ws, targets, s_len, s_ang, inv_h, eps, rj[0], True)
    history[0] = energy
    cur = 0
    lam = LAMBDA0
    n_pieces = ti[code, I_PIECES, 0]
    n_res = 2 * ti[code, I_PIECES, 1 + n_pieces] - 3 * n_pieces
    for it in range(iterations):
        normal_equations(rj[cur], n_res, a, vec[0])
        for _ in range(MAX_TRIES):
            if damped_solve(a, vec[0], lam, 1.0 / inv_h, lw, vec[1]):
                for p in range(N_UNKNOWNS):
                    vec[2, p] = theta[p] + vec[1, p]
                knot_points(vec[2], knots, code, ti, tf, radius, ws)
                e_trial = residuals(code, ti, ws, targets, s_len, s_ang, inv_h, eps, rj[1 - cur],
                                    it + 1 < iterations)  # the last iteration's Jacobian is never used
                if e_trial < energy:
                    energy = e_trial
                    cur = 1 - cur
                    for p in range(N_UNKNOWNS):
                        theta[p] = vec[2, p]
                    lam = max(lam * 0.1, LAMBDA_MIN)
                    break
            lam *= 10.0
        history[it + 1] = energy
    knot_points(theta, knots, code, ti, tf, radius, ws)
    return energy


@njit(cache=True, fastmath=FASTMATH)
def face_setup(v, nv, code, ti, tf, rest, beta, radius, frame, fmat, knots, theta, ws):
    """Steps 1-5 of the module docstring for one face (vertices ``v``, rest row ``rest``): frame, F (``fmat``),
    knot centres, boundary points and the knot points' lifts (in ``ws``), initial Θ. Returns (cos, sin) of R's
    angle."""
    face_frame(v, nv, rest[R_NORMAL:R_NORMAL + 3], frame)
    s00 = s01 = s10 = s11 = 0.0
    for i in range(nv):
        px, py, pz = v[i, 0] - frame[0, 0], v[i, 1] - frame[0, 1], v[i, 2] - frame[0, 2]
        x = px * frame[1, 0] + py * frame[1, 1] + pz * frame[1, 2]
        y = px * frame[2, 0] + py * frame[2, 1] + pz * frame[2, 2]
        rx, ry = rest[R_XY + 2 * i], rest[R_XY + 2 * i + 1]
        s00 += x * rx
        s01 += x * ry
        s10 += y * rx
        s11 += y * ry
    m00, m01, m10, m11 = rest[R_MINV], rest[R_MINV + 1], rest[R_MINV + 2], rest[R_MINV + 3]
    fmat[0, 0], fmat[0, 1] = s00 * m00 + s01 * m10, s00 * m01 + s01 * m11
    fmat[1, 0], fmat[1, 1] = s10 * m00 + s11 * m10, s10 * m01 + s11 * m11
    cp, sp = fmat[0, 0] + fmat[1, 1], fmat[1, 0] - fmat[0, 1]  # R = polar rotation of F: angle atan2(sp, cp)
    norm = math.sqrt(cp * cp + sp * sp)
    cp, sp = (cp / norm, sp / norm) if norm > 0.0 else (1.0, 0.0)
    g00, g01 = cp + beta * (fmat[0, 0] - cp), -sp + beta * (fmat[0, 1] + sp)
    g10, g11 = sp + beta * (fmat[1, 0] - sp), cp + beta * (fmat[1, 1] - cp)
    w_pos, w_neg = shear_weights(fmat, tf[code, F_SHEAR, 0])
    for j in range(2):
        kx, ky, th0, l0 = rest[R_KNOTS + 4 * j], rest[R_KNOTS + 4 * j + 1], rest[R_KNOTS + 4 * j + 2], \
            rest[R_KNOTS + 4 * j + 3]
        kx += w_pos * rest[R_SHEAR + 2 * j] + w_neg * rest[R_SHEAR + 4 + 2 * j]
        ky += w_pos * rest[R_SHEAR + 2 * j + 1] + w_neg * rest[R_SHEAR + 4 + 2 * j + 1]
        knots[j, 0], knots[j, 1] = g00 * kx + g01 * ky, g10 * kx + g11 * ky
        ax, ay = math.cos(th0), math.sin(th0)
        fx, fy = fmat[0, 0] * ax + fmat[0, 1] * ay, fmat[1, 0] * ax + fmat[1, 1] * ay
        theta[j] = math.atan2(fy, fx)
        theta[2 + j] = l0 * math.sqrt(fx * fx + fy * fy)
    boundary_points(v, code, ti, tf, frame, ws)
    knot_lifts(code, ti, tf, radius, w_pos, w_neg, ws)
    return cp, sp


@njit(cache=True, fastmath=FASTMATH)
def naive_points(code, ti, tf, rest, radius, fmat, ws):
    """Naive interpolation: every rest knot point X mapped by x = F X, lifted by its rest s·r (no shear lifts: the
    rest template mapped as it is; boundary points untouched)."""
    n_points = ti[code, I_PIECES, 1 + ti[code, I_PIECES, 0]]
    for i in range(n_points):
        j = ti[code, I_KNOT, i]
        if j < 0:
            continue
        th0, l0 = rest[R_KNOTS + 4 * j + 2], rest[R_KNOTS + 4 * j + 3]
        ct, st = math.cos(th0), math.sin(th0)
        al, cr = tf[code, F_A, i] * l0, tf[code, F_C, i] * radius
        x = rest[R_KNOTS + 4 * j] + al * ct + cr * st
        y = rest[R_KNOTS + 4 * j + 1] + al * st - cr * ct
        ws[i, W_X], ws[i, W_X + 1] = fmat[0, 0] * x + fmat[0, 1] * y, fmat[1, 0] * x + fmat[1, 1] * y
        ws[i, W_X + 2] = tf[code, F_S, i] * radius


@njit(cache=True, fastmath=FASTMATH)
def fallback_theta(theta, theta0, rest, cp, sp):
    """Θ of a face whose optimisation failed: the initial guess if finite, else the rest knots turned by R."""
    if _all_finite(theta0, N_UNKNOWNS):
        for p in range(N_UNKNOWNS):
            theta[p] = theta0[p]
        return
    for j in range(2):
        phi = math.atan2(sp, cp)
        theta[j] = rest[R_KNOTS + 4 * j + 2] + (phi if abs(phi) < math.inf else 0.0)
        theta[2 + j] = rest[R_KNOTS + 4 * j + 3]


@njit(cache=True, fastmath=FASTMATH)
def face_output(v, code, ti, tf, frame, ws, out):
    """3-D points of a face into ``out`` (n, 3): knot points lifted from the face frame, boundary points exactly on
    their edges (so faces sharing an edge give bit-identical points)."""
    n_points = ti[code, I_PIECES, 1 + ti[code, I_PIECES, 0]]
    for i in range(n_points):
        if ti[code, I_KNOT, i] < 0:
            t, a, b = tf[code, F_T, i], ti[code, I_V0, i], ti[code, I_V1, i]
            for k in range(3):
                out[i, k] = (1.0 - t) * v[a, k] + t * v[b, k]
        else:
            for k in range(3):
                out[i, k] = frame[0, k] + ws[i, 0] * frame[1, k] + ws[i, 1] * frame[2, k] + ws[i, 2] * frame[3, k]


@njit(parallel=True, cache=True, fastmath=FASTMATH)
def solve_faces(vertices, face_offsets, face_vertices, stitch_type, point_offset, rest, template_int,
                template_float, params, iterations, naive, n_chunks, out_points, out_theta, out_energy):
    """Knot simulation of one frame (module docstring). ``vertices`` (V, 3) deformed; ``rest`` (F, REST_SIZE) from
    ``prepare_faces``; ``params`` = (radius, length_scale, w_angle, w_length, beta). Writes the 3-D points of face f to
    ``out_points[point_offset[f]:point_offset[f+1]]``, its Θ to ``out_theta[f]`` and E after each iteration to
    ``out_energy[f, :iterations+1]`` (E of the naive points in column 0 when ``naive``; NaN for a face whose points
    are not finite, which only overflowing vertex coordinates cause)."""
    n_faces = stitch_type.shape[0]
    radius, beta = params[P_RADIUS], params[P_BETA]
    for chunk in prange(n_chunks):
        ti, tf = template_int.copy(), template_float.copy()  # thread-local: see "Layout" in the module docstring
        weights = np.array([math.sqrt(params[P_W_LENGTH]), math.sqrt(params[P_W_ANGLE]), 1.0 / params[P_SCALE],
                            EPS_LENGTH * params[P_SCALE]])
        v = np.empty((5, 3))
        rest_f = np.empty(REST_SIZE)
        frame = np.empty((4, 3))
        fmat = np.empty((2, 2))
        knots = np.empty((2, 2))
        ws = np.zeros((MAX_POINTS, W_SIZE))
        rj = np.zeros((2, MAX_RESIDUALS, 1 + N_UNKNOWNS))
        mats = np.zeros((3, N_UNKNOWNS, N_UNKNOWNS))
        theta = np.empty(N_UNKNOWNS)
        theta0 = np.empty(N_UNKNOWNS)
        history = np.empty(iterations + 1)
        out = np.empty((MAX_POINTS, 3))
        for f in range(chunk * n_faces // n_chunks, (chunk + 1) * n_faces // n_chunks):
            code = stitch_type[f]
            nv = gather_face(vertices, face_offsets, face_vertices, f, v)
            for k in range(REST_SIZE):
                rest_f[k] = rest[f, k]
            cp, sp = face_setup(v, nv, code, ti, tf, rest_f, beta, radius, frame, fmat, knots, theta, ws)
            if naive:
                naive_points(code, ti, tf, rest_f, radius, fmat, ws)
                history[:] = 0.0
                history[0] = residuals(code, ti, ws, rest_f[R_TARGETS:], weights[0], weights[1], weights[2],
                                       weights[3], rj[0], False)
            else:
                theta0[:] = theta
                energy = gauss_newton(theta, knots, code, ti, tf, radius, rest_f[R_TARGETS:], weights, iterations, ws,
                                      rj, mats, history)
                if not (abs(energy) < math.inf and _all_finite(theta, N_UNKNOWNS)):
                    fallback_theta(theta, theta0, rest_f, cp, sp)
                    knot_points(theta, knots, code, ti, tf, radius, ws)
                    history[:] = residuals(code, ti, ws, rest_f[R_TARGETS:], weights[0], weights[1], weights[2],
                                           weights[3], rj[0], False)
            face_output(v, code, ti, tf, frame, ws, out)
            o = point_offset[f]
            finite = True
            for i in range(point_offset[f + 1] - o):
                for k in range(3):
                    out_points[o + i, k] = out[i, k]
                    finite = finite and abs(out[i, k]) < math.inf
            for p in range(N_UNKNOWNS):
                out_theta[f, p] = theta[p]
            for k in range(iterations + 1):
                out_energy[f, k] = history[k] if finite else math.nan


@njit(cache=True, fastmath=FASTMATH)
def prepare_faces(vertices, face_offsets, face_vertices, stitch_type, template_int, template_float, radius, rest,
                  bad):
    """Rest row of every face (``R_*`` layout) from the rest ``vertices``: 2-D vertices in the rest frame, (Σ X Xᵀ)⁻¹,
    knots (centre = M(knot_uv), axis c0 − c1 = M(uv + axis) − M(uv − axis): θ_0 its angle, l_0 half its length), the
    rest normal and the rest value of every residual. ``bad[f]`` = 1 where the rest face has no area (its row is then
    meaningless). Serial: it runs once per mesh."""
    ti, tf = template_int, template_float
    v = np.empty((5, 3))
    xy = np.empty((5, 2))
    frame = np.empty((4, 3))
    ws = np.zeros((MAX_POINTS, W_SIZE))
    rj = np.zeros((MAX_RESIDUALS, 1 + N_UNKNOWNS))
    zeros = np.zeros(MAX_RESIDUALS)
    theta = np.empty(N_UNKNOWNS)
    knots = np.empty((2, 2))
    up = np.array([0.0, 0.0, 1.0])
    for f in range(stitch_type.shape[0]):
        rj[:] = 0.0
        code = stitch_type[f]
        nv = gather_face(vertices, face_offsets, face_vertices, f, v)
        face_frame(v, nv, up, frame)
        m00 = m01 = m11 = 0.0
        for i in range(nv):
            px, py, pz = v[i, 0] - frame[0, 0], v[i, 1] - frame[0, 1], v[i, 2] - frame[0, 2]
            xy[i, 0] = px * frame[1, 0] + py * frame[1, 1] + pz * frame[1, 2]
            xy[i, 1] = px * frame[2, 0] + py * frame[2, 1] + pz * frame[2, 2]
            rest[f, R_XY + 2 * i], rest[f, R_XY + 2 * i + 1] = xy[i, 0], xy[i, 1]
            m00 += xy[i, 0] * xy[i, 0]
            m01 += xy[i, 0] * xy[i, 1]
            m11 += xy[i, 1] * xy[i, 1]
        det = m00 * m11 - m01 * m01
        if not det > 1e-12 * (m00 + m11) ** 2:
            bad[f] = 1
            continue
        rest[f, R_MINV], rest[f, R_MINV + 1] = m11 / det, -m01 / det
        rest[f, R_MINV + 2], rest[f, R_MINV + 3] = -m01 / det, m00 / det
        for k in range(3):
            rest[f, R_NORMAL + k] = frame[3, k]
        for j in range(2):
            u, w, du, dw = tf[code, F_KNOTS, 4 * j], tf[code, F_KNOTS, 4 * j + 1], tf[code, F_KNOTS, 4 * j + 2], \
                tf[code, F_KNOTS, 4 * j + 3]
            knots[j, 0], knots[j, 1] = ruled_point(xy, nv, u, w)
            px, py = ruled_point(xy, nv, u + du, w + dw)
            mx, my = ruled_point(xy, nv, u - du, w - dw)
            theta[j] = math.atan2(py - my, px - mx)
            theta[2 + j] = 0.5 * math.sqrt((px - mx) ** 2 + (py - my) ** 2)
            rest[f, R_KNOTS + 4 * j], rest[f, R_KNOTS + 4 * j + 1] = knots[j, 0], knots[j, 1]
            rest[f, R_KNOTS + 4 * j + 2], rest[f, R_KNOTS + 4 * j + 3] = theta[j], theta[2 + j]
            for way in range(2):  # the shear shape's knot shift, face coordinates → rest frame
                k = 1 + 4 * way + 2 * j
                sx, sy = ruled_point(xy, nv, u + tf[code, F_SHEAR, k], w + tf[code, F_SHEAR, k + 1])
                rest[f, R_SHEAR + 4 * way + 2 * j] = sx - knots[j, 0]
                rest[f, R_SHEAR + 4 * way + 2 * j + 1] = sy - knots[j, 1]
        boundary_points(v, code, ti, tf, frame, ws)
        knot_lifts(code, ti, tf, radius, 0.0, 0.0, ws)
        knot_points(theta, knots, code, ti, tf, radius, ws)
        residuals(code, ti, ws, zeros, 1.0, 1.0, 1.0, 0.0, rj, False)
        for k in range(MAX_RESIDUALS):
            rest[f, R_TARGETS + k] = rj[k, 0]
