"""Weak forms of the conservation laws, written once as scikit-fem integrands.

The semi-discrete system on each cell [R18 eq 12, 19], [L23 eq 27] reads

    M dU/dt = K^alpha F_alpha(Q) - int_Gamma Phi F_N*

and every term below is integrated by whatever quadrature the basis carries: Gauss points
(DGFEM) or material points with their volumes as weights (DGMPM, [R18 eq 14-18]).
"""
from skfem import BilinearForm, LinearForm


@BilinearForm
def mass(u, v, w):
    """Mass matrix ``int u v`` (lumped by row sums in DGMPM [R18 eq 38])."""
    return u * v


def pseudo_stiffness(alpha):
    """Pseudo-stiffness ``K^alpha_ij = int dPhi_i/dX_alpha Phi_j`` [R18 eq 38].

    Rows are test functions (i), columns trial functions (j).
    """
    @BilinearForm
    def form(u, v, w):
        return v.grad[alpha] * u

    return form


@LinearForm
def surface_flux(v, w):
    """Surface term ``int_Gamma Phi_i F_N*`` for one component of the numerical flux ``w.flux``.

    The stepper applies this integrand through trace operators pre-factored from the same facet
    bases (a sparse matrix product per step instead of a re-assembly); the tests check that both
    agree.
    """
    return w.flux * v
