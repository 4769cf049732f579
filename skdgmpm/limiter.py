"""Slope limiters of L23 §3.3 (eq 39-43) for the high-order DG solution.

Cell averages, a least-squares gradient from the face neighbours (eq 40) and, at the limiting
points (the facet Gauss points of the cell), the coefficients alpha_K = g(bound / excursion)
(eq 43) with g(x) = min(1, x) (Barth-Jespersen) or (x^2 + 2x) / (x^2 + x + 2) (Venkatakrishnan),
componentwise on U = [F, p]. A cell is *troubled* when its DG solution leaves the local bounds
[min, max] of the neighbouring averages (eq 39) at one of its limiting points; only troubled
cells are replaced by the limited linear reconstruction u_bar + diag(alpha) grad u_bar (X - X_e)
(eq 41), so smooth regions keep their order. The excursion in eq 43 is that of the function eq 41
limits, the reconstruction grad u_bar (X_K - X_e) (Barth & Jespersen): so the limited solution
keeps the bounds (BJ) at every limiting point. (The DG solution's own excursion there, with the
gradient of eq 40, would not: a cell whose DG slope is barely out of bounds but whose neighbours'
gradient is steep got alpha ~ 1 and a new extremum, which fed energy into limited impacts.)

Componentwise limiting is not frame invariant (L23 §5.3): rotating a whole scene rotates F and p
(F -> R F R^T, p -> R p) but the bounds [min, max] of each component are not those of the rotated
components. The ``-invariant`` kinds limit each block of U (the tensor F, the vector p) with one
scalar factor alpha_block per cell, built from rotation-independent quantities only: at a limiting
point with excursion delta = u_q - u_bar (a block, norm |delta| in the Frobenius / Euclidean
norm), the bound is the largest neighbour difference projected on the excursion's direction,
M = max(0, max_j (u_bar_j - u_bar) : delta / |delta|), and alpha = g(M / |delta|). The projections
are inner products of blocks, unchanged by F -> R F R^T, p -> R p, and the least-squares gradient
rotates with the scene, so the limited solution of a rotated scene is the rotated limited
solution. In 1D it is the componentwise limiter.

The ``-scaled`` kinds keep the cell's own DG solution and scale its deviation from the average:
u_lim = u_bar + diag(alpha) (u_h - u_bar), alpha from the DG solution's excursion at the limiting
points (the scaling limiter of Zhang & Shu; for P = 1 the DG solution's own slope limited as by
Barth & Jespersen). It keeps the same bounds at the limiting points but never steepens a
component and never imports the neighbours' gradient: the kinetic energy of a limited cell never
grows, and F keeps the rotation it carries. Eq 41's reconstruction replaces F by neighbour
gradients component by component: where the material rotates (the ligaments of the multi-holed
cell) it turned rotation into shear and created stored energy (measured: +1.4e5 J/m over 6e-6 s
on the 2 mm mesh, ADER-DGFEM S1T1; the run then stops with J <= 0).
"""
import numpy as np

from .errors import InputError

INVARIANT, SCALED = "-invariant", "-scaled"
KINDS = ("none", *(g + inv + sc for sc in ("", SCALED) for inv in ("", INVARIANT)
                   for g in ("barth-jespersen", "venkatakrishnan")))


