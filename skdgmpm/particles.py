"""Material points: placement in grid cells, location of given points, per-particle constants.

Total Lagrangian: a particle's reference position, cell and parent coordinates never change, so
they are computed once [R18 §5].
"""
from dataclasses import dataclass

import numpy as np

from .errors import InputError


def tensor_layout(per_dim, dim):
    """Parent coordinates (n, dim) of a regular layout with ``per_dim`` points per direction.

    ``per_dim`` is an int (points at (k + 1/2) / n) or a sequence of parent coordinates in (0, 1).
    """
    if np.isscalar(per_dim):
        n = int(per_dim)
        if n < 1:
            raise InputError(f"particles.per_cell = {per_dim!r} must be a positive integer")
        coords = (np.arange(n) + 0.5) / n
    else:
        coords = np.asarray(per_dim, dtype=float)
        if coords.ndim != 1 or coords.size == 0 or np.any((coords <= 0) | (coords >= 1)):
            raise InputError(f"particles.layout = {list(per_dim)!r} must be parent coordinates in (0, 1)")
    grids = np.meshgrid(*([coords] * dim), indexing="xy")
    return np.stack([g.ravel() for g in grids], axis=1)


@dataclass(frozen=True)
class Particles:
    """Per-particle constants.

    Attributes
    ----------
    X : (n, d) reference positions
    xi : (n, d) parent coordinates in their cell
    cell : (n,) index of the cell in the active sub-mesh
    volume : (n,) reference volume V_p (length in 1D, area per unit thickness in 2D)
    rho0 : (n,) reference density
    material : (n,) index into the scene's list of materials
    """

    X: np.ndarray
    xi: np.ndarray
    cell: np.ndarray
    volume: np.ndarray
    rho0: np.ndarray
    material: np.ndarray

    @property
    def mass(self):
        return self.rho0 * self.volume

    def __len__(self):
        return len(self.X)


def fill_cells(mesh, cells, layout, cell_volumes):
    """Place ``layout`` (parent coordinates, (nq, d)) in every cell of ``cells``.

    Returns reference positions (n, d), parent coordinates (n, d), cell indices (n,) and volumes
    (n,) = cell volume / nq, so the body's volume is exact.
    """
    cells = np.asarray(cells)
    nq = len(layout)
    xi = np.broadcast_to(layout.T[:, None, :], (mesh.dim(), len(cells), nq))
    X = mesh.mapping().F(np.ascontiguousarray(xi), tind=cells)       # (d, ncells, nq)
    X = X.reshape(mesh.dim(), -1).T
    xi = np.tile(layout, (len(cells), 1))
    cell = np.repeat(cells, nq)
    volume = np.repeat(np.asarray(cell_volumes)[cells] / nq, nq)
    return X, xi, cell, volume


def locate(mesh, X, source="particles"):
    """Cells and parent coordinates of points ``X`` (n, d); error naming the first point outside.

    1D: binary search. 2D: nearest cell centroids (k-d tree) then the bilinear inverse map.
    """
    X = np.atleast_2d(np.asarray(X, dtype=float))
    if mesh.dim() == 1:
        nodes = mesh.p[0, mesh.t]                                   # (2, nel)
        lo, hi = nodes.min(axis=0), nodes.max(axis=0)
        order = np.argsort(lo)
        k = np.searchsorted(lo[order], X[:, 0], side="right") - 1
        cell = order[np.clip(k, 0, len(order) - 1)]
        inside = (k >= 0) & (X[:, 0] <= hi[cell] * (1 + 1e-12) + 1e-300)
        xi = ((X[:, 0] - nodes[0, cell]) / (nodes[1, cell] - nodes[0, cell]))[:, None]
    else:
        from scipy.spatial import cKDTree

        centroids = mesh.p[:, mesh.t].mean(axis=1).T
        _, cand = cKDTree(centroids).query(X, k=min(4, mesh.nelements))
        cand = np.atleast_2d(cand.T).reshape(-1, len(X))
        cell = np.full(len(X), -1)
        xi = np.zeros_like(X)
        mapping = mesh.mapping()
        for c in cand:                                              # at most 4 candidates
            todo = cell < 0
            if not todo.any():
                break
            ref = mapping.invF(X[todo].T[:, :, None], tind=c[todo])[:, :, 0].T
            ok = np.all((ref >= -1e-10) & (ref <= 1 + 1e-10), axis=1)
            idx = np.flatnonzero(todo)[ok]
            cell[idx], xi[idx] = c[todo][ok], np.clip(ref[ok], 0.0, 1.0)
        inside = cell >= 0
    if not inside.all():
        p = int(np.flatnonzero(~inside)[0])
        raise InputError(f"{source}: particle {p} at X = {X[p].tolist()} is outside the grid")
    return cell, xi
