"""Faces of the active sub-mesh and their trace operators, built once from scikit-fem facet bases.

First-order DGMPM solves one Riemann problem per face with side-averaged states [R18 §4.1]: the
operators here give the face average of each side's DG trace, and the surface integral
``int_Gamma Phi_i F*`` of a face-constant flux F* (see ``skdgmpm.forms.surface_flux``).
"""
from dataclasses import dataclass

import numpy as np
from numba import njit
import scipy.sparse as sp
from skfem import FacetBasis, InteriorFacetBasis
from skfem.assembly import Dofs

from . import parallel
from .equations import embed
from .kernel_cache import scratch


@njit(cache=True, inline="always")
def gather_row(trace, f, u, q, q_f, F, d, offset=0):
    """Row f of a trace (CSR triple) applied to q (into q_f (nc,)) and to u's F part (embedded into
    F (3, 3)), each row's products summed in CSR order as scipy's product does: the side state of
    one face row, for the compiled face passes. The trace's columns are rows ``offset + j`` of u
    and q (a time node s of a predictor flattened to (S n, nc): offset s n; a view u[s] handed to
    an inlined function would be reference counted at every face)."""
    indptr, indices, data = trace
    nc = q_f.shape[0]
    u_f = scratch((d * d,))
    for c in range(nc):
        q_f[c] = 0.0
    for c in range(d * d):
        u_f[c] = 0.0
    for k in range(indptr[f], indptr[f + 1]):
        n, w = offset + indices[k], data[k]
        for c in range(nc):
            q_f[c] += w * q[n, c]
        for c in range(d * d):
            u_f[c] += w * u[n, c]
    embed(u_f, F, d)


def _point_trace(fb):
    """(n_faces * nqp, n_dofs) trace at every facet quadrature point, and the point weights."""
    w = fb.dx                                                      # (nf, nqp)
    nf, nq = w.shape
    rows, cols, vals = [], [], []
    for k in range(fb.Nbfun):
        phi = np.asarray(fb.basis[k][0])                           # (nf, nqp)
        rows.append(np.arange(nf * nq))
        cols.append(np.repeat(fb.element_dofs[k], nq))
        vals.append(phi.ravel())
    T = sp.csr_matrix((np.concatenate(vals), (np.concatenate(rows), np.concatenate(cols))),
                      shape=(nf * nq, fb.N))
    T.eliminate_zeros()
    return T, w.ravel()


def _average_trace(fb):
    """(n_faces, n_dofs) face-averaged trace of a facet basis, and face measures (n_faces,)."""
    w = fb.dx                                                      # (nf, nqp)
    measure = w.sum(axis=1)
    nf = w.shape[0]
    rows, cols, vals = [], [], []
    for k in range(fb.Nbfun):
        phi = np.asarray(fb.basis[k][0])                           # (nf, nqp)
        rows.append(np.arange(nf))
        cols.append(fb.element_dofs[k])
        vals.append((phi * w).sum(axis=1) / measure)
    T = sp.csr_matrix((np.concatenate(vals), (np.concatenate(rows), np.concatenate(cols))),
                      shape=(nf, fb.N))
    T.eliminate_zeros()
    return T, measure


@dataclass(frozen=True)
class FaceSet:
    """A set of faces with side-averaged traces.

    Attributes
    ----------
    facets : (nf,) facet indices in the active sub-mesh
    normal : (nf, d) unit normal, from side L to side R (outward on boundary faces)
    measure : (nf,) face length (2D) or 1 (1D)
    cell_L, cell_R : (nf,) cells on each side (``cell_R`` is -1 on boundary faces)
    T_L, T_R : (nf, n_dofs) face-average trace operators (``T_R`` is None on boundary faces)
    """

    facets: np.ndarray
    normal: np.ndarray
    measure: np.ndarray
    cell_L: np.ndarray
    cell_R: np.ndarray
    T_L: sp.csr_matrix
    T_R: sp.csr_matrix = None
    X: np.ndarray = None          # (nf, d) reference coordinates of the rows

    def __len__(self):
        return len(self.facets)

    def integrate(self, flux, side="L", out=None, sign=1.0):
        """``sign int_Gamma Phi_i F*`` on the given side for face-constant ``flux`` (nf, ncomp),
        added to ``out`` (n_dofs, ncomp) if given: each dof sums its own rows' T[f, i] (measure[f]
        flux[f]) in face order (`parallel.matmul` on T^T), the bits of scipy's T.T @ (measure flux)
        or of the scatter into ``out``."""
        return parallel.matmul(self.gather((side,), sign), flux, out, add=out is not None, scale=self.measure)

    def gather(self, sides, sign):
        """sign T_(sides[0])^T, -sign T_(sides[1])^T, ... side by side: (n_dofs, nf) rows of one CSR
        triple, each dof's entries side by side, then in face order; made once, on first use.
        With the measures as the scale of its columns, `integrate` applies one side's, and
        `dgfem.cell_update` forms the rows of (("R", "L"), 1), int_Gamma Phi_i F* on side R minus
        that on side L (what the interior faces add to both their cells' residuals), and of the
        boundary's (("L",), -1) where it uses them: the bits of `integrate` on side R, then on
        side L with sign -1."""
        cache = self.__dict__.setdefault("_gathers", {})
        key = (sides, sign)
        if key not in cache:
            parts = [(sign if k == 0 else -sign) * (self.T_L if side == "L" else self.T_R).T.tocsr()
                     for k, side in enumerate(sides)]
            G = sp.hstack(parts, format="csr") if len(parts) > 1 else parts[0]
            cache[key] = (G.indptr, G.indices % max(len(self), 1), G.data)      # each part's columns: the rows
        return cache[key]


