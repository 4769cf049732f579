"""Lagrange line element of any order for the broken spaces of DGFEM in 1D.

scikit-fem's ``ElementLinePp`` is hierarchical and its traces on interior facets of a
``MeshLine`` fail for P >= 3 in scikit-fem 12 (shape error, or wrong values), so 1D uses this
nodal element: vertices first, then interior nodes at Gauss-Lobatto points.
"""
import numpy as np
from numpy.polynomial import legendre
from skfem.element import ElementH1
from skfem.refdom import RefLine


def lobatto_nodes(order):
    """Gauss-Lobatto nodes on [0, 1]: 0, 1, then the interior ones ascending."""
    inner = np.sort(legendre.Legendre.basis(order).deriv().roots().real) if order > 1 else np.zeros(0)
    return np.concatenate([[0.0, 1.0], 0.5 * (inner + 1.0)])


class ElementLineLagrange(ElementH1):
    """Piecewise Lagrange polynomial of degree ``order`` on Gauss-Lobatto nodes."""

    nodal_dofs = 1
    refdom = RefLine

    def __init__(self, order):
        self.order = order
        self.maxdeg = order
        self.interior_dofs = order - 1
        nodes = lobatto_nodes(order)
        self.doflocs = nodes[:, None]
        self.dofnames = ["u"] * (order + 1)
        # coefficients of each nodal basis polynomial (Vandermonde inverse), degree ascending
        self._coef = np.linalg.inv(np.vander(nodes, order + 1, increasing=True)).T
        self._dcoef = [np.polynomial.polynomial.polyder(c) for c in self._coef]

    def lbasis(self, X, i):
        if not 0 <= i <= self.order:
            self._index_error()
        x = X[0]
        phi = np.polynomial.polynomial.polyval(x, self._coef[i])
        dphi = np.polynomial.polynomial.polyval(x, self._dcoef[i])
        return phi, np.array([dphi])
