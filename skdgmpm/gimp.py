"""Shape functions of MPM and GIMP on a uniform axis-aligned background grid [WG08 §2].

Three kinds, tensor products of 1D functions in 2D:

* ``hat``: linear hat N_i of the grid (classic MPM), 2 nodes per axis;
* ``ugimp``: S_ip = (1 / V_p) int chi_p N_i with a particle domain chi_p of constant half-length
  l_p = l_p0 (half the initial particle spacing), 3 nodes per axis;
* ``cpgimp``: the same with l_p = l_p0 F_ii, the domain stretched with the particle.

The 1D GIMP convolution has the closed form [WG08 eq 5-6], with xi = x_p - x_i and h the spacing:

    |xi| < l_p:              S = 1 - (xi^2 + l_p^2) / (2 h l_p),   dS/dx = -xi / (h l_p)
    l_p <= |xi| < h - l_p:   S = 1 - |xi| / h,                      dS/dx = -sign(xi) / h
    h - l_p <= |xi| < h + l_p: S = (h + l_p - |xi|)^2 / (4 h l_p),  dS/dx = -sign(xi) (h + l_p - |xi|) / (2 h l_p)

The gradient is taken at fixed l_p: it is the domain average (1 / V_p) int chi_p grad N_i.
The nodes are those of the scikit-fem mesh (``mesh.p``); the matrices are scipy CSR,
(n_particles, n_nodes).
"""
from dataclasses import dataclass

import numpy as np
import scipy.sparse as sp
from numba import njit

from . import parallel
from .errors import InputError, InstabilityError
from .kernel_cache import kernel_factory

SHAPES = ("hat", "ugimp", "cpgimp")


@dataclass(frozen=True)
class Lattice:
    """The nodes of a uniform axis-aligned grid as a lattice.

    Attributes
    ----------
    origin, h : (d,) lowest corner and spacing per axis (m)
    shape : (d,) nodes per axis
    node : int array of ``shape``, lattice index -> mesh node (column of ``mesh.p``)
    """

    origin: np.ndarray
    h: np.ndarray
    shape: tuple
    node: np.ndarray

    @classmethod
    def from_mesh(cls, mesh):
        """Lattice of ``mesh``'s nodes; InputError if they are not a uniform axis-aligned grid."""
        p = mesh.p
        d = p.shape[0]
        origin, upper = p.min(axis=1), p.max(axis=1)
        shape, h, index = [], [], []
        for k in range(d):
            n = len(np.unique(np.round((p[k] - origin[k]) / (upper[k] - origin[k]), 9)))
            hk = (upper[k] - origin[k]) / max(n - 1, 1)
            ik = np.rint((p[k] - origin[k]) / hk).astype(np.int64)
            if n < 2 or np.abs(p[k] - origin[k] - ik * hk).max() > 1e-9 * hk:
                raise InputError(f"grid: mpm needs a uniform axis-aligned grid; the node coordinates "
                                 f"along axis {'xyz'[k]} are not evenly spaced")
            shape.append(n)
            h.append(hk)
            index.append(ik)
        node = np.full(shape, -1, dtype=np.int64)
        node[tuple(index)] = np.arange(p.shape[1])
        if p.shape[1] != np.prod(shape) or np.any(node < 0):
            raise InputError(f"grid: mpm needs a uniform axis-aligned grid; its {p.shape[1]} nodes "
                             f"do not fill a {' x '.join(map(str, shape))} lattice")
        return cls(origin, np.array(h), tuple(shape), node)

    @property
    def dim(self):
        return len(self.shape)

    @property
    def upper(self):
        return self.origin + self.h * (np.array(self.shape) - 1)

    @property
    def n_nodes(self):
        return int(np.prod(self.shape))


