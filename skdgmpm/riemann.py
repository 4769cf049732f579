"""Linearised Godunov solver for Q = [P, v] along a face normal N [R18 §4], [L23 eq 35-37].

Closed form: the waves of family k travel at +-sqrt(omega_k / rho0), with (omega_k, Y_k) the
eigenpairs of the acoustic tensor A_N = C_iajb N_a N_b. Across the left-going waves (side L's
linearisation) and the right-going waves (side R's) traction t = P N and velocity v satisfy

    t* - t_L = Z_L (v* - v_L),      t* - t_R = -Z_R (v* - v_R),      Z = sqrt(rho0 A_N),

so the stationary state is v* = (Z_L + Z_R)^-1 (t_R - t_L + Z_L v_L + Z_R v_R). The flux, linear in
Q, needs only (t*, v*). All functions are batched over faces: traction and velocity (nf, d),
impedances (nf, d, d), tangents C (nf, d, d, d, d).

Each quantity is one compiled point function (numba) looped over the faces inside the compiled
code: a face costs a few hundred flops, far below numpy's per-call overhead on (d, d) axes. The
batched functions and the fused face and CTU kernels call the same point functions.
"""
import numpy as np
from numba import njit
from scipy.linalg import null_space

from .errors import InstabilityError
from .kernel_cache import kernel_factory


def _not_hyperbolic(face):
    raise InstabilityError(f"loss of hyperbolicity: acoustic tensor not positive definite at face {face}")


# ---------------------------------------------------------------- point functions (one face)
@njit(cache=True, inline="always")
def _acoustic2(C, i, j, n0, n1):
    """A_ij = C_iajb n_a n_b in 2D, summed as `_acoustic` does."""
    return C[i, 0, j, 0] * (n0 * n0) + C[i, 0, j, 1] * (n0 * n1) + C[i, 1, j, 0] * (n1 * n0) + C[i, 1, j, 1] * (n1 * n1)


@njit(cache=True, inline="always")
def _acoustic(C, n, rho, M, d):
    """M_ij = rho C_iajb n_a n_b into M (d, d)."""
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
    meaningless). Scalars and no branch, so the 2D kernels keep them in registers and overlap the
    square roots of several impedances."""
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
def _sqrt_spd(M, Z, Zi, d):
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
def _solve(A, b, x, d):
    """x = A^-1 b for a small (d, d) A by Gaussian elimination with partial pivoting (A, b are
    overwritten)."""
    for k in range(d):
        p = k
        for r in range(k + 1, d):
            if abs(A[r, k]) > abs(A[p, k]):
                p = r
        for c in range(d):
            A[k, c], A[p, c] = A[p, c], A[k, c]
        b[k], b[p] = b[p], b[k]
        for r in range(k + 1, d):
            m = A[r, k] * (1.0 / A[k, k])                # as LAPACK getrf: same round-off
            for c in range(k, d):
                A[r, c] -= m * A[k, c]
            b[r] -= m * b[k]
    for k in range(d - 1, -1, -1):
        s = b[k]
        for c in range(d - 1, k, -1):
            s -= A[k, c] * x[c]
        x[k] = s / A[k, k]


@njit(cache=True, inline="always")
def _godunov(t_L, v_L, t_R, v_R, Z_L, Z_R, t_s, v_s, A, b, d):
    """(t*, v*) of one face into t_s, v_s; A (d, d) and b (d,) are scratch."""
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
def _godunov_sides(q_L, C_L, rho_L, q_R, C_R, rho_R, n, t_L, t_R, M, Z_L, Z_R, Zi, A, b, t_s, v_s, d):
    """(t*, v*) of one face into t_s, v_s from both sides' Q = [P, v] (nc,), tangents (d, d, d, d)
    and densities, any d: tractions t = P n into t_L, t_R, both impedances, `_godunov`; the rest
    are the caller's scratch arrays. False where an acoustic tensor is not positive definite."""
    for i in range(d):
        sL, sR = 0.0, 0.0
        for a in range(d):
            sL += q_L[i * d + a] * n[a]
            sR += q_R[i * d + a] * n[a]
        t_L[i], t_R[i] = sL, sR
    _acoustic(C_L, n, rho_L, M, d)
    if not _sqrt_spd(M, Z_L, Zi, d):
        return False
    _acoustic(C_R, n, rho_R, M, d)
    if not _sqrt_spd(M, Z_R, Zi, d):
        return False
    dd = d * d
    _godunov(t_L, q_L[dd:], t_R, q_R[dd:], Z_L, Z_R, t_s, v_s, A, b, d)
    return True


