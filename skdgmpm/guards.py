"""Run guards that catch garbage the per-point health checks (`skdgmpm.health`) cannot see.

The per-point checks stop on non-finite values, J <= 0 and lost hyperbolicity. An unstable scheme
can run for a long time before any of those happens, with a stress many times the load; these
guards stop it earlier (exit 3, like the other health stops), or refuse it before it starts:

- **Energy created** (`EnergyGuard`): the energy balance (total energy minus the work of the
  boundaries and body forces) of a stable, consistent scheme stays level or falls (upwind fluxes
  and plastic flow dissipate); its discretisation error is a fraction of the energy actually in
  play. The run stops when the balance has grown by more than ``MARGIN`` = 1 times all the energy
  put in so far, E_avail = E_total(0) + max_t |W(t)|: a run that has created more energy than
  was ever given to it is unstable, whatever its resolution. (The CFL-limit study,
  `skdgmpm.stability_study`, already fails a trial at 0.1 of the energy scale; stable runs of
  every shipped scene stay far below 1.) Below an absolute floor, the energy of a uniform strain
  of about 1e-6 (1e-12 sum_p V_p E_p), round-off of a body nearly at rest is not taken for growth.
  The first step is not checked: MPM books the work of a velocity imposed on a body at rest one
  step late (its external_work is still 0 after a first step that set the body moving), and an
  unstable run is caught from the second step on all the same.
- **Time-step collapse** (`StepGuard`): Delta t below ``COLLAPSE`` = 1/1000 of the first step's
  (the final step, cut to reach t_end, aside) means the fastest wave became 1000 times faster,
  a stiffness 1e6 times the initial: no law of skdgmpm does that in a sound run, and the run
  would never end. Up front, a run whose first Delta t would need more than ``run.step_limit``
  (default 1e7) steps to reach t_end is refused (E = 1e300 or rho = 1e-300 make Delta t ~ 0);
  reaching the limit during the run stops it.
- **CFL above a known stability limit** (`check_cfl`, `cfl_limit`): refused (exit 2) unless the
  scene sets ``method.cfl_above_limit = true``; a scene without ``method.cfl`` takes one below the
  limit (`default_cfl`). Known limits: first-order DGMPM, the von Neumann limit of
  its step (in 2D `skdgmpm.stability2d`'s table for regular layouts, else the layout's 1D limit,
  R18 §6, `skdgmpm.stability`); ADER P = 1-5 (P = 4, 5 at the knee of their slow growth) and
  RK-DGFEM P = 1-3 (RK2: P = 1), that of their 1D or 2D step (the same table); MPM,
  1 (dt = h / (c + |v|)). The DGFEM and ADER steps are already scaled by 1 / (2P + 1), and the
  scene admits CFL <= 2 for them.
"""
import functools
import math
import warnings

import numpy as np

from . import compile_helper
from .errors import InputError, InstabilityError

MARGIN = 1.0
COLLAPSE = 1e-3
STEP_LIMIT = 10_000_000
DEFAULT_SHARE = 0.9     # a scene without method.cfl, where the method's limit is below 1: this share of it


ENERGY_POINTS = 20_000       # above this many points, the energy every 10 steps by default


def energy_every(scene, stepper):
    """Steps between two rows of the energy history (and checks of the energy balance):
    ``run.energy_every``; by default every step, or every 10th on more than ENERGY_POINTS points
    (its cost is a compiled pass over them: 0.5 ms at 256^2, 8 % of a DGMPM DCU step on one
    thread). Frames, checkpoints and the last step always get one."""
    points = len(stepper.particles)
    value = scene.get("run.energy_every", 1 if points <= ENERGY_POINTS else 10)
    if not (isinstance(value, int) and not isinstance(value, bool) and value >= 1):
        raise InputError(f"{scene.where('run.energy_every')} = {value!r} must be a whole number of steps >= 1")
    return value


class EnergyGuard:
    """Stops a run whose energy balance grows by more than MARGIN times the energy put in."""

    def __init__(self, stepper, history):
        p, mats = stepper.particles, stepper.materials.materials
        E = np.array([getattr(m, "E", 0.0) or 0.0 for m in mats])[np.asarray(p.material)]
        self.floor = 1e-12 * float(np.sum(p.volume * E))
        self.total0 = float(history["total"][0]) if history["total"] else None
        self.balance0 = float(history["balance"][0]) if history["balance"] else None
        self.work_max = max((abs(float(w)) for w in history["external_work"]), default=0.0)

    def check(self, state, total, work):
        """After the step to ``state``: total energy ``total`` and boundary work ``work`` so far."""
        if self.total0 is None:               # the initial state
            self.total0, self.balance0 = total, total - work
        self.work_max = max(self.work_max, abs(work))
        growth = (total - work) - self.balance0
        available = abs(self.total0) + self.work_max
        if state.step >= 2 and growth > MARGIN * available + self.floor:
            raise InstabilityError(
                f"energy created at step {state.step}, t = {state.t:.6g} s: the energy balance grew by "
                f"{growth:.4g} J, more than all the energy put in ({available:.4g} J: initial energy + "
                f"work of the loads): the scheme is unstable (lower method.cfl)", step=state.step, time=state.t)