def half_lengths(kind, l0, F=None, h=None):
    """Particle half-lengths (n, d): None for ``hat``, ``l0`` for ``ugimp``, ``l0 F_ii`` for
    ``cpgimp``, clipped to [0, h/2] per axis: the 3-node stencil holds for l_p <= h/2 only, and
    a stretch past it (or a rotation making F_ii < 0) would otherwise break the partition of unity.
    """
    if kind == "hat":
        return None
    if kind == "ugimp":
        return l0
    return np.clip(l0 * np.diagonal(F, axis1=1, axis2=2), 0.0, 0.5 * h)


@njit(cache=True, inline="always")
def _axis_hat(s, n, k, nodes, w, dw):
    """Axis k of one particle at s (in spacings from the origin), hat functions: its 2 nodes,
    weights and d/ds into nodes[k], w[k], dw[k]."""
    i = min(max(np.floor(s), 0.0), n - 2.0)
    r = s - i
    nodes[k, 0], nodes[k, 1] = int(i), int(i) + 1
    w[k, 0], w[k, 1] = 1.0 - r, r
    dw[k, 0], dw[k, 1] = -1.0, 1.0


@njit(cache=True, inline="always")
def _axis_gimp(s, lp, n, k, nodes, w, dw):
    """Axis k of one particle at s with half-length lp (both in spacings): GIMP weights on the
    nearest node and its two neighbours, into nodes[k], w[k], dw[k].

    The domain is kept inside the grid (l_p <= distance to the grid's edge): S then stays a
    partition of unity without ghost nodes beyond the edge. Below 1e-8 h, l_p is taken as 0 (the
    hat, its limit): the quadratic pieces would lose digits to cancellation."""
    l = min(lp, min(s, n - 1 - s))
    if l < 1e-8:
        l = 0.0
    safe = l if l > 0 else 1.0                 # the quadratic pieces are empty when l_p = 0
    base = min(max(np.floor(s), 0.0), n - 2.0)  # with l_p = 0: the hat's (one-sided) gradient
    centre = np.rint(s)
    for j in range(3):
        node = centre + (j - 1)
        xi = s - node
        a = abs(xi)
        sign = 1.0 if xi > 0 else (-1.0 if xi < 0 else 0.0)
        if a < l:
            wj, dj = 1.0 - (xi ** 2 + l ** 2) / (2.0 * safe), -xi / safe
        elif a >= 1.0 - l and a < 1.0 + l:
            wj, dj = (1.0 + l - a) ** 2 / (4.0 * safe), -sign * (1.0 + l - a) / (2.0 * safe)
        else:
            wj, dj = max(1.0 - a, 0.0), (-sign if a < 1.0 else 0.0)
        if not l > 0:
            dj = -1.0 if node == base else (1.0 if node == base + 1 else 0.0)
        if node < 0 or node >= n:
            wj, dj = 0.0, 0.0
        nodes[k, j] = int(min(max(node, 0.0), n - 1.0))
        w[k, j], dw[k, j] = wj, dj


@kernel_factory
def _weights(d, m, stretched):          # literal d, nodes per axis (2: hat, 3: GIMP), stretched: 0 or 1
    def weights(x, lp, F, origin, shape, h, lattice, cols, S, G):
        """Per particle p at x[p] with half-lengths lp[p] (m) (stretched: lp[p] l0 and F[p] the
        deformation gradient, the lengths of `half_lengths` formed here): the m^d columns and values
        of row p of S and of each dS/dx_k (G[k]), the tensor product of the axes' weights in lattice
        order (the last axis fastest). Returns the first particle outside the grid (or not finite),
        or -1."""
        nodes = np.empty((d, m), np.int64)
        w, dw = np.empty((d, m)), np.empty((d, m))
        for p in range(len(x)):
            for k in range(d):
                s = (x[p, k] - origin[k]) / h[k]            # in spacings
                if not (s >= -1e-12 and s <= shape[k] - 1 + 1e-12):
                    return p
                s = min(max(s, 0.0), shape[k] - 1.0)
                if m == 2:
                    _axis_hat(s, shape[k], k, nodes, w, dw)
                elif stretched:         # np.clip(l0 F_kk, 0, h/2) as numpy clips (a nan stays nan)
                    l, top = lp[p, k] * F[p, k, k], 0.5 * h[k]
                    l = l if (l != l or l > 0.0) else 0.0
                    l = l if (l != l or l < top) else top
                    _axis_gimp(s, l / h[k], shape[k], k, nodes, w, dw)
                else:
                    _axis_gimp(s, lp[p, k] / h[k], shape[k], k, nodes, w, dw)
                for j in range(m):
                    dw[k, j] = dw[k, j] / h[k]
            for e in range(m ** d):
                if d == 1:
                    cols[p, e] = lattice[nodes[0, e]]
                    S[p, e] = w[0, e]
                    G[0, p, e] = dw[0, e]
                else:
                    i0, i1 = e // m, e % m
                    cols[p, e] = lattice[nodes[0, i0], nodes[1, i1]]
                    S[p, e] = w[0, i0] * w[1, i1]
                    G[0, p, e] = dw[0, i0] * w[1, i1]
                    G[1, p, e] = w[0, i0] * dw[1, i1]
        return -1
    return weights


