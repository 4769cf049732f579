"""Linearised Godunov solver for Q = [P, v] along a face normal N [R18 §4], [L23 eq 35-37].

Closed form: the waves of family k travel at +-sqrt(omega_k / rho0), with (omega_k, Y_k) the
eigenpairs of the acoustic tensor A_N = C_iajb N_a N_b. Across the left-going waves (side L's
linearisation) and the right-going waves (side R's) traction t = P N and velocity v satisfy

    t* - t_L = Z_L (v* - v_L),      t* - t_R = -Z_R (v* - v_R),      Z = sqrt(rho0 A_N),

so the stationary state is v* = (Z_L + Z_R)^-1 (t_R - t_L + Z_L v_L + Z_R v_R). The flux, linear in
Q, needs only (t*, v*). All functions are batched over faces: traction and velocity (nf, d),
impedances (nf, d, d), tangents C (nf, d, d, d, d).
"""
import numpy as np
from scipy.linalg import null_space

from .errors import InstabilityError


def acoustic_tensor(C, N):
    """A_ij = C_iajb N_a N_b: (nf, d, d), as a batch of (d*d, d*d) @ (d*d,) products (several
    times faster than einsum on these tiny axes)."""
    nf, d = N.shape
    Ct = C.transpose(0, 1, 3, 2, 4).reshape(nf, d * d, d * d)              # (f, ij, ab)
    return np.matmul(Ct, (N[:, :, None] * N[:, None, :]).reshape(nf, d * d, 1)).reshape(nf, d, d)


def _not_hyperbolic(bad):
    face = int(np.flatnonzero(bad)[0])
    raise InstabilityError(f"loss of hyperbolicity: acoustic tensor not positive definite at face {face}")


def impedance(C, N, rho0, inverse=False):
    """Z = sqrt(rho0 A_N) (or its inverse), (nf, d, d); fails loudly where A_N is not positive.

    d = 1, 2 in closed form (sqrt(M) = (M + s I) / sqrt(tr M + 2 s), s = sqrt(det M)),
    otherwise by eigen-decomposition.
    """
    Z, Zinv = impedances(C, N, rho0)
    return Zinv if inverse else Z


def impedances(C, N, rho0):
    """Z = sqrt(rho0 A_N) and its inverse, (nf, d, d) each, from one decomposition."""
    M = rho0[:, None, None] * acoustic_tensor(C, N)
    d = M.shape[1]
    if d == 1:
        if not np.all(M > 0):
            _not_hyperbolic(M[:, 0, 0] <= 0)
        Z = np.sqrt(M)
        return Z, 1.0 / Z
    if d == 2:
        det = M[:, 0, 0] * M[:, 1, 1] - M[:, 0, 1] * M[:, 1, 0]
        tr = M[:, 0, 0] + M[:, 1, 1]
        if not np.all((det > 0) & (tr > 0)):
            _not_hyperbolic(~((det > 0) & (tr > 0)))
        s = np.sqrt(det)
        Z = (M + s[:, None, None] * np.eye(2)) / np.sqrt(tr + 2 * s)[:, None, None]
        adj = np.empty_like(Z)
        adj[:, 0, 0], adj[:, 0, 1], adj[:, 1, 0], adj[:, 1, 1] = Z[:, 1, 1], -Z[:, 0, 1], -Z[:, 1, 0], Z[:, 0, 0]
        return Z, adj / (Z[:, 0, 0] * Z[:, 1, 1] - Z[:, 0, 1] * Z[:, 1, 0])[:, None, None]
    omega, Y = np.linalg.eigh(M)
    if not np.all(omega > 0):
        _not_hyperbolic(np.any(omega <= 0, axis=1))
    z = np.sqrt(omega)
    return np.einsum("fik,fk,fjk->fij", Y, z, Y), np.einsum("fik,fk,fjk->fij", Y, 1.0 / z, Y)


def _matvec(A, x):
    return np.einsum("fij,fj->fi", A, x)


def godunov_state(t_L, v_L, t_R, v_R, Z_L, Z_R):
    """Stationary traction and velocity (t*, v*) of the linearised Riemann problem."""
    rhs = t_R - t_L + _matvec(Z_L, v_L) + _matvec(Z_R, v_R)
    v = np.linalg.solve(Z_L + Z_R, rhs[..., None])[..., 0]
    return t_L + _matvec(Z_L, v - v_L), v


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
    B+ w = [ (Z^-1 g - w_p / rho0) / 2 (x) n ;  -g / 2 + Z w_p / (2 rho0) ].
    """
    nf, d = n.shape
    Cw = np.matmul(C.reshape(nf, d * d, d * d), w_F.reshape(nf, d * d, 1)).reshape(nf, d, d)   # C : w_F
    g = np.matmul(Cw, n[:, :, None])[:, :, 0]
    Z, Zinv = impedances(C, n, rho0)
    a = 0.5 * (_matvec(Zinv, g) - w_p / rho0[:, None])
    return a[:, :, None] * n[:, None, :], -0.5 * g + 0.5 * _matvec(Z, w_p) / rho0[:, None]
