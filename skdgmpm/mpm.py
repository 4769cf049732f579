"""Updated-Lagrangian MPM / GIMP [WG08], the baseline DGMPM is compared with [R18 §7.1].

Particles carry mass m_p = rho0 V0_p, F, P and v and move through the whole background grid
(WG08). One step is a short list of named stages; an update variant is the order of those
stages (cb-geo style):

    shape_functions -> project -> impose_velocity -> [strain_stress (USF)] -> grid_forces
    -> grid_update -> particle_update -> [reproject -> impose_velocity (UVF)] -> [strain_stress]

* USF: stress from the projected velocity before the momentum update;
* USL: stress from the updated grid velocity after it;
* CD: USL with velocities at half steps (the first step's grid acceleration is halved);
* UVF: CD with the updated particle velocities projected again before the strain update.

Boundary conditions: imposed velocity components fix the grid's boundary nodes (velocity and
acceleration); tractions are carried by the particles next to the loaded facets, so the load
follows the material as it moves away from the grid's edge. A particle leaving the grid stops the
run (InstabilityError naming it).

The state is the `ParticleState` of the Godunov schemes (U = [F, rho0 v], Q = [P, v], x), so the
checks, energy, outputs and run driver are shared.
"""
from dataclasses import dataclass, field

import numpy as np
from numba import njit

from . import parallel, system
from .bcs import Mixed, NormalVelocity, Transmissive
from .errors import InputError
from .gimp import SHAPES, Lattice, half_lengths, shape_functions
from .health import with_momenta
from .kernel_cache import kernel_factory, scratch
from .scheme import GodunovScheme, ParticleState, stage


@dataclass(frozen=True)
class Update:
    """An MPM update variant: named stages in order; ``half_first_step`` starts the centred
    difference (v^{1/2} = v^0 + dt/2 a^0)."""

    name: str
    stages: tuple
    half_first_step: bool = False


_START = ("shape_functions", "project", "impose_velocity")
_MOMENTUM = ("grid_forces", "grid_update", "particle_update")
USF = Update("usf", _START + ("strain_stress",) + _MOMENTUM)
USL = Update("usl", _START + _MOMENTUM + ("strain_stress",))
CD = Update("cd", USL.stages, half_first_step=True)
UVF = Update("uvf", _START + _MOMENTUM + ("reproject", "impose_velocity", "strain_stress"), half_first_step=True)
UPDATES = {u.name: u for u in (USF, USL, CD, UVF)}


@dataclass
class StepData:
    """What the stages of one step read and write: particle arrays (n, ...) and nodal arrays
    (n_nodes, ...)."""

    t: float
    dt: float
    step: int
    F: np.ndarray                  # (n, d, d)
    P: np.ndarray                  # (n, d, d)
    v: np.ndarray                  # (n, d) particle velocities
    x: np.ndarray                  # (n, d) current positions
    history: np.ndarray            # (n, n_history) the laws' internal variables, updated with the stress
    shape: object = None           # ShapeFunctions
    mass: np.ndarray = None        # (n_nodes,)
    filled: np.ndarray = None      # (n_nodes,) bool, nodes with mass
    v_grid: np.ndarray = None      # (n_nodes, d) the grid velocity of the latest stage
    force: np.ndarray = None       # (n_nodes, d) internal + external
    external: np.ndarray = None    # (n_nodes, d) external only
    a: np.ndarray = None           # (n_nodes, d)
    work: float = 0.0              # work of the external forces on the free components in the step (J)
    work_constraints: float = 0.0  # work of the imposed velocities in the step (J), from strain_stress
    health: object = None          # Health of F and P at the new state, from strain_stress


