"""RK-DGFEM: broken Q_P Lagrange space with Gauss quadrature, the baseline of [L23].

The semi-discrete operator is the DGMPM one [L23 eq 27-33] with Gauss points instead of material
points: consistent mass (block diagonal, inverted once per cell), volume term
``sum_q w_q dPhi_i/dX_alpha F_alpha(Q(X_q))`` with the law evaluated at the Gauss points, and
Godunov fluxes at every facet Gauss point from the same Riemann solver and boundary conditions.
Time integration: TVD-RK2 (Heun) or classical RK4; Delta t = CFL h_min / ((2P + 1) c_max)
[L23 eq 67]. A body force adds ``int Phi rho0 b`` at the Gauss points, at each stage's time.

The Gauss points play the part of the particles for everything downstream (fields, energy,
errors, VTK output): ``self.particles`` holds them with their quadrature weights as volumes.
"""
from dataclasses import dataclass, field

import numpy as np
import scipy.sparse as sp
from numba import njit
from skdgmpm.materials.points import law_table
from skfem import (CellBasis, ElementDG, ElementLineP1, ElementLineP2, ElementQuad1, ElementQuad2,
                   ElementQuadDG, ElementQuadP)

from . import forms, integrators, parallel, system
from .elements import ElementLineLagrange
from .equations import power
from .errors import InputError
from .faces import interior_faces
from .integrators import base_entry, base_parts
from .kernel_cache import kernel_factory, scratch
from .parallel import csr_row_add
from .limiter import SlopeLimiter
from .particles import Particles
from .riemann import boundary_fluxes, face_passes, trace_fluxes
from .scheme import GodunovScheme, GridState, ParticleState, stage
from .system import DIMENSION, volume_row

INTEGRATORS = ("rk2", "rk4")        # Euler is unstable for DG of degree >= 1


def _apply_blocks(blocks, cell_dofs, R, out):
    """out[dofs of c] = blocks[c] @ R[dofs of c] for every cell c: blocks (nel, nb, nb), cell_dofs
    (nel, nb), R and out (n_dofs, nc) (a compiled loop: numpy's batched matmul on a gathered copy
    cost ~4 ms a call at 128^2). A stage's update applies its blocks where it forms R
    (`cell_update`)."""
    nb, nc = blocks.shape[1], R.shape[1]
    literal = nc == 6 and nb in (4, 9)      # Q1, Q2 in 2D: literal sizes, the loops unrolled
    kernel = _apply_blocks_kernel(nb if literal else None, nc if literal else None)
    kind, bases = base_parts(R)             # not read: no update
    parallel.chunked(len(blocks), kernel, "rrww(wwww)w", (blocks, cell_dofs, R, kind, bases, out))


@kernel_factory
def _apply_blocks_kernel(nb, nc):
    if nb is None:                      # sizes read at run time (1D; P >= 3, whose rows outgrow the stack scratch)
        def apply_blocks(blocks, cell_dofs, R, kind, bases, out):
            _apply_blocks_n(blocks, cell_dofs, R, kind, bases, out, np.empty((blocks.shape[1], R.shape[1])),
                            blocks.shape[1], R.shape[1])
    else:
        def apply_blocks(blocks, cell_dofs, R, kind, bases, out):
            _apply_blocks_n(blocks, cell_dofs, R, kind, bases, out, scratch((nb, nc)), nb, nc)
    return apply_blocks


@njit(cache=True, inline="always")
def _apply_blocks_n(blocks, cell_dofs, R, kind, bases, out, x, nb, nc):
    """Each cell's rows of R gathered into ``x`` (nb, nc) before its rows of ``out`` are written:
    the compiler cannot tell ``out`` from the arrays it reads and, reading them in place, loads
    them again after every store (the pass x3-4 slower on one thread, where `parallel.chunked`
    calls it from Python). On the stack (the literal sizes) ``x`` stays in registers."""
    for c in range(len(blocks)):
        for m in range(nb):
            r = cell_dofs[c, m]
            for j in range(nc):
                x[m, j] = R[r, j]
        _block_rows(blocks, cell_dofs, c, x, kind, bases, 1.0, out, nb, nc, False)


