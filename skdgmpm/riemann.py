"""The linearised Riemann solver batched over a set of faces [R18 §4], [L23 eq 35-37]: traction
and velocity (nf, d), impedances (nf, d, d), tangents C (nf, d, d, d, d), states Q = [P, v]
(nf, d*d + d). Each function is one compiled loop over the faces calling the point functions of
`skdgmpm.equations` (where the formulas are written) and `skdgmpm.bcs` (the ghost states). The
batched ones (`godunov_fluxes`, `impedance`, `normal_flux`) take face arrays, for the tests'
references; DGFEM's faces (`trace_fluxes`, `boundary_fluxes`, also ADER's boundary) and the fused
DGMPM and ADER face passes call the same point functions from the traces, without face arrays.
"""
import numpy as np
from numba import njit

from skdgmpm.materials.points import only_law, stress_point, stress_points, tangent_call, tangent_point, tangent_points

from . import parallel
from .bcs import ghost_face
from .equations import (add_normal_flux, ctu_split, flux_state, fluctuations, godunov, impedance as _impedance,
                        riemann)
from .errors import InstabilityError
from .faces import gather_row
from .kernel_cache import kernel_factory, scratch


def _not_hyperbolic(face):
    raise InstabilityError(f"loss of hyperbolicity: acoustic tensor not positive definite at face {face}")


def face_passes(interior, boundary, together=True):
    """Run a scheme's interior and boundary faces' passes (each a `parallel.Pass` returning its
    first face that is not hyperbolic, or -1) in one loop over the threads (`parallel.together`),
    or one after the other; stop at the first such face, the interior's first."""
    found = (parallel.together(interior, boundary) if together else
             (parallel.chunked(*interior), parallel.chunked(*boundary)))
    for first in found:
        if first >= 0:
            _not_hyperbolic(first)


# ---------------------------------------------------------------- loops over faces
# One kernel per literal d (`skdgmpm.kernel_cache.kernel_factory`): the compiler unrolls every
# (d, d) loop of the point functions it inlines and drops the other dimensions' branches.
@kernel_factory
def _impedances(d):
    def impedances(C, N, rho, Z, Zi):
        for f in range(len(N)):
            if not _impedance(C[f], N[f], rho[f], Z[f], Zi[f], d):
                return f
        return -1
    return impedances


@kernel_factory
def _godunov_states(d):
    def godunov_states(t_L, v_L, t_R, v_R, Z_L, Z_R, t_s, v_s):
        for f in range(len(v_L)):
            godunov(t_L[f], v_L[f], t_R[f], v_R[f], Z_L[f], Z_R[f], t_s[f], v_s[f], d)
    return godunov_states


@kernel_factory
def _godunov_fluxes(d):
    nc = d * d + d

    def godunov_fluxes(Q_L, C_L, rho_L, Q_R, C_R, rho_R, N, flux, fluct_L, fluct_R):
        """Each face's rows copied into stack scratch: row views (Q_L[f], C_L[f], ...) handed to
        the inlined point functions would be reference counted at every face."""
        t_L, t_R, t_s, v_s, n = scratch((d,)), scratch((d,)), scratch((d,)), scratch((d,)), scratch((d,))
        q_L, q_R, o, w_L, w_R = scratch((nc,)), scratch((nc,)), scratch((nc,)), scratch((nc,)), scratch((nc,))
        c_L, c_R = scratch((d, d, d, d)), scratch((d, d, d, d))
        for f in range(len(N)):
            for k in range(nc):
                q_L[k], q_R[k], o[k] = Q_L[f, k], Q_R[f, k], 0.0
            for i in range(d):
                n[i] = N[f, i]
                for a in range(d):
                    for j in range(d):
                        for b in range(d):
                            c_L[i, a, j, b], c_R[i, a, j, b] = C_L[f, i, a, j, b], C_R[f, i, a, j, b]
            if not riemann(q_L, c_L, rho_L[f], q_R, c_R, rho_R[f], n, t_L, t_R, t_s, v_s, d):
                return f
            add_normal_flux(t_s, v_s, n, 1.0, o, d)
            fluctuations(q_L, q_R, n, t_L, t_R, o, w_L, w_R, d)
            for k in range(nc):
                flux[f, k], fluct_L[f, k], fluct_R[f, k] = o[k], w_L[k], w_R[k]
        return -1
    return godunov_fluxes


