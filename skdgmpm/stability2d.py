"""Linear stability of a method's 2D (or 1D) step, read off the engine's own step.

R18 gives a von Neumann analysis in 1D only (§6; `skdgmpm.stability`) and set the 2D CFL of
DCU to 0.7 "by testing" (§7.3). Here the analysis is the step itself: on a uniform grid of
square cells, every cell with the same particle layout and a linear elastic material at rest,
one step is a linear map of the particles' U that commutes with shifts by whole cells. Its
Bloch symbol ``G(theta) = sum_r R_r exp(-i theta . r)`` (``6 npc x 6 npc``) has as blocks
``R_r`` the response of the cell at offset ``r`` to a unit change of one particle component
in a centre cell, one `DGMPM.step` per component on a small grid whose boundary the centre's
domain of dependence does not reach (a CTU step couples a cell with its eight neighbours, a
two-stage step with those at offset two). The step is stable when the spectral radius of
``G(theta)`` is at most 1 for every ``theta``; the CFL limit is found by bisection.

Units are free (the limit depends on the layout, the integrator, the transverse corrections
and Poisson's ratio only: the CFL counts cells crossed by the P wave). The same reading serves
ADER-DGMPM, ADER-DGFEM and RK-DGFEM, and 1D steps (``dim = 1``: checked against Cockburn and
Shu's RK-DG limits and `skdgmpm.stability`). `skdgmpm run` reads the
limits of the regular layouts from ``stability_2d.json`` (`limit`), written by
``python -m skdgmpm.stability2d`` (a few minutes): the analysis itself compiles the linear law's
step, which a run of another law should not wait for.
"""

from __future__ import annotations

import argparse
import functools
import itertools
import json
import warnings
from pathlib import Path

import numpy as np

__all__ = ["bracket", "dg_key", "dg_limit", "dg_limit_1d", "dg_table", "dg_table_1d", "dgmpm", "grows_at_every_cfl",
           "growth", "limit", "shown", "spectral_radius", "step_blocks", "table"]

#: The limits `skdgmpm run` checks a 2D DGMPM scene against (`table`, `limit`).
TABLE = Path(__file__).with_name("stability_2d.json")
#: Poisson's ratios of the table; a ratio between two reads the lower limit of the two.
NUS = (0.0, 0.05, 0.1, 0.15, 0.2, 0.25, 0.3, 0.35, 0.4, 0.45, 0.49)
PER_CELL = (1, 2, 3)            # particles a direction, at (k + 1/2) / n: `particles.per_cell = n`

_EPS = 1e-3          # the perturbation: the law is linear, so any size that keeps J > 0 reads R exactly
#: Offsets a step's response reaches, by its stages (CTU couples a cell with its eight neighbours a
#: stage; ADER's predictor is cell-local, its corrector one stage): the blocks are read to this
#: offset, the ring beyond checked to be zero, the grid's boundary one ring further.
REACH = {"euler": 1, "rk2": 2, "rk4": 4, "ader": 1}


def dgmpm(integrator="euler", transverse="ctu", layout="auto"):
    """The [method] table of first-order DGMPM."""
    return {"name": "dgmpm", "integrator": integrator, "transverse": transverse, "layout": layout}


def _reach(method):
    return REACH["ader" if method["name"].startswith("ader") else method.get("integrator", "euler")]


def _scene(method, per_cell, nu, cfl, n_cells, dim):
    from .scene import Scene

    grid, sides = (({"size": [1.0, 1.0], "cells": [n_cells, n_cells]}, ("left", "right", "bottom", "top")) if dim == 2
                   else ({"length": 1.0, "cells": n_cells}, ("left", "right")))
    data = {
        "dim": dim,
        "grid": grid,
        "particles": {"per_cell": [float(x) for x in per_cell] if np.ndim(per_cell) else int(per_cell)},
        "material": {"law": "linear_elastic", "E": 1.0, "nu": float(nu), "rho": 1.0},
        "bc": {side: {"kind": "transmissive"} for side in sides},
        "method": {**method, "cfl": float(cfl), "cfl_above_limit": True, "cfl_guard": "largest"},
        "run": {"t_end": 1.0},
    }
    return Scene.from_dict(data, "stability2d")


