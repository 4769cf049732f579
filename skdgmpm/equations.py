"""The point physics of hyperelastodynamics in total Lagrangian form, each formula written once
[R18 eq 5-6, §4; L23 eq 35-37]:

    dU/dt + d F_alpha / dX_alpha = rho0 b,   U = [F, p],   Q = [P, v],
    F_alpha(Q) = -[v (x) E_alpha ; P E_alpha],      F_N(Q) = N_alpha F_alpha(Q) = -[v (x) N ; P N].

Every scheme's compiled loops call these functions: the DGMPM face passes, the DGFEM and ADER
volume terms and face fluxes, the CTU split, the health check, the laws' point loops (through
`embed`). They are compiled point functions (numba, inlined where called) on one point or face:
state rows laid out ``[F or P row-major (d, d), p or v (d)]`` (docs/CONVENTIONS.md), tangents C
(d, d, d, d), normals n (d,). ``d`` is a literal int in every caller (a kernel per dimension,
`skdgmpm.kernel_cache.kernel_factory`): the loops unroll and the `scratch` arrays stay in
registers. A 3D scheme needs here only `sqrt_spd` for d = 3 (by eigen-decomposition, already
written) and a CTU split along three edges (`ctu_split` is 2D).

The linearised Riemann problem along n: waves of family k travel at +-sqrt(omega_k / rho0),
(omega_k, Y_k) the eigenpairs of the acoustic tensor A_n = C_iajb n_a n_b; across the left-going
waves (side L's linearisation) and the right-going ones (side R's) traction t = P n and velocity v
satisfy

    t* - t_L = Z_L (v* - v_L),      t* - t_R = -Z_R (v* - v_R),      Z = sqrt(rho0 A_n),

so v* = (Z_L + Z_R)^-1 (t_R - t_L + Z_L v_L + Z_R v_R); the flux, linear in Q, needs only (t*, v*).
A boundary condition's ghost state is the same relation with the side R given by the condition
(`skdgmpm.bcs`).
"""
import numpy as np
from numba import njit

from .kernel_cache import scratch



# ---------------------------------------------------------------- state and flux
@njit(cache=True, inline="always")
def embed(u, F, d):
    """F (3, 3) = the deformation gradient of the state row u (its first d*d entries) embedded in
    3D: plane strain in 2D, uniaxial strain in 1D (identity outside the d-block)."""
    for i in range(3):
        for a in range(3):
            F[i, a] = u[i * d + a] if i < d and a < d else (1.0 if i == a else 0.0)


@njit(cache=True, inline="always")
def flux_state(P, u, rho, q, d):
    """q = [P, v] from the stress P (d, d) and the state row u = [F, p] (`velocity`)."""
    for i in range(d):
        for a in range(d):
            q[i * d + a] = P[i, a]
    velocity(u, rho, q, d)


@njit(cache=True, inline="always")
def velocity(u, rho, q, d):
    """v = p / rho0 into q = [P, v] from the state row u = [F, p]."""
    for i in range(d):
        q[d * d + i] = u[d * d + i] / rho


@njit(cache=True, inline="always")
def traction(q, n, t, d):
    """t = P n of the state row q = [P, v]."""
    for i in range(d):
        s = 0.0
        for a in range(d):
            s += q[i * d + a] * n[a]
        t[i] = s


@njit(cache=True, inline="always")
def power(t, v, d):
    """t . v: the power per unit area through a face of traction t and velocity v (W/m^2 in 2D),
    summed over i in order: every boundary's energy budget adds its faces' so."""
    s = 0.0
    for i in range(d):
        s += t[i] * v[i]
    return s


@njit(cache=True, inline="always")
def add_flux(q, alpha, scale, out, d):
    """out += scale F_alpha(q), F_alpha = -[v (x) E_alpha ; P E_alpha] (F_alpha is linear: the
    volume terms apply it once to a weighted sum of states)."""
    dd = d * d
    for i in range(d):
        out[i * d + alpha] += scale * -q[dd + i]
        out[dd + i] += scale * -q[i * d + alpha]


@njit(cache=True, inline="always")
def add_normal_flux(t, v, n, scale, out, d):
    """out += scale F_N for traction t = P n and velocity v: F_N = -[v (x) n ; t]."""
    for i in range(d):
        for a in range(d):
            out[i * d + a] += scale * -(v[i] * n[a])
        out[d * d + i] += scale * -t[i]


# ---------------------------------------------------------------- waves
@njit(cache=True, inline="always")
def acoustic(C, n, rho, M, d):
    """M = rho A_n, A_ij = C_iajb n_a n_b."""
    for i in range(d):
        for j in range(d):
            s = 0.0
            for a in range(d):
                for b in range(d):
                    s += C[i, a, j, b] * (n[a] * n[b])
            M[i, j] = rho * s


