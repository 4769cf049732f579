"""ADER-DGMPM [L23 §4]: the ADER-DGFEM corrector on the grid, the predictor on the particles.

Forward map: the particles of each cell define MLS shape functions chi_p (skdgmpm.mls); the
predictor's space-time dofs are the particle values at the P+1 time nodes (L23 eq 45-46) and its
matrices come from Gauss quadrature of the MLS functions (eq 59-61):

    u_hat[s] = U^n - dt sum_s' T[s, s'] sum_alpha D_alpha F_alpha(q_hat[s']),
    D_alpha = M_chi^-1 G_alpha,  M_chi = int chi_k chi_l,  G_alpha = int chi_k dchi_l/dX_alpha,

with the law evaluated at the particles at every Picard iteration and the Taylor guess of eq 64
(collocated MLS gradients). The grid solution at t_n is the L2 projection of the MLS
reconstruction onto the DG space (exact for polynomials the MLS basis reproduces). The corrector
evaluates the predictor with chi at the Gauss and facet points. Back-mapping: PIC (eq 65) or FLIP
(eq 66); then the law at the particles. A body force enters the predictor at the particles (its
values there are the MLS coefficients, as for U) and the corrector at the Gauss points, both at
the time nodes t_n + tau_s dt.
"""
from dataclasses import dataclass

import numpy as np
import scipy.sparse as sp

from . import parallel
from .ader import ADERDGFEM
from .errors import InputError
from .mls import shape_functions
from .quadrature import cell_slots, interpolation_matrix, particle_basis
from .scheme import GodunovScheme, cell_values, stage

BACKMAPS = ("pic", "flip")