class StepGuard:
    """Stops a run whose time step collapses, or that reaches ``run.step_limit`` steps."""

    def __init__(self, scene, dt0=None):
        self.dt0 = dt0
        self.limit = step_limit(scene)

    def check(self, old, new, t_end):
        dt = new.t - old.t
        if self.dt0 is None:
            self.dt0 = dt
            return
        last = new.t >= t_end * (1 - 1e-12)                # cut short to reach t_end
        if not last and dt < COLLAPSE * self.dt0:
            raise InstabilityError(
                f"time step collapsed at step {new.step}, t = {new.t:.6g} s: Delta t = {dt:.4g} s, below "
                f"{COLLAPSE:g} of the first step's {self.dt0:.4g} s (the fastest wave became "
                f"{self.dt0 / dt:.3g} times faster)", step=new.step, time=new.t)
        if new.step >= self.limit and not last:
            raise InstabilityError(
                f"step limit reached at step {new.step}, t = {new.t:.6g} s of t_end = {t_end:.6g} s "
                f"(run.step_limit = {self.limit})", step=new.step, time=new.t)


def step_limit(scene):
    value = scene.get("run.step_limit", STEP_LIMIT)
    if not (isinstance(value, int) and not isinstance(value, bool) and value >= 1):
        raise InputError(f"{scene.where('run.step_limit')} = {value!r} must be an integer >= 1")
    return value


def check_step_count(disc, t_end):
    """Refuse a run whose first Delta t would need more than ``run.step_limit`` steps."""
    scene, stepper = disc.scene, disc.stepper
    limit = step_limit(scene)
    dt = stepper.time_step(disc.initial)
    with np.errstate(divide="ignore", over="ignore"):
        steps = t_end / dt if dt > 0 else np.inf
    if not (np.isfinite(dt) and dt > 0) or steps > limit:
        c = float(np.max(disc.initial.speed)) if disc.initial.speed is not None else np.nan
        raise InputError(f"{scene.where('run.t_end')} = {t_end!r} would take {steps:.3g} steps of "
                         f"Delta t = {dt:.3g} s (fastest wave {c:.3g} m/s, from material E and rho), more than "
                         f"run.step_limit = {limit}: check material.E and material.rho, or raise run.step_limit")


def allowed_above_limit(scene):
    value = scene.get("method.cfl_above_limit", False)
    if not isinstance(value, bool):
        raise InputError(f"{scene.where('method.cfl_above_limit')} = {value!r} must be true or false")
    return value


def mpm_limit(disc):
    """MPM: dt = CFL h / (c + |v|): a wave or a particle may cross at most one cell per step."""
    return 1.0


@functools.lru_cache(maxsize=32)
def _critical_cfl(layout, integrator):
    from .stability import critical_cfl
    return critical_cfl(list(layout), integrator, criterion="spectral")


def _poisson_ratios(scene):
    """nu of every material table of the scene, None where one gives none."""
    tables = [scene.data["material"], *(r.get("material", {}) for r in scene.get("regions") or [])]
    nus = [t.get("nu") for t in tables]
    return None if any(isinstance(nu, bool) or not isinstance(nu, (int, float)) for nu in nus) else nus


def _nus_text(nus):
    return ", ".join(f"{nu:g}" for nu in dict.fromkeys(nus))


def _dgmpm_limit(disc, coords, cfl):
    """(CFL refused from, the limit, what it is) of a DGMPM layout, run at ``cfl`` (the hint
    names the other transverse scheme where it admits ``cfl``): in 2D the von Neumann limit
    of the 2D step from `skdgmpm.stability2d`'s table (regular layouts, materials that give nu),
    else the 1D limit of the layout (R18 §6; in 2D an upper bound)."""
    stepper, scene = disc.stepper, disc.scene
    n = len(coords)
    nus = _poisson_ratios(scene) if scene.dim == 2 else None
    if nus is not None and np.allclose(coords, (np.arange(n) + 0.5) / n, rtol=0, atol=1e-9):
        from .stability2d import limit as limit_2d, shown
        pair = limit_2d(n, stepper.integrator, stepper.transverse, nus)
        if pair is not None:
            stable, unstable = pair
            other = "dcu" if stepper.transverse == "ctu" else "ctu"
            alternative = limit_2d(n, stepper.integrator, other, nus)
            hint = (f"; with method.transverse = \"{other}\" it is {shown(alternative)}"
                    if alternative is not None and alternative[1] > cfl >= unstable else "")
            return unstable, stable, (
                f"the 2D von Neumann limit {shown(pair)} of {stepper.integrator} with {stepper.transverse}, "
                f"{n} x {n} particles a cell, nu = {_nus_text(nus)} "
                f"(skdgmpm stability --dim 2 --per-cell {n}){hint}")
    limit = _critical_cfl(coords, stepper.integrator)
    return limit + 1e-6, limit, (f"the von Neumann limit {limit:.2f} of layout {list(coords)} with {stepper.integrator} "
                                 f"(skdgmpm stability --layout {','.join(f'{c:g}' for c in coords)})")