@njit(cache=True, inline="always")
def _block_rows(blocks, cell_dofs, c, x, kind, bases, step, out, nb, nc, update):
    """Cell c's rows of out: blocks[c] @ x (x (nb, nc) the cell's rows of the right-hand side), or
    with ``update`` base + step * (...), base's entries formed as read (`integrators.base_entry`)."""
    for k in range(nb):
        i = cell_dofs[c, k]
        for j in range(nc):
            s = 0.0
            for m in range(nb):
                s += blocks[c, k, m] * x[m, j]
            out[i, j] = base_entry(kind, bases, i, j) + step * s if update else s


def cell_update(blocks, cell_dofs, faces, Q, stiffness, source, base, step, volume_first):
    """base + step M^-1 R in one pass over the cells, each row of R = volume + surface (+ source)
    formed where the cell's block reads it, none stored: M^-1 per cell (blocks (nel, nb, nb),
    cell_dofs (nel, nb)); the surface term as `faces.FaceSet.integrate` sums it (the interior
    faces' side R, then side L with sign -1; the boundary's side L with sign -1:
    `faces.FaceSet.gather`), ``faces`` = (interior gather (a CSR triple, n_dofs rows), the
    interior facet points' measures, their fluxes, boundary gather, measures, fluxes); the volume
    term as `system.volume_flux` sums it (Q at the points, a `system.Stiffness`); ``source`` the
    source term's rows or None. The terms are added in the order each method's sum takes:
    ``volume_first`` (ADER's corrector) volume, interior, boundary, else (RK) interior, boundary,
    then the volume; then the source. Entry by entry the operations of those passes and of
    `_apply_blocks`: the same bits as R stored and read back, without its 4-6 passes over memory.
    ``base``: an array or an integrator's `Combination`. Rows of a cell in parallel chunks of cells."""
    nb, nc = blocks.shape[1], Q.shape[1]
    d = DIMENSION[nc]
    kernel = _cell_update(nb if d == 2 and nb in (4, 9) else None, d, int(volume_first), int(source is not None))
    kind, bases = base_parts(base)
    out = np.empty((stiffness.shape[0], nc))
    source = np.empty((0, nc)) if source is None else source
    parallel.chunked(len(blocks), kernel, "rr(www)ww(www)www(www)ww(wwww)ww",
                     (blocks, cell_dofs, *faces, Q, tuple(stiffness), source, kind, bases, float(step), out))
    return out


@kernel_factory
def _cell_update(nb, d, volume_first, sourced):   # nb literal (2D Q1, Q2: the loops unrolled) or None
    nc = d * d + d
    if nb is None:                      # sizes read at run time, as `_apply_blocks_kernel`'s
        def cell_update(blocks, cell_dofs, interior, measure, flux, boundary, measure_b, flux_bnd, Q, stiffness,
                        source, kind, bases, step, out):
            _cell_update_n(blocks, cell_dofs, interior, measure, flux, boundary, measure_b, flux_bnd, Q, stiffness,
                           source, kind, bases, step, out, np.empty((blocks.shape[1], nc)), blocks.shape[1], d,
                           volume_first, sourced)
    else:
        def cell_update(blocks, cell_dofs, interior, measure, flux, boundary, measure_b, flux_bnd, Q, stiffness,
                        source, kind, bases, step, out):
            _cell_update_n(blocks, cell_dofs, interior, measure, flux, boundary, measure_b, flux_bnd, Q, stiffness,
                           source, kind, bases, step, out, scratch((nb, nc)), nb, d, volume_first, sourced)
    return cell_update


@njit(cache=True, inline="always")
def _cell_update_n(blocks, cell_dofs, interior, measure, flux, boundary, measure_b, flux_bnd, Q, stiffness, source,
                   kind, bases, step, out, x, nb, d, volume_first, sourced):
    """`cell_update`'s loop over the cells, x (nb, nc) a cell's rows of R."""
    nc = d * d + d
    u, o = scratch((nc,)), scratch((nc,))
    for c in range(len(blocks)):
        for m in range(nb):
            r = cell_dofs[c, m]
            for j in range(nc):
                u[j] = 0.0
            if volume_first:
                volume_row(Q, stiffness, r, u, d)
            csr_row_add(interior, measure, flux, r, u, nc, True)
            csr_row_add(boundary, measure_b, flux_bnd, r, u, nc, True)
            if not volume_first:
                for j in range(nc):
                    o[j] = 0.0
                volume_row(Q, stiffness, r, o, d)
                for j in range(nc):
                    u[j] = u[j] + o[j]
            if sourced:
                for j in range(nc):
                    u[j] = u[j] + source[r, j]
            for j in range(nc):
                x[m, j] = u[j]
        _block_rows(blocks, cell_dofs, c, x, kind, bases, step, out, nb, nc, True)


