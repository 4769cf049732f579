"""Convergence studies: one scene, several methods, orders and grids; errors against the scene's
exact solution, observed rates, wall time and dofs (speed against error)."""
import csv
from dataclasses import dataclass

import numpy as np

from .errors import InputError
from .run import progress_bar, run
from .scene import load_scene

# particles per cell of ADER-DGMPM at order P: (P+1)^d at the parent coordinates of L23 §5.1
L23_LAYOUT = {1: "[0.25, 0.75]", 2: "[0.25, 0.5, 0.75]", 3: "[0.2, 0.4, 0.6, 0.8]"}

DEFAULT_INTEGRATOR = {"dgmpm": "euler", "rk-dgfem": "rk4", "ader-dgfem": "ader", "ader-dgmpm": "ader"}


@dataclass(frozen=True)
class Variant:
    """A method with its options, written ``name`` or ``name/integrator`` (e.g. rk-dgfem/rk2)."""

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


def _int_list(text, option):
    try:
        values = [int(v) for v in str(text).split(",") if v.strip()]
    except ValueError:
        raise InputError(f"{option} {text!r}: expected comma-separated integers") from None
    if not values or min(values) < 1:
        raise InputError(f"{option} {text!r}: expected positive integers")
    return values


def convergence(scene_name, methods, orders, cells, overrides=(), fields=None, progress=True,
                reference=None):
    """Run every (method, order, grid) and return one row per run.

    Rows: method, order, cells, h, dofs, steps, wall_s, and ``L2_<field>`` (relative L2 error at
    the method's points: particles for DGMPM, Gauss points for DGFEM) plus ``rate_<field>``
    (observed order against the previous grid of the same method and order). Errors are taken
    against the scene's exact solution, or against ``reference`` = "method/integrator:P:cells"
    (a fine DGFEM run) for scenes without one. ADER-DGMPM runs use (P+1)^d particles per cell at
    the L23 §5.1 parent coordinates.
    """
    base = load_scene(scene_name, overrides)
    ref = None
    if reference is not None:
        ref = _reference_run(base, reference, progress)
    elif base.get("exact") is None:
        raise InputError(f"{base.where('exact')}: a convergence study needs a scene with an exact "
                         f"solution, or --reference METHOD:P:CELLS")
    if "mesh" in base.data["grid"]:
        raise InputError(f"{base.where('grid.mesh')}: convergence studies refine generated grids only")
    scene_method = base.data["method"]

    def resolved(v):            # the scene's integrator for its own method, else the default
        if v.integrator:
            return v
        same = scene_method.get("name", "dgmpm") == v.name and "integrator" in scene_method
        return Variant(v.name, scene_method["integrator"] if same else DEFAULT_INTEGRATOR[v.name])

    variants = [resolved(Variant.parse(m)) for m in methods]
    runs = [(v, p, n) for v in variants for p in (orders if v.name != "dgmpm" else [1]) for n in cells]
    bar = progress_bar(progress, len(runs), unit="run")
    rows = []
    size = base.get("grid.size") or [base.get("grid.length")]
    for v, p, n in runs:
        bar.set_description(f"{v.label} P{p} {n} cells")
        grid = f"grid.cells=[{n}, {n}]" if base.dim == 2 else f"grid.cells={n}"
        layout = [f"particles.per_cell={L23_LAYOUT[p]}"] if v.name == "ader-dgmpm" and p in L23_LAYOUT else []
        result = run(base, [f'method.name="{v.name}"', f'method.integrator="{v.integrator}"',
                            f"method.order={p}", grid, *layout], progress=False)
        if result.status != "ok":
            raise InputError(f"{v.label} P{p} with {n} cells stopped: {result.message}")
        summary = result.summary()
        row = {"method": v.label, "order": p, "cells": n, "h": float(size[0]) / n,
               "dofs": summary["dofs"], "steps": summary["steps"], "wall_s": summary["wall_s"]}
        errors = result.errors if ref is None else reference_errors(result, ref, fields or ("eps11", "P11", "v1"))
        for name in fields or errors:
            if name not in errors:
                raise InputError(f"--fields: {name!r} is not a field of the exact solution "
                                 f"(known: {', '.join(errors)})")
            row[f"L2_{name}"] = errors[name]["L2_rel"]
        rows.append(row)
        bar.update()
    bar.close()
    _rates(rows)
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
    result = run(base, [f'method.name="{v.name}"', f'method.integrator="{v.integrator or DEFAULT_INTEGRATOR[v.name]}"',
                        f"method.order={order}", grid], progress=progress)
    if result.status != "ok":
        raise InputError(f"--reference run stopped: {result.message}")
    return GridReference(result)


def _rates(rows):
    previous = {}
    for row in rows:
        key = (row["method"], row["order"])
        for name in [k[3:] for k in row if k.startswith("L2_")]:
            before = previous.get(key)
            row[f"rate_{name}"] = (float(np.log(before[f"L2_{name}"] / row[f"L2_{name}"]) /
                                         np.log(before["h"] / row["h"])) if before else float("nan"))
        previous[key] = row


def format_table(rows):
    fields = [k[3:] for k in rows[0] if k.startswith("L2_")]
    head = f"{'method':<16}{'P':>2}{'cells':>6}{'h':>9}{'dofs':>8}{'wall s':>8}"
    head += "".join(f"{'L2 ' + f:>12}{'rate':>6}" for f in fields)
    lines = [head, "-" * len(head)]
    for r in rows:
        line = f"{r['method']:<16}{r['order']:>2}{r['cells']:>6}{r['h']:>9.4f}{r['dofs']:>8}{r['wall_s']:>8.2f}"
        line += "".join(f"{r['L2_' + f]:>12.3e}{r['rate_' + f]:>6.2f}" for f in fields)
        lines.append(line)
    return "\n".join(lines)


def write_csv(path, rows):
    with open(path, "w", newline="") as fh:
        w = csv.DictWriter(fh, fieldnames=list(rows[0]))
        w.writeheader()
        w.writerows(rows)


def plot(rows, folder):
    """error_vs_h.png and error_vs_time.png (speed against error), one line per method/order."""
    import matplotlib
    matplotlib.use("Agg", force=False)
    import matplotlib.pyplot as plt

    fields = [k[3:] for k in rows[0] if k.startswith("L2_")]
    groups = {}
    for r in rows:
        groups.setdefault((r["method"], r["order"]), []).append(r)
    for xkey, name, xlabel in (("h", "error_vs_h.png", "h (m)"), ("wall_s", "error_vs_time.png", "wall time (s)")):
        fig, axes = plt.subplots(1, len(fields), figsize=(4.2 * len(fields), 3.6), squeeze=False)
        for ax, f in zip(axes[0], fields):
            for (method, order), rs in groups.items():
                ax.loglog([r[xkey] for r in rs], [r[f"L2_{f}"] for r in rs], "o-", label=f"{method} P{order}")
            ax.set_xlabel(xlabel)
            ax.set_ylabel(f"relative L2 error of {f}")
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


def reference_errors(result, reference, fields):
    from .exact import error_norms

    values = result.fields()
    ref = reference.fields(result.X, result.state.t)
    return {k: error_norms(values[k], ref[k], result.disc.particles.volume) for k in fields}