@kernel_factory
def _trace_fluxes(d, traced, only):    # traced: 1 if Q is traced (a law with history), 0: the law at the trace; one law
    nc = d * d + d

    def trace_fluxes(T_L, T_R, U, Q, rho_L, rho_R, N, mat_L, mat_R, laws, params, flux):
        """Each side's state is formed in stack scratch as the unfused path formed it (the trace
        summed in CSR order, embedded F, P from the law, v = p / rho0), never stored."""
        q_L, q_R, o = scratch((nc,)), scratch((nc,)), scratch((nc,))
        F_L, F_R, P_L, P_R = scratch((3, 3)), scratch((3, 3)), scratch((d, d)), scratch((d, d))
        c_L, c_R = scratch((d, d, d, d)), scratch((d, d, d, d))
        t_L, t_R, t_s, v_s, n = scratch((d,)), scratch((d,)), scratch((d,)), scratch((d,)), scratch((d,))
        for f in range(len(N)):
            for i in range(d):
                n[i] = N[f, i]
            gather_row(T_L, f, U, Q, q_L, F_L, d)
            gather_row(T_R, f, U, Q, q_R, F_R, d)
            m_L, m_R = mat_L[f], mat_R[f]
            if not traced:              # q holds the trace of U: [F, p] -> [P(F), p / rho0]
                stress_points(laws, params, m_L, m_R, only, F_L, F_R, P_L, P_R, d)
                flux_state(P_L, q_L, rho_L[f], q_L, d)      # q's p read before its v is written, entry by entry
                flux_state(P_R, q_R, rho_R[f], q_R, d)
            if d == 1:                  # the law called, not inlined (`points.tangent_call`)
                tangent_call(laws, params, m_L, only, F_L, c_L, d)
                tangent_call(laws, params, m_R, only, F_R, c_R, d)
            else:
                tangent_points(laws, params, m_L, m_R, only, F_L, F_R, c_L, c_R, d)
            if not riemann(q_L, c_L, rho_L[f], q_R, c_R, rho_R[f], n, t_L, t_R, t_s, v_s, d):
                return f
            for k in range(nc):
                o[k] = 0.0
            add_normal_flux(t_s, v_s, n, 1.0, o, d)
            for k in range(nc):
                flux[f, k] = o[k]
        return -1
    return trace_fluxes


@kernel_factory
def _boundary_fluxes(d, traced, only):  # traced: 1 if q is given (ADER's predictor, a law with history), 0: the law
    nc = d * d + d

    def boundary_fluxes(lo, hi, T, u, q, rho, N, material, laws, params, ghosts, values, weights, flux, t_s, v_s):
        """Node by node (the imposed values of node s, a view taken once a chunk), each row's
        side formed in stack scratch as `trace_fluxes` forms it."""
        frame, velocity, copy = ghosts
        q_f, o, F, P = scratch((nc,)), scratch((nc,)), scratch((3, 3)), scratch((d, d))
        C, Z, Zi = scratch((d, d, d, d)), scratch((d, d)), scratch((d, d))
        t_L, v_L, t_f, v_f, n = scratch((d,)), scratch((d,)), scratch((d,)), scratch((d,)), scratch((d,))
        n_points = u.shape[1]
        u_flat = u.reshape((-1, nc))
        q_flat = q.reshape((-1, nc))
        for s in range(len(weights)):
            rule = (frame, velocity, values[s], copy)
            for f in range(lo, hi):
                for i in range(d):
                    n[i] = N[f, i]
                gather_row(T, f, u_flat, q_flat, q_f, F, d, s * n_points)
                m = material[f]
                if not traced:          # q_f holds the trace of U: [F, p] -> [P(F), p / rho0]
                    stress_point(laws, params, m, only, F, P, d)
                    flux_state(P, q_f, rho[f], q_f, d)
                if d == 1:              # the law called, not inlined (`points.tangent_call`)
                    tangent_call(laws, params, m, only, F, C, d)
                else:
                    tangent_point(laws, params, m, only, F, C, d)
                if not _impedance(C, n, rho[f], Z, Zi, d):
                    return f - lo
                ghost_face(rule, f, q_f, n, Z, t_L, v_L, t_f, v_f, d)
                for k in range(nc):     # sum_s weights[s] F_N, summed from 0 in node order
                    o[k] = 0.0 if s == 0 else flux[f, k]
                add_normal_flux(t_f, v_f, n, weights[s], o, d)
                for k in range(nc):
                    flux[f, k] = o[k]
                for i in range(d):
                    t_s[s, f, i], v_s[s, f, i] = t_f[i], v_f[i]
        return -1
    return boundary_fluxes


@kernel_factory
def _normal_fluxes(d):
    def normal_fluxes(t, v, N, flux):
        for f in range(len(N)):
            flux[f] = 0.0
            add_normal_flux(t[f], v[f], N[f], 1.0, flux[f], d)
    return normal_fluxes


@njit(cache=True)
def _transverse_positives(w, C, n, rho, out):
    for f in range(len(n)):                              # the opposite normal: the same impedance
        ok, G, _ = ctu_split(w[f], C[f], rho[f], 1.0, n[f, 0], n[f, 1], -n[f, 0], -n[f, 1])
        if not ok:
            return f
        for k in range(6):
            out[f, k] = G[k]
    return -1


