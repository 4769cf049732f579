"""Stability study: the largest CFL at which a scene runs to its end time, per method and limiter.

A trial runs the scene at one CFL and *passes* when it reaches ``run.t_end`` with status "ok"
(no non-finite value, no J <= 0, no loss of hyperbolicity: `skdgmpm.health`) and without an
energy blow-up: the balance total - boundary work may not grow by more than ``ENERGY_GROWTH`` of
the energy scale (max of the total energy and of the boundary work) *more than a run of the same
chain at a small CFL does* (the baseline, CFL ``BASELINE``): a scheme whose limiter or nonlinear
fluxes create some energy at every CFL (measured: DGFEM P = 1 without limiter on the 1000 m/s
plate, +14 % whatever the CFL) is not declared unstable for it, while the growth of a time-step
instability, which has not (yet) made the state inadmissible, is caught. The critical CFL is
bracketed by bisection between a passing and a failing CFL (`critical_cfl`); each (scene, method,
limiter) chain is one task of the study executor (`skdgmpm.executor`), chains run in parallel.
A trial also fails when it takes more than ``STEP_BUDGET`` times the baseline's steps without
reaching t_end: its time step has collapsed (waves stiffening without bound as J -> 0), and
without a budget such a run grinds on for hours before it fails.

CFL is the scene's ``method.cfl``: Delta t = CFL h_min / c_max for DGMPM, CFL h_min / ((2P+1) c_max)
for the high-order methods (L23 eq 67).
"""
import csv
import time
import warnings
from dataclasses import asdict, dataclass, field

import numpy as np

from .errors import InputError, InstabilityError
from .limiter import KINDS

ENERGY_GROWTH = 0.1
BASELINE = 0.2
STEP_BUDGET = 10        # trials at CFL >= BASELINE need fewer steps than the baseline run

# method variants: label -> scene overrides (the L23 particle layouts for ADER-DGMPM)
VARIANTS = {
    "dgmpm": ['method.name="dgmpm"', 'method.integrator="euler"', 'method.transverse="ctu"',
              "particles.per_cell=1", 'method.limiter="none"'],
    "rk-dgfem/rk2 S1": ['method.name="rk-dgfem"', 'method.integrator="rk2"', "method.order=1"],
    "ader-dgfem S1T1": ['method.name="ader-dgfem"', "method.order=1"],
    "ader-dgmpm S1T1": ['method.name="ader-dgmpm"', "method.order=1", "particles.per_cell=[0.25, 0.75]"],
    "rk-dgfem/rk4 S2": ['method.name="rk-dgfem"', 'method.integrator="rk4"', "method.order=2"],
    "ader-dgfem S2T2": ['method.name="ader-dgfem"', "method.order=2"],
    "ader-dgmpm S2T2": ['method.name="ader-dgmpm"', "method.order=2", "particles.per_cell=[0.25, 0.5, 0.75]"],
}
LIMITERS = KINDS           # every kind of `skdgmpm.limiter`


@dataclass
class Trial:
    cfl: float
    passed: bool
    status: str
    reason: str
    steps: int
    t_final: float
    wall_s: float
    growth: float = np.nan        # balance growth / energy scale


@dataclass
class Chain:
    """The bisection of one (scene, method, limiter)."""

    scene: str
    method: str
    limiter: str
    overrides: list
    critical_cfl: float = np.nan          # largest passing CFL found
    baseline_growth: float = np.nan       # energy growth of the run at CFL BASELINE
    first_failing_cfl: float = np.nan
    trials: list = field(default_factory=list)
    wall_s: float = 0.0


def trial(scene, overrides, cfl, allowed_growth=ENERGY_GROWTH, max_steps=None):
    """One run at ``cfl``: a `Trial` (never raises for an unstable run); it fails if the energy
    balance grows by more than ``allowed_growth`` of the energy scale, or if it has not reached
    t_end after ``max_steps`` steps (None: no limit)."""
    from .run import run

    start = time.perf_counter()
    try:
        with warnings.catch_warnings():          # CFL above the 1D von Neumann limit: the point here
            warnings.simplefilter("ignore")
            r = run(scene, [*overrides, f"method.cfl={cfl!r}", "method.cfl_above_limit=true"], progress=False,
                    frames=1, max_steps=max_steps)
    except InstabilityError as exc:      # raised before the loop (e.g. the first CTU step)
        return Trial(cfl, False, "unstable", str(exc), 0, 0.0, time.perf_counter() - start)
    h = r.history
    scale = max(np.nanmax(np.abs(h["total"])), np.nanmax(np.abs(h["external_work"])), 1e-300)
    growth = float(np.nanmax(h["balance"] - h["balance"][0])) / scale
    t_end = float(r.scene.get("run.t_end"))
    if r.status != "ok":
        passed, reason = False, r.message
    elif growth > allowed_growth:
        passed, reason = False, f"energy blow-up: balance grew by {growth:.3g} of the energy scale (> {allowed_growth:.3g})"
    elif r.state.t < t_end * (1 - 1e-9):
        passed, reason = False, (f"time step collapsed: {r.state.step} steps without reaching t_end "
                                 f"(t = {r.state.t:.4g} s, min J {np.nanmin(h['min_J']):.3g})")
    else:
        passed, reason = True, ""
    return Trial(cfl, passed, r.status, reason, int(r.state.step), float(r.state.t), time.perf_counter() - start,
                 growth)


