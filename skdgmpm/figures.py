"""Figures like the papers': one scene run by several methods, sigma11 maps in the current
configuration and sigma11 / v1 along the bottom line at the papers' times (L23 Fig. 7-8, 10-13,
R18 Fig. 16-17), as PNG plots and CSV.

Each (method, time) is an independent run to that time (a task of the study executor); the
figure times come from the scene's ``[figures] times`` (default: the end time). Methods:
S1T1 = TVD-RK2-DGFEM, ADER-DGFEM and ADER-DGMPM at P = 1 ({1/4, 3/4}^2 particles), S2T2 = RK4-DGFEM,
ADER-DGFEM and ADER-DGMPM at P = 2 ({1/4, 1/2, 3/4}^2), and first-order DGMPM (CTU, 1 particle
per cell, its own CFL: without the 2P+1 factor of L23 eq 67) where it applies.

Values along the bottom line: a point-line interpolator like L23's ParaView filter: the points'
values (particles or Gauss points, in the reference configuration) linearly interpolated on the
line X2 = lowest point height, nearest point outside their convex hull; plotted against the
current abscissa x1 interpolated the same way.
"""
import csv
import time
from dataclasses import dataclass

import numpy as np

from .errors import InputError

S1 = {
    "rk-dgfem/rk2 S1": ['method.name="rk-dgfem"', 'method.integrator="rk2"', "method.order=1"],
    "ader-dgfem S1T1": ['method.name="ader-dgfem"', "method.order=1"],
    "ader-dgmpm S1T1": ['method.name="ader-dgmpm"', "method.order=1", "particles.per_cell=[0.25, 0.75]"],
}
S2 = {
    "rk-dgfem/rk4 S2": ['method.name="rk-dgfem"', 'method.integrator="rk4"', "method.order=2"],
    "ader-dgfem S2T2": ['method.name="ader-dgfem"', "method.order=2"],
    "ader-dgmpm S2T2": ['method.name="ader-dgmpm"', "method.order=2", "particles.per_cell=[0.25, 0.5, 0.75]"],
}
DGMPM = {"dgmpm": ['method.name="dgmpm"', 'method.integrator="euler"', 'method.transverse="ctu"',
                   "particles.per_cell=1"]}
MPM = {"mpm cd-cpgimp": ['method.name="mpm"', 'method.update="cd"', 'method.shape="cpgimp"', "method.cfl=0.4",
                         "particles.per_cell=2"]}
GROUPS = {"S1": S1, "S2": S2, "dgmpm": DGMPM, "mpm": MPM}
FIELDS = ("sigma11", "v1")


@dataclass
class Snapshot:
    """What a figure needs from one run: points (reference and current), fields, run record."""

    method: str
    time: float            # the figure time asked for (the run stops earlier if it goes unstable)
    t_final: float
    status: str
    message: str
    steps: int
    wall_s: float
    X: np.ndarray
    x: np.ndarray
    fields: dict
    outline: list          # boundary edges of the body in the reference configuration


def _snapshot(scene_name, method, overrides, t, fields=FIELDS):
    from .run import run

    r = run(scene_name, [*overrides, f"run.t_end={t!r}"], progress=False, frames=1)
    f = r.fields()
    m = r.stepper.grid.submesh
    edges = m.facets[:, m.boundary_facets()]
    outline = [m.p[:, e].T for e in edges.T]
    return Snapshot(method, t, float(r.state.t), r.status, r.message, int(r.state.step), r.wall_s, r.X.copy(),
                    r.state.x.copy(), {k: f[k].copy() for k in dict.fromkeys([*FIELDS, *fields])}, outline)


def line_values(snapshot, n=200):
    """(X1, x1, {field: values}) on the bottom line by the point-line interpolator (computed once
    per snapshot)."""
    cached = getattr(snapshot, "_line", None)
    if cached is None or len(cached[0]) != n:
        cached = snapshot._line = _line_values(snapshot, n)
    return cached


def _line_values(snapshot, n):
    from scipy.interpolate import griddata

    X = snapshot.X
    y = X[:, 1].min()
    s = np.linspace(X[:, 0].min(), X[:, 0].max(), n)
    probe = np.column_stack([s, np.full(n, y)])

    def interp(values):
        out = griddata(X, values, probe, method="linear")
        miss = ~np.isfinite(out)
        if miss.any():
            out[miss] = griddata(X, values, probe[miss], method="nearest")
        return out

    return s, interp(snapshot.x[:, 0]), {k: interp(v) for k, v in snapshot.fields.items()}


def compare(scene, groups=("S1", "S2", "dgmpm"), overrides=(), times=None, workers=None, dgmpm_cfl=0.5,
            progress=False):
    """Run every method of ``groups`` to every figure time; returns the `Snapshot` list."""
    from .executor import make_executor, map_ordered
    from .run import progress_bar
    from .scene import load_scene

    s = load_scene(scene, overrides)
    times = times or s.get("figures.times") or [s.get("run.t_end")]
    fields = tuple(s.get("figures.fields") or ("sigma11",))
    tasks = []
    for g in groups:
        if g not in GROUPS:
            raise InputError(f"--groups: {g!r} is unknown (known: {', '.join(GROUPS)})")
        for method, extra in GROUPS[g].items():
            extra = [*extra, f"method.cfl={dgmpm_cfl!r}"] if g == "dgmpm" else extra
            for t in times:
                tasks.append((str(s.path or scene), method, [*overrides, *extra], float(t), fields))
    bar = progress_bar(progress, len(tasks), desc=f"compare {s.name}", unit="run")
    with make_executor(workers) as pool:
        snaps = map_ordered(pool, _snapshot, tasks, bar)
    bar.close()
    return snaps


