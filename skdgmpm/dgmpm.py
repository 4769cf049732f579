"""First-order DGMPM [R18 §5]: Q1 broken grid, particles as quadrature, Godunov fluxes.

One step is the list of named stages of R18 §5 (a)-(h):

    project -> time_step -> volume_flux -> boundary_flux -> interface_flux -> transverse_flux
    -> source -> advance -> back_map -> constitutive_update

``advance`` is forward Euler [R18 eq 20] or Heun's RK2 with both stages on the grid [R18 §7.1]
(the second stage evaluates the law at the grid nodes). ``transverse_flux`` adds the CTU
corrections of R18 §4.4 in 2D (``transverse="ctu"``); DCU leaves it out. ``source`` adds
int Phi rho0 b = sum_p S_ip V_p rho0 b(X_p, t) when a body force is set (particle quadrature, at
the time the boundary values are taken).
"""
from dataclasses import dataclass, field

import numpy as np

from . import system
from .errors import InputError
from .faces import interior_faces
from .quadrature import ParticleMap, VolumeOperators, interpolation_matrix, particle_basis
from .riemann import transverse_fluxes
from .scheme import GodunovScheme, GridState, cell_values


@dataclass
class DGMPM(GodunovScheme):
    """First-order DGMPM stepper on a `Grid` with `Particles`.

    Parameters
    ----------
    grid, particles : the discretisation (``particles.cell`` indexes ``grid.submesh``)
    materials : MaterialSet
    bcs : list of (boundary name, BoundaryCondition); later entries override earlier ones on
        shared faces; boundary faces with no condition are free (zero traction).
    cfl : Courant number; integrator : "euler" | "rk2"; transverse : "dcu" | "ctu" (2D)
    body_force : callable (X (n, d), t) -> b (n, d) in m/s^2, or None (no source, no cost)
    """

    grid: object
    particles: object
    materials: object
    bcs: list
    cfl: float = 1.0
    integrator: str = "euler"
    transverse: str = "dcu"
    body_force: object = None
    stages: tuple = ("project", "time_step", "volume_flux", "boundary_flux", "interface_flux",
                     "transverse_flux", "source", "advance", "back_map", "constitutive_update")
    external_work: float = field(default=0.0, init=False)

    def __post_init__(self):
        if self.integrator not in ("euler", "rk2"):
            raise InputError(f"method.integrator = {self.integrator!r}: expected 'euler' or 'rk2'")
        if self.transverse not in ("dcu", "ctu"):
            raise InputError(f"method.transverse = {self.transverse!r}: expected 'dcu' or 'ctu'")
        g, p = self.grid, self.particles
        self.d = g.dim
        basis, slot = particle_basis(g, p)
        self.ops = VolumeOperators.assemble(basis)
        self.map = ParticleMap.build(interpolation_matrix(basis, slot), p.volume, p.rho0, self.ops.lumped)
        self.n_dofs = basis.N
        self.dof_cell = np.empty(basis.N, dtype=np.int64)
        self.dof_cell[basis.element_dofs] = np.arange(g.submesh.nelements)[None, :]
        n_cells = g.submesh.nelements
        self.cell_material = cell_values("materials", p.cell, p.material, n_cells)
        self.cell_volume = g.cell_volumes()
        self.h_min = float(g.cell_sizes().min())
        self.interior = interior_faces(g.submesh, g.element)
        self._setup_boundary(g.element)
        self._setup_transverse()

    # ---------------------------------------------------------------- set-up
    def _setup_transverse(self):
        """CTU topology: for each face and side, the source cell's two edges adjacent to the face
        (axis 0 of the (2, nf) arrays), with their outward normals and their index among interior
        faces (with the sign of the interior normal) or boundary faces (-1 where not one)."""
        self.ctu = None
        if self.transverse != "ctu" or self.d != 2:
            return
        m = self.grid.submesh
        pos_int = -np.ones(m.nfacets, dtype=np.int64)
        pos_int[self.interior.facets] = np.arange(len(self.interior))
        pos_bnd = -np.ones(m.nfacets, dtype=np.int64)
        pos_bnd[self.boundary.facets] = np.arange(len(self.boundary))
        self.ctu = []
        for kind, faces in (("interior", self.interior), ("boundary", self.boundary)):
            sides = (("L", faces.cell_L), ("R", faces.cell_R)) if kind == "interior" else (("L", faces.cell_L),)
            for side, cells in sides:
                k = np.argmax(m.t2f[:, cells] == faces.facets[None, :], axis=0)
                j = m.t2f[(k[None, :] + np.array([1, 3])[:, None]) % 4, cells[None, :]]     # (2, nf)
                j_int, j_bnd = pos_int[j], pos_bnd[j]
                sign = np.where(self.interior.cell_L[j_int] == cells, 1.0, -1.0)
                n = np.where((j_int >= 0)[..., None], sign[..., None] * self.interior.normal[j_int],
                             self.boundary.normal[j_bnd])
                h = self.cell_volume[cells] / faces.measure
                self.ctu.append((kind, side, h, (n, j_int, j_bnd, sign)))
        frame = np.zeros((len(self.boundary), 2, 2))
        free_v = np.zeros((len(self.boundary), 2), bool)
        free_t = np.zeros((len(self.boundary), 2), bool)
        for sel, bc in self.bc_groups:
            frame[sel], imp_v, imp_t = bc.constraints(self.boundary.normal[sel])
            free_v[sel], free_t[sel] = ~imp_v, ~imp_t
        self.ctu_boundary = (frame, free_v, free_t)

    # ---------------------------------------------------------------- stages
    def project(self, state):
        """(a) M_i U_i = sum_p S_ip V_p U_p; Q likewise (v from the projected momentum)."""
        U = self.map.project(state.U)
        Q = self.map.project(state.Q)
        Q[:, self.d * self.d:] = U[:, self.d * self.d:] / self.map.rho[:, None]
        return GridState(U, Q)

    def volume_flux(self, grid_state, out=None):
        """(c) sum_alpha K^alpha F_alpha(Q) (added to ``out`` if given)."""
        return system.volume_flux(grid_state.Q, self.ops.stiffness, out)

    def transverse_flux(self, interior, boundary, dt):
        """CTU [R18 eq 34-37]: each fluctuation entering a cell is split on the characteristic
        basis of the cell's two edges adjacent to the source face; the part moving out through an
        edge becomes the extra flux G = -dt / (2 h) B+ A dU there (h: cell size across the source
        face). Returns corrections of the interior and boundary face fluxes.

        At a boundary edge the ghost cell is a copy of the cell (it sends back the cell's own
        correction through the opposite edge), and only the components the boundary condition
        leaves free are changed, so the condition still holds exactly.
        """
        corr_int = np.zeros_like(interior.flux)
        corr_bnd = np.zeros_like(boundary.flux)
        if self.ctu is None:
            return corr_int, corr_bnd
        for kind, side, h, (n, j_int, j_bnd, sign) in self.ctu:
            fs = interior if kind == "interior" else boundary
            w = fs.fluct_L if side == "L" else fs.fluct_R
            C = fs.C_L if side == "L" else fs.C_R
            rho = fs.rho_L if side == "L" else fs.rho_R
            transverse_fluxes(w, C, rho, -dt / (2.0 * h), n, j_int, j_bnd, sign, corr_int, corr_bnd)
        return corr_int, self._free_part(corr_bnd)

    def _free_part(self, flux):
        """Keep the components of a boundary flux correction that the condition leaves free."""
        frame, free_v, free_t = self.ctu_boundary
        F, p = system.split(flux, self.d)
        dv = np.einsum("fkj,fja,fa->fk", frame, F, self.boundary.normal) * free_v
        dt_ = np.einsum("fkj,fj->fk", frame, p) * free_t
        return system.join(np.einsum("fkj,fk->fj", frame, dv)[:, :, None] * self.boundary.normal[:, None, :],
                           np.einsum("fkj,fk->fj", frame, dt_))

    def face_values(self, T, grid_state, cells):
        """Side-averaged Q, F and density on a face set (Q projected from the particles)."""
        d = self.d
        return T @ grid_state.Q, (T @ grid_state.U)[:, : d * d].reshape(-1, d, d), T @ self.map.rho

    def residual(self, grid_state, time, dt):
        """M dU/dt = K^alpha F_alpha - int Phi F_N* + int Phi S; also returns the boundary power (W)."""
        R, power = self.surface_residual(grid_state, time, dt)
        self.volume_flux(grid_state, out=R)
        if self.body_force is not None:          # int Phi rho0 b, the particles as quadrature
            R += self.map.S.T @ (self.particles.volume[:, None] * self.source(self.particles, time))
        return R, power

    def advance(self, grid_state, time, dt):
        """(f) forward Euler [R18 eq 20] or Heun's RK2, both stages on the grid."""
        inv_M = 1.0 / self.ops.lumped[:, None]
        # Euler takes boundary values at mid-step (the step's mean for a ramp; a release at
        # t_u = n dt is not missed through round-off in t); Heun at its stage times
        R, power = self.residual(grid_state, time + (0.5 * dt if self.integrator == "euler" else 0.0), dt)
        U1 = grid_state.U + dt * inv_M * R
        if self.integrator == "euler":
            return U1, dt * power
        R2, power2 = self.residual(self.nodal_state(U1), time + dt, dt)
        return 0.5 * (grid_state.U + U1 + dt * inv_M * R2), 0.5 * dt * (power + power2)

    def nodal_state(self, U):
        """Q at the nodes from U at the nodes (the law evaluated at nodes, RK2 second stage)."""
        d = self.d
        F, p = system.split(U, d)
        P = self.materials.stress(F, self.cell_material[self.dof_cell])
        return GridState(U, system.primitive(P, p, self.map.rho))

    def back_map(self, U_nodes):
        """(g) U_p = sum_i S_ip U_i [R18 eq 40] (PIC)."""
        return self.map.interpolate(U_nodes)

    # ---------------------------------------------------------------- driver-facing
    def step(self, state, dt_max=np.inf):
        grid_state = self.project(state)

        def attempt(dt):
            U_nodes, work = self.advance(grid_state, state.t, dt)
            return self.constitutive_update(state, self.back_map(U_nodes), dt), work

        return self.step_with_cfl_guard(state, dt_max, attempt)
