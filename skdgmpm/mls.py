"""Moving least squares shape functions of the particles of each cell [L23 §4.2, eq 47-54].

chi_p(x) = p(x)^T A(x)^-1 w_p(x) p(x_p),  A(x) = sum_p w_p(x) p(x_p) p(x_p)^T,

in parent coordinates of the cell [L23 Remark 2], with the tensor-product monomial basis of order
m (1, xi, eta, xi eta, ... up to xi^m eta^m, the space Q_m of the DG cell) and a tensor-product
weight of support = cell size: the cubic spline of eq 52 (m <= 2) or a quartic spline (m = 3).
Order 0 is Shepard's partition of unity (eq 54). Arrays are batched over cells: particles
``xi`` (n_cells, n_max, d) with a ``mask`` for the padding of cells holding fewer, evaluation
points (n_cells, n_eval, d).
"""
import numpy as np

from .errors import InputError


def exponents(order, d):
    """Monomial exponents of Q_order in d dimensions, (n_basis, d), lowest degree first."""
    grids = np.meshgrid(*[np.arange(order + 1)] * d, indexing="ij")
    e = np.stack([g.ravel() for g in grids], axis=1)
    return e[np.lexsort((e[:, 0], e.sum(axis=1)))]


def weight(r, kind):
    """Spline weight of r = |x - x_p| / support and its derivative dw/dr."""
    r = np.abs(r)
    if kind == "cubic":                                     # L23 eq 52
        w = np.where(r <= 0.5, 2 / 3 - 4 * r**2 + 4 * r**3,
                     np.where(r <= 1, 4 / 3 - 4 * r + 4 * r**2 - 4 / 3 * r**3, 0.0))
        dw = np.where(r <= 0.5, -8 * r + 12 * r**2, np.where(r <= 1, -4 + 8 * r - 4 * r**2, 0.0))
    elif kind == "quartic":
        w = np.where(r <= 1, 1 - 6 * r**2 + 8 * r**3 - 3 * r**4, 0.0)
        dw = np.where(r <= 1, -12 * r + 24 * r**2 - 12 * r**3, 0.0)
    else:
        raise InputError(f"MLS weight {kind!r}: expected 'cubic' or 'quartic'")
    return w, dw


def _monomials(x, e):
    """p(x) (..., n_basis) and dp/dx (..., n_basis, d) for exponents e (n_basis, d)."""
    p = np.prod(x[..., None, :] ** e, axis=-1)
    d = x.shape[-1]
    dp = np.empty(p.shape + (d,))
    for k in range(d):
        ek = e.copy()
        ek[:, k] = np.maximum(e[:, k] - 1, 0)
        dp[..., k] = e[:, k] * np.prod(x[..., None, :] ** ek, axis=-1)
    return p, dp


def shape_functions(xi, mask, points, order, kind=None, support=1.0, cells=None):
    """MLS shape functions and their parent-coordinate gradients.

    Parameters
    ----------
    xi : (n_cells, n_max, d) particle parent coordinates; mask : (n_cells, n_max) real particles
    points : (n_cells, n_eval, d) evaluation points (parent coordinates)
    order : MLS order m (0 = Shepard); kind : weight, default cubic (m <= 2) / quartic (m = 3)
    cells : (n_cells,) cell numbers for error messages

    Returns
    -------
    phi (n_cells, n_eval, n_max), dphi (n_cells, n_eval, n_max, d); zero on padding.
    """
    kind = kind or ("cubic" if order <= 2 else "quartic")
    nc, nm, d = xi.shape
    e = exponents(order, d)
    if np.all(mask.sum(axis=1) == len(e)) and nm == len(e) and order > 0:
        return _interpolation(xi, points, e, order, cells)
    # centre the basis on the evaluation point for conditioning: p(x_p - x)
    rel = xi[:, None, :, :] - points[:, :, None, :]                          # (nc, ne, nm, d)
    w1, dw1 = weight(rel / support, kind)
    w = np.prod(w1, axis=-1) * mask[:, None, :]
    dw = np.empty(w.shape + (d,))                                            # d w / d x (eval point)
    for k in range(d):
        others = np.prod(np.delete(w1, k, axis=-1), axis=-1) if d > 1 else 1.0
        dw[..., k] = -dw1[..., k] * np.sign(rel[..., k]) / support * others * mask[:, None, :]
    P, dP = _monomials(rel, e)                                               # (nc, ne, nm, nb[, d])
    A = np.einsum("cep,cepi,cepj->ceij", w, P, P)
    cond = np.linalg.cond(A)
    bad = ~np.isfinite(cond) | (cond > 1e12)
    if bad.any():
        c, _ = np.argwhere(bad)[0]
        cell = c if cells is None else cells[c]
        raise InputError(f"MLS order {order}: singular moment matrix in cell {cell} "
                         f"({int(mask[c].sum())} particles; need at least {len(e)} in a "
                         f"non-degenerate layout)")
    # p(0) at the evaluation point (relative coordinates): only the constant monomial is 1
    p0 = (e.sum(axis=1) == 0).astype(float)
    Ainv_p0 = np.linalg.solve(A, np.broadcast_to(p0, A.shape[:-1])[..., None])[..., 0]   # (nc, ne, nb)
    phi = w * np.einsum("cei,cepi->cep", Ainv_p0, P)
    # gradient w.r.t. the evaluation point x: rel = x_p - x, so dP/dx = -dP/drel
    dA = (np.einsum("cepk,cepi,cepj->ceijk", dw, P, P)
          - np.einsum("cep,cepik,cepj->ceijk", w, dP, P) - np.einsum("cep,cepi,cepjk->ceijk", w, P, dP))
    g = np.einsum("cei,ceijk->cejk", Ainv_p0, dA)                             # a^T dA
    Ainv_g = np.linalg.solve(A[..., None, :, :].repeat(d, axis=-3),
                             np.moveaxis(g, -1, -2)[..., None])[..., 0]        # (nc, ne, d, nb)
    dphi = (dw * np.einsum("cei,cepi->cep", Ainv_p0, P)[..., None]
            - w[..., None] * np.einsum("cei,cepik->cepk", Ainv_p0, dP)
            - w[..., None] * np.einsum("ceki,cepi->cepk", Ainv_g, P))
    return phi, dphi


def _interpolation(xi, points, e, order, cells):
    """MLS with exactly as many particles as monomials: the weights cancel (A^-1 B = P^-1) and
    chi_p are the Lagrange polynomials through the particles. Solved directly on the Vandermonde
    matrix (centred on the cell) instead of the normal equations, which square its condition."""
    P, _ = _monomials(xi - 0.5, e)                                          # (nc, nm, nb)
    cond = np.linalg.cond(P)
    bad = ~np.isfinite(cond) | (cond > 1e10)
    if bad.any():
        c = int(np.flatnonzero(bad)[0])
        cell = c if cells is None else cells[c]
        raise InputError(f"MLS order {order}: singular moment matrix in cell {cell} "
                         f"({xi.shape[1]} particles in a degenerate layout)")
    inv = np.linalg.inv(P)                                                  # (nc, nb, nm)
    p, dp = _monomials(points - 0.5, e)                                     # (nc, ne, nb[, d])
    return np.einsum("ceb,cbp->cep", p, inv), np.einsum("cebk,cbp->cepk", dp, inv)