def write(snaps, out, scene_name, map_fields=("sigma11",)):
    """map_FIELD_t*.png (``map_fields``: the scene's ``[figures] fields``), line_sigma11.png,
    line_v1.png, lines.csv, runs.csv in ``out``."""
    import matplotlib
    matplotlib.use("Agg", force=False)
    import matplotlib.pyplot as plt

    from .pictures import SEQUENTIAL
    from .plots import field_label

    out.mkdir(parents=True, exist_ok=True)
    with open(out / "runs.csv", "w", newline="") as fh:
        w = csv.writer(fh)
        w.writerow(["method", "t", "t_final", "status", "steps", "wall_s", "sigma11_min", "sigma11_max", "v1_min",
                    "v1_max", "message"])
        for s in snaps:
            w.writerow([s.method, f"{s.time:.6g}", f"{s.t_final:.6g}", s.status, s.steps, f"{s.wall_s:.2f}",
                        *(f"{fn(s.fields[k]):.6g}" for k in FIELDS for fn in (np.min, np.max)), s.message])
    with open(out / "lines.csv", "w", newline="") as fh:
        w = csv.writer(fh)
        w.writerow(["method", "t", "X1", "x1", *FIELDS])
        for s in snaps:
            X1, x1, vals = line_values(s)
            for k in range(len(X1)):
                w.writerow([s.method, f"{s.time:.6g}", f"{X1[k]:.6g}", f"{x1[k]:.6g}",
                            *(f"{vals[f][k]:.6g}" for f in FIELDS)])
    by_time = {}
    for s in snaps:
        by_time.setdefault(round(s.time, 12), []).append(s)
    for (t, group), field in ((item, f) for item in sorted(by_time.items()) for f in map_fields):
        values = np.concatenate([s.fields[field] for s in group])
        lim = np.nanpercentile(np.abs(values), 99.5) or 1.0
        lo, cmap = (0.0, "viridis") if field in SEQUENTIAL else (-lim, "coolwarm")   # eqp >= 0
        fig, axes = plt.subplots(1, len(group), figsize=(3.6 * len(group), 3.4), squeeze=False)
        for ax, s in zip(axes[0], group):
            for e in s.outline:
                ax.plot(e[:, 0], e[:, 1], "-", color="0.6", lw=0.6)
            sc = ax.scatter(s.x[:, 0], s.x[:, 1], c=s.fields[field], s=4, cmap=cmap, vmin=lo, vmax=lim)
            ax.set_aspect("equal")
            ax.set_title(f"{s.method}\n{s.status}", fontsize=8)
            ax.tick_params(labelsize=6)
        fig.colorbar(sc, ax=axes[0].tolist(), shrink=0.8, label=field_label(field))
        fig.suptitle(f"{scene_name}: {field}, current configuration, t = {t:.4g} s", fontsize=9)
        fig.savefig(out / f"map_{field}_t{t:.4g}.png", dpi=110)
        plt.close(fig)
    plastic = all("eqp" in s.fields for s in snaps)
    for field in FIELDS + (("eqp",) if plastic else ()):
        fig, axes = plt.subplots(1, len(by_time), figsize=(5 * len(by_time), 3.5), squeeze=False)
        for ax, (t, group) in zip(axes[0], sorted(by_time.items())):
            for s in group:
                _, x1, vals = line_values(s)
                ax.plot(x1, vals[field], "-", lw=1, label=s.method)
            ax.set_title(f"t = {t:.4g} s", fontsize=9)
            ax.set_xlabel("x1 (m), bottom line")
            ax.set_ylabel(field_label(field))
            ax.legend(fontsize=6)
        fig.suptitle(f"{scene_name}: {field} along the bottom line", fontsize=9)
        fig.tight_layout()
        fig.savefig(out / f"line_{field}.png", dpi=110)
        plt.close(fig)
    return sorted(p.name for p in out.iterdir())


def agreement(snaps):
    """Per time, the spread between methods along the bottom line: max |f_m - median| / max |median|
    for each field, and the method farthest from the median."""
    by_time = {}
    for s in snaps:
        if s.status == "ok":
            by_time.setdefault(round(s.time, 12), []).append(s)
    rows = []
    for t, group in sorted(by_time.items()):
        lines = [line_values(s) for s in group]
        for field in FIELDS:
            stack = np.array([vals[field] for _, _, vals in lines])
            med = np.median(stack, axis=0)
            scale = np.abs(med).max() or 1.0
            dev = np.abs(stack - med).max(axis=1) / scale
            rows.append({"t": t, "field": field, "spread": float(dev.max()),
                         "farthest": group[int(dev.argmax())].method,
                         "per_method": {s.method: float(v) for s, v in zip(group, dev)}})
    return rows


def main_compare(scene, groups, overrides, workers, out, dgmpm_cfl=0.5, progress=True):
    start = time.perf_counter()
    from .scene import load_scene

    snaps = compare(scene, groups, overrides, workers=workers, dgmpm_cfl=dgmpm_cfl, progress=progress)
    files = write(snaps, out, scene, tuple(load_scene(scene, overrides).get("figures.fields") or ("sigma11",)))
    return snaps, files, time.perf_counter() - start
