"""State arrays of hyperelastodynamics in total Lagrangian form [R18 eq 5-6] and the batched
passes over them (the volume flux, the embedding of F), on the point physics of
`skdgmpm.equations`. State rows are laid out ``[F (row-major d x d), p or v (d)]`` (see
docs/CONVENTIONS.md); ``d`` is the scene dimension.
"""
import numpy as np
from numba import njit

from .equations import add_flux, embed as _embed_point
from . import parallel
from .kernel_cache import kernel_factory, scratch


def n_components(d):
    return d * d + d


DIMENSION = {n_components(d): d for d in (1, 2, 3)}     # the dimension of a state row's width


def split(W, d):
    """View a state array (n, d*d + d) as a tensor part (n, d, d) and a vector part (n, d)."""
    return W[:, : d * d].reshape(-1, d, d), W[:, d * d:]


def join(T, v):
    """Inverse of ``split``: one compiled pass (in parallel chunks)."""
    n, d = v.shape
    out, T = np.empty((n, d * d + d)), T.reshape(n, d, d)
    kernel = _join(d)
    parallel.chunked(n, kernel, "rrr", (T, v, out))
    return out


@kernel_factory
def _join(d):                           # a literal d: the loops unrolled
    def join(T, v, out):
        for k in range(len(v)):
            for i in range(d):
                for a in range(d):
                    out[k, i * d + a] = T[k, i, a]
                out[k, d * d + i] = v[k, i]
    return join


def kinetic_density(U, scale):
    """scale_k |p_k|^2 of each row k of a state array U (n, d*d + d) (scale (n,) = V / (2 rho0):
    the kinetic energy 1/2 m |v|^2 of the point, p = rho0 v): one compiled pass."""
    n, d = len(U), DIMENSION[U.shape[1]]
    out = np.empty(n)
    parallel.chunked(n, _momentum_squares(d), "rrr", (U, scale, out))
    return out


@kernel_factory
def _momentum_squares(d):               # a literal d: the loop unrolled
    def momentum_squares(U, scale, out):
        for k in range(len(out)):
            s = 0.0
            for i in range(d):
                s += U[k, d * d + i] * U[k, d * d + i]
            out[k] = scale[k] * s
    return momentum_squares


@kernel_factory
def _embed(d):
    def embed(F, F3):
        for p in range(len(F)):
            _embed_point(F[p], F3[p], d)
    return embed


def embed(F):
    """(n, d, d) -> (n, 3, 3): plane strain / uniaxial strain embedding, identity elsewhere
    (`equations.embed`; F may be a strided view of a state array)."""
    n, d = len(F), F.shape[1]
    F3, F = np.empty((n, 3, 3)), np.reshape(F, (n, d * d))
    kernel = _embed(d)
    parallel.chunked(n, kernel, "rr", (F, F3))
    return F3


@njit(cache=True, inline="always")
def volume_row(Q, stiffness, r, o, d):
    """o += sum_alpha (K^alpha F_alpha(Q))[r], row r of the volume term (`volume_flux`), for a
    prepared `Stiffness` (indptr, indices, data (d, nnz)): F_alpha (`equations.add_flux`) applied
    to the row's weighted sums of Q (the flux is linear), summed in CSR order as scipy's product
    does and added in the order of alpha. Also called inside other node passes (DGMPM's Euler
    stage), so that the term is never stored."""
    indptr, indices, data = stiffness
    nc = d * d + d
    s = scratch((d, nc))
    for a in range(d):
        for c in range(nc):
            s[a, c] = 0.0
    for k in range(indptr[r], indptr[r + 1]):    # the row read once for all the matrices
        n = indices[k]
        for a in range(d):
            w = data[a, k]
            for c in range(nc):
                s[a, c] += w * Q[n, c]
    for a in range(d):
        add_flux(s[a], a, 1.0, o, d)


@kernel_factory
def _volume_flux(d):                    # a literal d: the loops unrolled
    def volume_flux(Q, indptr, indices, data, add, R):
        """R += sum_alpha K^alpha F_alpha(Q) for the CSR matrices K^alpha on one pattern (data:
        their data arrays stacked (d, nnz)), row by row (`volume_row`); R = ... (each row zeroed as
        it is reached) unless ``add``."""
        nc = d * d + d
        o = scratch((nc,))
        for r in range(len(indptr) - 1):
            for c in range(nc):
                o[c] = R[r, c] if add else 0.0
            volume_row(Q, (indptr, indices, data), r, o, d)
            for c in range(nc):                          # each entry written once
                R[r, c] = o[c]
    return volume_flux


class Stiffness(tuple):
    """The matrices K^alpha (alpha = 0 .. d-1, CSR) as `volume_flux` reads them, prepared once:
    (indptr, indices, data (d, nnz)) on the union of their patterns (`quadrature.common_pattern`),
    a 2D array of weights that the compiled pass indexes faster than a tuple of arrays (5.3 ->
    3.2 ms at 256^2). Build it once per grid: it copies the data."""

    def __new__(cls, matrices):
        from .quadrature import common_pattern

        K0 = matrices[0]
        if not all(K.indptr is K0.indptr and K.indices is K0.indices for K in matrices):
            matrices = common_pattern(matrices)
        self = super().__new__(cls, (matrices[0].indptr, matrices[0].indices, np.stack([K.data for K in matrices])))
        self.shape = matrices[0].shape                  # (rows, columns) of each K^alpha
        return self

    @classmethod
    def from_arrays(cls, indptr, indices, data, shape):
        """From the arrays themselves, (d, nnz) data, kept as they are (no copy)."""
        self = super().__new__(cls, (indptr, indices, data))
        self.shape = shape
        return self


def volume_flux(Q, stiffness, out=None):
    """sum_alpha K^alpha F_alpha(Q) for nodal Q (n_dofs, d*d + d) [R18 eq 19], added to ``out`` if
    given; ``stiffness``: a `Stiffness` (or the CSR matrices, prepared on each call): one compiled
    pass over the rows."""
    if not isinstance(stiffness, Stiffness):
        stiffness = Stiffness(stiffness)
    R = np.empty((stiffness.shape[0], Q.shape[1])) if out is None else out
    (indptr, indices, data), kernel, add = stiffness, _volume_flux(len(stiffness[2])), out is not None
    parallel.chunked(len(R), kernel, "wiwwwr", (Q, indptr, indices, data, add, R))
    return R