@njit(cache=True, inline="always")
def _sqrt_spd2(m00, m01, m10, m11):
    """sqrt(M) = (M + s I) / q, q = sqrt(tr M + 2 s), s = sqrt(det M), and its inverse
    adj(M + s I) / (q s) (det sqrt(M) = s) for a symmetric 2 x 2 M: (ok, Z00, Z01, Z10, Z11,
    Zi00, Zi01, Zi10, Zi11), ok False where M is not positive definite (the values are then
    meaningless). No branch: the square roots of several impedances overlap."""
    det = m00 * m11 - m01 * m10
    tr = m00 + m11
    ok = (det > 0) & (tr > 0)
    det, tr = (det, tr) if ok else (1.0, 1.0)       # not ok: finite values, never used
    s = np.sqrt(det)
    q = np.sqrt(tr + 2 * s)
    r = 1.0 / q                         # det Z = s: one division serves Z and Z^-1
    ri = r / s
    return (ok, (m00 + s) * r, m01 * r, m10 * r, (m11 + s) * r,
            (m11 + s) * ri, -m01 * ri, -m10 * ri, (m00 + s) * ri)


@njit(cache=True, inline="always")
def sqrt_spd(M, Z, Zi, d):
    """Z = sqrt(M) and Zi = Z^-1 for a symmetric (d, d) M; False where M is not positive definite.
    d = 1, 2 in closed form, otherwise by eigen-decomposition."""
    if d == 1:
        if not M[0, 0] > 0:
            return False
        Z[0, 0] = np.sqrt(M[0, 0])
        Zi[0, 0] = 1.0 / Z[0, 0]
        return True
    if d == 2:
        ok, Z[0, 0], Z[0, 1], Z[1, 0], Z[1, 1], Zi[0, 0], Zi[0, 1], Zi[1, 0], Zi[1, 1] = _sqrt_spd2(
            M[0, 0], M[0, 1], M[1, 0], M[1, 1])
        return ok
    return _sqrt_spd_eig(M, Z, Zi, d)


@njit(cache=True)
def _sqrt_spd_eig(M, Z, Zi, d):
    """`sqrt_spd` by eigen-decomposition (d = 3): a function of its own, compiled once and called.
    (numba prunes an ``if d == ...`` branch only at the top of a kernel, not inside an inlined
    helper: inlined, this branch would be compiled into every 1D and 2D kernel.)"""
    omega, Y = np.linalg.eigh(M)
    if not np.all(omega > 0):
        return False
    z = np.sqrt(omega)
    for i in range(d):
        for j in range(d):
            Z[i, j] = np.sum(Y[i] * z * Y[j])
            Zi[i, j] = np.sum(Y[i] / z * Y[j])
    return True


@njit(cache=True, inline="always")
def impedance(C, n, rho, Z, Zi, d):
    """Z = sqrt(rho A_n) and Zi = Z^-1; False where A_n is not positive definite."""
    M = scratch((d, d))
    acoustic(C, n, rho, M, d)
    return sqrt_spd(M, Z, Zi, d)


@njit(cache=True, inline="always")
def _solve(A, b, x, d):
    """x = A^-1 b for a small (d, d) A: Cramer's rule for d <= 2, otherwise Gaussian elimination
    with partial pivoting (A, b are overwritten)."""
    if d == 1:
        x[0] = b[0] / A[0, 0]
        return
    if d == 2:
        r = 1.0 / (A[0, 0] * A[1, 1] - A[0, 1] * A[1, 0])
        x[0], x[1] = (A[1, 1] * b[0] - A[0, 1] * b[1]) * r, (A[0, 0] * b[1] - A[1, 0] * b[0]) * r
        return
    _eliminate(A, b, x, d)


@njit(cache=True)
def _eliminate(A, b, x, d):
    """`_solve` by Gaussian elimination with partial pivoting (d = 3), compiled once and called
    (see `_sqrt_spd_eig`)."""
    for k in range(d):
        p = k
        for r in range(k + 1, d):
            if abs(A[r, k]) > abs(A[p, k]):
                p = r
        for c in range(d):
            A[k, c], A[p, c] = A[p, c], A[k, c]
        b[k], b[p] = b[p], b[k]
        for r in range(k + 1, d):
            m = A[r, k] * (1.0 / A[k, k])
            for c in range(k, d):
                A[r, c] -= m * A[k, c]
            b[r] -= m * b[k]
    for k in range(d - 1, -1, -1):
        s = b[k]
        for c in range(d - 1, k, -1):
            s -= A[k, c] * x[c]
        x[k] = s / A[k, k]


