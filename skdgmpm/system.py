"""The conservation laws of hyperelastodynamics in total Lagrangian form [R18 eq 5-6].

    dU/dt + d F_alpha / dX_alpha = rho0 b,   U = [F, p],   Q = [P, v],
    F_alpha(Q) = -[v (x) E_alpha ; P E_alpha]

The flux is linear in Q. State rows are laid out ``[F (row-major d x d), p or v (d)]`` (see
docs/CONVENTIONS.md); ``d`` is the scene dimension.
"""
import llvmlite.ir as ir
import numpy as np
from numba import njit, types
from numba.core import cgutils
from numba.extending import intrinsic
from numba.np.numpy_support import carray

from .kernel_cache import kernel_factory

SCRATCH_SIZE = 81       # entries of a `scratch` array: a (3, 3, 3, 3) tangent


@intrinsic
def _stack_doubles(typingctx):
    """Pointer to SCRATCH_SIZE doubles on the stack of the compiled function being built."""
    def codegen(context, builder, signature, args):
        return cgutils.alloca_once(builder, context.get_value_type(types.float64),
                                   size=ir.Constant(ir.IntType(64), SCRATCH_SIZE))
    return types.CPointer(types.float64)(), codegen


@njit(cache=True, inline="always")
def scratch(shape):
    """Uninitialised float array of ``shape`` (at most SCRATCH_SIZE entries) on the stack of the
    compiled function that calls it, for the per-point scratch of the compiled loops: unlike
    ``np.empty`` (heap memory the compiler must assume any other array may alias), its entries
    stay in registers once the loops over it are unrolled (a literal d). It lives as long as that
    function's call: never return it or keep it in another object."""
    n = 1
    for s in shape:
        n *= s
    if n > SCRATCH_SIZE:
        raise ValueError("scratch: more than SCRATCH_SIZE entries")
    return carray(_stack_doubles(), shape)


def n_components(d):
    return d * d + d


def split(W, d):
    """View a state array (n, d*d + d) as a tensor part (n, d, d) and a vector part (n, d)."""
    return W[:, : d * d].reshape(-1, d, d), W[:, d * d:]


def join(T, v):
    """Inverse of ``split``."""
    n, d = v.shape
    return np.concatenate([T.reshape(n, d * d), v], axis=1)


@kernel_factory
def _primitive(d):                      # a literal d: the loops unrolled (2x faster)
    def primitive(P, p, rho, Q):
        for k in range(len(p)):
            for i in range(d):
                for a in range(d):
                    Q[k, i * d + a] = P[k, i, a]
                Q[k, d * d + i] = p[k, i] / rho[k]
    return primitive


def primitive(P, p, rho):
    """Q = [P, v], v = p / rho0, from the stress P (n, d, d), momentum p (n, d) and density (n,):
    one compiled pass (P and p may be strided views, e.g. a law's (n, 3, 3) output sliced)."""
    Q = np.empty((len(p), n_components(p.shape[1])))
    _primitive(p.shape[1])(P, p, np.asarray(rho, dtype=float), Q)
    return Q


@kernel_factory
def _embed(d):                          # a literal d: the loops unrolled
    def embed(F, F3):
        for p in range(len(F)):
            for i in range(3):
                for j in range(3):
                    F3[p, i, j] = F[p, i, j] if i < d and j < d else (1.0 if i == j else 0.0)
    return embed


def embed(F):
    """(n, d, d) -> (n, 3, 3): plane strain / uniaxial strain embedding, identity elsewhere (one
    compiled pass; F may be a strided view of a state array)."""
    F3 = np.empty((len(F), 3, 3))
    _embed(F.shape[1])(F, F3)
    return F3


def normal_flux(traction, velocity, N):
    """F_N = -[v (x) N ; t] for traction t = P N and velocity v, all (n, d): returns (n, d*d + d)."""
    return -join(velocity[:, :, None] * N[:, None, :], traction)


@kernel_factory
def _volume_flux(d):                    # a literal d: the loops unrolled
    def volume_flux(Q, indptr, indices, data, add, R):
        """R += sum_alpha K^alpha F_alpha(Q) for the CSR matrices K^alpha on one pattern (data:
        their data arrays stacked (d, nnz)): F-rows (i, alpha) get -K^alpha v_i, p-rows
        -K^alpha P_i,alpha, each row's products summed in CSR order as scipy's product does and
        subtracted in the order of alpha; R = ... (each row zeroed as it is reached) unless
        ``add``."""
        dd = d * d
        sv, sP = scratch((d, d)), scratch((d, d))
        for r in range(len(indptr) - 1):
            for a in range(d):
                for i in range(d):
                    sv[a, i], sP[a, i] = 0.0, 0.0
            for k in range(indptr[r], indptr[r + 1]):    # the row read once for all the matrices
                n = indices[k]
                for a in range(d):
                    w = data[a, k]
                    for i in range(d):
                        sv[a, i] += w * Q[n, dd + i]
                        sP[a, i] += w * Q[n, i * d + a]
            for i in range(d):                           # each entry written once (0 - x is -x exactly)
                for a in range(d):
                    R[r, i * d + a] = (R[r, i * d + a] if add else 0.0) - sv[a, i]
                acc = R[r, dd + i] if add else 0.0
                for a in range(d):
                    acc -= sP[a, i]
                R[r, dd + i] = acc
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


def volume_flux(Q, stiffness, out=None):
    """sum_alpha K^alpha F_alpha(Q) for nodal Q (n_dofs, d*d + d) [R18 eq 19], added to ``out`` if
    given; ``stiffness``: a `Stiffness` (or the CSR matrices, prepared on each call): one compiled
    pass over the rows."""
    if not isinstance(stiffness, Stiffness):
        stiffness = Stiffness(stiffness)
    R = np.empty_like(Q) if out is None else out
    _volume_flux(len(stiffness[2]))(Q, *stiffness, out is not None, R)
    return R
