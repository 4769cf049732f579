"""The conservation laws of hyperelastodynamics in total Lagrangian form [R18 eq 5-6].

    dU/dt + d F_alpha / dX_alpha = rho0 b,   U = [F, p],   Q = [P, v],
    F_alpha(Q) = -[v (x) E_alpha ; P E_alpha]

The flux is linear in Q. State rows are laid out ``[F (row-major d x d), p or v (d)]`` (see
docs/CONVENTIONS.md); ``d`` is the scene dimension.
"""
import numpy as np


def n_components(d):
    return d * d + d


def split(W, d):
    """View a state array (n, d*d + d) as a tensor part (n, d, d) and a vector part (n, d)."""
    return W[:, : d * d].reshape(-1, d, d), W[:, d * d:]


def join(T, v):
    """Inverse of ``split``."""
    n, d = v.shape
    return np.concatenate([T.reshape(n, d * d), v], axis=1)


def embed(F):
    """(n, d, d) -> (n, 3, 3): plane strain / uniaxial strain embedding, identity elsewhere."""
    n, d, _ = F.shape
    F3 = np.broadcast_to(np.eye(3), (n, 3, 3)).copy()
    F3[:, :d, :d] = F
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