# ---------------------------------------------------------------- the Riemann solver
@njit(cache=True, inline="always")
def godunov(t_L, v_L, t_R, v_R, Z_L, Z_R, t_s, v_s, d):
    """The stationary state (t*, v*) of the linearised Riemann problem into t_s, v_s, given both
    sides' tractions, velocities and impedances (interior faces and boundary ghosts alike)."""
    A, b = scratch((d, d)), scratch((d,))
    for i in range(d):
        zv_L, zv_R = 0.0, 0.0
        for j in range(d):
            zv_L += Z_L[i, j] * v_L[j]
            zv_R += Z_R[i, j] * v_R[j]
            A[i, j] = Z_L[i, j] + Z_R[i, j]
        b[i] = t_R[i] - t_L[i] + zv_L + zv_R
    _solve(A, b, v_s, d)
    for i in range(d):
        s = 0.0
        for j in range(d):
            s += Z_L[i, j] * (v_s[j] - v_L[j])
        t_s[i] = t_L[i] + s


@njit(cache=True, inline="always")
def riemann(q_L, C_L, rho_L, q_R, C_R, rho_R, n, t_L, t_R, t_s, v_s, d):
    """(t*, v*) of one face into t_s, v_s from both sides' states q = [P, v] (nc,), tangents and
    densities; the sides' tractions into t_L, t_R. False where an acoustic tensor is not positive
    definite."""
    Z_L, Z_R, Zi = scratch((d, d)), scratch((d, d)), scratch((d, d))
    traction(q_L, n, t_L, d)
    traction(q_R, n, t_R, d)
    ok_L = impedance(C_L, n, rho_L, Z_L, Zi, d)
    ok_R = impedance(C_R, n, rho_R, Z_R, Zi, d)
    dd = d * d
    godunov(t_L, q_L[dd:], t_R, q_R[dd:], Z_L, Z_R, t_s, v_s, d)
    return ok_L and ok_R


@njit(cache=True, inline="always")
def fluctuations(q_L, q_R, n, t_L, t_R, flux, w_L, w_R, d):
    """The fluctuations entering each side of a face of flux F* [R18 eq 34]:
    w_L = A- dQ = F* - F_N(Q_L) into side L, w_R = A+ dQ = F_N(Q_R) - F* into side R."""
    dd = d * d
    for k in range(dd + d):
        w_L[k], w_R[k] = flux[k], 0.0
    add_normal_flux(t_L, q_L[dd:], n, -1.0, w_L, d)
    add_normal_flux(t_R, q_R[dd:], n, 1.0, w_R, d)
    for k in range(dd + d):
        w_R[k] -= flux[k]


# ---------------------------------------------------------------- corner transport upwind (2D)
@njit(cache=True, inline="always")
def _edge_split(w, m, n0, n1, inv_rho, scale, Z):
    """scale B+_n w of a fluctuation w = [w_F, w_p] (6,) along an edge normal n = (n0, n1) as a
    6-tuple, given m = C : w_F and Z = (sqrt(rho A_n), its inverse) as an 8-tuple. Decomposing w on
    the eigenvectors r_k = [Y_k (x) n ; -rho c_k Y_k] of d F_n / dU [R18 eq 35-36] gives, with
    g = (C : w_F) n,  B+ w = [(Z^-1 g - w_p / rho) / 2 (x) n ;  -g / 2 + Z w_p / (2 rho)]."""
    g0, g1 = _traction_change(m, n0, n1)
    return _edge_part(_edge_terms(w, g0, g1, inv_rho, Z), g0, g1, n0, n1, scale)


@njit(cache=True, inline="always")
def _traction_change(m, n0, n1):
    """g = (C : w_F) n along an edge normal n, given m = C : w_F (row-major 4-tuple)."""
    return 0.0 + m[0] * n0 + m[1] * n1, 0.0 + m[2] * n0 + m[3] * n1


@njit(cache=True, inline="always")
def _edge_terms(w, g0, g1, inv_rho, Z):
    """What B+_n w is made of besides g and n (`_edge_split`): Z^-1 g, w_p / rho, Z w_p / (2 rho)."""
    z00, z01, z10, z11, i00, i01, i10, i11 = Z
    return (i00 * g0 + i01 * g1, i10 * g0 + i11 * g1, w[4] * inv_rho, w[5] * inv_rho,
            0.5 * (z00 * w[4] + z01 * w[5]) * inv_rho, 0.5 * (z10 * w[4] + z11 * w[5]) * inv_rho)


