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
import functools
from dataclasses import dataclass

import numpy as np
import scipy.sparse as sp

from .errors import InputError, InstabilityError

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


def _axis_hat(s, n):
    """s (n_p,) positions in spacings from the origin -> nodes, weights, d/ds (n_p, 2)."""
    k = np.clip(np.floor(s).astype(np.int64), 0, n - 2)
    r = s - k
    nodes = np.stack([k, k + 1], axis=1)
    return nodes, np.stack([1.0 - r, r], axis=1), np.broadcast_to([-1.0, 1.0], nodes.shape)


def _axis_gimp(s, lp, n):
    """GIMP weights on the nearest node and its two neighbours, in units of the spacing.

    The domain is kept inside the grid (l_p <= distance to the grid's edge): S then stays a
    partition of unity without ghost nodes beyond the edge. Below 1e-8 h, l_p is taken as 0 (the
    hat, its limit): the quadratic pieces would lose digits to cancellation.
    """
    lp = np.minimum(lp, np.minimum(s, n - 1 - s))
    lp = np.where(lp < 1e-8, 0.0, lp)
    nodes = np.rint(s).astype(np.int64)[:, None] + np.arange(-1, 2)
    xi = s[:, None] - nodes
    a, l = np.abs(xi), lp[:, None]
    safe = np.where(l > 0, l, 1.0)                 # the quadratic pieces are empty when l_p = 0
    k = np.clip(np.floor(s), 0, n - 2)[:, None]    # with l_p = 0: the hat's (one-sided) gradient
    hat = np.where(nodes == k, -1.0, np.where(nodes == k + 1, 1.0, 0.0))
    inner, outer = a < l, (a >= 1.0 - l) & (a < 1.0 + l)
    w = np.where(inner, 1.0 - (xi ** 2 + l ** 2) / (2.0 * safe),
                 np.where(outer, (1.0 + l - a) ** 2 / (4.0 * safe), np.maximum(1.0 - a, 0.0)))
    dw = np.where(inner, -xi / safe,
                  np.where(outer, -np.sign(xi) * (1.0 + l - a) / (2.0 * safe),
                           np.where(a < 1.0, -np.sign(xi), 0.0)))
    dw = np.where(l > 0, dw, hat)
    valid = (nodes >= 0) & (nodes < n)
    return np.clip(nodes, 0, n - 1), np.where(valid, w, 0.0), np.where(valid, dw, 0.0)


@dataclass
class ShapeFunctions:
    """S (n_particles, n_nodes) and its gradient, ``grad[k]`` = dS/dx_k, all CSR."""

    S: sp.csr_matrix
    grad: list


def shape_functions(lattice, x, kind, lp=None, step=None, time=None):
    """S_ip and grad S_ip at current positions ``x`` (n, d) with half-lengths ``lp`` (n, d).

    A particle outside the grid raises InstabilityError naming it (index, position, step, time).
    """
    d = lattice.dim
    s = (x - lattice.origin) / lattice.h                  # (n, d), in spacings
    outside = np.any((s < -1e-12) | (s > np.array(lattice.shape) - 1 + 1e-12) | ~np.isfinite(s), axis=1)
    if outside.any():
        p = int(np.flatnonzero(outside)[0])
        when = "" if step is None else f" at step {step}, t = {time:.6g} s"
        raise InstabilityError(
            f"particle {p} at x = {np.round(x[p], 6).tolist()} is outside the background grid "
            f"[{lattice.origin.tolist()}, {lattice.upper.tolist()}]{when}", step=step, time=time, particle=p)
    s = np.clip(s, 0.0, np.array(lattice.shape) - 1)
    axes = [_axis_hat(s[:, k], lattice.shape[k]) if kind == "hat"
            else _axis_gimp(s[:, k], lp[:, k] / lattice.h[k], lattice.shape[k]) for k in range(d)]
    # tensor product: (n, m, m) in 2D, flattened to m^d entries per row
    n = len(x)
    idx = tuple(a[0].reshape((n,) + (1,) * k + (-1,) + (1,) * (d - 1 - k)) for k, a in enumerate(axes))
    w = [a[1].reshape(idx[k].shape) for k, a in enumerate(axes)]
    dw = [a[2].reshape(idx[k].shape) / lattice.h[k] for k, a in enumerate(axes)]
    cols = lattice.node[idx].reshape(n, -1)
    m = cols.shape[1]
    indptr = np.arange(0, n * m + 1, m)

    def csr(factors):                               # m^d entries per row, in the order of cols
        values = functools.reduce(np.multiply, factors)
        return sp.csr_matrix((values.ravel(), cols.ravel(), indptr), shape=(n, lattice.n_nodes))

    return ShapeFunctions(csr(w), [csr([dw[j] if j == k else w[j] for j in range(d)]) for k in range(d)])