@njit(cache=True, inline="always")
def _stress_rate(w, C):
    """M_ia = C_iajb w_jb of a fluctuation w (6,) in 2D, as four scalars (M00, M01, M10, M11):
    the traction rate along n is g = M n, shared by every direction of one face."""
    m = (C[0, 0, 0, 0] * w[0] + C[0, 0, 0, 1] * w[1] + C[0, 0, 1, 0] * w[2] + C[0, 0, 1, 1] * w[3],
         C[0, 1, 0, 0] * w[0] + C[0, 1, 0, 1] * w[1] + C[0, 1, 1, 0] * w[2] + C[0, 1, 1, 1] * w[3],
         C[1, 0, 0, 0] * w[0] + C[1, 0, 0, 1] * w[1] + C[1, 0, 1, 0] * w[2] + C[1, 0, 1, 1] * w[3],
         C[1, 1, 0, 0] * w[0] + C[1, 1, 0, 1] * w[1] + C[1, 1, 1, 0] * w[2] + C[1, 1, 1, 1] * w[3])
    return m


@njit(cache=True, inline="always")
def _transverse_positive(w, m, C, n0, n1, rho, scale, out):
    """scale B+_n w of one face into out (6,) (see `transverse_positive`), 2D only (the CTU
    corrections are 2D): w (6,), m = `_stress_rate` (w, C), C (2, 2, 2, 2), n = (n0, n1). False
    where the acoustic tensor along n is not positive definite."""
    g0 = 0.0 + m[0] * n0 + m[1] * n1                     # g = (C : w_F) n
    g1 = 0.0 + m[2] * n0 + m[3] * n1
    ok, z00, z01, z10, z11, i00, i01, i10, i11 = _sqrt_spd2(
        rho * _acoustic2(C, 0, 0, n0, n1), rho * _acoustic2(C, 0, 1, n0, n1),
        rho * _acoustic2(C, 1, 0, n0, n1), rho * _acoustic2(C, 1, 1, n0, n1))
    if not ok:
        return False
    a0 = 0.5 * ((i00 * g0 + i01 * g1) - w[4] / rho)
    a1 = 0.5 * ((i10 * g0 + i11 * g1) - w[5] / rho)
    out[0], out[1], out[2], out[3] = scale * (a0 * n0), scale * (a0 * n1), scale * (a1 * n0), scale * (a1 * n1)
    out[4] = scale * (-0.5 * g0 + 0.5 * (z00 * w[4] + z01 * w[5]) / rho)
    out[5] = scale * (-0.5 * g1 + 0.5 * (z10 * w[4] + z11 * w[5]) / rho)
    return True


