"""First-order DGMPM [R18 §5]: Q1 broken grid, particles as quadrature, Godunov fluxes.

One step is the list of named stages of R18 §5 (a)-(h):

    project -> time_step -> volume_flux -> boundary_flux -> interface_flux -> transverse_flux
    -> advance -> back_map -> constitutive_update

``advance`` is forward Euler [R18 eq 20] or Heun's RK2 with both stages on the grid [R18 §7.1]
(the second stage evaluates the law at the grid nodes). ``transverse_flux`` adds the CTU
corrections of R18 §4.4 in 2D (``transverse="ctu"``); DCU leaves it out.
"""
from dataclasses import dataclass, field

import numpy as np

from . import system
from .bcs import FREE
from .errors import InputError, InstabilityError
from .faces import boundary_faces, interior_faces
from .quadrature import ParticleMap, VolumeOperators, interpolation_matrix, particle_basis
from .riemann import godunov_state, impedance, transverse_positive


@dataclass
class ParticleState:
    """What the particles carry at time ``t``: U = [F, p], Q = [P, v], current positions x."""

    t: float
    U: np.ndarray          # (n, d*d + d)
    Q: np.ndarray          # (n, d*d + d)
    x: np.ndarray          # (n, d)
    step: int = 0
    speed: np.ndarray = None   # (n,) fastest wave speed along the grid axes

    def copy(self):
        return ParticleState(self.t, self.U.copy(), self.Q.copy(), self.x.copy(), self.step, self.speed)


@dataclass
class GridState:
    """Nodal U and Q (n_dofs, d*d + d)."""

    U: np.ndarray
    Q: np.ndarray


@dataclass
class FaceStates:
    """Side-averaged states and linearisation on a face set (one side or both)."""

    t_L: np.ndarray
    v_L: np.ndarray
    C_L: np.ndarray
    rho_L: np.ndarray
    Z_L: np.ndarray
    flux: np.ndarray = None          # F_N* (nf, ncomp)
    fluct_L: np.ndarray = None       # A- dU entering side L (nf, ncomp)
    fluct_R: np.ndarray = None       # A+ dU entering side R


def _cell_values(name, cells, values, n_cells):
    """One value per cell from per-particle values; error if a cell mixes them."""
    out = np.full(n_cells, -1, dtype=values.dtype)
    out[cells] = values
    if np.any(out[cells] != values):
        raise InputError(f"particles: a cell holds particles of different {name}")
    return out


