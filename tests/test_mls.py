"""MLS shape functions [L23 §4.2]: reproduction of the basis, Shepard at order 0, clear errors."""
import numpy as np
import pytest

from skdgmpm.errors import InputError
from skdgmpm.mls import exponents, shape_functions, weight


def layout(n, d):
    c = (np.arange(n) + 0.5) / n
    g = np.meshgrid(*[c] * d, indexing="ij")
    return np.stack([x.ravel() for x in g], axis=1)


@pytest.mark.parametrize("d", [1, 2])
@pytest.mark.parametrize("order", [0, 1, 2, 3])
def test_reproduces_every_polynomial_of_its_basis_and_their_gradients(d, order):
    rng = np.random.default_rng(order)
    xi = layout(order + 2, d)[None] + 0.02 * rng.standard_normal((1, (order + 2) ** d, d))
    mask = np.ones(xi.shape[:2])
    pts = rng.uniform(0, 1, (1, 15, d))
    phi, dphi = shape_functions(xi, mask, pts, order)
    for e in exponents(order, d):
        q = np.prod(xi[0] ** e, axis=1)
        exact = np.prod(pts[0] ** e, axis=1)
        assert np.allclose(phi[0] @ q, exact, atol=1e-10)
        for k in range(d):
            ek = e.copy()
            ek[k] -= 1
            grad = e[k] * np.prod(pts[0] ** np.maximum(ek, 0), axis=1) if e[k] else 0 * exact
            assert np.allclose(np.einsum("ep,p->e", dphi[0, :, :, k], q), grad, atol=1e-8)


def test_order_zero_is_shepard():
    xi = layout(3, 2)[None]
    pts = np.random.default_rng(1).uniform(0, 1, (1, 7, 2))
    phi, _ = shape_functions(xi, np.ones((1, 9)), pts, 0)
    w = np.prod(weight(xi[0][None, :, :] - pts[0][:, None, :], "cubic")[0], axis=-1)
    assert np.allclose(phi[0], w / w.sum(axis=1, keepdims=True))


def test_padding_is_ignored():
    xi = np.concatenate([layout(2, 2), np.full((3, 2), 0.5)])[None]
    mask = np.r_[np.ones(4), np.zeros(3)][None]
    pts = np.array([[[0.3, 0.6]]])
    phi, dphi = shape_functions(xi, mask, pts, 1)
    assert np.allclose(phi[0, 0, 4:], 0) and np.isclose(phi.sum(), 1)


@pytest.mark.parametrize("xi, order", [
    (layout(2, 2)[:3], 1),                                        # too few for Q1 (4 needed)
    (np.column_stack([np.linspace(0.1, 0.9, 9), np.full(9, 0.5)]), 1),   # all on one line
])
def test_singular_moment_matrix_is_a_clear_error(xi, order):
    with pytest.raises(InputError, match="singular moment matrix in cell 7"):
        shape_functions(xi[None], np.ones((1, len(xi))), np.array([[[0.4, 0.4]]]), order,
                        cells=np.array([7]))


@pytest.mark.parametrize("order", [1, 2, 3])
def test_as_many_particles_as_monomials_is_lagrange_interpolation(order):
    """With n_particles = n_basis the weights cancel: the direct interpolation path agrees with
    the weighted normal equations (forced here by one zero-weight padding particle) and is
    nodal (chi_p(x_q) = delta_pq)."""
    xi = layout(order + 1, 2)[None] + 0.01
    pts = np.random.default_rng(2).uniform(0.05, 0.95, (1, 9, 2))
    direct, ddirect = shape_functions(xi, np.ones(xi.shape[:2]), pts, order)
    padded = np.concatenate([xi, [[[0.5, 0.5]]]], axis=1)
    mask = np.r_[np.ones(xi.shape[1]), 0.0][None]
    weighted, dweighted = shape_functions(padded, mask, pts, order)
    assert np.allclose(direct, weighted[:, :, :-1], atol=1e-8)
    assert np.allclose(ddirect, dweighted[:, :, :-1], atol=1e-6)
    nodal, _ = shape_functions(xi, np.ones(xi.shape[:2]), xi, order)
    assert np.allclose(nodal[0], np.eye(xi.shape[1]), atol=1e-12)