@njit(cache=True, inline="always")
def _godunov_flux2(Q_L, C_L, rho_L, Q_R, C_R, rho_R, n0, n1):
    """(ok, t*_0, t*_1, v*_0, v*_1) of one 2D face from the sides' Q (6,), tangents and densities,
    in scalars (no scratch arrays, so the whole face stays in registers): both impedances by
    `_sqrt_spd2`, the 2 x 2 system (Z_L + Z_R) v* = t_R - t_L + Z_L v_L + Z_R v_R by Cramer's rule."""
    tL0, tL1 = Q_L[0] * n0 + Q_L[1] * n1, Q_L[2] * n0 + Q_L[3] * n1
    tR0, tR1 = Q_R[0] * n0 + Q_R[1] * n1, Q_R[2] * n0 + Q_R[3] * n1
    okL, a00, a01, a10, a11, _, _, _, _ = _sqrt_spd2(
        rho_L * _acoustic2(C_L, 0, 0, n0, n1), rho_L * _acoustic2(C_L, 0, 1, n0, n1),
        rho_L * _acoustic2(C_L, 1, 0, n0, n1), rho_L * _acoustic2(C_L, 1, 1, n0, n1))
    okR, b00, b01, b10, b11, _, _, _, _ = _sqrt_spd2(
        rho_R * _acoustic2(C_R, 0, 0, n0, n1), rho_R * _acoustic2(C_R, 0, 1, n0, n1),
        rho_R * _acoustic2(C_R, 1, 0, n0, n1), rho_R * _acoustic2(C_R, 1, 1, n0, n1))
    vL0, vL1, vR0, vR1 = Q_L[4], Q_L[5], Q_R[4], Q_R[5]
    A00, A01, A10, A11 = a00 + b00, a01 + b01, a10 + b10, a11 + b11
    c0 = tR0 - tL0 + (a00 * vL0 + a01 * vL1) + (b00 * vR0 + b01 * vR1)
    c1 = tR1 - tL1 + (a10 * vL0 + a11 * vL1) + (b10 * vR0 + b11 * vR1)
    det = A00 * A11 - A01 * A10
    r = 1.0 / det
    vs0, vs1 = (A11 * c0 - A01 * c1) * r, (A00 * c1 - A10 * c0) * r
    ts0 = tL0 + (a00 * (vs0 - vL0) + a01 * (vs1 - vL1))
    ts1 = tL1 + (a10 * (vs0 - vL0) + a11 * (vs1 - vL1))
    return okL and okR, ts0, ts1, vs0, vs1


# ---------------------------------------------------------------- loops over faces
# One kernel per literal d (`skdgmpm.kernel_cache.kernel_factory`): the compiler unrolls every
# (d, d) loop of the point functions it inlines and drops the other dimensions' branches.
@kernel_factory
def _impedances(d):
    def impedances(C, N, rho, Z, Zi):
        M = np.empty((d, d))
        for f in range(len(N)):
            _acoustic(C[f], N[f], rho[f], M, d)
            if not _sqrt_spd(M, Z[f], Zi[f], d):
                return f
        return -1
    return impedances


@kernel_factory
def _godunov_states(d):
    def godunov_states(t_L, v_L, t_R, v_R, Z_L, Z_R, t_s, v_s):
        A, b = np.empty((d, d)), np.empty(d)
        for f in range(len(v_L)):
            _godunov(t_L[f], v_L[f], t_R[f], v_R[f], Z_L[f], Z_R[f], t_s[f], v_s[f], A, b, d)
    return godunov_states


@kernel_factory
def _godunov_fluxes(d):
    def godunov_fluxes(Q_L, C_L, rho_L, Q_R, C_R, rho_R, N, flux, fluct_L, fluct_R):
        M, Z_L, Z_R, Zi, A, b = (np.empty((d, d)), np.empty((d, d)), np.empty((d, d)), np.empty((d, d)),
                                 np.empty((d, d)), np.empty(d))
        t_L, t_R, t_s, v_s = np.empty(d), np.empty(d), np.empty(d), np.empty(d)
        dd = d * d
        for f in range(len(N)):
            if not _godunov_sides(Q_L[f], C_L[f], rho_L[f], Q_R[f], C_R[f], rho_R[f], N[f], t_L, t_R, M, Z_L, Z_R, Zi,
                                  A, b, t_s, v_s, d):
                return f
            v_L, v_R = Q_L[f, dd:], Q_R[f, dd:]
            for i in range(d):                               # F_N = -[v (x) N ; t]
                for a in range(d):
                    k = i * d + a
                    flux[f, k] = -(v_s[i] * N[f, a])
                    fluct_L[f, k] = flux[f, k] + v_L[i] * N[f, a]
                    fluct_R[f, k] = -(v_R[i] * N[f, a]) - flux[f, k]
                flux[f, dd + i] = -t_s[i]
                fluct_L[f, dd + i] = flux[f, dd + i] + t_L[i]
                fluct_R[f, dd + i] = -t_R[i] - flux[f, dd + i]
        return -1
    return godunov_fluxes


@njit(cache=True)
def _transverse_positives(w, C, n, rho, out):
    for f in range(len(n)):
        m = _stress_rate(w[f], C[f])
        if not _transverse_positive(w[f], m, C[f], n[f, 0], n[f, 1], rho[f], 1.0, out[f]):
            return f
    return -1