def dg_element(d, order):
    """Broken tensor-product element Q_P on lines (d = 1) or quads (d = 2): Lagrange for P <= 2,
    above, scikit-fem's ElementQuadP (whose basis is no partition of unity) and, in 1D,
    `ElementLineLagrange`."""
    if d == 1:
        return ElementDG({1: ElementLineP1, 2: ElementLineP2}.get(order, lambda: ElementLineLagrange(order))())
    return ElementQuadDG({1: ElementQuad1, 2: ElementQuad2}.get(order, lambda: ElementQuadP(order))())


def _point_matrix(basis, values):
    """Sparse (n_cells * nq, n_dofs) from per-basis-function values (nb, n_cells, nq)."""
    nb, nel, nq = values.shape
    rows = np.broadcast_to(np.arange(nel * nq).reshape(1, nel, nq), values.shape)
    cols = np.broadcast_to(basis.element_dofs[:, :, None], values.shape)
    return sp.csr_matrix((values.ravel(), (rows.ravel(), cols.ravel())), shape=(nel * nq, basis.N))


@njit(cache=True, nogil=True)
def boundary_power_sums(measure, t, v, out):
    """out[s] = sum_f |f| t_f . v_f (W) at each time node s of tractions t and velocities v (S,
    nf, d) on boundary faces of measures ``measure`` (nf,), as the energy budget counts it: the
    faces in order (`equations.power`). Compiled: numpy's einsum and sum out of the caches after
    the face pass took 70-150 µs a node at 256^2, for a few thousand faces."""
    d = t.shape[2]
    t_f, v_f = np.empty(d), np.empty(d)     # rows copied, not viewed (views are reference counted)
    for s in range(t.shape[0]):
        e = 0.0
        for f in range(t.shape[1]):
            for i in range(d):
                t_f[i], v_f[i] = t[s, f, i], v[s, f, i]
            e += measure[f] * power(t_f, v_f, d)
        out[s] = e