@dataclass
class ShapeFunctions:
    """S (n_particles, n_nodes) and its gradient dS/dx_k on one CSR pattern (``indptr``,
    ``cols``), their values stacked in ``values`` (1 + d, nnz): S, then the gradient; and that
    pattern transposed (`parallel.Transposed`) for the nodes' sums over their particles."""

    indptr: np.ndarray
    cols: np.ndarray
    values: np.ndarray
    n_nodes: int
    pattern_T: parallel.Transposed

    def matrix(self, k):
        """CSR triple of S (k = 0) or dS/dx_(k-1), for `parallel.matmul`."""
        return self.indptr, self.cols, self.values[k]

    @property
    def S(self):
        """S as a scipy CSR matrix (n_particles, n_nodes)."""
        return sp.csr_matrix(self.matrix(0)[::-1], shape=(len(self.indptr) - 1, self.n_nodes))

    @property
    def grad(self):
        """[dS/dx_k] as scipy CSR matrices."""
        return [sp.csr_matrix(self.matrix(1 + k)[::-1], shape=(len(self.indptr) - 1, self.n_nodes))
                for k in range(len(self.values) - 1)]

    def S_T(self, X, scale=None):
        """S^T diag(scale) X (`parallel.matmul_T`: the bits of scipy's S.T @ (scale X))."""
        return parallel.matmul_T(self.pattern_T, self.values[0], X, scale=scale)

    def grad_T(self, k, X):
        """(dS/dx_k)^T X."""
        return parallel.matmul_T(self.pattern_T, self.values[1 + k], X)

    def mass_momentum(self, m, v):
        """(S^T m, S^T diag(m) v) in one pass over the pattern: the bits of S_T(m) and S_T(v,
        scale=m)."""
        d = v.shape[1]
        mass, momentum = np.empty(self.n_nodes), np.empty((self.n_nodes, d))
        kernel = _mass_momentum(d)
        self._over_nodes(kernel, (self.indptr, self.cols, self.values, m, v), (mass, momentum))
        return mass, momentum

    def grad_T_sum(self, X):
        """sum(grad_T(k, X[:, :, k]) for k in range(d)) (Python's sum, from 0) for X (n, d, d), in
        one pass over the pattern (the same bits)."""
        d = X.shape[1]
        out = np.empty((self.n_nodes, d))
        kernel = _grad_T_sum(d)
        self._over_nodes(kernel, (self.indptr, self.cols, self.values, X), (out,))
        return out

    def _over_nodes(self, kernel, before, after):
        """kernel(*before, first, last, lo, hi, *after) for the chunks of nodes lo:hi of the
        transposed pattern (the particles first:last reach them), in parallel (`parallel.matmul_T`'s
        split)."""
        A = self.pattern_T
        if len(A.chunks) != len(parallel.chunks(A.n_cols)):
            raise ValueError("the thread count changed since the pattern was made")
        parallel.chunked(A.n_cols, kernel, "w" * len(before) + "nnlh" + "w" * len(after),
                         (*before, A.first, A.last, *after))