@dataclass
class MPM(GodunovScheme):
    """Explicit MPM / GIMP stepper on the whole background grid.

    Parameters
    ----------
    grid : Grid (``grid.mesh`` is the background; uniform and axis-aligned)
    particles : Particles; materials : MaterialSet
    bcs : list of (boundary name of ``grid.mesh``, BoundaryCondition); later entries override
        earlier ones on shared facets. Imposed velocities act on the grid's boundary nodes,
        tractions on the particles next to the loaded facets; transmissive is not supported.
    cfl : Courant number, dt = cfl h_min / max_p(c_p + |v_p|) (``time_step="current"``) or the fixed
        dt = cfl h_min / max sqrt(E / rho0) of WG08 (``time_step="bar"``: the bar wave speed of the
        undeformed material, so the step does not shrink where a stiffening law is compressed)
    update : "usf" | "usl" | "cd" | "uvf"; shape : "hat" | "ugimp" | "cpgimp"
    geometry : "updated" (the particles move over the grid: MPM as usual) or "linearised" (small
        displacements: the particles stay at their reference positions, so the shape functions
        never change, as in R18 §7.1's "linearized geometrical framework"; with one particle per
        cell and hat functions, the updated geometry makes every particle of a uniformly moving
        zone cross a node at once, and USL blows up there, see docs/results.md)
    body_force : None or callable b(X, t) -> (n, d) (m/s^2) at reference positions
    """

    initial_pass = "stress and health"      # `stress_update` with the health: the step's pass

    grid: object
    particles: object
    materials: object
    bcs: list
    cfl: float = 0.5
    update: str = "usl"
    shape: str = "cpgimp"
    body_force: object = None
    time_step_rule: str = "current"
    geometry: str = "updated"
    external_work: float = field(default=0.0, init=False)

    def __post_init__(self):
        if self.update not in UPDATES:
            raise InputError(f"method.update = {self.update!r}: expected one of {', '.join(UPDATES)}")
        if self.shape not in SHAPES:
            raise InputError(f"method.shape = {self.shape!r}: expected one of {', '.join(SHAPES)}")
        if self.time_step_rule not in ("current", "bar"):
            raise InputError(f"method.time_step = {self.time_step_rule!r}: expected 'current' or 'bar'")
        if self.geometry not in ("updated", "linearised"):
            raise InputError(f"method.geometry = {self.geometry!r}: expected 'updated' (particles move over the "
                             "grid) or 'linearised' (they stay at their reference positions: small displacements)")
        self.variant = UPDATES[self.update]
        self.d = self.grid.dim
        self.lattice = Lattice.from_mesh(self.grid.mesh)
        self.h_min = float(self.lattice.h.min())
        # half the initial particle spacing per axis: (V_p / V_cell)^(1/d) of a cell's side
        ratio = self.particles.volume / np.prod(self.lattice.h)
        self.l0 = 0.5 * ratio[:, None] ** (1.0 / self.d) * self.lattice.h[None, :]
        self._setup_grid_conditions()

    # the report names used by run.summary
    @property
    def integrator(self):
        return self.update

    @property
    def transverse(self):
        return self.shape

    @property
    def n_dofs_total(self):
        return self.lattice.n_nodes * self.d

    # ---------------------------------------------------------------- set-up
    def _setup_grid_conditions(self):
        """Imposed velocities on the grid's boundary nodes, tractions on the particles next to the
        loaded facets; a shared facet belongs to the later condition.

        Tractions are nominal (per reference area, t = P N as for the Godunov schemes). They are
        carried by the particles, not lumped on the edge nodes: the material moves away from a
        fixed grid edge, whose nodes then hold a vanishing mass (in the elastic bar the edge-node
        load pumped 16 times the true work into the bar once the end had moved by one cell).
        """
        mesh, d = self.grid.mesh, self.d
        names = mesh.boundaries or {}
        owner = np.full(mesh.nfacets, -1)
        for k, (name, bc) in enumerate(self.bcs):
            if name not in names:
                raise InputError(f"bc.{name}: no boundary of that name in the background grid, where mpm "
                                 f"applies its conditions (known: {', '.join(sorted(names))})")
            if isinstance(bc, Transmissive):
                raise InputError(f"bc.{name}: kind = 'transmissive' is not supported by mpm")
            owner[names[name]] = k
        facets = np.flatnonzero(owner >= 0)
        nodes = mesh.facets[:, facets]                                  # (n_vertices, nf)
        lattice_index = np.rint((mesh.p[:, nodes] - self.lattice.origin[:, None, None])
                                / self.lattice.h[:, None, None])        # (d, n_vertices, nf)
        top = np.array(self.lattice.shape)[:, None, None] - 1
        on_low, on_high = np.all(lattice_index == 0, axis=1), np.all(lattice_index == top, axis=1)
        if not np.all(on_low.any(axis=0) | on_high.any(axis=0)):
            raise InputError("bc: mpm applies conditions on the edges of the background grid only")
        axis = np.argmax(on_low | on_high, axis=0)                      # (nf,) normal axis
        sign = np.where(on_low[axis, np.arange(len(facets))], -1.0, 1.0)
        self.constraints, self.tractions = [], []
        self.constrained = np.zeros((self.lattice.n_nodes, d), bool)      # where reactions act
        for k, (_, bc) in enumerate(self.bcs):
            sel = owner[facets] == k
            if not sel.any():
                continue
            fnodes = nodes[:, sel].ravel()
            if isinstance(bc, NormalVelocity):                          # includes symmetry
                comp = np.broadcast_to(axis[sel], nodes[:, sel].shape).ravel()
                value = np.broadcast_to(bc.value * sign[sel], nodes[:, sel].shape).ravel()
                self.constraints.append((fnodes, comp, value, bc.schedule))
                self.constrained[fnodes, comp] = True
            elif isinstance(bc, Mixed):
                for c, ax in enumerate("xyz"[:d]):
                    if ax in bc.velocity:
                        self.constraints.append((fnodes, np.full(fnodes.shape, c),
                                                 np.full(fnodes.shape, bc.velocity[ax]), bc.schedule))
                        self.constrained[fnodes, c] = True
                t = np.array([bc.traction.get(ax, 0.0) if ax not in bc.velocity else 0.0 for ax in "xyz"[:d]])
                if np.any(t != 0):
                    force = np.zeros((len(self.particles), d))
                    particle, area = self._surface_particles(facets[sel], axis[sel])
                    np.add.at(force, particle, area[:, None] * t[None, :])
                    self.tractions.append((force, bc.schedule))
            else:
                raise InputError(f"bc: condition {type(bc).__name__} is not supported by mpm")
        self.acting = self.constrained.any(axis=1)                      # nodes with an imposed component

    def _surface_particles(self, facets, axis):
        """Particles of the cells next to boundary ``facets`` (nf,) in the layer nearest to each
        facet (normal ``axis`` (nf,)), and their shares of the facet's reference measure."""
        mesh = self.grid.mesh
        cell = self.grid.active[self.particles.cell]                    # cells of the background grid
        order = np.argsort(cell, kind="stable")
        owner_cell = mesh.f2t[0, facets]
        lo = np.searchsorted(cell[order], owner_cell, side="left")
        count = np.searchsorted(cell[order], owner_cell, side="right") - lo
        face = np.repeat(np.arange(len(facets)), count)                 # (facet, particle) pairs
        particle = order[np.repeat(lo - np.cumsum(count) + count, count) + np.arange(count.sum())]
        plane = mesh.p[axis, mesh.facets[0, facets]]
        dist = np.abs(self.particles.X[particle, axis[face]] - plane[face])
        nearest = np.full(len(facets), np.inf)
        np.minimum.at(nearest, face, dist)
        keep = dist <= nearest[face] + 1e-9 * self.h_min
        face, particle = face[keep], particle[keep]
        measure = (np.ones(len(facets)) if self.d == 1 else
                   np.linalg.norm(np.diff(mesh.p[:, mesh.facets[:, facets]], axis=1)[:, 0], axis=0))
        return particle, (measure / np.bincount(face, minlength=len(facets)).clip(1))[face]

    # ---------------------------------------------------------------- stages
    @stage
    def shape_functions(self, s):
        """S_ip, grad S_ip at the current positions (cpGIMP: l_p from the current F)."""
        cp = self.shape == "cpgimp"         # the half-lengths l0 F_ii formed in the pass
        lp = self.l0 if cp else half_lengths(self.shape, self.l0)
        s.shape = shape_functions(self.lattice, s.x, self.shape, lp, step=s.step + 1, time=s.t,
                                  reuse=self.__dict__.pop("_last_shape", None), F=s.F if cp else None)
        self._last_shape = s.shape              # overwritten by the next step's

    @stage
    def project(self, s):
        """m_i = sum_p S_ip m_p, v_i = sum_p S_ip m_p v_p / m_i (zero on empty nodes)."""
        m = self.particles.mass
        s.mass, momentum = s.shape.mass_momentum(m, s.v)
        # every node with mass takes part: grad S ~ sqrt(S) near the edge of a GIMP support, so
        # dropping nodes of small mass drops finite forces (and momentum conservation)
        s.filled = s.mass > 0
        s.v_grid = self._per_mass(s, momentum)

    @stage
    def impose_velocity(self, s):
        """Imposed velocity components on the boundary nodes, at mid-step."""
        t = s.t + 0.5 * s.dt
        for nodes, comp, value, schedule in self.constraints:
            s.v_grid[nodes, comp] = value * schedule(t)

    @stage
    def strain_stress(self, s):
        """L_p = sum_i v_i (x) grad S_ip, F <- (I + dt L) F, P = P(F, history) with the history
        of t_n (the particles' internal variables: once per step in every variant), with the
        new state's health at the law's tangent in the same pass (`check`)."""
        L = self._gradient(s, s.v_grid)
        F_n, P_n = s.F, s.P
        s.F = np.empty_like(F_n)
        kernel = _deformation_update(self.d)
        parallel.chunked(len(F_n), kernel, "rrwr", (F_n, L, s.dt, s.F))
        s.P, s.history, s.health = self.materials.stress_update(s.F, self.particles.material, s.history, assess=True)
        s.work_constraints = self._constraint_work(s, F_n, P_n)

    def _constraint_work(self, s, F_n, P_n):
        """The work the imposed velocity components do in the step, booked where they act: in the
        strain update. Their part of the velocity gradient, L^C_p = sum_(i,c imposed) v_ic e_c (x)
        grad S_ip, deforms the particles under the mid-step stress, so the work is
        dt sum_p V0_p (P_n + P_n+1)/2 : L^C_p F_n: the reaction at mid-step times the imposed
        velocity (for a law whose energy is quadratic in F, exactly the stored energy that part of
        the update adds). The reaction of the forces at t_n (-f_int(sigma_n) on the nodes), booked
        before, lags half a step in USL/CD (the first step's strain energy came with no work) and
        leads half a step in USF (docs/results.md). Only a particle with a constrained node has
        L^C != 0: the others' power is 0 without the gradient (the same bits)."""
        if not self.constraints:
            return 0.0
        v_imposed = np.where(self.constrained, s.v_grid, 0.0)
        power = np.empty(len(F_n))              # per particle, summed once (any thread count)
        sf, kernel = s.shape, _constraint_power(self.d)
        parallel.chunked(len(F_n), kernel, "iwwwwrrrrr", (sf.indptr, sf.cols, sf.values, v_imposed, self.acting,
                                                           self.particles.volume, P_n, s.P, F_n, power))
        return s.dt * float(np.sum(power))

    @staticmethod
    def _gradient(s, v_grid):
        """L_p = sum_i v_i (x) grad S_ip (n, d, d): one pass over the particles' rows, each entry
        summed in CSR order as `parallel.matmul` sums column a of L (the same bits)."""
        d = s.v.shape[1]
        L = np.empty((len(s.x), d, d))
        sf, kernel = s.shape, _gradient(d)
        parallel.chunked(len(L), kernel, "iwwwr", (sf.indptr, sf.cols, sf.values, v_grid, L))
        return L

    @stage
    def grid_forces(self, s):
        """f_int,i = -sum_p sigma_p grad S_ip V_p (sigma V = P F^T V0), plus sum_p S_ip f_p of the
        body forces and the boundary tractions (at mid-step) carried by the particles."""
        tau = np.empty_like(s.P)                        # sigma V = P F^T V0 (n, d, d)
        kernel = _kirchhoff(self.d)
        parallel.chunked(len(tau), kernel, "rrrr", (s.P, s.F, self.particles.volume, tau))
        s.force = -s.shape.grad_T_sum(tau)
        if self.body_force is None and not self.tractions:
            s.external = np.zeros_like(s.force)
        else:
            carried = np.zeros_like(s.v)               # (n, d) external forces on the particles
            if self.body_force is not None:
                carried += self.particles.mass[:, None] * self.body_force(self.particles.X, s.t)
            for force, schedule in self.tractions:
                carried += schedule(s.t + 0.5 * s.dt) * force
            s.external = s.shape.S_T(carried)
        s.force += s.external

    @stage
    def grid_update(self, s):
        """a_i = f_i / m_i, v_i* = v_i + dt a_i with the imposed components, and the work of the
        external forces and constraint reactions at the mid-step grid velocity."""
        factor = 0.5 if self.variant.half_first_step and s.step == 0 else 1.0
        force = factor * s.force
        v_old = s.v_grid
        s.v_grid = v_old + s.dt * self._per_mass(s, force)
        self.impose_velocity(s)
        s.a = (s.v_grid - v_old) / s.dt
        # the external forces' work on the free components; at imposed ones the reaction takes
        # them up, and the imposed velocities' work is booked in strain_stress
        free = ~self.constrained
        s.work = s.dt * float(np.sum(np.where(free, factor * s.external, 0.0) * 0.5 * (v_old + s.v_grid)))

    @stage
    def particle_update(self, s):
        """v_p += dt sum_i S_ip a_i (FLIP), x_p += dt sum_i S_ip v_i* (not in a linearised geometry)."""
        sf, v, x, moving = s.shape, np.empty(s.v.shape), s.x, self.geometry == "updated"
        if moving:
            x = np.empty(s.x.shape)
        kernel = _particle_update(self.d, int(moving))    # both sums in one pass (matmul's bits, then + dt *)
        parallel.chunked(len(v), kernel, "iwwwwwrrrr",
                         (sf.indptr, sf.cols, sf.values, s.a, s.v_grid, s.dt, s.v, s.x, v, x))
        s.v, s.x = v, x

    @stage
    def reproject(self, s):
        """UVF: the updated particle velocities projected again (same S and m_i)."""
        s.v_grid = self._per_mass(s, s.shape.S_T(s.v, scale=self.particles.mass))

    @staticmethod
    def _per_mass(s, nodal):
        """nodal / m_i on nodes with mass, zero elsewhere (a pass on the threads)."""
        out = np.empty(nodal.shape)
        parallel.chunked(len(out), _per_mass, "rrrr", (nodal, s.mass, s.filled, out))
        return out

    # ---------------------------------------------------------------- driver-facing
    @stage
    def time_step(self, state, dt_max=np.inf):
        """dt = cfl h_min / max_p(c_p + |v_p|): waves and particles cross at most cfl cells; or
        WG08's fixed dt = cfl h_min / sqrt(E / rho0)."""
        if self.time_step_rule == "bar":
            c = max(np.sqrt(m.E / m.rho) for m in self.materials.materials)
            return min(self.cfl * self.h_min / c, dt_max)
        _, v = system.split(state.Q, self.d)
        kernel = _fastest(self.d)
        chunks = parallel.chunked(len(v), kernel, "rr", (state.speed, v), 1)[:, 0].tolist()
        fastest = np.nan if any(c != c for c in chunks) else max(chunks)        # max is exact: any thread count
        return min(self.cfl * self.h_min / fastest, dt_max)

    @property
    def stages(self):
        """The variant's stages in their order, after the time step and before the check."""
        return ("time_step",) + tuple(dict.fromkeys(self.variant.stages)) + ("check",)

    def step(self, state, dt_max=np.inf):
        F, p = system.split(state.U, self.d)
        P, v = system.split(state.Q, self.d)

        # dt from the state at the start of the step (no retry as in the Godunov schemes: with
        # |v| in the bound nearly every step would be taken twice)
        # the stages replace F, P and v, never write into them: views of the state will do
        s = StepData(state.t, self.time_step(state, dt_max), state.step, F, P, v, state.x.copy(), state.history)
        for name in self.variant.stages:
            getattr(self, name)(s)
        new = ParticleState(state.t + s.dt, system.join(s.F, self.particles.rho0[:, None] * s.v),
                            system.join(s.P, s.v), s.x, state.step + 1, history=s.history)
        # the health of F and P came with the stress: the state's where p and v are finite too
        self.check(new, with_momenta(s.health, new.U[:, self.d * self.d:], s.v))
        self.external_work += s.work + s.work_constraints
        return new


