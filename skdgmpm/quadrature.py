"""Particle quadrature: the forms of ``skdgmpm.forms`` integrated at material points.

DGMPM replaces Gauss quadrature by the material points of each cell, with their volumes as
weights [R18 eq 14-18]; the same forms with Gauss points give DGFEM. Everything here is built once
per grid (total Lagrangian: particles never change cell).
"""
from dataclasses import dataclass
from functools import cached_property

import numpy as np
import scipy.sparse as sp
from skfem import CellBasis
from skfem.assembly import Dofs

from skdgmpm import forms

from . import parallel
from .equations import velocity
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


CELL_CHUNK = 16384      # cells per particle basis in `particle_operators` (its arrays were the set-up's peak)


def particle_operators(grid, particles, element=None):
    """What first-order DGMPM keeps of the particle quadrature, built a chunk of cells at a time:
    the lumped mass (n_dofs,), the K^alpha as a `system.Stiffness`, S (`interpolation_matrix`) and
    the cell of each dof (n_dofs,) int32.

    The same numbers as `particle_basis`, `VolumeOperators.assemble` and `interpolation_matrix`
    over all the cells at once, bit for bit (tests/test_quadrature.py): every cell's entries are
    computed by scikit-fem from that cell alone (the padding to the same number of points per
    cell is kept), and a DG row couples the dofs of one cell only, so the rows of a chunk of
    cells are whole rows of the matrices, put in place with the same scipy conversions. Each
    chunk's basis (its points, basis values, gradients and the Jacobians scikit-fem memoises) is
    dropped before the next: the peak is a chunk's, not the grid's (~2.1 kB per cell at 512^2
    with one basis over all the cells), and the mass matrix itself is never kept."""
    from .system import Stiffness

    mesh = grid.submesh
    element = element or grid.element
    nel, d = mesh.nelements, grid.dim
    nq, slot = cell_slots(particles.cell, nel)
    order = np.argsort(slot, kind="stable")          # the particles by (cell, point in the cell)
    sorted_slot = slot[order]
    del slot
    n_chunks = max(1, -(-nel // CELL_CHUNK))
    dof_numbering = Dofs(mesh, element)
    lumped = indptr = indices = data = None
    S_parts, nnz, row = [], 0, 0
    for c0, c1 in ((nel * k // n_chunks, nel * (k + 1) // n_chunks) for k in range(n_chunks)):
        a, b = np.searchsorted(sorted_slot, [c0 * nq, c1 * nq])
        m = c1 - c0
        Xe = np.full((d, m * nq), 0.5)
        Xe[:, sorted_slot[a:b] - c0 * nq] = particles.xi[order[a:b]].T
        W = np.zeros(m * nq)
        W[sorted_slot[a:b] - c0 * nq] = particles.volume[order[a:b]]
        # one dof numbering for all the chunks and no global dof locations (scikit-fem would
        # compute both over the whole mesh for each chunk: quadratic in the cells)
        basis = CellBasis(mesh, element, quadrature=(Xe.reshape(d, m, nq), np.ones((m, nq))),
                          elements=np.arange(c0, c1), dofs=dof_numbering, disable_doflocs=True)
        basis.dx = W.reshape(m, nq)         # volumes as weights, replacing w_q |det J|
        del Xe, W
        dofs = basis.element_dofs
        r0, r1 = int(dofs.min()), int(dofs.max()) + 1
        if r0 != row or r1 - r0 != dofs.size:          # DG: a chunk's rows follow the previous chunk's
            raise AssertionError("particle_operators: the cells' dofs are not numbered cell by cell")
        if lumped is None:
            N = basis.N
            lumped = np.zeros(N)
            dof_cell = np.empty(N, dtype=np.int32)
            indptr = np.zeros(N + 1, dtype=np.int64)
            bound = basis.Nbfun ** 2 * nel                # at most every pair of a cell's dofs
            indices = np.empty(bound, dtype=np.int64)
            data = np.empty((d, bound))
        dof_cell[dofs] = np.arange(c0, c1, dtype=np.int32)[None, :]
        mass_rows = _rows_of(forms.mass, basis, r0, r1)
        lumped[r0:r1] = np.asarray(mass_rows.sum(axis=1)).ravel()
        del mass_rows
        Ks = common_pattern([_rows_of(forms.pseudo_stiffness(al), basis, r0, r1) for al in range(d)])
        k = Ks[0].nnz
        indptr[r0 + 1:r1 + 1] = nnz + Ks[0].indptr[1:]
        indices[nnz:nnz + k] = Ks[0].indices
        for al in range(d):
            data[al, nnz:nnz + k] = Ks[al].data
        nnz, row = nnz + k, r1
        del Ks
        # S's rows of the chunk's particles (sorted by cell), as `interpolation_matrix` builds them
        local = sorted_slot[a:b] - c0 * nq
        rows, cols, vals = [], [], []
        for j in range(basis.Nbfun):
            rows.append(np.arange(b - a))
            cols.append(np.repeat(dofs[j], nq)[local])
            vals.append(np.asarray(basis.basis[j][0]).reshape(-1)[local])
        S_parts.append(sp.csr_matrix((np.concatenate(vals), (np.concatenate(rows), np.concatenate(cols))),
                                     shape=(b - a, N)))
        del basis, rows, cols, vals
        _forget_jacobians(mesh)
    if row != N:
        raise AssertionError("particle_operators: not every dof belongs to a cell")
    S = S_parts[0] if len(S_parts) == 1 else sp.vstack(S_parts, format="csr")
    del S_parts
    if not np.array_equal(order, np.arange(len(order))):        # back to the particles' order
        S = S[np.argsort(order)]
    # scipy's index dtype for such a matrix (int32 where it fits), arrays of the exact size
    idx = np.int32 if max(N, nnz) <= np.iinfo(np.int32).max else np.int64
    indices = indices[:nnz].astype(idx)
    data = data[:, :nnz].copy() if nnz < data.shape[1] else data
    stiffness = Stiffness.from_arrays(indptr.astype(idx), indices, data, (N, N))
    return lumped, stiffness, S, dof_cell


def _rows_of(form, basis, r0, r1):
    """Rows r0:r1 of ``form.assemble(basis)`` (a basis over some cells), renumbered from 0:
    scikit-fem's own COO -> CSR conversion (zeros dropped, duplicates summed, indices sorted)."""
    (rows, cols), data, shape, _ = form._assemble(basis)
    K = sp.coo_matrix((data, (rows - r0, cols)), shape=(r1 - r0, shape[1]))
    K.eliminate_zeros()
    return K.tocsr()


def _forget_jacobians(mesh):
    """Drop what scikit-fem's isoparametric mapping memoised for the bases built so far."""
    mapping = getattr(mesh, "_cached_mapping", None)
    if isinstance(getattr(mapping, "_cache", None), dict):
        mapping._cache.clear()


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

    def project_state(self, U, Q, d, out=None):
        """Nodal (U, Q) from particle (U, Q) (n, d*d + d): U and the stress by `project`, the
        nodal velocity from the projected momentum (v = p / rho), in one compiled pass (into
        ``out`` = (U_n, Q_n) if given)."""
        if out is None:
            out = np.empty((self.P2G.shape[0], U.shape[1])), np.empty((self.P2G.shape[0], Q.shape[1]))
        U_n, Q_n = out
        A, kernel = self.P2G, _project_state(d)
        parallel.chunked(len(U_n), kernel, "iwwwwrrr", (A.indptr, A.indices, A.data, U, Q, self.rho, U_n, Q_n))
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
            velocity(u, rho[r], q, d)
            for c in range(nc):
                U_n[r, c], Q_n[r, c] = u[c], q[c]
    return project_state
