"""Compiled face pass of the ADER corrector [L23 eq 28-33]: one loop over the interior faces for
every time node of the predictor.

For each interior facet row and time node tau_s the pass gathers both sides' states from the
predictor's points through the trace operators (CSR rows), evaluates each side's tangent with the
law's point function (`skdgmpm.materials.points`), solves the linearised Riemann problem
(`skdgmpm.riemann` point functions) and adds w_s F_N* to the row's flux. Only the time-weighted
fluxes (nf, nc) are stored: the surface integral is linear in F_N*, so it is taken once after.

A trace is the triple (indptr, indices, data) of its CSR matrix (n_rows, n_points); the predictor
u_hat, q_hat is (S, n_points, nc) at S time nodes.
"""
import numpy as np
from numba import njit

from skdgmpm.materials.points import tangent_point

from .dgmpm_kernels import tangent_call
from .faces import gather_row as _gather
from .kernel_cache import kernel_factory
from .riemann import _godunov_flux2, _godunov_sides


def interior_flux_sum(T_L, T_R, u_hat, q_hat, rho_L, rho_R, N, mat_L, mat_R, laws, params, weights, flux):
    """flux[f] = sum_s weights[s] F_N(Q*[s, f]) for every interior row f (flux (nf, nc)), both
    sides traced from the predictor (u_hat, q_hat) at each node; mat_L, mat_R (nf,) material of
    each side, (laws, params) the law table. Returns the first row that is not hyperbolic, or -1."""
    return _interior_flux_sum(N.shape[1])(T_L, T_R, u_hat, q_hat, rho_L, rho_R, N, mat_L, mat_R, laws, params,
                                          weights, flux)


@kernel_factory
def _interior_flux_sum(d):              # a literal d: the (d, d) loops unrolled
    def interior_flux_sum(T_L, T_R, u_hat, q_hat, rho_L, rho_R, N, mat_L, mat_R, laws, params, weights, flux):
        dd, nc = d * d, d * d + d
        q_L, q_R = np.empty(nc), np.empty(nc)
        F_L, F_R = np.empty((3, 3)), np.empty((3, 3))
        C_L, C_R = np.empty((d, d, d, d)), np.empty((d, d, d, d))
        M, Z_L, Z_R, Zi, A = np.empty((d, d)), np.empty((d, d)), np.empty((d, d)), np.empty((d, d)), np.empty((d, d))
        b, t_L, t_R, t_s, v_s = np.empty(d), np.empty(d), np.empty(d), np.empty(d), np.empty(d)
        for f in range(len(N)):
            for c in range(nc):
                flux[f, c] = 0.0
            for s in range(len(weights)):
                _gather(T_L, f, u_hat[s], q_hat[s], q_L, F_L, d)
                _gather(T_R, f, u_hat[s], q_hat[s], q_R, F_R, d)
                if d == 1:              # the law called, not inlined: compile time (`tangent_call`)
                    tangent_call(laws[mat_L[f]], params[mat_L[f]], F_L, C_L, d)
                    tangent_call(laws[mat_R[f]], params[mat_R[f]], F_R, C_R, d)
                else:
                    tangent_point(laws[mat_L[f]], params[mat_L[f]], F_L, C_L, d)
                    tangent_point(laws[mat_R[f]], params[mat_R[f]], F_R, C_R, d)
                if d == 2:                  # the face in scalars (registers)
                    ok, t_s[0], t_s[1], v_s[0], v_s[1] = _godunov_flux2(q_L, C_L, rho_L[f], q_R, C_R, rho_R[f],
                                                                        N[f, 0], N[f, 1])
                    if not ok:
                        return f
                elif not _godunov_sides(q_L, C_L, rho_L[f], q_R, C_R, rho_R[f], N[f], t_L, t_R, M, Z_L, Z_R, Zi, A, b,
                                        t_s, v_s, d):
                    return f
                w = weights[s]
                for i in range(d):                           # F_N = -[v* (x) N ; t*]
                    for a in range(d):
                        flux[f, i * d + a] += w * -(v_s[i] * N[f, a])
                    flux[f, dd + i] += w * -t_s[i]
        return -1
    return interior_flux_sum


@njit(cache=True)
def traces(T, u_hat, q_hat, F, Q):
    """F[s, r] = (T u_hat[s])_F (S, n_rows, d*d) and Q[s, r] = T q_hat[s] (S, n_rows, nc) for the
    rows r of a trace T at every time node s (the boundary faces, whose conditions are applied in
    Python per node)."""
    d = int(np.sqrt(F.shape[2]))
    Fe = np.empty((3, 3))
    for s in range(len(Q)):
        for r in range(Q.shape[1]):
            _gather(T, r, u_hat[s], q_hat[s], Q[s, r], Fe, d)
            for i in range(d):
                for a in range(d):
                    F[s, r, i * d + a] = Fe[i, a]
