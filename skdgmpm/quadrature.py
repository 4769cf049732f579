"""Particle quadrature: the forms of ``skdgmpm.forms`` integrated at material points.

DGMPM replaces Gauss quadrature by the material points of each cell, with their volumes as
weights [R18 eq 14-18]; the same forms with Gauss points give DGFEM. Everything here is built once
per grid (total Lagrangian: particles never change cell).
"""
from dataclasses import dataclass
from functools import cached_property

import numpy as np
import scipy.sparse as sp
from numba import njit
from skfem import CellBasis

from skdgmpm import forms

from . import parallel
from .kernel_cache import kernel_factory, scratch


def cell_slots(cell, n_cells):
    """Per-cell padding of particles: (n_max, slot) with slot (n_particles,) the flat index of each
    particle in a (n_cells, n_max) array."""
    counts = np.bincount(cell, minlength=n_cells)
    n_max = max(int(counts.max()), 1)
    order = np.argsort(cell, kind="stable")
    start = np.concatenate([[0], np.cumsum(counts)[:-1]])
    local = np.empty(len(cell), dtype=np.int64)
    local[order] = np.arange(len(cell)) - np.repeat(start, counts)
    return n_max, cell * n_max + local


def particle_basis(grid, particles, element=None):
    """CellBasis on the active sub-mesh whose quadrature points are the particles.

    Cells hold different numbers of particles: they are padded to the largest count with points at
    the cell centre and zero weight. Returns the basis and ``slot`` (n_particles,), the flat index
    of each particle in the (cell, point) quadrature array. ``element`` defaults to the grid's.
    """
    nel = grid.submesh.nelements
    nq, slot = cell_slots(particles.cell, nel)

    d = grid.dim
    Xe = np.full((d, nel * nq), 0.5)
    Xe[:, slot] = particles.xi.T
    W = np.zeros(nel * nq)
    W[slot] = particles.volume
    basis = CellBasis(grid.submesh, element or grid.element,
                      quadrature=(Xe.reshape(d, nel, nq), np.ones((nel, nq))), elements=np.arange(nel))
    basis.dx = W.reshape(nel, nq)          # volumes as weights, replacing w_q |det J|
    return basis, slot


def interpolation_matrix(basis, slot):
    """Sparse S (n_points x n_dofs) with S[p, i] = Phi_i(X_p) for the quadrature points ``slot``."""
    nel, nq = basis.dx.shape
    rows, cols, vals = [], [], []
    for k in range(basis.Nbfun):                                     # local basis functions
        phi = np.asarray(basis.basis[k][0]).reshape(-1)              # (nel * nq,)
        rows.append(np.arange(len(slot)))
        cols.append(np.repeat(basis.element_dofs[k], nq)[slot])
        vals.append(phi[slot])
    return sp.csr_matrix((np.concatenate(vals), (np.concatenate(rows), np.concatenate(cols))),
                         shape=(len(slot), basis.N))


@dataclass(frozen=True)
class VolumeOperators:
    """Grid operators from one quadrature (particles or Gauss points).

    Attributes
    ----------
    mass : (n_dofs, n_dofs) consistent mass, ``int Phi_i Phi_j`` (volume-weighted)
    lumped : (n_dofs,) row sums of ``mass`` [R18 eq 38]
    stiffness : list of d sparse (n_dofs, n_dofs), K^alpha [R18 eq 38], all on one sparsity
        pattern (explicit zeros kept) so that one compiled pass reads them together
    """

    mass: sp.csr_matrix
    lumped: np.ndarray
    stiffness: tuple

    @classmethod
    def assemble(cls, basis):
        mass = forms.mass.assemble(basis).tocsr()
        stiffness = common_pattern([forms.pseudo_stiffness(a).assemble(basis).tocsr()
                                    for a in range(basis.mesh.dim())])
        return cls(mass, np.asarray(mass.sum(axis=1)).ravel(), stiffness)