def critical_cfl(scene, overrides, lo=0.0, hi=1.6, tol=0.05, start=None, allowed_growth=ENERGY_GROWTH,
                 max_steps=None):
    """Bisection for the largest passing CFL in (lo, hi]: returns (largest passing, smallest
    failing, trials). ``lo`` is assumed to pass (0 always does), ``hi`` is tried first unless
    ``start`` is given (then ``start`` first). Stops when hi - lo <= tol. ``max_steps``: each
    trial's step budget (`trial`)."""
    trials = []
    passing, failing = lo, np.inf
    cfl = hi if start is None else start
    while True:
        t = trial(scene, overrides, cfl, allowed_growth, max_steps)
        trials.append(t)
        if t.passed:
            passing = max(passing, cfl)
        else:
            failing = min(failing, cfl)
        if failing == np.inf:              # everything passed up to hi
            if cfl >= hi:
                break
            cfl = hi
            continue
        if failing - passing <= tol:
            break
        cfl = round(0.5 * (passing + failing), 6)
    return passing, failing, trials


def _chain_task(chain, lo, hi, tol, baseline=BASELINE):
    """Baseline run at CFL ``baseline`` (it must pass the health checks), then the bisection."""
    start = time.perf_counter()
    base = trial(chain.scene, chain.overrides, baseline, np.inf)
    chain.baseline_growth = base.growth
    if not base.passed:
        chain.critical_cfl, chain.first_failing_cfl, chain.trials = lo, baseline, [base]
    else:
        chain.critical_cfl, chain.first_failing_cfl, trials = critical_cfl(
            chain.scene, chain.overrides, max(lo, baseline), hi, tol,
            allowed_growth=max(base.growth, 0.0) + ENERGY_GROWTH, max_steps=STEP_BUDGET * max(base.steps, 1))
        chain.trials = [base, *trials]
    chain.wall_s = time.perf_counter() - start
    return chain


def chains(scene, methods, limiters, overrides=()):
    """The (method, limiter) chains of a study; DGMPM has no limiter (one chain)."""
    out = []
    for method in methods:
        if method not in VARIANTS:
            raise InputError(f"--methods: {method!r} is unknown (known: {', '.join(VARIANTS)})")
        for limiter in (["none"] if method == "dgmpm" else limiters):
            if limiter not in LIMITERS:
                raise InputError(f"--limiters: {limiter!r} is unknown (known: {', '.join(LIMITERS)})")
            extra = [] if method == "dgmpm" else [f'method.limiter="{limiter}"']
            out.append(Chain(scene, method, limiter, [*overrides, *VARIANTS[method], *extra]))
    return out


def study(scene, methods=("dgmpm", "rk-dgfem/rk2 S1", "ader-dgfem S1T1", "ader-dgmpm S1T1"),
          limiters=("none", "barth-jespersen"), overrides=(), workers=None, lo=0.0, hi=2.0, tol=0.05,
          progress=False):
    """Critical CFL of every (method, limiter) chain of ``scene``, chains in parallel."""
    from .executor import make_executor, map_ordered
    from .run import progress_bar

    todo = chains(scene, methods, limiters, overrides)
    bar = progress_bar(progress, len(todo), desc=f"cfl-limit {scene}", unit="chain")
    with make_executor(workers) as pool:
        done = map_ordered(pool, _chain_task, [(c, lo, hi, tol) for c in todo], bar)
    bar.close()
    return done


def format_table(done):
    """Markdown table: scene, method, limiter, critical CFL, first failing CFL and why."""
    lines = ["| scene | method | limiter | largest passing CFL | smallest failing CFL | failure | energy growth "
             f"at CFL {BASELINE} | runs | wall (s) |", "|---|---|---|---|---|---|---|---|---|"]
    for c in done:
        failing = [t for t in c.trials if t.cfl == c.first_failing_cfl]
        why = failing[0].reason.split(" at step")[0] if failing else "-"
        lines.append(f"| {c.scene} | {c.method} | {c.limiter} | {c.critical_cfl:.3g} | "
                     f"{c.first_failing_cfl:.3g} | {why} | {c.baseline_growth:+.3f} | {len(c.trials)} | "
                     f"{c.wall_s:.0f} |")
    return "\n".join(lines)


def write_csv(path, done):
    with open(path, "w", newline="") as fh:
        w = csv.writer(fh)
        w.writerow(["scene", "method", "limiter", "cfl", "passed", "status", "reason", "steps", "t_final", "wall_s",
                    "energy_growth"])
        for c in done:
            for t in c.trials:
                d = asdict(t)
                w.writerow([c.scene, c.method, c.limiter, d["cfl"], d["passed"], d["status"], d["reason"],
                            d["steps"], d["t_final"], f"{d['wall_s']:.2f}", f"{d['growth']:.4g}"])