@dataclass
class ADERDGMPM(ADERDGFEM):
    """ADER-DGMPM of order P with ``particles``; ``mls_order`` defaults to P."""

    particles_in: object = None
    mls_order: int = -1
    backmap: str = "pic"
    stages: tuple = ("project_particles", "time_step", "predictor", "corrector", "surface_integral", "interface_flux",
                     "source", "cell_update", "limit", "back_map", "constitutive_update", "check")

    def __post_init__(self):
        if self.backmap not in BACKMAPS:
            raise InputError(f"method.backmap = {self.backmap!r}: expected one of {', '.join(BACKMAPS)}")
        super().__post_init__()
        p = self.particles = self.particles_in
        if self.mls_order < 0:
            self.mls_order = self.order
        nel, nq = self.basis.dx.shape
        d = self.d
        self.n_max, self.slot = cell_slots(p.cell, nel)
        if self.n_max > nq:                 # M below (L23 eq 59) sums nq rank-one terms: singular
            raise InputError(f"particles.per_cell: {self.n_max} particles in a cell, more than the {nq} Gauss points "
                             f"of ADER-DGMPM of order {self.order}, whose projection (L23 eq 59) would be singular: "
                             f"at most {nq} a cell")
        xi = np.full((nel * self.n_max, d), 0.5)
        xi[self.slot] = p.xi
        self.mask = np.zeros(nel * self.n_max)
        self.mask[self.slot] = 1.0
        self.is_padding = self.mask == 0       # the predictor's points (`_points`): made once, not every step
        self.padding = np.flatnonzero(self.is_padding)
        self.slot_particle = np.full(nel * self.n_max, -1, dtype=np.int32)      # -1: padding
        self.slot_particle[self.slot] = np.arange(len(p))
        self.slot_cell = np.repeat(np.arange(nel), self.n_max)                   # cell and density of
        self.slot_rho0 = np.ones(nel * self.n_max)                              # each padded slot
        self.slot_rho0[self.slot] = p.rho0
        xi, mask = xi.reshape(nel, self.n_max, d), self.mask.reshape(nel, self.n_max)
        cells = np.arange(nel)
        mapping = self.basis.mapping

        def mls(points, tind):
            """chi and physical gradients at parent ``points`` (nel, n, d) of each cell."""
            phi, dphi = shape_functions(xi, mask, points, self.mls_order, cells=cells)
            inv = mapping.invDF(np.moveaxis(points, -1, 0), tind=tind)          # (d, d, nel, n)
            return phi, np.einsum("cepm,mace->cepa", dphi, inv)

        # Gauss points: projection of the reconstruction and predictor matrices (eq 59-61)
        gauss = np.broadcast_to(self.basis.X.T[None], (nel, nq, d)).copy()
        self.chi_gauss, dchi_gauss = mls(gauss, cells)
        w = self.basis.dx
        M = np.einsum("cg,cgk,cgl->ckl", w, self.chi_gauss, self.chi_gauss)
        M += np.einsum("ck,kl->ckl", 1.0 - mask, np.eye(self.n_max))          # padding rows
        G = np.einsum("cg,cgk,cgla->ackl", w, self.chi_gauss, dchi_gauss)
        self.D_particles = np.ascontiguousarray(np.linalg.solve(M[None], G))    # (d, nel, nm, nm)
        _, grad = mls(xi, cells)                                                # Taylor guess
        self.grad_at_particles = np.ascontiguousarray(np.moveaxis(grad, -1, 0))  # (d, nel, nm, nm)
        self.E_gauss = self._sparse(self.chi_gauss, np.arange(nel * nq).reshape(nel, nq))
        # facet rows: each side evaluates its own cell's MLS reconstruction
        self.set_point_operators([self._facet_operator(X, cell, mls, nel) for X, cell in (
            (self.interior.X, self.interior.cell_L), (self.interior.X, self.interior.cell_R),
            (self.boundary.X, self.boundary.cell_L))], self.E_gauss)
        basis_p, slot_p = particle_basis(self.grid, p, self.basis.elem)
        self.S = interpolation_matrix(basis_p, slot_p)                          # DG basis at particles
        self.cell_material = cell_values("materials", p.cell, p.material, nel)

    def _sparse(self, values, rows):
        """(n_rows, n_slots) from per-cell values (nel, n, n_max) on the padded particle slots (the
        predictor's points; padding columns and rows < 0 are left out)."""
        nel, n, nm = values.shape
        cols = np.broadcast_to(np.arange(nel * nm).reshape(nel, 1, nm), values.shape)
        r = np.broadcast_to(rows[:, :, None], values.shape)
        keep = (self.mask.reshape(nel, 1, nm) > 0) & (r >= 0)
        return sp.csr_matrix((values[keep], (r[keep], cols[keep])),
                             shape=(int(rows.max()) + 1 if rows.size else 0, nel * nm))

    def _facet_operator(self, X, cell, mls, nel):
        """MLS evaluation at facet rows: parent coordinates of each row in its cell."""
        n = len(X)
        if n == 0:
            return sp.csr_matrix((0, len(self.mask)))
        ref = self.basis.mapping.invF(X.T[:, :, None], tind=cell)[:, :, 0].T    # (n, d)
        counts = np.bincount(cell, minlength=nel)
        width = max(int(counts.max()), 1)
        _, row_slot = cell_slots(cell, nel)
        pts = np.full((nel * width, self.d), 0.5)
        pts[row_slot] = ref
        rows = -np.ones(nel * width, dtype=np.int64)
        rows[row_slot] = np.arange(n)
        phi, _ = mls(pts.reshape(nel, width, self.d), np.arange(nel))
        op = self._sparse(phi, rows.reshape(nel, width))          # padding rows (-1) left out
        op.resize((n, len(self.mask)))
        return op.tocsr()

    # ---------------------------------------------------------------- predictor at particles
    def _padded(self, values):
        """Particle values (n, ...) on the padded slots (nel, n_max, ...), zero in the padding (a
        gather on the threads)."""
        out = np.empty((self.basis.dx.shape[0], self.n_max) + values.shape[1:])
        return parallel.take_rows(np.ascontiguousarray(values), self.slot_particle, out)

    @stage
    def predictor(self, U_slots, dt, source=None, Q_slots=None):
        """Space-time predictor with dofs at the particles: (u_hat, q_hat) (P+1, nel, n_max, nc) and
        the time nodes' weighted sum q_sum (nel, n_max, nc) on the padded slots, from U on them
        (nel, n_max, nc) (and the law there, Q_slots, if known); ``source`` (P+1, n_particles, nc)
        from `space_time_source` at the particles, or None."""
        S = None if source is None else np.stack([self._padded(s) for s in source])   # P+1 time nodes
        return self._picard(U_slots, dt, self._law_cells, self.D_particles, self.grad_at_particles,
                            self._points(self.slot_cell, self.slot_rho0, self.is_padding), S, Q_slots)

    def _law_cells(self, U):
        """The law at the particles on padded (..., nel, n_max, nc) arrays (padding stays zero):
        one evaluation over every slot of every batch entry (padding slots hold U = 0, an
        admissible input of every law, and are zeroed after), so no gather or scatter."""
        Q = self._law_at(U, self.slot_cell, self.slot_rho0)
        Q.reshape(-1, len(self.mask), Q.shape[-1])[:, self.padding] = 0.0
        return Q

    # ---------------------------------------------------------------- corrector and back-map
    @stage
    def project_particles(self, U_slots):
        """The grid image of the MLS field of the particles' U: its L2 projection onto the DG space."""
        return self.project(parallel.matmul(self.E_gauss, U_slots.reshape(-1, U_slots.shape[-1])))

    @stage
    def back_map(self, state, dofs, dofs_n):
        """U at the particles from the corrected dofs: PIC (S dofs) or FLIP (U_p + S (dofs - dofs_n))."""
        if self.backmap == "pic":
            return parallel.matmul(self.S, dofs)
        return state.U + parallel.matmul(self.S, dofs - dofs_n)

    def step(self, state, dt_max=np.inf):
        U_slots, Q_slots = self._padded(state.U), self._padded(state.Q)       # Q: the law at t_n
        if self.materials.n_history:            # the particles' history of t_n on the padded slots
            virgin = self.materials.initial_history(self.slot_cell * 0)       # padding: a virgin state
            virgin[self.slot] = state.history
            self.history_n = virgin
        dofs_n = self.project_particles(U_slots)

        def attempt(dt):
            predicted = self.predictor(U_slots, dt, self.space_time_source(self.particles, state.t, dt), Q_slots)
            dofs, work = self.corrector(dofs_n, *predicted, state.t, dt,
                                        self.space_time_source(self.gauss, state.t, dt))
            return self.constitutive_update(state, self.back_map(state, dofs, dofs_n), dt), work

        return self.step_with_cfl_guard(state, dt_max, attempt)

    initial_state = GodunovScheme.initial_state          # the state lives on the particles
    initial_pass = "law"                                  # `constitutive_update`'s pass, as the step's