@dataclass
class DGFEM(GodunovScheme):
    """RK-DGFEM of order ``order`` (P) on the active cells of ``grid``.

    Parameters
    ----------
    grid : Grid; materials : MaterialSet; bcs : list of (name, BoundaryCondition)
    cell_material : (n_cells,) material index of each active cell
    order : P in 1..3 (any P >= 1 works); cfl : Courant number of L23 eq 67
    integrator : "rk2" (TVD-RK2) | "rk4"
    body_force : callable (X (n, d), t) -> b (n, d) in m/s^2, or None (no source, no cost)
    """

    grid: object
    materials: object
    bcs: list
    cell_material: np.ndarray
    order: int = 1
    cfl: float = 0.5
    integrator: str = "rk2"
    stages: tuple = ("time_step", "advance", "gauss_state", "interface_flux", "source", "cell_update",
                     "limit", "evaluate_points", "check")
    external_work: float = field(default=0.0, init=False)
    transverse: str = "none"
    limiter: str = "none"
    limited_cells: int = field(default=0, init=False)
    body_force: object = None

    def __post_init__(self):
        if self.integrator not in INTEGRATORS:
            raise InputError(f"method.integrator = {self.integrator!r}: expected one of {', '.join(INTEGRATORS)}")
        if not (isinstance(self.order, int) and self.order >= 1):
            raise InputError(f"method.order = {self.order!r} must be an integer >= 1")
        g = self.grid
        self.d = d = g.dim
        q = 2 * self.order + 1                      # exact for the mass matrix of Q_P
        element = dg_element(d, self.order)
        basis = CellBasis(g.submesh, element, intorder=q)
        self.basis = basis
        self.n_dofs = basis.N
        self.nb = basis.Nbfun
        nel, nq = basis.dx.shape
        phi = np.array([np.asarray(basis.basis[k][0]) for k in range(self.nb)])        # (nb, nel, nq)
        grad = np.array([np.asarray(basis.basis[k][0].grad) for k in range(self.nb)])  # (nb, d, nel, nq)
        self._phi, self._grad = phi, grad
        self.B = _point_matrix(basis, phi)
        self.B_T = self.B.T.tocsr()                 # the dofs' gathers over their points
        self.D = tuple(_point_matrix(basis, grad[:, a] * basis.dx[None]) for a in range(d))
        # sum_q D[q, i] F_alpha(Q_q) as a gather over each dof's points (`system.volume_flux`: F_alpha
        # is linear, each row summed in point order): the same sums as D^T F, rows in parallel
        self.K_points = system.Stiffness(tuple(D.T.tocsr() for D in self.D))
        # the consistent mass is block diagonal (broken space): invert each cell's block once
        self.cell_dofs = np.ascontiguousarray(basis.element_dofs.T)                     # (nel, nb)
        dof_cell = np.empty(basis.N, dtype=np.int64)
        dof_local = np.empty(basis.N, dtype=np.int64)
        dof_cell[self.cell_dofs] = np.arange(nel)[:, None]
        dof_local[self.cell_dofs] = np.arange(self.nb)[None, :]
        mass = forms.mass.assemble(basis).tocoo()
        blocks = np.zeros((nel, self.nb, self.nb))
        np.add.at(blocks, (dof_cell[mass.row], dof_local[mass.row], dof_local[mass.col]), mass.data)
        self.mass_inv = np.linalg.inv(blocks)
        rho_cell = np.array([m.rho for m in self.materials.materials])[self.cell_material]
        X = np.asarray(basis.global_coordinates()).reshape(d, -1).T
        cell = np.repeat(np.arange(nel), nq)
        self.gauss = Particles(X, np.zeros_like(X), cell, basis.dx.ravel(), rho_cell[cell],
                               self.cell_material[cell])
        self.particles = self.gauss            # the points that carry the state
        self.h_min = float(g.cell_sizes().min())
        self.speed_factor = 2 * self.order + 1
        self.face_options = {"pointwise": True, "intorder": q}
        self.interior = interior_faces(g.submesh, element, pointwise=True, intorder=q)
        self.rho_cell = rho_cell
        self._setup_boundary(element)
        f = self.interior          # each interior row's sides: material, density, the traces as CSR triples
        self.interior_sides = (self.cell_material[f.cell_L], self.cell_material[f.cell_R], rho_cell[f.cell_L],
                               rho_cell[f.cell_R], parallel.csr(f.T_L), parallel.csr(f.T_R))
        b = self.boundary          # each boundary row's side: material, density, the trace from the dofs
        self.boundary_side = (self.cell_material[b.cell_L], rho_cell[b.cell_L], parallel.csr(b.T_L))
        self.laws = law_table(self.materials.materials)          # the compiled point laws
        # (P+1)^d Gauss points = (P+1)^d dofs: point values <-> coefficients, cell by cell
        self.point_to_dofs = np.linalg.inv(np.transpose(phi, (1, 2, 0)))                # (nel, nb, nq)
        self.slope_limiter = SlopeLimiter(self, self.limiter)

    # ---------------------------------------------------------------- operators
    def apply_mass_inverse(self, R):
        """M^-1 R with the per-cell inverse blocks."""
        out = np.empty_like(R)
        _apply_blocks(self.mass_inv, self.cell_dofs, R, out)
        return out

    def project(self, U_points):
        """L2 projection of point values onto the DG space (Gauss weights)."""
        return self.apply_mass_inverse(self.source_integral(U_points))

    def point_state(self, U, cells, rho, history=None):
        """Q from U pointwise: P = P(F, history) with each cell's law, v = p / rho0."""
        return self.materials.state(U, self.cell_material[cells], rho, history)

    @stage
    def gauss_state(self, U_dofs, U_points=None):
        """Q at the Gauss points from the dofs (their values there, U_points, where known), with the
        internal variables of t_n there."""
        U = parallel.matmul(self.B, U_dofs) if U_points is None else U_points
        return self.materials.state(U, self.gauss.material, self.gauss.rho0, self.history_n)

    history_n = None          # (n_gauss, n_history) internal variables of the step's t_n

    # ---------------------------------------------------------------- stages
    def interior_pass(self, grid_state):
        """The interior facet points' Godunov fluxes (nf, nc): their pass from the dofs
        (`riemann.trace_fluxes`: traces, law, tangents, Riemann problem, no face array kept; a
        `parallel.Pass`, run by `interface_flux`) and the array it fills."""
        f = self.interior
        mat_L, mat_R, rho_L, rho_R, T_L, T_R = self.interior_sides
        flux = np.empty((len(f), grid_state.U.shape[1]))
        return trace_fluxes(T_L, T_R, grid_state.U, grid_state.Q, rho_L, rho_R, f.normal, mat_L, mat_R, *self.laws,
                            flux), flux

    def boundary_pass(self, T, u, q, times, weights):
        """The boundary facet points' fluxes under their conditions [R18 §4.5], sum_s weights[s]
        F_N(t*, v*) (nb, nc), from the states u, q (S, n, nc) at the times ``times`` (S,) through
        the trace T: their pass (`riemann.boundary_fluxes`: trace, law, tangent, ghost state,
        flux; q None: the law at the trace of u; a `parallel.Pass`, run by `interface_flux`) and
        the arrays it fills, (flux, t*, v*), t*, v* (S, nb, d) (`boundary_powers`)."""
        b, g = self.boundary, self.ghosts
        material, rho, _ = self.boundary_side
        S, nb, d = len(times), len(b), self.d
        flux, t_s, v_s = np.empty((nb, d * d + d)), np.empty((S, nb, d)), np.empty((S, nb, d))
        values = np.stack([g.values_at(t) for t in times])
        return boundary_fluxes(T, u, q, rho, b.normal, material, *self.laws, (g.frame, g.velocity, g.copy), values,
                               np.asarray(weights, dtype=float), flux, t_s, v_s), (flux, t_s, v_s)

    def boundary_powers(self, t_s, v_s):
        """The power through the boundary (W) at each time node of `boundary_pass`, a list
        (`boundary_power_sums`)."""
        out = np.empty(len(t_s))
        boundary_power_sums(self.boundary.measure, t_s, v_s, out)
        return out.tolist()

    @stage
    def interface_flux(self, interior, boundary):
        """(d)-(e) The Godunov fluxes of the interior and boundary facet points: their passes
        (`interior_pass`, `boundary_pass`, or ADER's over its time nodes) in one loop over the
        threads (`riemann.face_passes`). Stops at the first face that is not hyperbolic."""
        face_passes(interior, boundary)

    def surface_fluxes(self, grid_state, time):
        """The Godunov fluxes of the interior and boundary facet points, each one pass from the
        dofs, both in one loop over the threads (`interface_flux`), as the surface term reads them
        (`faces_read`), and the power through the boundary (W)."""
        T_B = self.boundary_side[2]
        Q = None if grid_state.Q is None else grid_state.Q[None]
        interior, flux = self.interior_pass(grid_state)
        boundary, (flux_bnd, t_s, v_s) = self.boundary_pass(T_B, grid_state.U[None], Q, (time,), (1.0,))
        self.interface_flux(interior, boundary)
        return self.faces_read(flux, flux_bnd), self.boundary_powers(t_s, v_s)[0]

    def faces_read(self, flux, flux_bnd):
        """What `cell_update` reads of the faces: -int Phi F_N* over the interior faces (side R
        minus side L, `faces.FaceSet.gather`) and over the boundary's (side L, sign -1) as
        gathers per dof, with the facet points' measures and fluxes."""
        f, b = self.interior, self.boundary
        return f.gather(("R", "L"), 1.0), f.measure, flux, b.gather(("L",), -1.0), b.measure, flux_bnd

    volume_first = False        # RK's residual: the faces' terms, then + the volume's (`cell_update`)

    @stage
    def cell_update(self, base, step, faces, Q, source=None):
        """base + step M^-1 (volume + surface (+ source)) in one pass over the cells, the terms'
        rows formed where M^-1 reads them (`dgfem.cell_update`): the volume term of Q at the
        points of `volume_stiffness`, the faces' as `faces_read` gives them, source the source
        term's rows or None."""
        return cell_update(self.mass_inv, self.cell_dofs, faces, Q, self.volume_stiffness, source, base, step,
                           self.volume_first)

    @property
    def volume_stiffness(self):
        """The volume term's K^alpha over the Gauss points (`system.Stiffness`)."""
        return self.K_points

    def source_integral(self, S):
        """int Phi S from values S (n_points, nc) at the Gauss points (Gauss quadrature): B^T (w S),
        each dof summing its own points (`parallel.matmul` on B^T)."""
        return parallel.matmul(self.B_T, S, scale=self.gauss.volume)

    def rate_update(self, U_dofs, base, step, time, U_points=None, Q_points=None):
        """base + step dU/dt, dU/dt = M^-1 (surface + volume terms + source), and the boundary
        power: the faces' pass, then the terms' sum, M^-1 and the update in one pass over the cells
        (`cell_update`). U_points, Q_points: U_dofs's values at the Gauss points and the law there,
        where known (the state's, at the first stage)."""
        if self.materials.n_history:     # the law at the Gauss points only, where the history is
            Q = self.gauss_state(U_dofs, U_points)
            faces, power = self.surface_fluxes(GridState(U_dofs, self.project(Q)), time)
        else:
            faces, power = self.surface_fluxes(GridState(U_dofs, None), time)
            Q = self.gauss_state(U_dofs, U_points) if Q_points is None else Q_points
        source = None if self.body_force is None else self.source_integral(self.source(self.gauss, time))
        return self.cell_update(base, step, faces, Q, source), power

    @stage
    def limit(self, dofs):
        """The slope limiter (L23 §3.3), when the scene switches it on."""
        out, n = self.slope_limiter(dofs)
        self.limited_cells += n
        return out

    @stage
    def advance(self, U, time, dt, U_points, Q_points):
        """TVD-RK2 (Heun) or classical RK4 (`skdgmpm.integrators`), limiting every stage's result;
        returns dofs and boundary work. The first stage, at U, takes U's values at the Gauss points
        U_points and the law there Q_points (None: evaluated from the history of t_n) from the
        state: no product with B, no law's pass."""
        def rk_stage(U_eval, base, t, step):
            at = (U_points, Q_points) if U_eval is U else (None, None)
            U_next, power = self.rate_update(U_eval, base, step, t, *at)
            return self.limit(U_next), power

        return integrators.INTEGRATORS[self.integrator](rk_stage, U, time, dt)

    @stage
    def evaluate_points(self, state, dofs, dt):
        """State at the Gauss points from the dofs; positions advanced with the new velocity. The
        law's pass keeps the health summary only, as DGMPM's step (`GodunovScheme.check`)."""
        U = parallel.matmul(self.B, dofs)
        Q, history, health, x = self.materials.update_and_assess(
            U, self.gauss.material, self.gauss.rho0, state.history, (state.x, state.Q[:, self.d * self.d:], dt),
            points=False)
        new = ParticleState(state.t + dt, U, Q, x, state.step + 1, dofs=dofs, history=history)
        self.check(new, health)
        return new

    # ---------------------------------------------------------------- driver-facing
    def initial_state(self, F, v, t=0.0):
        """From F (n, d, d) and v (n, d) at the Gauss points: L2 projection onto the DG space."""
        U = system.join(F, self.gauss.rho0[:, None] * v)
        dofs = self.project(U)
        history = self.materials.initial_history(self.cell_material[self.gauss.cell])
        state = ParticleState(t, parallel.matmul(self.B, dofs), None, self.particles.X.copy(), dofs=dofs, history=history)
        state.Q, _, health = self.at_rest(state, self.gauss)     # `evaluate_points`'s pass; the history virgin
        self.check(state, health)
        return state

    def step(self, state, dt_max=np.inf):
        self.history_n = state.history          # every stage's law reads the history of t_n

        # the state's U and Q: B dofs and the law at the Gauss points (evaluate_points); a law
        # with internal variables has Q of its updated ones there, not those of t_n
        Q = None if self.materials.n_history else state.Q

        def attempt(dt):
            dofs, work = self.advance(state.dofs, state.t, dt, state.U, Q)
            return self.evaluate_points(state, dofs, dt), work

        return self.step_with_cfl_guard(state, dt_max, attempt)
