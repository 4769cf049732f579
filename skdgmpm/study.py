"""Convergence studies: one scene, several methods, orders and grids; errors against the scene's
exact solution, observed rates, wall time and dofs (speed against error)."""
import csv
from dataclasses import dataclass

import numpy as np

from .errors import InputError
from .run import progress_bar, run
from .scene import exact_solution, load_scene

# particles per cell of ADER-DGMPM at order P: (P+1)^d at the parent coordinates of L23 §5.1
L23_LAYOUT = {1: "[0.25, 0.75]", 2: "[0.25, 0.5, 0.75]", 3: "[0.2, 0.4, 0.6, 0.8]"}

DEFAULT_INTEGRATOR = {"dgmpm": "euler", "rk-dgfem": "rk4", "ader-dgfem": "ader", "ader-dgmpm": "ader",
                      "mpm": "cd-cpgimp"}
MEASURES = ("l2", "wg08")


@dataclass(frozen=True)
class Variant:
    """A method with its options, written ``name`` or ``name/integrator`` (e.g. rk-dgfem/rk2);
    for MPM the integrator is ``update-shape`` (e.g. mpm/cd-cpgimp, mpm/usl)."""

    name: str
    integrator: str

    @classmethod
    def parse(cls, text):
        name, _, integrator = text.partition("/")
        if name not in DEFAULT_INTEGRATOR:
            raise InputError(f"--methods: {name!r} is not a method (known: {', '.join(DEFAULT_INTEGRATOR)})")
        return cls(name, integrator)

    @property
    def label(self):
        return f"{self.name}/{self.integrator}"

    @property
    def first_order(self):
        return self.name in ("dgmpm", "mpm")

    def overrides(self, order):
        """Scene overrides that select this variant at order ``order``."""
        if self.name == "mpm":
            update, _, shape = self.integrator.partition("-")
            return ['method.name="mpm"', f'method.update="{update}"'] + ([f'method.shape="{shape}"'] if shape else [])
        return [f'method.name="{self.name}"', f'method.integrator="{self.integrator}"', f"method.order={order}"]


def _int_list(text, option):
    try:
        values = [int(v) for v in str(text).split(",") if v.strip()]
    except ValueError:
        raise InputError(f"{option} {text!r}: expected comma-separated integers") from None
    if not values or min(values) < 1:
        raise InputError(f"{option} {text!r}: expected positive integers")
    return values


def _float_list(text, option):
    try:
        values = [float(v) for v in str(text).split(",") if v.strip()]
    except ValueError:
        raise InputError(f"{option} {text!r}: expected comma-separated numbers") from None
    if not values or min(values) <= 0:
        raise InputError(f"{option} {text!r}: expected numbers > 0")
    return values


class DisplacementError:
    """WG08 eq 64-65: max over all particles and all steps of |(x_p - X_p) - u(X_p, t)| (m)."""

    def __init__(self, solution):
        self.solution, self.value = solution, 0.0

    def __call__(self, state, disc):
        X = disc.particles.X                    # reference positions (x = X + u(X, 0) at the start)
        u = self.solution.displacement(X, state.t)
        self.value = max(self.value, float(np.max(np.linalg.norm(state.x - X - u, axis=1))))


def study_run(base, overrides, measure="l2", keep_fields=False):
    """One run of a study (in a worker process): summary, errors and, if asked, the fields."""
    monitor = DisplacementError(exact_solution(base)) if measure == "wg08" else None
    result = run(base, overrides, progress=False, on_step=monitor)
    out = {"summary": result.summary(), "errors": result.errors, "wg08": monitor and monitor.value}
    if keep_fields:
        out.update(fields=result.fields(), X=result.X, volume=result.disc.particles.volume, t=result.state.t)
    return out


def _map(executor, tasks, progress, labels):
    """Every study run on ``executor`` (None: here, one after the other); results in task order."""
    from .executor import make_executor, map_ordered

    own = executor is None
    pool = make_executor(1) if own else executor
    bar = progress_bar(progress, len(tasks), unit="run")
    try:
        return map_ordered(pool, study_run, tasks, bar, labels)
    finally:
        bar.close()
        if own:
            pool.shutdown()