@njit(cache=True, nogil=True)
def _per_mass(nodal, mass, filled, out):
    for i in range(len(out)):
        m, has = mass[i], filled[i]     # read once: a store to out could alias them (called from Python)
        for k in range(out.shape[1]):
            out[i, k] = nodal[i, k] / m if has else 0.0


# ---------------------------------------------------------------- per-particle passes (literal d)
@njit(cache=True, inline="always")
def _gradient_row(indptr, cols, values, v, p, u, d):
    """u[c, a] = sum_k dS/dx_a[k] v[cols[k], c] over row p (values: S, then the gradient)."""
    for c in range(d):
        for a in range(d):
            u[c, a] = 0.0
    for k in range(indptr[p], indptr[p + 1]):
        j = cols[k]
        for a in range(d):
            w = values[1 + a, k]
            for c in range(d):
                u[c, a] += w * v[j, c]


@kernel_factory
def _gradient(d):
    def gradient(indptr, cols, values, v, L):
        """L_p = sum_i v_i (x) grad S_ip per particle row (`_gradient_row`)."""
        u = scratch((d, d))
        for p in range(len(indptr) - 1):
            _gradient_row(indptr, cols, values, v, p, u, d)
            for c in range(d):
                for a in range(d):
                    L[p, c, a] = u[c, a]
    return gradient