@njit(cache=True)
def _transverse_scatter(w, C, rho, scale, normals, edge_int, edge_bnd, sign, corr_int, corr_bnd):
    nc = 6                                               # 2D only: a literal width, loops unrolled
    G = np.empty((2, nc))
    for f in range(len(w)):
        m = _stress_rate(w[f], C[f])
        for e in range(2):
            n0, n1 = normals[e, f, 0], normals[e, f, 1]
            if not _transverse_positive(w[f], m, C[f], n0, n1, rho[f], scale[f], G[e]):
                return f
        for e in range(2):
            j = edge_int[e, f]
            if j >= 0:
                for k in range(nc):
                    corr_int[j, k] += sign[e, f] * G[e, k]
            j = edge_bnd[e, f]
            if j >= 0:
                for k in range(nc):
                    corr_bnd[j, k] += G[e, k] - G[1 - e, k]
    return -1


# ---------------------------------------------------------------- batched over faces
def impedance(C, N, rho0, inverse=False):
    """Z = sqrt(rho0 A_N) (or its inverse), (nf, d, d); fails loudly where A_N is not positive."""
    Z, Zinv = impedances(C, N, rho0)
    return Zinv if inverse else Z


def impedances(C, N, rho0):
    """Z = sqrt(rho0 A_N) and its inverse, (nf, d, d) each, from one decomposition."""
    nf, d = N.shape
    Z, Zinv = np.empty((nf, d, d)), np.empty((nf, d, d))
    bad = _impedances(d)(C, N, np.asarray(rho0, dtype=float), Z, Zinv)
    if bad >= 0:
        _not_hyperbolic(bad)
    return Z, Zinv


def godunov_state(t_L, v_L, t_R, v_R, Z_L, Z_R):
    """Stationary traction and velocity (t*, v*) of the linearised Riemann problem."""
    t_s, v_s = np.empty_like(t_L), np.empty_like(v_L)
    _godunov_states(v_L.shape[1])(t_L, v_L, t_R, v_R, Z_L, Z_R, t_s, v_s)
    return t_s, v_s


def godunov_fluxes(Q_L, C_L, rho_L, Q_R, C_R, rho_R, N):
    """Godunov flux F_N(Q*) and the fluctuations entering each side, F_N(Q*) - F_N(Q_L) (A- dQ,
    into side L) and F_N(Q_R) - F_N(Q*) (A+ dQ, into side R), from the two sides' states
    Q = [P, v] (nf, d*d + d) and linearisations (tangents C, densities rho) in one pass over the
    faces: traction, both impedances, `godunov_state`, flux. Returns three (nf, d*d + d) arrays."""
    flux, fluct_L, fluct_R = np.empty_like(Q_L), np.empty_like(Q_L), np.empty_like(Q_L)
    bad = _godunov_fluxes(N.shape[1])(Q_L, C_L, np.asarray(rho_L, dtype=float), Q_R, C_R,
                                      np.asarray(rho_R, dtype=float), N, flux, fluct_L, fluct_R)
    if bad >= 0:
        _not_hyperbolic(bad)
    return flux, fluct_L, fluct_R


