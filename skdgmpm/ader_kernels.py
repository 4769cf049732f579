"""Compiled face pass of the ADER corrector [L23 eq 28-33]: one loop over the interior faces for
every time node of the predictor.

For each interior facet row and time node tau_s the pass gathers both sides' states from the
predictor's points through the trace operators (CSR rows), evaluates each side's tangent with the
law's point function (`skdgmpm.materials.points`), solves the linearised Riemann problem
(`skdgmpm.equations`) and adds w_s F_N* to the row's flux. Only the time-weighted
fluxes (nf, nc) are stored: the surface integral is linear in F_N*, so it is taken once after.

A trace is the triple (indptr, indices, data) of its CSR matrix (n_rows, n_points); the predictor
u_hat, q_hat is (S, n_points, nc) at S time nodes.
"""
from skdgmpm.materials.points import only_law, tangent_call, tangent_points

from . import parallel
from .equations import add_normal_flux, riemann
from .faces import gather_row as _gather
from .kernel_cache import kernel_factory, scratch


def interior_flux_sum(T_L, T_R, u_hat, q_hat, rho_L, rho_R, N, mat_L, mat_R, laws, params, weights, flux):
    """flux[f] = sum_s weights[s] F_N(Q*[s, f]) for every interior row f (flux (nf, nc)), both
    sides traced from the predictor (u_hat, q_hat) at each node; mat_L, mat_R (nf,) material of
    each side, (laws, params) the law table. Returns the pass (a `parallel.Pass`, to run with the
    boundary's: `parallel.together`), which returns the first row that is not hyperbolic, or -1."""
    return parallel.Pass(len(N), _interior_flux_sum(N.shape[1], only_law(laws)), "ccwwrrrrrwwwr",
                         (T_L, T_R, u_hat, q_hat, rho_L, rho_R, N, mat_L, mat_R, laws, params, weights, flux), "first")


@kernel_factory
def _interior_flux_sum(d, only):        # literals: the (d, d) loops unrolled, one law's code
    def interior_flux_sum(T_L, T_R, u_hat, q_hat, rho_L, rho_R, N, mat_L, mat_R, laws, params, weights, flux):
        """Rows of the arrays are read into stack scratch, never handed on as views (u_hat[s],
        N[f], flux[f]): a view is reference counted at every face."""
        nc = d * d + d
        q_L, q_R, o = scratch((nc,)), scratch((nc,)), scratch((nc,))
        F_L, F_R = scratch((3, 3)), scratch((3, 3))
        C_L, C_R = scratch((d, d, d, d)), scratch((d, d, d, d))
        t_L, t_R, t_s, v_s, n = scratch((d,)), scratch((d,)), scratch((d,)), scratch((d,)), scratch((d,))
        n_points = u_hat.shape[1]
        u_flat = u_hat.reshape((-1, nc))
        q_flat = q_hat.reshape((-1, nc))
        for f in range(len(N)):
            for c in range(nc):
                o[c] = 0.0
            for i in range(d):
                n[i] = N[f, i]
            for s in range(len(weights)):
                _gather(T_L, f, u_flat, q_flat, q_L, F_L, d, s * n_points)
                _gather(T_R, f, u_flat, q_flat, q_R, F_R, d, s * n_points)
                if d == 1:              # the law called, not inlined (`points.tangent_call`)
                    tangent_call(laws, params, mat_L[f], only, F_L, C_L, d)
                    tangent_call(laws, params, mat_R[f], only, F_R, C_R, d)
                else:
                    tangent_points(laws, params, mat_L[f], mat_R[f], only, F_L, F_R, C_L, C_R, d)
                if not riemann(q_L, C_L, rho_L[f], q_R, C_R, rho_R[f], n, t_L, t_R, t_s, v_s, d):
                    return f
                add_normal_flux(t_s, v_s, n, weights[s], o, d)
            for c in range(nc):
                flux[f, c] = o[c]
        return -1
    return interior_flux_sum