def common_pattern(matrices):
    """The CSR matrices on the union of their sparsity patterns (explicit zeros kept, indices
    sorted): the same ``indptr`` and ``indices`` arrays, one ``data`` each."""
    coo = [K.tocoo() for K in matrices]
    rows = np.concatenate([c.row for c in coo])
    cols = np.concatenate([c.col for c in coo])
    out = []
    for k in range(len(coo)):
        data = np.concatenate([c.data if j == k else np.zeros_like(c.data) for j, c in enumerate(coo)])
        K = sp.csr_matrix((data, (rows, cols)), shape=matrices[k].shape)    # duplicates summed, zeros kept
        K.sort_indices()
        if out:                                       # the same arrays, not copies
            assert np.array_equal(K.indices, out[0].indices) and np.array_equal(K.indptr, out[0].indptr)
            K.indices, K.indptr = out[0].indices, out[0].indptr
        out.append(K)
    return tuple(out)


@dataclass(frozen=True)
class ParticleMap:
    """Particle <-> grid maps of first-order DGMPM.

    ``project`` is the volume-weighted least-squares map ``M_i U_i = sum_p S_ip V_p U_p``
    [R18 eq 39] (for the momentum p = rho0 v this is the paper's mass-weighted map);
    ``interpolate`` is ``U_p = sum_i S_ip U_i`` [R18 eq 40].
    """

    S: sp.csr_matrix               # (n_particles, n_dofs)
    P2G: sp.csr_matrix             # (n_dofs, n_particles) = diag(1/M) S^T diag(V)
    rho: np.ndarray                # (n_dofs,) nodal reference density
    active_dofs: np.ndarray        # (n_dofs,) bool: M_i > 0

    @classmethod
    def build(cls, S, volume, rho0, lumped):
        active = lumped > 0
        inv = np.where(active, 1.0 / np.where(active, lumped, 1.0), 0.0)
        P2G = (sp.diags(inv) @ S.T @ sp.diags(volume)).tocsr()
        rho = P2G @ rho0
        return cls(S, P2G, rho, active)

    def project(self, values):
        return parallel.matmul(self.P2G, values)

    @cached_property
    def S_T(self):
        """S^T as CSR (`parallel.matmul`: S^T X with the bits of scipy's S.T @ X)."""
        return self.S.T.tocsr()

    def project_state(self, U, Q, d):
        """Nodal (U, Q) from particle (U, Q) (n, d*d + d): U and the stress by `project`, the
        nodal velocity from the projected momentum (v = p / rho), in one compiled pass."""
        U_n, Q_n = np.empty((self.P2G.shape[0], U.shape[1])), np.empty((self.P2G.shape[0], Q.shape[1]))
        A, kernel = self.P2G, _project_state(d)
        parallel.rows(len(U_n), lambda lo, hi: kernel(A.indptr[lo:hi + 1], A.indices, A.data, U, Q, self.rho[lo:hi],
                                                      U_n[lo:hi], Q_n[lo:hi]))
        return U_n, Q_n

    def interpolate(self, nodal):
        """S nodal for nodal values (n_dofs, nc) (`parallel.matmul`)."""
        return parallel.matmul(self.S, nodal)


@kernel_factory
def _project_state(d):                  # literal widths: the loops unrolled
    dd, nc = d * d, d * d + d

    def project_state(indptr, indices, data, U, Q, rho, U_n, Q_n):
        """U_n = P2G U, Q_n = [P2G P, p_n / rho] (each row's products summed in CSR order, as
        scipy's product does)."""
        u, q = scratch((nc,)), scratch((nc,))       # the row's sums, in registers
        for r in range(len(indptr) - 1):
            for c in range(nc):
                u[c], q[c] = 0.0, 0.0
            for k in range(indptr[r], indptr[r + 1]):
                p, w = indices[k], data[k]
                for c in range(nc):
                    u[c] += w * U[p, c]
                for c in range(dd):
                    q[c] += w * Q[p, c]
            for c in range(nc):
                U_n[r, c] = u[c]
            for c in range(dd):
                Q_n[r, c] = q[c]
            for c in range(dd, nc):
                Q_n[r, c] = u[c] / rho[r]
    return project_state