def _rows(fb, pointwise, coordinates=True):
    """Per-row facet index, normal, cell and coordinates (None unless ``coordinates``): one row
    per face (its centre of quadrature) or per facet quadrature point."""
    nq = fb.dx.shape[1] if pointwise else 1
    normal = fb.normals[:, :, :nq].reshape(fb.normals.shape[0], -1).T.copy()
    if not coordinates:
        return np.repeat(fb.find, nq), normal, np.repeat(fb.tind, nq), None
    X = np.asarray(fb.global_coordinates())                              # (d, nf, nqp)
    X = X.reshape(X.shape[0], -1).T if pointwise else np.einsum("dfq,fq->fd", X, fb.dx) / fb.dx.sum(1)[:, None]
    return np.repeat(fb.find, nq), normal, np.repeat(fb.tind, nq), X


FACET_CHUNK = 16384     # interior facets per pair of facet bases (their arrays are the set-up's peak)


def interior_faces(mesh, element, pointwise=False, intorder=None, coordinates=True, traces=True):
    """Interior faces: one row per face (side averages) or per facet Gauss point (``pointwise``);
    ``coordinates=False`` leaves their reference coordinates X out (None: 16 B per row),
    ``traces=False`` the trace operators (None: a scheme that reads its cells' states directly).
    The facet bases are built for FACET_CHUNK facets at a time and dropped (with the Jacobians
    scikit-fem memoises for them): each facet's rows depend on that facet alone, so the result is
    the same as from one pair of bases over all of them, at a fraction of the peak memory."""
    kw = {} if intorder is None else {"intorder": intorder}
    trace = _point_trace if pointwise else _average_trace
    interior = np.nonzero(mesh.f2t[1] != -1)[0].astype(np.int32)     # scikit-fem's own default
    parts = []
    # one numbering of the dofs for every chunk, and no global dof locations: scikit-fem would
    # otherwise compute both over the whole mesh for each basis (set-up time quadratic in the cells)
    kw.update(dofs=Dofs(mesh, element), disable_doflocs=True)
    for chunk in np.array_split(interior, max(1, -(-len(interior) // FACET_CHUNK))):
        # side R's basis only for its traces: its cells are scikit-fem's f2t[1] of the facets
        # (its `tind`), read without it (half the set-up)
        fb = [InteriorFacetBasis(mesh, element, side=i, facets=chunk, **kw) for i in ((0, 1) if traces else (0,))]
        if traces:
            T_L, measure = trace(fb[0])
            T_R, _ = trace(fb[1])
        else:
            T_L = T_R = None
            measure = fb[0].dx.sum(axis=1) if not pointwise else fb[0].dx.ravel()
        cell_R = np.repeat(mesh.f2t[1, fb[0].find], fb[0].dx.shape[1] if pointwise else 1)
        facets, normal, cell_L, X = _rows(fb[0], pointwise, coordinates)
        parts.append((facets, normal, measure, cell_L, cell_R, T_L, T_R, X))
        del fb
        mapping = getattr(mesh, "_cached_mapping", None)
        if len(interior) > FACET_CHUNK and isinstance(getattr(mapping, "_cache", None), dict):
            mapping._cache.clear()
    if len(parts) == 1:
        return FaceSet(*parts[0])
    column = list(zip(*parts))
    stack = lambda k: np.concatenate(column[k])                      # noqa: E731
    T_L, T_R = (sp.vstack(column[k], format="csr") if traces else None for k in (5, 6))
    return FaceSet(stack(0), stack(1), stack(2), stack(3), stack(4), T_L, T_R, stack(7) if coordinates else None)


def boundary_faces(mesh, element, facets, n_dofs, pointwise=False, intorder=None):
    """Boundary faces ``facets`` with outward normals (rows as in `interior_faces`)."""
    facets = np.asarray(facets, dtype=np.int64)
    if len(facets) == 0:
        return FaceSet(facets, np.zeros((0, mesh.dim())), np.zeros(0), facets, facets,
                       sp.csr_matrix((0, n_dofs)), None, np.zeros((0, mesh.dim())))
    kw = {} if intorder is None else {"intorder": intorder}
    fb = FacetBasis(mesh, element, facets=facets, **kw)
    T, measure = (_point_trace if pointwise else _average_trace)(fb)
    facets, normal, cell, X = _rows(fb, pointwise)
    return FaceSet(facets, normal, measure, cell, -np.ones_like(cell), T, None, X)