@njit(cache=True)
def _transverse_scatter(w, C, rho, scale, normals, edge_int, edge_bnd, sign, corr_int, corr_bnd):
    G = np.empty((2, 6))
    for f in range(len(w)):
        ok, G_0, G_1 = ctu_split(w[f], C[f], rho[f], scale[f], normals[0, f, 0], normals[0, f, 1],
                                 normals[1, f, 0], normals[1, f, 1])
        if not ok:
            return f
        for k in range(6):
            G[0, k], G[1, k] = G_0[k], G_1[k]
        for e in range(2):
            j = edge_int[e, f]
            if j >= 0:
                for k in range(6):
                    corr_int[j, k] += sign[e, f] * G[e, k]
            j = edge_bnd[e, f]
            if j >= 0:
                for k in range(6):
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


def normal_flux(t, v, N):
    """F_N = -[v (x) N ; t] of every face for traction t and velocity v (nf, d): (nf, d*d + d)."""
    flux = np.empty((len(N), N.shape[1] * (N.shape[1] + 1)))
    _normal_fluxes(N.shape[1])(t, v, N, flux)
    return flux


def godunov_fluxes(Q_L, C_L, rho_L, Q_R, C_R, rho_R, N):
    """Godunov flux F_N(Q*) and the fluctuations entering each side, F_N(Q*) - F_N(Q_L) (A- dQ,
    into side L) and F_N(Q_R) - F_N(Q*) (A+ dQ, into side R), from the two sides' states
    Q = [P, v] (nf, d*d + d) and linearisations (tangents C, densities rho) in one pass over the
    faces: traction, both impedances, `godunov_state`, flux. Returns three (nf, d*d + d) arrays."""
    flux, fluct_L, fluct_R = np.empty_like(Q_L), np.empty_like(Q_L), np.empty_like(Q_L)
    rho_L, rho_R, kernel = np.asarray(rho_L, dtype=float), np.asarray(rho_R, dtype=float), _godunov_fluxes(N.shape[1])
    bad = parallel.chunked(len(N), kernel, "rrrrrrrrrr", (Q_L, C_L, rho_L, Q_R, C_R, rho_R, N, flux, fluct_L, fluct_R),
                           "first")
    if bad >= 0:
        _not_hyperbolic(bad)
    return flux, fluct_L, fluct_R


def trace_fluxes(T_L, T_R, U, Q, rho_L, rho_R, N, mat_L, mat_R, laws, params, flux):
    """Godunov flux F_N(Q*) (nf, nc) into ``flux`` at the rows of the traces T_L, T_R (CSR triples
    (nf, n_dofs)) of the nodal states U (n_dofs, nc), in one pass over the faces that keeps no
    face array: each side's Q is the law (mat_L, mat_R (nf,) into the table laws, params) at the
    trace of U with densities rho_L, rho_R (nf,), or, if Q (n_dofs, nc) is given, its trace (a
    law with history, which lives at the points only); the tangent at the trace of F. The same
    numbers as `godunov_fluxes` on the traced face states, bit for bit. Returns the pass (a
    `parallel.Pass`, to run with the boundary's: `parallel.together`), which returns the first
    face that is not hyperbolic, or -1."""
    kernel = _trace_fluxes(N.shape[1], int(Q is not None), only_law(laws))
    Q = U if Q is None else Q
    return parallel.Pass(len(N), kernel, "ccwwrrrrrwwr", (T_L, T_R, U, Q, rho_L, rho_R, N, mat_L, mat_R, laws, params,
                                                         flux), "first")


def boundary_fluxes(T, u, q, rho, N, material, laws, params, ghosts, values, weights, flux, t_s, v_s):
    """The Godunov fluxes of the boundary face rows under their conditions, summed over time nodes:
    flux[f] = sum_s weights[s] F_N(t*, v*) (nf, nc), the stationary states of every node into t_s,
    v_s (S, nf, d). Row f's interior side at node s is the trace T (CSR triple (nf, n_points)) of
    the node's states u (S, n_points, nc) with the law (``material`` (nf,) into the table laws,
    params; densities rho (nf,)) at the trace of F, or, with ``q`` (S, n_points, nc) given, the trace
    of q (ADER's predictor; a law with history); the tangent at the trace of F; then the face's
    ghost state (`bcs.ghost_face`; ``ghosts`` = `BoundaryGhosts`'s (frame, imposes velocity,
    copies the interior), ``values`` (S, nf, d) the imposed values at each node's time). One
    compiled pass on the threads, each row written by one chunk: the same bits for any thread
    count. Returns the pass (a `parallel.Pass`), which returns the first row whose acoustic
    tensor is not positive definite, or -1."""
    kernel = _boundary_fluxes(N.shape[1], int(q is not None), only_law(laws))
    q = u if q is None else q
    return parallel.Pass(len(N), kernel, "lh" + "w" * 14, (T, u, q, rho, N, material, laws, params, ghosts, values,
                                                          weights, flux, t_s, v_s), "first",
                         max(1, parallel.MIN_ROWS // 8))


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