@kernel_factory
def _particle_update(d, moving):
    def particle_update(indptr, cols, values, a, v_grid, dt, v, x, v_out, x_out):
        """v_out = v + dt (S a), x_out = x + dt (S v_grid) (moving) per particle row of S."""
        ua, ux = scratch((d,)), scratch((d,))
        for p in range(len(indptr) - 1):
            for c in range(d):
                ua[c], ux[c] = 0.0, 0.0
            for k in range(indptr[p], indptr[p + 1]):
                j, w = cols[k], values[0, k]
                for c in range(d):
                    ua[c] += w * a[j, c]
                    if moving:
                        ux[c] += w * v_grid[j, c]
            for c in range(d):
                v_out[p, c] = v[p, c] + dt * ua[c]
                if moving:
                    x_out[p, c] = x[p, c] + dt * ux[c]
    return particle_update


@kernel_factory
def _deformation_update(d):
    def deformation_update(F, L, dt, out):
        """out = F + (dt L) F per particle (the bits of numpy's F + dt * L @ F)."""
        for p in range(len(F)):
            for i in range(d):
                for j in range(d):
                    s = 0.0
                    for k in range(d):
                        s += (dt * L[p, i, k]) * F[p, k, j]
                    out[p, i, j] = F[p, i, j] + s
    return deformation_update