@njit(cache=True, inline="always")
def _edge_part(terms, g0, g1, n0, n1, scale):
    """scale B+_n w as a 6-tuple from `_edge_terms`, g and n."""
    x0, x1, y0, y1, zw0, zw1 = terms
    a0 = 0.5 * (x0 - y0)
    a1 = 0.5 * (x1 - y1)
    return (scale * (a0 * n0), scale * (a0 * n1), scale * (a1 * n0), scale * (a1 * n1),
            scale * (-0.5 * g0 + zw0), scale * (-0.5 * g1 + zw1))


@njit(cache=True, inline="always")
def _edge_impedance(C, rho, n0, n1):
    """(ok, (Z, Z^-1) as an 8-tuple), Z = sqrt(rho A_n) along the edge normal (n0, n1)."""
    M = scratch((2, 2))
    acoustic(C, (n0, n1), rho, M, 2)
    ok, z00, z01, z10, z11, i00, i01, i10, i11 = _sqrt_spd2(M[0, 0], M[0, 1], M[1, 0], M[1, 1])
    return ok, (z00, z01, z10, z11, i00, i01, i10, i11)


@njit(cache=True, inline="always")
def ctu_split(w, C, rho, scale, a0, a1, b0, b1):
    """Corner transport upwind [R18 eq 34-37], 2D: the transverse parts G_e = scale B+_n w of a
    fluctuation w (6,) entering a cell, for the cell's two edges e of normals a = (a0, a1) and
    b = (b0, b1) adjacent to the face, B+_n the positive part of the Jacobian along n (the waves
    leaving the cell through that edge): (ok, G_0, G_1) as 6-tuples (scalars: the split stays in
    registers); ok False where an acoustic tensor is not positive definite. Two opposite edges
    share one impedance (A_n is quadratic in n)."""
    ok, Z = _edge_impedance(C, rho, a0, a1)
    if b0 == -a0 and b1 == -a1:
        G_0, G_1 = ctu_parts_opposite(w, C, 1.0 / rho, scale, a0, a1, Z)
        return ok, G_0, G_1
    Z_b = Z
    if ok:
        ok, Z_b = _edge_impedance(C, rho, b0, b1)
    G_0, G_1 = ctu_parts(w, C, 1.0 / rho, scale, a0, a1, b0, b1, Z, Z_b)
    return ok, G_0, G_1


@njit(cache=True, inline="always")
def ctu_parts(w, C, inv_rho, scale, a0, a1, b0, b1, Z_a, Z_b):
    """`ctu_split` given 1 / rho and the impedances along both edges, (Z, Z^-1) as 8-tuples (as
    `_edge_impedance` gives them; a side that knows them already, e.g. a cell whose state is
    uniform, `skdgmpm.dgmpm_kernels`): (G_0, G_1)."""
    m = _stress_change(C, w)
    return _edge_split(w, m, a0, a1, inv_rho, scale, Z_a), _edge_split(w, m, b0, b1, inv_rho, scale, Z_b)


@njit(cache=True, inline="always")
def ctu_parts_opposite(w, C, inv_rho, scale, a0, a1, Z):
    """`ctu_parts` for two opposite edges, normals a and -a (a parallelogram's), which share Z:
    the second edge's g and Z^-1 g are the first's negated, so its part costs a few additions
    (the same numbers as `ctu_parts` with b = -a and Z_b = Z, up to the sign of a zero)."""
    m = _stress_change(C, w)
    g0, g1 = _traction_change(m, a0, a1)
    x0, x1, y0, y1, zw0, zw1 = _edge_terms(w, g0, g1, inv_rho, Z)
    return (_edge_part((x0, x1, y0, y1, zw0, zw1), g0, g1, a0, a1, scale),
            _edge_part((-x0, -x1, y0, y1, zw0, zw1), -g0, -g1, -a0, -a1, scale))


@njit(cache=True, inline="always")
def _stress_change(C, w):
    """m = C : w_F (row-major 4-tuple) of a fluctuation w (6,), 2D."""
    return (C[0, 0, 0, 0] * w[0] + C[0, 0, 0, 1] * w[1] + C[0, 0, 1, 0] * w[2] + C[0, 0, 1, 1] * w[3],
            C[0, 1, 0, 0] * w[0] + C[0, 1, 0, 1] * w[1] + C[0, 1, 1, 0] * w[2] + C[0, 1, 1, 1] * w[3],
            C[1, 0, 0, 0] * w[0] + C[1, 0, 0, 1] * w[1] + C[1, 0, 1, 0] * w[2] + C[1, 0, 1, 1] * w[3],
            C[1, 1, 0, 0] * w[0] + C[1, 1, 0, 1] * w[1] + C[1, 1, 1, 0] * w[2] + C[1, 1, 1, 1] * w[3])
