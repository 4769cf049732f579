"""Slope limiters of L23 §3.3 (eq 39-43) for the high-order DG solution.

Cell averages, a least-squares gradient from the face neighbours (eq 40) and, at the limiting
points (the facet Gauss points of the cell), the coefficients alpha_K = g(bound / excursion)
(eq 43) with g(x) = min(1, x) (Barth-Jespersen) or (x^2 + 2x) / (x^2 + x + 2) (Venkatakrishnan),
componentwise on U = [F, p]. A cell is *troubled* when its DG solution leaves the local bounds
[min, max] of the neighbouring averages (eq 39) at one of its limiting points; only troubled
cells are replaced by the limited linear reconstruction u_bar + diag(alpha) grad u_bar (X - X_e)
(eq 41), so smooth regions keep their order.
"""
import numpy as np

from .errors import InputError

KINDS = ("none", "barth-jespersen", "venkatakrishnan")


def _g(x, kind):
    if kind == "barth-jespersen":
        return np.minimum(1.0, x)
    return (x * x + 2 * x) / (x * x + x + 2)


class SlopeLimiter:
    """Built once from a DGFEM-type stepper (Gauss points, cell dofs, face rows)."""

    def __init__(self, stepper, kind):
        if kind not in KINDS:
            raise InputError(f"method.limiter = {kind!r}: expected one of {', '.join(KINDS)}")
        self.kind = kind
        self.st = st = stepper
        nel, nq = st.basis.dx.shape
        self.nel, self.nq = nel, nq
        self.w = st.basis.dx                                               # (nel, nq)
        self.volume = self.w.sum(axis=1)
        X = np.asarray(st.basis.global_coordinates())                       # (d, nel, nq)
        self.Xg = np.moveaxis(X, 0, -1)                                    # (nel, nq, d)
        self.centroid = np.einsum("eq,eqd->ed", self.w, self.Xg) / self.volume[:, None]
        f = st.interior
        pairs = np.unique(np.sort(np.stack([f.cell_L, f.cell_R], axis=1), axis=1), axis=0)
        self.pairs = pairs                                                  # face neighbours
        v = self.centroid[pairs[:, 1]] - self.centroid[pairs[:, 0]]
        dist = np.linalg.norm(v, axis=1)
        self.dist, self.unit = dist, v / dist[:, None]
        G = np.zeros((nel, st.d, st.d))
        outer = np.einsum("pi,pj->pij", self.unit, self.unit)
        np.add.at(G, pairs[:, 0], outer)
        np.add.at(G, pairs[:, 1], outer)
        self.G_inv = np.linalg.pinv(G)
        # limiting points: interior facet points of each side, traced from that side's cell (on the
        # body's boundary a cell has neighbours on one side only: every slope would look like an
        # extremum there)
        self.rows = [(f.T_L, f.cell_L, f.X), (f.T_R, f.cell_R, f.X)]
        # ... instead, a cell's own values on the body's boundary widen its bounds (data there are
        # not a new extremum)
        self.boundary_rows = (st.boundary.T_L, st.boundary.cell_L)

    def averages(self, dofs):
        U = (self.st.B @ dofs).reshape(self.nel, self.nq, -1)
        return np.einsum("eq,eqc->ec", self.w, U) / self.volume[:, None]

    def __call__(self, dofs):
        """Limited dofs (a copy) and the number of troubled cells."""
        if self.kind == "none":
            return dofs, 0
        mean = self.averages(dofs)                                          # (nel, nc)
        lo, hi = mean.copy(), mean.copy()
        i, j = self.pairs[:, 0], self.pairs[:, 1]
        np.minimum.at(lo, i, mean[j])
        np.minimum.at(lo, j, mean[i])
        np.maximum.at(hi, i, mean[j])
        np.maximum.at(hi, j, mean[i])
        T_b, cell_b = self.boundary_rows
        if T_b.shape[0]:
            values_b = T_b @ dofs
            np.minimum.at(lo, cell_b, values_b)
            np.maximum.at(hi, cell_b, values_b)
        diff = (mean[j] - mean[i]) / self.dist[:, None]                     # (npairs, nc)
        rhs = np.zeros(mean.shape + (self.st.d,))
        contrib = np.einsum("pc,pd->pcd", diff, self.unit)
        np.add.at(rhs, i, contrib)
        np.add.at(rhs, j, contrib)                  # for j: ((u_i - u_j)/d) (-unit), the same product
        grad = np.einsum("ekd,ecd->eck", self.G_inv, rhs)                   # (nel, nc, d)
        alpha = np.ones_like(mean)
        troubled = np.zeros(self.nel, dtype=bool)
        scale = np.abs(mean).max(axis=0) + 1e-300
        for T, cell, X in self.rows:
            if T.shape[0] == 0:
                continue
            excursion = T @ dofs - mean[cell]                               # DG solution at the points
            bound = np.where(excursion > 0, hi[cell] - mean[cell], lo[cell] - mean[cell])
            out = np.abs(excursion) > np.abs(bound) + 1e-12 * scale
            np.logical_or.at(troubled, cell, out.any(axis=1))
            moved = np.abs(excursion) > 1e-14 * scale
            ratio = np.clip(bound / np.where(moved, excursion, 1.0), 0.0, 1e6)    # g(1e6) ~ 1
            np.minimum.at(alpha, cell, np.where(moved, _g(ratio, self.kind), 1.0))
        if not troubled.any():
            return dofs, 0
        cells = np.flatnonzero(troubled)
        linear = (mean[cells, None, :] + np.einsum("ec,ecd,eqd->eqc", alpha[cells], grad[cells],
                                                   self.Xg[cells] - self.centroid[cells, None, :]))
        out = dofs.copy()
        out[self.st.cell_dofs[cells]] = np.einsum("ebq,eqc->ebc", self.st.point_to_dofs[cells], linear)
        return out, int(len(cells))
