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


@njit(cache=True)
def _primitive(P, p, rho, Q):
    if p.shape[1] == 2:                 # a literal d: the loops unrolled (2x faster)
        _primitive_d(P, p, rho, Q, 2)
    else:
        _primitive_d(P, p, rho, Q, p.shape[1])


@njit(cache=True, inline="always")
def _primitive_d(P, p, rho, Q, d):
    for k in range(len(p)):
        for i in range(d):
            for a in range(d):
                Q[k, i * d + a] = P[k, i, a]
            Q[k, d * d + i] = p[k, i] / rho[k]


def primitive(P, p, rho):
    """Q = [P, v], v = p / rho0, from the stress P (n, d, d), momentum p (n, d) and density (n,):
    one compiled pass (P and p may be strided views, e.g. a law's (n, 3, 3) output sliced)."""
    Q = np.empty((len(p), n_components(p.shape[1])))
    _primitive(P, p, np.asarray(rho, dtype=float), Q)
    return Q


@njit(cache=True)
def _embed(F, F3):
    if F.shape[1] == 2:                 # a literal d: the loops unrolled
        _embed_d(F, F3, 2)
    else:
        _embed_d(F, F3, F.shape[1])


@njit(cache=True, inline="always")
def _embed_d(F, F3, d):
    for p in range(len(F)):
        for i in range(3):
            for j in range(3):
                F3[p, i, j] = F[p, i, j] if i < d and j < d else (1.0 if i == j else 0.0)


def embed(F):
    """(n, d, d) -> (n, 3, 3): plane strain / uniaxial strain embedding, identity elsewhere (one
    compiled pass; F may be a strided view of a state array)."""
    F3 = np.empty((len(F), 3, 3))
    _embed(F, F3)
    return F3


def normal_flux(traction, velocity, N):
    """F_N = -[v (x) N ; t] for traction t = P N and velocity v, all (n, d): returns (n, d*d + d)."""
    return -join(velocity[:, :, None] * N[:, None, :], traction)


@njit(cache=True)
def _volume_flux(Q, indptr, indices, data, alphas, d, add, R):
    """R += sum_j K^alpha_j F_alpha_j(Q) for CSR matrices K^alpha_j sharing one pattern (data: a
    tuple of their data arrays, alphas: their alpha): F-rows (i, alpha) get -K^alpha v_i, p-rows
    -K^alpha P_i,alpha, each row's products summed in CSR order as scipy's product does and
    subtracted in the order of the matrices; R = ... (each row zeroed as it is reached) unless
    ``add``."""
    if d == 2:                          # a literal d: the loops unrolled
        _volume_flux_d(Q, indptr, indices, data, alphas, add, R, 2)
    else:
        _volume_flux_d(Q, indptr, indices, data, alphas, add, R, d)


@njit(cache=True, inline="always")
def _volume_flux_d(Q, indptr, indices, data, alphas, add, R, d):
    dd, m = d * d, len(data)
    sv, sP = scratch((m, d)), scratch((m, d))
    for r in range(len(indptr) - 1):
        if not add:
            for c in range(dd + d):
                R[r, c] = 0.0
        for j in range(m):
            for i in range(d):
                sv[j, i], sP[j, i] = 0.0, 0.0
        for k in range(indptr[r], indptr[r + 1]):    # the row read once for all the matrices
            n = indices[k]
            for j in range(m):
                w, alpha = data[j][k], alphas[j]
                for i in range(d):
                    sv[j, i] += w * Q[n, dd + i]
                    sP[j, i] += w * Q[n, i * d + alpha]
        for j in range(m):
            for i in range(d):
                R[r, i * d + alphas[j]] -= sv[j, i]
                R[r, dd + i] -= sP[j, i]


def volume_flux(Q, stiffness, out=None):
    """sum_alpha K^alpha F_alpha(Q) for nodal Q (n_dofs, d*d + d) [R18 eq 19] (CSR stiffness
    matrices), added to ``out`` if given; one compiled pass over the rows for matrices that
    share their pattern arrays (`quadrature.common_pattern`), one per matrix otherwise."""
    R = np.empty_like(Q) if out is None else out
    d = len(stiffness)
    K0 = stiffness[0]
    if all(K.indptr is K0.indptr and K.indices is K0.indices for K in stiffness):
        _volume_flux(Q, K0.indptr, K0.indices, tuple(K.data for K in stiffness), tuple(range(d)), d,
                     out is not None, R)
    else:
        for alpha, K in enumerate(stiffness):
            _volume_flux(Q, K.indptr, K.indices, (K.data,), (alpha,), d, out is not None or alpha > 0, R)
    return R