@kernel_factory
def _mass_momentum(d):
    def mass_momentum(indptr, cols, values, m, v, first, last, lo, hi, mass, momentum):
        """Nodes lo:hi: mass[j] += S m_p, momentum[j] += S (m_p v_p) over the particles first:last
        in their order (`parallel.matmul_T`'s sums)."""
        for j in range(lo, hi):
            mass[j] = 0.0
            for c in range(d):
                momentum[j, c] = 0.0
        for r in range(first, last):
            s = m[r]
            for k in range(indptr[r], indptr[r + 1]):
                j = cols[k]
                if j >= lo and j < hi:
                    w = values[0, k]
                    mass[j] += w * m[r]
                    for c in range(d):
                        momentum[j, c] += w * (s * v[r, c])
    return mass_momentum


@kernel_factory
def _grad_T_sum(d):
    def grad_T_sum(indptr, cols, values, X, first, last, lo, hi, out):
        """Nodes lo:hi: each axis' sum (dS/dx_a)^T X[:, :, a] kept apart over the particles
        first:last in their order, then added from 0 in the order of the axes."""
        part = np.zeros((d, hi - lo, d))
        for r in range(first, last):
            for k in range(indptr[r], indptr[r + 1]):
                j = cols[k]
                if j >= lo and j < hi:
                    for a in range(d):
                        w = values[1 + a, k]
                        for c in range(d):
                            part[a, j - lo, c] += w * X[r, c, a]
        for j in range(hi - lo):
            for c in range(d):
                x = 0.0
                for a in range(d):
                    x = x + part[a, j, c]
                out[lo + j, c] = x
    return grad_T_sum


_NO_LENGTHS = np.zeros((0, 0))
_NO_STRETCH = np.zeros((0, 0, 0))


def shape_functions(lattice, x, kind, lp=None, step=None, time=None, reuse=None, F=None):
    """S_ip and grad S_ip at current positions ``x`` (n, d) with half-lengths ``lp`` (n, d), in
    one compiled pass over the particles (in parallel chunks). With ``F`` (n, d, d) (cpGIMP), lp
    is l0 and the pass takes the half-lengths of `half_lengths` (no serial numpy before it, the
    same bits). ``reuse``: shape functions no
    longer needed (the last step's), whose arrays are overwritten rather than new ones taken
    (~80 MB at 256^2: fresh pages cost a page fault each, and the faults of two threads queue).

    A particle outside the grid raises InstabilityError naming it (index, position, step, time).
    """
    d = lattice.dim
    n, m = len(x), 2 if kind == "hat" else 3
    lp = _NO_LENGTHS if kind == "hat" else lp
    if reuse is not None and reuse.values.shape == (1 + d, n * m ** d):
        cols, W = reuse.cols.reshape(n, m ** d), reuse.values.reshape(1 + d, n, m ** d)
    else:
        cols, W = np.empty((n, m ** d), np.int64), np.empty((1 + d, n, m ** d))   # W: S, then grad
    kernel, shape = _weights(d, m, int(F is not None)), np.array(lattice.shape, dtype=np.int64)
    F = _NO_STRETCH if F is None else F
    bad = parallel.chunked(n, kernel, "rrrwwwwrrk",
                           (x, lp, F, lattice.origin, shape, lattice.h, lattice.node, cols, W[0], W[1:]), "first")
    if bad >= 0:
        when = "" if step is None else f" at step {step}, t = {time:.6g} s"
        raise InstabilityError(
            f"particle {bad} at x = {np.round(x[bad], 6).tolist()} is outside the background grid "
            f"[{lattice.origin.tolist()}, {lattice.upper.tolist()}]{when}", step=step, time=time, particle=bad)
    indptr = np.arange(0, n * m ** d + 1, m ** d)
    cols = cols.reshape(-1)
    return ShapeFunctions(indptr, cols, W.reshape(1 + d, -1), lattice.n_nodes,
                          parallel.Transposed(indptr, cols, lattice.n_nodes))