def convergence(scene_name, methods, orders, cells, overrides=(), fields=None, progress=True,
                reference=None, cfls=None, measure="l2", executor=None):
    """Run every (method, order, grid, CFL) and return one row per run.

    Rows: method, order, cells, h, cfl, dt (mean step), dofs, steps, wall_s, startup_s, status, and the
    errors with observed rates: ``measure="l2"`` gives ``L2_<field>`` (relative L2 error at the
    method's points at the end: particles for DGMPM/MPM, Gauss points for DGFEM) and
    ``rate_<field>``; ``measure="wg08"`` gives ``Linf_u``, the WG08 displacement error (max over
    particles and steps) and ``rate_u``. Rates are taken along the grids (several ``cells``) or,
    for a temporal study at one grid, along the CFL numbers (against the mean step).

    Errors are taken against the scene's exact solution, or against ``reference`` =
    "method/integrator:P:cells" (a fine DGFEM run, L2 only) for scenes without one. A run that
    goes unstable records error 1 (WG08's convention) and the study goes on. ADER-DGMPM runs use
    (P+1)^d particles per cell at the L23 §5.1 parent coordinates.

    The runs go through ``executor`` (a `concurrent.futures.Executor`, e.g. from
    `skdgmpm.executor.make_executor`; None runs them here one after the other). Wall times of
    runs that share a machine include the competition for its cores. ``wall_s`` leaves out each
    run's start-up (``startup_s``: the build and the first step, which compiles the kernels or
    loads them from numba's cache, once per process and method): it is the mean time of the later
    steps times the number of steps, so the first run of a study is not inflated by a cold cache
    (a run of one step has no warm step: 0).
    """
    if measure not in MEASURES:
        raise InputError(f"--measure {measure!r}: expected one of {', '.join(MEASURES)}")
    base = load_scene(scene_name, overrides)
    ref = None
    if reference is not None:
        if measure != "l2":
            raise InputError("--reference works with --measure l2 only")
        ref = _reference_run(base, reference, progress)
    elif base.get("exact") is None:
        raise InputError(f"{base.where('exact')}: a convergence study needs a scene with an exact "
                         f"solution, or --reference METHOD:P:CELLS")
    if "mesh" in base.data["grid"]:
        raise InputError(f"{base.where('grid.mesh')}: convergence studies refine generated grids only")
    scene_method = base.data["method"]
    if measure == "wg08" and not hasattr(exact_solution(base), "displacement"):
        raise InputError(f"{base.where('exact')}: --measure wg08 needs an exact displacement "
                         f"(a manufactured solution)")

    def resolved(v):            # the scene's integrator for its own method, else the default
        if v.integrator:
            return v
        same = scene_method.get("name", "dgmpm") == v.name
        if same and v.name == "mpm" and ("update" in scene_method or "shape" in scene_method):
            default_update, _, default_shape = DEFAULT_INTEGRATOR["mpm"].partition("-")
            return Variant("mpm", f"{scene_method.get('update', default_update)}-"
                                  f"{scene_method.get('shape', default_shape)}")
        if same and "integrator" in scene_method:
            return Variant(v.name, scene_method["integrator"])
        return Variant(v.name, DEFAULT_INTEGRATOR[v.name])

    variants = [resolved(Variant.parse(m)) for m in methods]
    cfl_list = cfls or [float(scene_method.get("cfl", 1.0))]
    runs = [(v, p, n, c) for v in variants for p in ([1] if v.first_order else orders)
            for c in cfl_list for n in cells]
    size = base.get("grid.size") or [base.get("grid.length")]
    tasks = []
    for v, p, n, c in runs:
        grid = f"grid.cells=[{n}, {n}]" if base.dim == 2 else f"grid.cells={n}"
        layout = [f"particles.per_cell={L23_LAYOUT[p]}"] if v.name == "ader-dgmpm" and p in L23_LAYOUT else []
        tasks.append((base, [*v.overrides(p), grid, f"method.cfl={c}", *layout], measure, ref is not None))
    outcomes = _map(executor, tasks, progress, [f"{v.label} P{p} {n} cells CFL {c:g}" for v, p, n, c in runs])
    rows = []
    for (v, p, n, c), out in zip(runs, outcomes):
        summary, ok = out["summary"], out["summary"]["status"] == "ok"
        row = {"method": v.label, "order": p, "cells": n, "h": float(size[0]) / n, "cfl": c,
               "dt": summary["t_final"] / max(summary["steps"], 1), "dofs": summary["dofs"],
               "steps": summary["steps"], "wall_s": summary["wall_per_step_s"] * summary["steps"],
               "startup_s": summary["startup_s"], "status": summary["status"]}
        if measure == "wg08":
            row["Linf_u"] = out["wg08"] if ok else 1.0
        else:
            errors = out["errors"] if ref is None else reference_errors(out, ref, fields or ("eps11", "P11", "v1"))
            for name in fields or errors:
                if name not in errors:
                    raise InputError(f"--fields: {name!r} is not a field of the exact solution "
                                     f"(known: {', '.join(errors)})")
                row[f"L2_{name}"] = errors[name]["L2_rel"] if ok else 1.0
        rows.append(row)
    _rates(rows, along="h" if len(cells) > 1 else "dt")
    return rows