def godunov_state_eigen(P_L, v_L, P_R, v_R, C_L, C_R, rho_L, rho_R, N):
    """Reference path: Q* = Q_L + sum over left-going waves, from a full eigen-decomposition.

    Builds the quasi-linear Jacobian A_N(Q) of [L23 eq 11-12] on each side, takes the left-going
    eigenvectors of side L, the right-going of side R and the (material-independent) stationary
    ones, and solves Q_R - Q_L = sum_m delta_m r_m [R18 eq 32-33]. Slow; used by the tests.
    Returns the full Q* = (P* (nf, d, d), v* (nf, d)).
    """
    nf, d = v_L.shape
    nq = d * d + d

    def jacobian(C, rho):
        A = np.zeros((nf, nq, nq))
        A[:, : d * d, d * d:] = -np.einsum("fiajb,fb->fiaj", C, N).reshape(nf, d * d, d)
        A[:, d * d:, : d * d] = -(np.eye(d)[None, :, :, None] * N[:, None, None, :]
                                  ).reshape(nf, d, d * d) / rho[:, None, None]
        return A

    J_L, J_R = jacobian(C_L, rho_L), jacobian(C_R, rho_R)
    lam_L, R_L = np.linalg.eig(J_L)
    lam_R, R_R = np.linalg.eig(J_R)
    scale = np.abs(np.concatenate([lam_L, lam_R], axis=1)).max(axis=1, keepdims=True)
    left = lam_L.real < -1e-8 * scale          # wave speeds are real (hyperbolicity)
    right = lam_R.real > 1e-8 * scale
    Q_L = np.concatenate([P_L.reshape(nf, -1), v_L], axis=1)
    Q_R = np.concatenate([P_R.reshape(nf, -1), v_R], axis=1)
    out = np.empty_like(Q_L)
    for f in range(nf):                       # reference path only: clarity over speed
        # stationary waves: v = 0, P N = 0, i.e. P = e_i (x) m with m . N = 0 (built
        # explicitly: eig may return this kernel as a complex pair)
        tangents = null_space(N[f][None, :])                            # (d, d - 1)
        kernel = np.zeros((nq, d * (d - 1)))
        kernel[: d * d] = np.einsum("ij,am->iajm", np.eye(d), tangents).reshape(d * d, -1)
        basis = np.concatenate([R_L[f][:, left[f]].real, kernel, R_R[f][:, right[f]].real], axis=1)
        delta = np.linalg.solve(basis, Q_R[f] - Q_L[f])
        n_left = left[f].sum()
        out[f] = Q_L[f] + basis[:, :n_left] @ delta[:n_left]
    return out[:, : d * d].reshape(nf, d, d), out[:, d * d:]


def transverse_positive(w_F, w_p, C, n, rho0):
    """B+_n w: the part of a flux fluctuation w = [w_F (nf, d, d), w_p (nf, d)] carried by the
    waves moving along +n, times their speeds [R18 eq 35-36].

    With g = (C : w_F) n and Z = sqrt(rho0 A_n), decomposing w on the eigenvectors
    r_k = [Y_k (x) n ; -rho0 c_k Y_k] of d F_n / dU gives the closed form
    B+ w = [ (Z^-1 g - w_p / rho0) / 2 (x) n ;  -g / 2 + Z w_p / (2 rho0) ].  2D only (CTU).
    """
    nf, d = n.shape
    if d != 2:
        raise ValueError(f"transverse_positive: the CTU splitting is 2D, got d = {d}")
    w = np.concatenate([w_F.reshape(nf, d * d), w_p], axis=1)
    out = np.empty_like(w)
    bad = _transverse_positives(w, C, n, np.asarray(rho0, dtype=float), out)
    if bad >= 0:
        _not_hyperbolic(bad)
    return out[:, : d * d].reshape(nf, d, d), out[:, d * d:]


def transverse_fluxes(w, C, rho0, scale, normals, edge_int, edge_bnd, sign, corr_int, corr_bnd):
    """Accumulate the transverse (CTU) flux corrections of one face side in place: the
    face-set-at-a-time reference that tests/test_dgmpm_kernels.py checks the fused DGMPM face pass
    (`skdgmpm.dgmpm_kernels`, which splits each fluctuation as soon as it is known) against.

    For every face f, the fluctuation w[f] (nc,) entering a cell is split along the normals
    ``normals[e, f]`` (2, nf, d) of the cell's two edges e adjacent to the face, G_e =
    scale[f] B+_n w[f]. ``corr_int[edge_int[e, f]] += sign[e, f] G_e`` where the edge is interior
    (index >= 0), and ``corr_bnd[edge_bnd[e, f]] += G_e - G_(1-e)`` where it is a boundary edge
    (the ghost cell, a copy of the cell, sends back the opposite edge's correction).
    """
    bad = _transverse_scatter(w, C, np.asarray(rho0, dtype=float), scale, normals, edge_int, edge_bnd, sign,
                              corr_int, corr_bnd)
    if bad >= 0:
        _not_hyperbolic(bad)
