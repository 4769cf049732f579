"""The conservation laws of hyperelastodynamics in total Lagrangian form [R18 eq 5-6].

    dU/dt + d F_alpha / dX_alpha = rho0 b,   U = [F, p],   Q = [P, v],
    F_alpha(Q) = -[v (x) E_alpha ; P E_alpha]

The flux is linear in Q. State rows are laid out ``[F (row-major d x d), p or v (d)]`` (see
docs/CONVENTIONS.md); ``d`` is the scene dimension.
"""
import numpy as np
from numba import njit


def n_components(d):
    return d * d + d


def split(W, d):
    """View a state array (n, d*d + d) as a tensor part (n, d, d) and a vector part (n, d)."""
    return W[:, : d * d].reshape(-1, d, d), W[:, d * d:]


def join(T, v):
    """Inverse of ``split``."""
    n, d = v.shape
    return np.concatenate([T.reshape(n, d * d), v], axis=1)


@njit(cache=True)
def _embed(F, F3):
    d = F.shape[1]
    for p in range(len(F)):
        for i in range(3):
            for j in range(3):
                F3[p, i, j] = F[p, i, j] if i < d and j < d else (1.0 if i == j else 0.0)


def embed(F):
    """(n, d, d) -> (n, 3, 3): plane strain / uniaxial strain embedding, identity elsewhere (one
    compiled pass; F may be a strided view of a state array)."""
    F3 = np.empty((len(F), 3, 3))
    _embed(F, F3)
    return F3


def embed_vector(N):
    """(n, d) -> (n, 3)."""
    out = np.zeros((len(N), 3))
    out[:, : N.shape[1]] = N
    return out


def normal_flux(traction, velocity, N):
    """F_N = -[v (x) N ; t] for traction t = P N and velocity v, all (n, d): returns (n, d*d + d)."""
    return -join(velocity[:, :, None] * N[:, None, :], traction)


def volume_flux(Q, stiffness):
    """sum_alpha K^alpha F_alpha(Q) for nodal Q (n_dofs, d*d + d) [R18 eq 19]."""
    d = len(stiffness)
    P, v = split(Q, d)
    R = np.zeros_like(Q)
    RF, Rp = split(R, d)
    for alpha, K in enumerate(stiffness):
        RF[:, :, alpha] = -(K @ v)                     # F-row i, column alpha: -v_i
        Rp -= K @ P[:, :, alpha]                       # p-row i: -P_i,alpha
    return R