def _dg_limit(disc):
    """(CFL refused from, the limit, what it is) of a DG step (ADER-DGFEM, ADER-DGMPM, RK-DGFEM)
    from `skdgmpm.stability2d`'s table, or None: in 2D a material without nu, an order or
    integrator the table lacks, ADER-DGMPM particles other than P + 1 a direction (with P + 1 its
    reconstruction interpolates them, and its step has ADER-DGFEM's limits), a particle file."""
    from .stability2d import SLOW_GROWTH, dg_key, dg_limit, dg_limit_1d, shown

    stepper, scene = disc.stepper, disc.scene
    name, order = scene.data["method"].get("name", "dgmpm"), stepper.order
    key = dg_key(name, order, stepper.integrator)
    if name == "ader-dgmpm" and (scene.get("particles.file") or compile_helper.per_axis(scene) != order + 1):
        key = None
    if key is None:
        return None
    nus = _poisson_ratios(scene) if scene.dim == 2 else None
    pair = dg_limit_1d(key) if scene.dim == 1 else None if nus is None else dg_limit(key, nus)
    if pair is None:
        return None
    stable, unstable = pair
    what = f"the {scene.dim}D von Neumann limit {shown(pair)} of {name} P{order}"
    what += f" with {stepper.integrator}" if name == "rk-dgfem" else ""
    if key in SLOW_GROWTH:                  # a knee: the step grows slowly below it
        what += f" (below it a step grows by at most {SLOW_GROWTH[key]:g}, beyond it by far more)"
    if scene.dim == 2:
        what += (f", nu = {_nus_text(nus)} "
                 f"(skdgmpm stability --dim 2 --method {name} --order {order})")
    return unstable, stable, what


def cfl_limit(disc, cfl):
    """(CFL refused from, the limit, what it is) of the method's known stability limit, for a run
    at ``cfl`` (a hint in the text where another choice admits it); None where none is known (P =
    3, RK2 with P >= 2, a particle file): for DGMPM the von Neumann limit of its step, in 2D from
    the analysis of the 2D step (`skdgmpm.stability2d`: regular layouts, every material with a
    Poisson's ratio), else the 1D limit of the particle layout (R18 §6; in 2D an upper bound); for
    the DG methods (ADER, RK-DGFEM) that of their step, 1D or 2D; for MPM 1."""
    name = disc.scene.data["method"].get("name", "dgmpm")
    if name == "mpm":
        limit = mpm_limit(disc)
        return limit + 1e-6, limit, "the MPM limit 1 (a wave or a particle crosses at most one cell a step)"
    if disc.layout is not None:
        coords = tuple(float(c) for c in np.unique(np.round(disc.layout[:, 0], 12)))
        return _dgmpm_limit(disc, coords, cfl)
    return _dg_limit(disc) if name != "dgmpm" else None


def check_cfl(disc):
    """Refuse a CFL above the method's known stability limit (`cfl_limit`); with
    ``method.cfl_above_limit = true`` a warning only. Returns the limit, or None where none is
    known. A DG step that grows at every CFL gets a warning too
    (`stability2d.grows_at_every_cfl`)."""
    from .stability2d import grows_at_every_cfl

    stepper, scene = disc.stepper, disc.scene
    known = cfl_limit(disc, stepper.cfl)
    if known is not None and stepper.cfl >= known[0]:
        text = f"{scene.where('method.cfl')} = {stepper.cfl} exceeds {known[2]}"
        if not allowed_above_limit(scene):
            raise InputError(f"{text}: the run would be unstable (method.cfl_above_limit = true runs it anyway)")
        warnings.warn(text, stacklevel=3)
    why = grows_at_every_cfl(scene.data["method"].get("name", "dgmpm"), getattr(stepper, "order", 1),
                             stepper.integrator)
    if why is not None:
        warnings.warn(f"{why} (docs/choices.md, the CFL check)", stacklevel=3)
    return None if known is None else known[1]


def default_cfl(disc):
    """(CFL, why) of a scene that gives no ``method.cfl``: 1, why None; or, where the method's
    known limit (`cfl_limit`) is below 1, `DEFAULT_SHARE` of it rounded down to 0.01, why the
    text that says so."""
    known = cfl_limit(disc, 1.0)
    if known is None or 1.0 < known[0]:
        return 1.0, None
    _, limit, what = known
    return math.floor(100 * DEFAULT_SHARE * limit) / 100, f"{DEFAULT_SHARE:g} of {what}"
