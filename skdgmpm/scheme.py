"""What every Godunov-type scheme of skdgmpm shares: states, the boundary faces and their
conditions, stability checks, energy and the CFL-guarded step.

A scheme provides its face passes, its volume term and its time integration; every face pass
calls the same point functions (`skdgmpm.equations`: the Riemann solver, `skdgmpm.bcs`: the
ghost states), from the cells' records (first-order DGMPM) or the traces at the facet points
(DGFEM, ADER).
"""
import functools
import operator
from time import perf_counter
from dataclasses import dataclass

import numpy as np

from . import system
from .bcs import FREE, BoundaryGhosts
from .errors import InputError, InstabilityError
from .faces import boundary_faces
from .health import assess, with_momenta


@dataclass
class ParticleState:
    """What the particles carry at time ``t``: U = [F, p], Q = [P, v], current positions x and
    the internal variables of the laws (n, n_history), zero width for hyperelastic laws."""

    t: float
    U: np.ndarray          # (n, d*d + d)
    Q: np.ndarray          # (n, d*d + d)
    x: np.ndarray          # (n, d)
    step: int = 0
    speed: np.ndarray = None   # (n,) fastest wave speed along the grid axes
    dofs: np.ndarray = None    # (n_dofs, d*d + d) grid unknowns of schemes that keep them (DGFEM)
    health: dict = None        # {"min_J", "min_acoustic"} over the points, set by the check
    history: np.ndarray = None  # (n, n_history) internal variables, committed once per step
    fastest: float = None      # max of speed, from the check's pass (the time step's)

    def copy(self):
        return ParticleState(self.t, self.U.copy(), self.Q.copy(), self.x.copy(), self.step, self.speed,
                             None if self.dofs is None else self.dofs.copy(), self.health,
                             None if self.history is None else self.history.copy(), self.fastest)


@dataclass
class GridState:
    """Nodal U and Q (n_dofs, d*d + d)."""

    U: np.ndarray
    Q: np.ndarray


def cell_values(name, cells, values, n_cells):
    """One value per cell from per-particle values; error if a cell mixes them."""
    out = np.full(n_cells, -1, dtype=values.dtype)
    out[cells] = values
    if np.any(out[cells] != values):
        raise InputError(f"particles: a cell holds particles of different {name}")
    return out


def stage(method):
    """A named stage of a step (the scheme's ``stages`` lists them in the order they run): each
    call's wall time, less that of the stages it calls, is added to the scheme's clock
    (`GodunovScheme.stage_times`), so that the stages' times add up to the step's. ``@stage`` takes
    the method's name, ``@stage("name")`` another."""
    if isinstance(method, str):
        return lambda m: _timed(m, method)
    return _timed(method, method.__name__)


def _timed(method, name):
    @functools.wraps(method)
    def timed(self, *args, **kwargs):
        clock = self.__dict__.get("_stage_clock")
        if clock is None:               # made once, not at every call (a step makes nine)
            clock = self.__dict__["_stage_clock"] = {"seconds": {}, "calls": {}, "inner": [0.0]}
        inner, seconds, calls = clock["inner"], clock["seconds"], clock["calls"]
        inner.append(0.0)
        t0 = perf_counter()
        try:
            return method(self, *args, **kwargs)
        finally:
            spent = perf_counter() - t0
            within = inner.pop()
            inner[-1] += spent
            seconds[name] = seconds.get(name, 0.0) + spent - within
            calls[name] = calls.get(name, 0) + 1

    timed.stage = name
    return timed


DT_WINDOW = 16                  # steps whose speed-ups and CFL steps set a predicted step (`step_with_cfl_guard`)


def predicted_growth(growths):
    """The speed-up of the fastest wave to expect over the next step, from those of the last
    steps (c_(k+1) / c_k, oldest first): the last one plus the largest rise of the speed-up from
    one step to the next among them, within [1, 2]. A wave that speeds up smoothly is foreseen;
    one whose speed-up grows, within the largest surprise seen lately."""
    if not growths:
        return 1.0
    rise = max(map(operator.sub, growths[1:], growths), default=0.0)
    return min(2.0, max(1.0, growths[-1] + max(0.0, rise)))