def _g(x, kind):
    if kind.startswith("barth-jespersen"):
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
        self.invariant = INVARIANT in kind
        self.scaled = kind.endswith(SCALED)
        if self.invariant:
            d = st.d
            self.blocks = (slice(0, d * d), slice(d * d, d * d + d))          # F, p
            # padded tables: face neighbours of each cell, and its own boundary rows (padding
            # points back at the cell itself: a zero difference, which never raises the bound)
            self.neighbours = _table(np.r_[pairs[:, 0], pairs[:, 1]], np.r_[pairs[:, 1], pairs[:, 0]], nel)         # (nel, K) cells
            self.boundary_table = _table(np.asarray(self.boundary_rows[1]), np.arange(len(self.boundary_rows[1])),
                                         nel, pad=-1)                      # (nel, Kb) boundary rows

    def _limited_excursion(self, grad, cell, X, excursion):
        """The excursion alpha scales at the limiting points X (rows, d) of ``cell``: the DG
        solution's own (``excursion``, -scaled kinds) or grad u_bar (X_K - X_e) of eq 41."""
        if self.scaled:
            return excursion
        return np.einsum("rcd,rd->rc", grad[cell], X - self.centroid[cell])

    def _invariant_alpha(self, dofs, mean, grad):
        """One factor per cell and block (F, p) from rotation-independent projections, and the
        troubled cells (the DG solution beyond the projected bound at a limiting point); the factor
        limits the reconstruction's excursion, as the componentwise kinds."""
        diffs = [mean[self.neighbours] - mean[:, None, :]]                 # (nel, K, nc)
        T_b, _ = self.boundary_rows
        if T_b.shape[0]:
            values_b = np.vstack([T_b @ dofs, np.zeros((1, dofs.shape[1]))])
            rows = self.boundary_table
            own = np.where((rows >= 0)[:, :, None], values_b[rows] - mean[:, None, :], 0.0)
            diffs.append(own)
        diffs = np.concatenate(diffs, axis=1)
        n_blocks = len(self.blocks)
        alpha = np.ones((self.nel, n_blocks))
        troubled = np.zeros(self.nel, dtype=bool)
        scales = [np.linalg.norm(mean[:, b], axis=1).max() + 1e-300 for b in self.blocks]
        for T, cell, X in self.rows:
            if T.shape[0] == 0:
                continue
            excursion = T @ dofs - mean[cell]
            scaled = self._limited_excursion(grad, cell, X, excursion)
            for k, (b, scale) in enumerate(zip(self.blocks, scales)):
                size, bound = _projected_bound(excursion[:, b], diffs[cell][:, :, b], scale)
                np.logical_or.at(troubled, cell, size > bound + 1e-12 * scale)
                if scaled is not excursion:             # eq 41: the reconstruction's own bound
                    size, bound = _projected_bound(scaled[:, b], diffs[cell][:, :, b], scale)
                moved = size > 1e-14 * scale
                ratio = np.clip(bound / np.where(moved, size, 1.0), 0.0, 1e6)
                np.minimum.at(alpha[:, k], cell, np.where(moved, _g(ratio, self.kind), 1.0))
        per_component = np.ones_like(mean)
        for k, b in enumerate(self.blocks):
            per_component[:, b] = alpha[:, k, None]
        return per_component, troubled

    def gradient(self, mean):
        """Least-squares gradient of the cell averages from the face neighbours (eq 40): (nel, nc, d)."""
        i, j = self.pairs[:, 0], self.pairs[:, 1]
        diff = (mean[j] - mean[i]) / self.dist[:, None]                     # (npairs, nc)
        rhs = np.zeros(mean.shape + (self.st.d,))
        contrib = np.einsum("pc,pd->pcd", diff, self.unit)
        np.add.at(rhs, i, contrib)
        np.add.at(rhs, j, contrib)                  # for j: ((u_i - u_j)/d) (-unit), the same product
        return np.einsum("ekd,ecd->eck", self.G_inv, rhs)

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
        grad = None if self.scaled else self.gradient(mean)
        if self.invariant:
            alpha, troubled = self._invariant_alpha(dofs, mean, grad)
            return self._replace(dofs, mean, grad, alpha, troubled)
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
            scaled = self._limited_excursion(grad, cell, X, excursion)     # what alpha scales
            bound = np.where(scaled > 0, hi[cell] - mean[cell], lo[cell] - mean[cell])
            moved = np.abs(scaled) > 1e-14 * scale
            ratio = np.clip(bound / np.where(moved, scaled, 1.0), 0.0, 1e6)    # g(1e6) ~ 1
            np.minimum.at(alpha, cell, np.where(moved, _g(ratio, self.kind), 1.0))
        return self._replace(dofs, mean, grad, alpha, troubled)

    def _replace(self, dofs, mean, grad, alpha, troubled):
        """Troubled cells get u_bar + alpha grad (X - X_e) (eq 41) or, -scaled kinds,
        u_bar + alpha (u_h - u_bar), at the Gauss points, projected back on their dofs."""
        if not troubled.any():
            return dofs, 0
        cells = np.flatnonzero(troubled)
        if self.scaled:
            deviation = (self.st.B @ dofs).reshape(self.nel, self.nq, -1)[cells] - mean[cells, None, :]
            linear = mean[cells, None, :] + alpha[cells, None, :] * deviation
        else:
            linear = (mean[cells, None, :] + np.einsum("ec,ecd,eqd->eqc", alpha[cells], grad[cells],
                                                       self.Xg[cells] - self.centroid[cells, None, :]))
        out = dofs.copy()
        out[self.st.cell_dofs[cells]] = np.einsum("ebq,eqc->ebc", self.st.point_to_dofs[cells], linear)
        return out, int(len(cells))


def _projected_bound(delta, diffs, scale):
    """|delta| of excursions delta (rows, block) and the bound max(0, max_j diff_j : delta / |delta|)
    over the neighbour differences diffs (rows, K, block): rotation-independent."""
    size = np.linalg.norm(delta, axis=1)
    unit = delta / np.where(size > 1e-14 * scale, size, 1.0)[:, None]
    return size, np.maximum(np.einsum("rkc,rc->rk", diffs, unit).max(axis=1), 0.0)


def _table(owner, value, n, pad=None):
    """Padded (n, K) table of the ``value``s of each ``owner`` (K = the largest count); padding is
    the owner's own index, or ``pad``."""
    owner, value = np.asarray(owner, dtype=np.int64), np.asarray(value, dtype=np.int64)
    counts = np.bincount(owner, minlength=n)
    width = max(int(counts.max()) if len(owner) else 0, 1)
    table = np.repeat(np.arange(n)[:, None], width, axis=1) if pad is None else np.full((n, width), pad)
    order = np.argsort(owner, kind="stable")
    start = np.concatenate([[0], np.cumsum(counts)[:-1]])
    slot = np.arange(len(owner)) - start[owner[order]]
    table[owner[order], slot] = value[order]
    return table