@kernel_factory
def _kirchhoff(d):
    def kirchhoff(P, F, volume, tau):
        """tau = (P F^T) V0 per particle (the bits of einsum("pia,pja->pij", P, F) * V0)."""
        for p in range(len(P)):
            for i in range(d):
                for j in range(d):
                    s = 0.0
                    for a in range(d):
                        s += P[p, i, a] * F[p, j, a]
                    tau[p, i, j] = s * volume[p]
    return kirchhoff


@kernel_factory
def _constraint_power(d):
    def constraint_power(indptr, cols, values, v_imposed, acting, volume, P_n, P, F_n, out):
        """out = V0 (P_n + P)/2 : (LC F_n) per particle, LC = sum_i v_imposed_i (x) grad S_ip
        (`_gradient_row`); 0 for a particle none of whose nodes is ``acting`` (LC = 0: the same
        bits, without the gradient)."""
        LC = scratch((d, d))
        for p in range(len(P)):
            touched = False
            for k in range(indptr[p], indptr[p + 1]):
                if acting[cols[k]]:
                    touched = True
                    break
            if not touched:
                out[p] = 0.0
                continue
            _gradient_row(indptr, cols, values, v_imposed, p, LC, d)
            s = 0.0
            for i in range(d):
                for j in range(d):
                    g = 0.0
                    for k in range(d):
                        g += LC[i, k] * F_n[p, k, j]
                    s += 0.5 * (P_n[p, i, j] + P[p, i, j]) * g
            out[p] = volume[p] * s
    return constraint_power


@kernel_factory
def _fastest(d):
    def fastest(speed, v):
        """max_p (speed_p + |v_p|) (nan if one is nan; -inf for no particle)."""
        out = -np.inf
        for p in range(len(v)):
            s = 0.0
            for i in range(d):
                s += v[p, i] * v[p, i]
            x = speed[p] + np.sqrt(s)
            if x > out or x != x:
                out = x
                if x != x:
                    return x
        return out
    return fastest