def step_blocks(per_cell=1, integrator="euler", transverse="ctu", cfl=1.0, nu=0.3, layout="auto", method=None,
                dim=2):
    """The blocks ``R_r`` of one step's Bloch symbol: first-order DGMPM with ``integrator``,
    ``transverse`` and ``layout``, or the method of the [method] table ``method`` (ADER-DGMPM,
    ADER-DGFEM, RK-DGFEM: its points are the particles or the Gauss points); in 2D, or in 1D
    with ``dim = 1`` (the bar: one wave speed, nu has no part).

    Returns
    -------
    dict
        ``{r: ndarray (nc npc, nc npc)}`` for offsets ``r`` (``(rx, ry)``, in 1D ``(rx,)``) up
        to the step's reach, ``nc`` = 6 (2D) or 2 (1D) components: row ``nc a + i`` is component
        ``i`` of point ``a`` of the cell at that offset after the step, column ``nc b + k``
        component ``k`` of point ``b`` of the centre cell before it; the points of a cell in
        the order of their (y, x) position in it.
    """
    from .build import build

    method = dict(method or dgmpm(integrator, transverse, layout))
    reach = _reach(method)
    n_cells = 2 * reach + 5
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")           # the CFL may lie above the 1D limit: that is the point
        disc = build(_scene(method, per_cell, nu, cfl, n_cells, dim))
    stepper = disc.stepper
    points_, X = stepper.particles, stepper.particles.X.reshape(len(stepper.particles.X), dim)
    h = 1.0 / n_cells
    cell = np.floor(X / h).astype(int)
    local = np.round(X / h - cell, 9)      # rounded: the points of a cell sort alike in every cell
    c = n_cells // 2
    nc = dim * dim + dim

    def points(r):
        idx = np.flatnonzero(np.all(cell == c + np.asarray(r), axis=1))
        return idx[np.lexsort(local[idx].T)]

    F0, v0 = np.tile(np.eye(dim), (len(X), 1, 1)), np.zeros((len(X), dim))
    base = stepper.step(stepper.initial_state(F0, v0))
    centre = points((0,) * dim)
    npc = len(centre)
    ring = reach + 1
    offsets = list(itertools.product(range(-ring, ring + 1), repeat=dim))
    rows = {r: points(r) for r in offsets}
    blocks = {r: np.zeros((nc * npc, nc * npc)) for r in offsets}
    for b, p in enumerate(centre):
        for k in range(nc):
            F, v = F0.copy(), v0.copy()
            if k < dim * dim:
                F[p, k // dim, k % dim] += _EPS
            else:
                v[p, k - dim * dim] += _EPS / points_.rho0[p]
            new = stepper.step(stepper.initial_state(F, v))
            if new.t != base.t:
                raise RuntimeError(f"the step's time step changed with the state ({new.t} != {base.t})")
            for r, idx in rows.items():
                blocks[r][:, nc * b + k] = ((new.U[idx] - base.U[idx]) / _EPS).ravel()
    beyond = max(np.abs(B).max() for r, B in blocks.items() if max(map(abs, r)) == ring)
    if beyond > 1e-12:
        raise RuntimeError(f"{method['name']}'s step reaches beyond offset {reach} ({beyond:.3g}): REACH is wrong")
    return {r: B for r, B in blocks.items() if max(map(abs, r)) < ring}


def spectral_radius(blocks, n_theta=None, theta=None, above=None):
    """Largest ``|eigenvalue|`` of ``G(theta)`` over an ``n_theta x n_theta`` grid of wave
    numbers (default 32; in 1D ``n_theta``, default 256), or over the wave numbers ``theta``
    (k, dim) given. The blocks are real, so ``G(-theta)`` is the conjugate of ``G(theta)``, with
    the conjugate eigenvalues: of each pair +-theta of the grid (which holds both, modulo 2 pi)
    one is read, in the grid's order (from theta = -pi). With ``above``: the largest so far as
    soon as a batch of wave numbers (`THETA_BATCH`) exceeds it, the rest unread (a bisection's
    unstable step)."""
    dim = len(next(iter(blocks)))
    n_theta = n_theta or (256 if dim == 1 else 32)
    if theta is None:
        k = np.stack([g.ravel() for g in np.meshgrid(*[np.arange(n_theta)] * dim, indexing="ij")], axis=1)
        flat, negated = (np.ravel_multi_index(tuple(i.T), (n_theta,) * dim) for i in (k, (n_theta - k) % n_theta))
        theta = -np.pi + 2 * np.pi / n_theta * k[flat <= negated]
    theta = np.asarray(theta, dtype=float).reshape(-1, dim)
    largest = 0.0
    for start in range(0, len(theta), THETA_BATCH):
        part = theta[start:start + THETA_BATCH]
        G = sum(B[None] * np.exp(-1j * (part @ np.asarray(r, dtype=float)))[:, None, None] for r, B in blocks.items())
        largest = max(largest, float(np.abs(np.linalg.eigvals(G)).max()))
        if above is not None and largest > above:
            break
    return largest


THETA_BATCH = 32       # wave numbers a batch of `spectral_radius` (its G stacked: 32 x 216 x 216 complex at ADER P5)


STABLE = 1e-9      # the growth a step may show and be called stable: the blocks are exact to rounding


def bracket(per_cell=1, integrator="euler", transverse="ctu", nu=0.3, layout="auto", lo=0.2, hi=1.4, tol=2e-3,
            n_theta=None, method=None, dim=2, growth=STABLE):
    """(lo, hi): the step is stable at CFL ``lo`` and unstable at ``hi`` (``hi - lo <= tol``),
    by bisection; stable means a spectral radius of at most 1 + ``growth`` (default `STABLE`: 1 +
    3e-13 where the limit is reached exactly; larger for a step that grows at every CFL, `growth`).
    (0, tol) where nothing is stable."""
    def stable(cfl):
        blocks = step_blocks(per_cell, integrator, transverse, cfl, nu, layout, method, dim)
        return spectral_radius(blocks, n_theta, above=1 + growth) <= 1 + growth

    if not stable(lo):                  # below the first guess: bisect from 0 (not a CFL it steps)
        lo, hi = 0.0, lo
    while hi - lo > tol:
        mid = 0.5 * (lo + hi)
        lo, hi = (mid, hi) if stable(mid) else (lo, mid)
    return lo, hi


def _key(per_cell, integrator, transverse):
    return f"{per_cell} {integrator} {transverse}"


#: The DG methods' rows of the table: ADER-DGMPM's step has ADER-DGFEM's limits where it has P + 1
#: particles a direction (L23's S1, S2: its reconstruction then interpolates them). ADER P >= 4
#: at the knee of its slow growth (`SLOW_GROWTH`). In 2D P3's rows take 12 (ADER, reach 1) and 16
#: minutes (RK4, reach 4) here, ADER P4's 5 and P5's 18 (half the wave numbers read, an unstable
#: bisection step stopped at its first batch above: `spectral_radius`); in 1D a row takes a second.
#: Left out: RK2 with P >= 2, which grows at every CFL with no knee (`grows_at_every_cfl`): its
#: limit would be the tolerance's.
DG_ROWS = {**{f"ader {p}": {"name": "ader-dgfem", "order": p} for p in (1, 2, 3, 4, 5)},
           "rk-dgfem 1 rk2": {"name": "rk-dgfem", "order": 1, "integrator": "rk2"},
           **{f"rk-dgfem {p} rk4": {"name": "rk-dgfem", "order": p, "integrator": "rk4"} for p in (1, 2, 3)}}
#: Rows whose step grows at every CFL, slowly up to a knee and fast beyond it (1D ADER P4: 1 +
#: 4.9e-6 a step at 0.6, 1 + 0.08 at 0.65): their bracket is that knee, the largest CFL at which
#: no mode grows by more than this much a step.
SLOW_GROWTH = {"ader 4": 1e-4, "ader 5": 1e-4}


def growth(key):
    """The growth a step may show where the table's row ``key`` is its limit: its knee's
    (`SLOW_GROWTH`), else `STABLE`."""
    return SLOW_GROWTH.get(key, STABLE)


def grows_at_every_cfl(name, order, integrator):
    """Why no CFL makes this DG step stable, or None: RK2 with P >= 2 (RK order below P + 1;
    1 + 2.6e-10 a step at 0.15, 1 + 5.6e-6 at 0.4 for P2) and ADER with P >= 4 (an independent
    ADER-DG grows alike, tests/test_stability2d.py: the scheme's own) grow slowly at every CFL."""
    if name == "rk-dgfem" and integrator == "rk2" and order >= 2:
        return (f"rk-dgfem P{order} with rk2 grows at every CFL, slowly (P2: 1 + 5.6e-6 a step at 0.4): a long "
                f"run grows; with rk4 it does not")
    if name in ("ader-dgfem", "ader-dgmpm") and order >= 4:
        return (f"{name} P{order} grows at every CFL, slowly below its knee (1D: 1 + 1.1e-6 a step at 0.3 for P4, "
                f"1 + 1.3e-5 for P5): a long run grows")
    return None


def shown(pair):
    """A bracket (stable, unstable) as text: 1.0 where it holds 1 (CTU's and RK2 with DCU's limit,
    reached exactly), else its stable end to three decimals."""
    stable, unstable = pair
    return "1.0" if stable <= 1.0 <= unstable else f"{stable:.3f}"


def dg_key(name, order, integrator=None):
    """The table's row of a DG method, in 1D and 2D alike (None where it has none)."""
    key = f"ader {order}" if name in ("ader-dgfem", "ader-dgmpm") else f"rk-dgfem {order} {integrator}"
    return key if key in DG_ROWS else None


def _row(key, nus, progress, *args, **keys):
    """[[lo, hi] per nu] of `bracket` (its arguments ``args``, ``keys``), rounded; said as it ends."""
    pairs = [[round(x, 6) for x in bracket(*args, nu=nu, **keys)] for nu in nus]
    progress(f"{key}: " + " ".join(f"{lo:.3f}" for lo, _ in pairs))
    return pairs


def dg_table(rows=tuple(DG_ROWS), nus=NUS, progress=print):
    """{row: [[lo, hi] per nu]} of the DG methods (`DG_ROWS`)."""
    return {key: _row(key, nus, progress, 1, method=DG_ROWS[key], growth=growth(key)) for key in rows}


def dg_table_1d(rows=tuple(DG_ROWS), progress=print):
    """{row: [lo, hi]} of the DG methods' 1D steps (one wave speed: no nu)."""
    return {key: _row(f"{key}, 1D", (0.0,), progress, 1, hi=2.0, method=DG_ROWS[key], dim=1,
                      growth=growth(key))[0] for key in rows}


def table(per_cells=PER_CELL, nus=NUS, progress=print):
    """{"nu": nus, "limits": {"n integrator transverse": [[lo, hi] per nu]}} for every regular
    layout, integrator and transverse correction."""
    limits = {_key(*row): _row(_key(*row), nus, progress, *row)
              for row in itertools.product(per_cells, ("euler", "rk2"), ("ctu", "dcu"))}
    return {"about": "CFL limits of 2D steps (skdgmpm.stability2d): DGMPM per layout 'n integrator "
                     "transverse' (limits), the DG methods per row of DG_ROWS (dg), one [stable, unstable] "
                     "CFL pair per Poisson's ratio",
            "nu": list(nus), "limits": limits}


@functools.lru_cache(maxsize=1)
def _table():
    return json.loads(TABLE.read_text(encoding="utf-8"))


def limit(per_cell, integrator, transverse, nus):
    """(stable, unstable) CFL of first-order DGMPM with a regular layout of ``per_cell``
    particles a direction, for materials of Poisson's ratios ``nus``, from the table: the lowest
    over the materials and, for a ratio between two of the table's, over both. None where the
    table has no entry."""
    return _lowest(_table()["limits"].get(_key(per_cell, integrator, transverse)), nus)


def dg_limit(key, nus):
    """As `limit`, for the DG method of row ``key`` (`dg_key`)."""
    return _lowest(_table()["dg"].get(key), nus)


def dg_limit_1d(key):
    """(stable, unstable) CFL of the 1D step of the DG method of row ``key``, or None."""
    pair = _table()["dg_1d"].get(key)
    return None if pair is None else tuple(pair)


def _lowest(rows, nus):
    grid = np.asarray(_table()["nu"])
    if rows is None or not nus or any(not grid[0] <= nu <= grid[-1] for nu in nus):
        return None
    pairs = []
    for nu in nus:
        k = int(np.searchsorted(grid, nu))
        pairs += [rows[k]] if grid[k] == nu else [rows[k - 1], rows[k]]
    return min(pairs, key=lambda pair: pair[1])


def main(argv=None):
    parser = argparse.ArgumentParser(prog="python -m skdgmpm.stability2d",
                                     description="Write the CFL limits that skdgmpm run checks.")
    parser.add_argument("--out", type=Path, default=TABLE, help=f"JSON file (default {TABLE})")
    parser.add_argument("--only", choices=PARTS, help="recompute one part, keep the others from --out")
    parser.add_argument("--rows", nargs="+", metavar="ROW",
                        help="with --only dg or dg_1d: recompute these rows (e.g. 'ader 4'), keep the others")
    args = parser.parse_args(argv)
    if args.rows and (args.only not in ROWS or not set(args.rows) <= set(DG_ROWS)):
        parser.error(f"--rows {' '.join(args.rows)}: rows of --only dg or dg_1d, one of: {', '.join(DG_ROWS)}")
    data = json.loads(args.out.read_text(encoding="utf-8")) if args.only else {}
    for part, compute in PARTS.items():
        if args.only in (None, part):
            data.update({part: {**data[part], **ROWS[part](args.rows)}} if args.rows else compute())
    args.out.write_text(json.dumps(data, indent=1) + "\n", encoding="utf-8")
    print(f"wrote {args.out}")
    return 0


#: The table's parts and what computes each (`main`).
PARTS = {"dgmpm": lambda: table(), "dg": lambda: {"dg": dg_table()}, "dg_1d": lambda: {"dg_1d": dg_table_1d()}}
ROWS = {"dg": dg_table, "dg_1d": dg_table_1d}       # the DG parts, row by row (`main`'s --rows)


if __name__ == "__main__":
    raise SystemExit(main())