def _reference_run(base, text, progress):
    try:
        label, order, cells = text.split(":")
        v = Variant.parse(label)
        order, cells = int(order), int(cells)
    except ValueError:
        raise InputError(f"--reference {text!r}: expected METHOD[/INTEGRATOR]:P:CELLS, "
                         f"e.g. rk-dgfem/rk4:3:40") from None
    grid = f"grid.cells=[{cells}, {cells}]" if base.dim == 2 else f"grid.cells={cells}"
    v = v if v.integrator else Variant(v.name, DEFAULT_INTEGRATOR[v.name])
    result = run(base, [*v.overrides(order), grid], progress=progress)
    if result.status != "ok":
        raise InputError(f"--reference run stopped: {result.message}")
    return GridReference(result)


def error_keys(row):
    """The error columns of a row: [(column, field)], e.g. ("L2_P11", "P11"), ("Linf_u", "u")."""
    return [(k, k.split("_", 1)[1]) for k in row if k.startswith(("L2_", "Linf_"))]


def _rates(rows, along="h"):
    """Observed orders between successive runs of a series: along the grids (same method, order
    and CFL) or, for ``along="dt"``, along the CFL numbers at one grid."""
    previous = {}
    for row in rows:
        key = (row["method"], row["order"], row["cfl"] if along == "h" else row["cells"])
        before = previous.get(key)
        for column, name in error_keys(row):
            ok = before is not None and row["status"] == before["status"] == "ok"
            row[f"rate_{name}"] = (float(np.log(before[column] / row[column]) /
                                         np.log(before[along] / row[along])) if ok else float("nan"))
        previous[key] = row


def format_table(rows):
    columns = error_keys(rows[0])
    head = f"{'method':<16}{'P':>2}{'cells':>6}{'h':>9}{'CFL':>6}{'dofs':>8}{'wall s':>8}"
    head += "".join(f"{column.replace('_', ' '):>12}{'rate':>6}" for column, _ in columns)
    lines = [head, "-" * len(head)]
    for r in rows:
        line = (f"{r['method']:<16}{r['order']:>2}{r['cells']:>6}{r['h']:>9.4f}{r['cfl']:>6.2f}"
                f"{r['dofs']:>8}{r['wall_s']:>8.2f}")
        line += "".join(f"{r[column]:>12.3e}{r['rate_' + name]:>6.2f}" for column, name in columns)
        lines.append(line + ("" if r["status"] == "ok" else f"  {r['status']}"))
    return "\n".join(lines)


def write_csv(path, rows):
    with open(path, "w", newline="") as fh:
        w = csv.DictWriter(fh, fieldnames=list(rows[0]))
        w.writeheader()
        w.writerows(rows)


def plot(rows, folder):
    """error_vs_h.png (or error_vs_cfl.png for a study at one grid) and error_vs_time.png
    (speed against error), one line per method/order (and CFL)."""
    import matplotlib
    matplotlib.use("Agg", force=False)
    import matplotlib.pyplot as plt

    columns = error_keys(rows[0])
    spatial = len({r["cells"] for r in rows}) > 1
    groups = {}
    for r in rows:
        key = (r["method"], r["order"], r["cfl"] if spatial else None)
        groups.setdefault(key, []).append(r)
    sweep = ("h", "error_vs_h.png", "h (m)") if spatial else ("cfl", "error_vs_cfl.png", "CFL")
    for xkey, name, xlabel in (sweep, ("wall_s", "error_vs_time.png", "wall time (s)")):
        fig, axes = plt.subplots(1, len(columns), figsize=(4.2 * len(columns), 3.6), squeeze=False)
        for ax, (column, field) in zip(axes[0], columns):
            for (method, order, cfl), rs in groups.items():
                label = f"{method} P{order}" + (f" CFL {cfl:g}" if cfl is not None and len(
                    {r["cfl"] for r in rows}) > 1 else "")
                ax.loglog([r[xkey] for r in rs], [r[column] for r in rs], "o-", label=label)
            ax.set_xlabel(xlabel)
            ax.set_ylabel("max displacement error (m), WG08" if column == "Linf_u"
                          else f"relative L2 error of {field}")
            ax.grid(True, which="both", alpha=0.3)
        axes[0][0].legend(fontsize=7)
        fig.tight_layout()
        fig.savefig(folder / name, dpi=110)
        plt.close(fig)