class GodunovScheme:
    """Base of the steppers: needs ``d``, ``materials``, ``bcs``, ``cell_material``,
    ``particles`` (the points carrying the state), ``interior``, ``n_dofs``, ``cfl`` and
    ``h_min``."""

    face_options = {}
    external_work = 0.0
    dt_growth = ()               # the fastest wave's speed-ups of the last DT_WINDOW steps (`step_with_cfl_guard`)
    dt_recent = ()               # the CFL steps of the last DT_WINDOW states (`step_with_cfl_guard`)
    cfl_guard = "predict"        # or "largest" (method.cfl_guard)
    body_force = None            # b(X, t) -> (n, d) in m/s^2 (a manufactured solution's); None: no source
    stages = ()                  # the `stage` methods of a step, in the order they run
    # the initial state's law pass, the step's own, so that t = 0 compiles no kernel of its own:
    # "law" (`constitutive_update`'s, `at_rest`) or "stress and health" (MPM's stress pass)
    initial_pass = "law"

    def stage_times(self, reset=False):
        """{stage: (seconds, calls)} since the start (or the last reset), in the order of
        ``stages``: each stage's own time, without the stages it calls."""
        clock = self.__dict__.get("_stage_clock", {"seconds": {}, "calls": {}})
        times = {name: (clock["seconds"][name], clock["calls"][name]) for name in self.stages
                 if name in clock["seconds"]}
        if reset:
            self.__dict__.pop("_stage_clock", None)
        return times

    @stage
    def source(self, points, time):
        """Point values of the source [0, rho0 b(X, t)] of ``dU/dt + DIV F = S`` at ``points``
        (anything with ``X`` (n, d) and ``rho0`` (n,)): (n, d*d + d), zero in the F rows. Each
        scheme integrates it against Phi with its own quadrature."""
        d = self.d
        S = np.zeros((len(points.X), system.n_components(d)))
        S[:, d * d:] = points.rho0[:, None] * self.body_force(points.X, time)
        return S

    def _setup_boundary(self, element):
        m = self.grid.submesh
        facets = m.boundary_facets()
        which = np.full(m.nfacets, -1)
        for k, (name, _) in enumerate(self.bcs):
            if name not in m.boundaries:
                raise InputError(f"boundary.{name}: no boundary of that name in the grid "
                                 f"(known: {', '.join(sorted(m.boundaries))})")
            which[m.boundaries[name]] = k
        self.boundary = boundary_faces(m, element, facets, self.n_dofs, **self.face_options)
        self.boundary_bc = which[self.boundary.facets]
        # boundary faces grouped by condition, once (faces without one are free)
        conditions = [FREE] + [bc for _, bc in self.bcs]
        self.bc_groups = [(self.boundary_bc == k, conditions[k + 1]) for k in range(-1, len(self.bcs))]
        self.bc_groups = [(sel, bc) for sel, bc in self.bc_groups if sel.any()]
        self.ghosts = BoundaryGhosts(self.bc_groups, self.boundary.normal)

    @stage
    def time_step(self, state, dt_max=np.inf):
        """Delta t = CFL h_min / (k c_max) from the current fastest wave [R18 §5(b), L23 eq 67]."""
        fastest = state.speed.max() if state.fastest is None else state.fastest
        return min(self.cfl * self.h_min / (self.speed_factor * fastest), dt_max)

    speed_factor = 1.0

    @stage
    def constitutive_update(self, state, U, dt, gather=None, records=None):
        """(h) P_p = P(F_p, history_p), v_p = p_p / rho0_p [R18 eq 41-42], the internal variables
        updated at the points from those of t_n (committed with the returned state); positions
        by the trapezoidal rule (second order, so displacement errors measure the scheme, not
        the position update). ``gather`` = (A, nodal): U is filled with A @ nodal in the same
        pass (DGMPM's back map); ``records``: the points' face records written in it too
        (`MaterialSet.update_and_assess`)."""
        d = self.d
        Q, history, health, x = self.materials.update_and_assess(U, self.particles.material, self.particles.rho0,
                                                                 state.history, (state.x, state.Q[:, d * d:], dt),
                                                                 gather, records, points=False)
        new = ParticleState(state.t + dt, U, Q, x, state.step + 1, history=history)
        self.check(new, health)
        return new

    def initial_state(self, F, v, t=0.0):
        """ParticleState from particle F (n, d, d) and v (n, d), the laws' internal variables in
        their virgin state."""
        points, d = self.particles, self.d
        history = self.materials.initial_history(points.material)
        U = system.join(F, points.rho0[:, None] * v)
        state = ParticleState(t, U, None, points.X.copy(), history=history)
        if self.initial_pass == "law":          # the step's `constitutive_update` pass (ADER-DGMPM, DGMPM)
            state.Q, state.history, health = self.at_rest(state, points)
            state.Q[:, d * d:] = v              # v as given, not p / rho0 recomputed
        else:                                   # "stress and health": MPM's step pass
            P, state.history, health = self.materials.stress_update(F, points.material, history, assess=True)
            state.Q = system.join(P, v)
            health = with_momenta(health, U[:, d * d:], np.asarray(v, dtype=float))
        self.check(state, health)
        return state

    def at_rest(self, state, points, gather=None, records=None, into=None):
        """(Q, history updated, `Health`) of the state's U at ``points`` from the law's pass of
        `constitutive_update` (`MaterialSet.update_and_assess`, with its ``gather`` and
        ``records``; a gathered U written into ``into``, default the state's U), its arguments
        typed as that pass types them: an initial state that compiles no kernel of its own. No
        motion: Delta t = 0, the old velocities a column view (U's momenta: read only into
        positions that are not kept)."""
        no_motion = (state.x, state.U[:, self.d * self.d:], 0.0)
        U = state.U if into is None else into
        Q, history, health, _ = self.materials.update_and_assess(U, points.material, points.rho0,
                                                                 state.history, no_motion, gather, records)
        return Q, history, health

    def step_with_cfl_guard(self, state, dt_max, attempt):
        """Run ``attempt(dt) -> (new state, boundary work)``; repeat with a smaller Delta t if the
        waves of the new state are faster than the CFL condition allowed (e.g. the first step of
        an impact on a stiffening law). With ``cfl_guard = "predict"`` the first attempt takes the
        state's CFL step divided by the speed-up `predicted_growth` expects from those of the
        last DT_WINDOW steps (``dt_growth``; 1 while the waves do not speed up), and no more than
        the CFL step of any of the last DT_WINDOW states (``dt_recent``): the fastest wave of an
        impact jitters by about 1 % from step to step, and a repeat costs a whole step
        (docs/results.md: the CFL guard). ``"largest"`` always starts from the state's CFL step."""
        dt_cfl = self.time_step(state)
        if self.cfl_guard == "predict":
            dt = min(dt_cfl / predicted_growth(self.dt_growth), *self.dt_recent, dt_max)
        else:
            dt = min(dt_cfl, dt_max)
        for _ in range(4):
            new = None          # a refused attempt's state is not held through the next attempt
            new, work = attempt(dt)
            dt_new = self.time_step(new)
            if dt <= dt_new * (1 + 1e-9):
                break
            dt = dt_new
        growth = dt_cfl / dt_new if 0 < dt_new < np.inf and dt_cfl < np.inf else 1.0
        self.dt_growth = (*self.dt_growth, growth)[-DT_WINDOW:]
        self.dt_recent = (*self.dt_recent, dt_new)[-DT_WINDOW:]
        self.external_work += work
        return new

    @stage
    def check(self, state, health=None):
        """Stop on non-finite values, J <= 0 or lost hyperbolicity, naming the step, time, point,
        cell, quantity and value (`skdgmpm.health`); sets the wave speeds of ``state`` used by the
        next time step and its ``health`` record (min J, smallest acoustic eigenvalue). ``health``:
        the state's, if the law's pass computed it (`MaterialSet.update_and_assess`)."""
        if health is None or (not health.kept and health.summary[0] >= 0):
            # none, or a bad point of a pass that kept its summary only: the state assessed whole
            # names it (the pass's numbers and summary, bit for bit)
            health = assess(self.materials, self.particles, state.U, state.Q)
        state.speed, state.fastest, state.health = health.speed, health.fastest, health.record()
        failure = health.first_failure(state, self.particles, self.d)
        if failure is not None:
            p, message = failure
            raise InstabilityError(message, step=state.step, time=state.t, particle=p)

    def energy(self, state):
        """Kinetic, stored (recoverable) and dissipated (plastic work) energy (J per unit
        thickness in 2D, per unit area in 1D)."""
        F, _ = system.split(state.U, self.d)
        index, volume = self.particles.material, self.particles.volume
        kinetic = np.sum(system.kinetic_density(state.U, 0.5 * volume / self.particles.rho0))
        stored = np.sum(volume * self.materials.energy(F, index, state.history))
        dissipated = np.sum(volume * self.materials.dissipation(index, state.history)) if self.materials.n_history else 0.0
        return kinetic, stored, dissipated

    @property
    def n_dofs_total(self):
        return self.n_dofs * system.n_components(self.d)