@dataclass
class DGMPM:
    """First-order DGMPM stepper on a `Grid` with `Particles`.

    Parameters
    ----------
    grid, particles : the discretisation (``particles.cell`` indexes ``grid.submesh``)
    materials : MaterialSet
    bcs : list of (boundary name, BoundaryCondition); later entries override earlier ones on
        shared faces; boundary faces with no condition are free (zero traction).
    cfl : Courant number; integrator : "euler" | "rk2"; transverse : "dcu" | "ctu" (2D)
    """

    grid: object
    particles: object
    materials: object
    bcs: list
    cfl: float = 1.0
    integrator: str = "euler"
    transverse: str = "dcu"
    stages: tuple = ("project", "time_step", "volume_flux", "boundary_flux", "interface_flux",
                     "transverse_flux", "advance", "back_map", "constitutive_update")
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
        self.cell_material = _cell_values("materials", p.cell, p.material, n_cells)
        self.cell_volume = g.cell_volumes()
        self.h_min = float(g.cell_sizes().min())
        self.interior = interior_faces(g.submesh, g.element)
        self._setup_boundary()
        self._setup_transverse()

    # ---------------------------------------------------------------- set-up
    def _setup_boundary(self):
        m = self.grid.submesh
        facets = m.boundary_facets()
        which = np.full(m.nfacets, -1)
        for k, (name, _) in enumerate(self.bcs):
            if name not in m.boundaries:
                raise InputError(f"boundary.{name}: no boundary of that name in the grid "
                                 f"(known: {', '.join(sorted(m.boundaries))})")
            which[m.boundaries[name]] = k
        self.boundary = boundary_faces(m, self.grid.element, facets, self.n_dofs)
        self.boundary_bc = which[self.boundary.facets]

    def _setup_transverse(self):
        """CTU topology: for each face and side, the source cell's two edges adjacent to the face,
        with their outward normals and their index among interior or boundary faces."""
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
                edges = []
                for shift in (1, 3):
                    j = m.t2f[(k + shift) % 4, cells]
                    j_int, j_bnd = pos_int[j], pos_bnd[j]
                    sign = np.where(self.interior.cell_L[j_int] == cells, 1.0, -1.0)
                    n = np.where((j_int >= 0)[:, None], sign[:, None] * self.interior.normal[j_int],
                                 self.boundary.normal[j_bnd])
                    edges.append((j_int, j_bnd, sign, n))
                h = self.cell_volume[cells] / faces.measure
                self.ctu.append((kind, side, h, edges))
        frame = np.zeros((len(self.boundary), 2, 2))
        free_v = np.zeros((len(self.boundary), 2), bool)
        free_t = np.zeros((len(self.boundary), 2), bool)
        for k, bc in [(-1, FREE)] + [(k, bc) for k, (_, bc) in enumerate(self.bcs)]:
            sel = self.boundary_bc == k
            if sel.any():
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

    def time_step(self, state, dt_max=np.inf):
        """(b) Delta t = CFL h_min / c_max from the current fastest wave [R18 §5(b)]."""
        return min(self.cfl * self.h_min / state.speed.max(), dt_max)

    def volume_flux(self, grid_state):
        """(c) sum_alpha K^alpha F_alpha(Q)."""
        return system.volume_flux(grid_state.Q, self.ops.stiffness)

    def _side(self, faces, T, grid_state, cells):
        d = self.d
        Qf = T @ grid_state.Q
        Ff = (T @ grid_state.U)[:, : d * d].reshape(-1, d, d)
        P, v = system.split(Qf, d)
        C = self.materials.tangent(Ff, self.cell_material[cells])
        rho = T @ self.map.rho
        t = np.einsum("fia,fa->fi", P, faces.normal)
        return t, v, C, rho, Qf

    def boundary_flux(self, grid_state, time):
        """(d) ghost states -> boundary stationary states and fluxes; returns states and power."""
        b = self.boundary
        t_L, v_L, C, rho, Q_L = self._side(b, b.T_L, grid_state, b.cell_L)
        Z = impedance(C, b.normal, rho)
        t_s, v_s = t_L.copy(), v_L.copy()
        for k, (_, bc) in [(-1, (None, None))] + list(enumerate(self.bcs)):
            sel = self.boundary_bc == k
            if not sel.any():
                continue
            t_s[sel], v_s[sel] = (bc or FREE).star(time, t_L[sel], v_L[sel], Z[sel], b.normal[sel])
        flux = system.normal_flux(t_s, v_s, b.normal)
        fs = FaceStates(t_L, v_L, C, rho, Z, flux,
                        fluct_L=flux - system.normal_flux(t_L, v_L, b.normal))
        power = float(np.sum(b.measure * np.einsum("fi,fi->f", t_s, v_s)))
        return fs, power

    def interface_flux(self, grid_state):
        """(e) Godunov fluxes at interior faces from the linearised Riemann solver."""
        f = self.interior
        t_L, v_L, C_L, rho_L, _ = self._side(f, f.T_L, grid_state, f.cell_L)
        t_R, v_R, C_R, rho_R, _ = self._side(f, f.T_R, grid_state, f.cell_R)
        Z_L, Z_R = impedance(C_L, f.normal, rho_L), impedance(C_R, f.normal, rho_R)
        t_s, v_s = godunov_state(t_L, v_L, t_R, v_R, Z_L, Z_R)
        flux = system.normal_flux(t_s, v_s, f.normal)
        fs = FaceStates(t_L, v_L, C_L, rho_L, Z_L, flux,
                        fluct_L=flux - system.normal_flux(t_L, v_L, f.normal),
                        fluct_R=system.normal_flux(t_R, v_R, f.normal) - flux)
        fs.C_R, fs.rho_R = C_R, rho_R
        return fs

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
        d = self.d
        for kind, side, h, edges in self.ctu:
            fs = interior if kind == "interior" else boundary
            w = fs.fluct_L if side == "L" else fs.fluct_R
            C = fs.C_L if side == "L" else fs.C_R
            rho = fs.rho_L if side == "L" else fs.rho_R
            w_F, w_p = system.split(w, d)
            G = [-(dt / (2.0 * h))[:, None] * system.join(*transverse_positive(w_F, w_p, C, n, rho))
                 for _, _, _, n in edges]
            for e, (j_int, j_bnd, sign, _) in enumerate(edges):
                ok = j_int >= 0
                np.add.at(corr_int, j_int[ok], sign[ok, None] * G[e][ok])
                ok = j_bnd >= 0
                np.add.at(corr_bnd, j_bnd[ok], (G[e] - G[1 - e])[ok])
        return corr_int, self._free_part(corr_bnd)

    def _free_part(self, flux):
        """Keep the components of a boundary flux correction that the condition leaves free."""
        frame, free_v, free_t = self.ctu_boundary
        F, p = system.split(flux, self.d)
        dv = np.einsum("fkj,fja,fa->fk", frame, F, self.boundary.normal) * free_v
        dt_ = np.einsum("fkj,fj->fk", frame, p) * free_t
        return system.join(np.einsum("fkj,fk->fj", frame, dv)[:, :, None] * self.boundary.normal[:, None, :],
                           np.einsum("fkj,fk->fj", frame, dt_))

    def residual(self, grid_state, time, dt):
        """M dU/dt = K^alpha F_alpha - int Phi F_N*; also returns the boundary power (W)."""
        R = self.volume_flux(grid_state)
        boundary, power = self.boundary_flux(grid_state, time)
        interior = self.interface_flux(grid_state)
        corr_int, corr_bnd = self.transverse_flux(interior, boundary, dt)
        flux = interior.flux + corr_int
        R -= self.interior.integrate(flux, "L")
        R += self.interior.integrate(flux, "R")
        R -= self.boundary.integrate(boundary.flux + corr_bnd, "L")
        if self.ctu is not None:                   # work of the corrected boundary flux
            F, p = system.split(boundary.flux + corr_bnd, self.d)
            v = -np.einsum("fia,fa->fi", F, self.boundary.normal)
            power = float(np.sum(self.boundary.measure * np.einsum("fi,fi->f", -p, v)))
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
        return GridState(U, system.join(P, p / self.map.rho[:, None]))

    def back_map(self, U_nodes):
        """(g) U_p = sum_i S_ip U_i [R18 eq 40] (PIC)."""
        return self.map.interpolate(U_nodes)

    def constitutive_update(self, state, U, dt):
        """(h) P_p = P(F_p), v_p = p_p / rho0_p, positions x += dt v [R18 eq 41-42]."""
        d = self.d
        F, p = system.split(U, d)
        v = p / self.particles.rho0[:, None]
        P = self.materials.stress(F, self.particles.material)
        new = ParticleState(state.t + dt, U, system.join(P, v), state.x + dt * v, state.step + 1)
        self.check(new)
        return new

    # ---------------------------------------------------------------- driver-facing
    def initial_state(self, F, v, t=0.0):
        """ParticleState from particle F (n, d, d) and v (n, d)."""
        P = self.materials.stress(F, self.particles.material)
        U = system.join(F, self.particles.rho0[:, None] * v)
        state = ParticleState(t, U, system.join(P, v), self.particles.X.copy())
        self.check(state)
        return state

    def step(self, state, dt_max=np.inf):
        """One step; repeated with a smaller Delta t if the waves of the new state are faster
        than the CFL condition allowed (e.g. the first step of an impact on a stiffening law)."""
        grid_state = self.project(state)
        dt = self.time_step(state, dt_max)
        for _ in range(4):
            U_nodes, work = self.advance(grid_state, state.t, dt)
            new = self.constitutive_update(state, self.back_map(U_nodes), dt)
            dt_new = self.cfl * self.h_min / new.speed.max()
            if dt <= dt_new * (1 + 1e-9):
                break
            dt = dt_new
        self.external_work += work
        return new

    def check(self, state):
        """Stop on non-finite values or lost hyperbolicity, naming the particle; sets the wave
        speeds of ``state`` used by the next time step."""
        finite = np.all(np.isfinite(state.U), axis=1) & np.all(np.isfinite(state.Q), axis=1)
        F, _ = system.split(state.U, self.d)
        state.speed, hyperbolic = self.materials.max_speed(
            np.where(finite[:, None, None], F, np.eye(self.d)), self.particles.material)
        bad = ~finite | ~hyperbolic
        if bad.any():
            p = int(np.flatnonzero(bad)[0])
            if not finite[p]:
                what = "non-finite values"
            elif np.linalg.det(F[p]) <= 0:
                what = "inverted material (det F <= 0)"
            else:
                what = "loss of hyperbolicity"
            raise InstabilityError(
                f"{what} at step {state.step}, t = {state.t:.6g} s, particle {p} "
                f"(X = {np.round(self.particles.X[p], 6).tolist()})",
                step=state.step, time=state.t, particle=p)

    def energy(self, state):
        """Kinetic and stored energy (J per unit thickness in 2D, per unit area in 1D)."""
        F, p = system.split(state.U, self.d)
        v = p / self.particles.rho0[:, None]
        kinetic = 0.5 * np.sum(self.particles.mass * np.sum(v * v, axis=1))
        stored = np.sum(self.particles.volume * self.materials.energy(F, self.particles.material))
        return kinetic, stored

    @property
    def n_dofs_total(self):
        return self.n_dofs * system.n_components(self.d)