class GridReference:
    """A finished DG run (RK-/ADER-DGFEM) as a reference solution: its fields at any points of
    the body at its final time, by evaluating the DG solution (for studies without an exact
    solution, e.g. L23 §5.1 against a fine grid)."""

    def __init__(self, result):
        st = result.stepper
        if getattr(result.state, "dofs", None) is None:
            raise InputError("--reference must be a DGFEM method (rk-dgfem or ader-dgfem)")
        self.stepper, self.dofs, self.t = st, result.state.dofs, result.state.t

    def fields(self, X, t):
        from . import output
        from .particles import Particles, locate
        from .quadrature import interpolation_matrix, particle_basis
        from .scheme import ParticleState

        if not np.isclose(t, self.t, rtol=1e-9, atol=0.0):
            raise InputError(f"reference at t = {self.t:.6g} s, asked at t = {t:.6g} s")
        st = self.stepper
        cell, xi = locate(st.grid.submesh, X, source="reference")
        rho = st.rho_cell[cell]
        points = Particles(np.asarray(X), xi, cell, np.ones(len(X)), rho, st.cell_material[cell])
        basis, slot = particle_basis(st.grid, points, st.basis.elem)
        U = interpolation_matrix(basis, slot) @ self.dofs
        Q = st.point_state(U, cell, rho)

        class _View:                           # what output.particle_fields reads
            d, materials, particles = st.d, st.materials, points

        return output.particle_fields(_View, ParticleState(t, U, Q, np.asarray(X)))


def reference_errors(out, reference, fields):
    """Relative errors of a study run's fields (``study_run(..., keep_fields=True)``) against a
    `GridReference` at the same points and time."""
    from .exact import relative_errors

    errors = relative_errors(out["fields"], reference.fields(out["X"], out["t"]), out["volume"])
    return {k: errors[k] for k in fields if k in errors}


def _curves(rows, column):
    """(method, order) -> list of (wall_s, error) of the stable runs, sorted by wall time."""
    curves = {}
    for r in rows:
        if r["status"] == "ok":
            curves.setdefault(f"{r['method']} P{r['order']}", []).append((r["wall_s"], r[column]))
    return {k: sorted(v) for k, v in curves.items()}


def winners(rows, column, per_decade=1):
    """Which method reaches each accuracy first: for error targets spaced ``per_decade`` per
    decade between the largest and smallest error of the study, the variant with the smallest
    wall time to reach it (log-log interpolation along its curve). Returns [(target, label, s)];
    a target no variant reaches is left out."""
    curves = _curves(rows, column)
    errors = [e for c in curves.values() for _, e in c]
    if not errors:
        return []
    hi, lo = np.log10(max(errors)), np.log10(min(errors))
    targets = 10.0 ** np.arange(np.floor(hi * per_decade) / per_decade, lo - 1e-9, -1.0 / per_decade)
    out = []
    for target in targets:
        best = None
        for label, curve in curves.items():
            t = _time_to_reach(curve, target)
            if t is not None and (best is None or t < best[1]):
                best = (label, t)
        if best is not None:
            out.append((float(f"{target:.6g}"), *best))
    return out


def _time_to_reach(curve, target):
    """Interpolated wall time at which a (time, error) curve first gets to ``target``."""
    for k, (t, e) in enumerate(curve):
        if e <= target:
            if k == 0:
                return t
            (t0, e0) = curve[k - 1]
            w = np.log(e0 / target) / np.log(e0 / e)
            return float(np.exp(np.log(t0) + w * np.log(t / t0)))
    return None


def plot_work_precision(rows, column, path, title=""):
    """Work-precision diagram: error of ``column`` against wall time, one curve per variant."""
    import matplotlib
    matplotlib.use("Agg", force=False)
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(6.4, 4.8))
    for label, curve in _curves(rows, column).items():
        ax.loglog([t for t, _ in curve], [e for _, e in curve], "o-", label=label)
    ax.set_xlabel("wall time (s)")
    ax.set_ylabel("max displacement error (m), WG08" if column == "Linf_u"
                  else f"relative L2 error of {column.split('_', 1)[1]}")
    ax.set_title(title or "work-precision diagram: lower left is better")
    ax.grid(True, which="both", alpha=0.3)
    ax.legend(fontsize=7)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)
