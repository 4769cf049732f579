"""The peer code in the bench: Clawpack/PyClaw's finite-volume elasticity on the bench's plate impact.

    skdgmpm bench --methods dgmpm-ctu,pyclaw-ctu --sizes 256

``pyclaw-ctu`` is PyClaw's classic wave-propagation solver (Fortran) with the Riemann solvers
``riemann.vc_elasticity_2D`` (2D variable-coefficient linear elasticity, plane strain, 5 equations:
sigma_11, sigma_22, sigma_12, u, v), first order (``solver.order = 1``) with transverse waves
(``solver.transverse_waves = 1``, corner transport upwind) and no dimensional splitting: the scheme
a user would otherwise pick for the bench's first-order DGMPM CTU row. ``pyclaw-ctu-2`` is the
same with second-order corrections and the MC limiter.

The problem is the bench's scene (`skdgmpm.bench.SCENE` on the bench's 4 x 4 plate, n x n cells),
translated: its material (E, nu, rho) becomes the Lame constants of linear elasticity, and every
boundary condition of the scene is a ghost-cell mirror (two ghost layers) whose Riemann problem
gives the condition exactly for this linear system:
- ``free`` (zero traction): normal and shear stresses negated;
- ``symmetry`` (zero normal velocity and shear): normal velocity and shear stress negated;
- the driven part (``mixed``: a normal velocity V, zero shear traction; the lower quarter of the
  left face at 1000 m/s): normal velocity mirrored about V (2 V - u), shear stress negated.
The time step is fixed: ``CFL * dx / c_p`` (CFL 0.9, PyClaw's default desired Courant number; the
cost of a step does not depend on it). The material stays linear, so the wave speeds do not grow
and no step is ever repeated.

Timing is the bench's: a fresh process per row, set-up (grid, state, solver.setup) excluded, the
CPU and wall time of each ``solver.evolve_to_time(solution)`` call (one step: boundary conditions,
the Fortran step, copies) after ``warmup`` steps, median over ``steps`` steps. The peer is serial,
so its row is a one-thread row whatever ``--threads`` says.

Rows run one after the other, seconds apart, and on a shared machine the ratio of two rows swings
with the load (0.81-1.47 over rounds whose minima agree within 6 %). So when a peer method and its
counterpart are both asked for, the bench also measures them paired (`measure_pair_here`): both
built on the same plate in one process, ours on one thread, stepping in turn (ABBA) after warm-up,
each step's CPU and wall time recorded; the ratio of two steps taken milliseconds apart sees the
same load. Its line reports the median per-pair CPU ratio, its quartiles and the ratio of the two
medians.

Clawpack is an optional dependency (``pip install '.[peer]'``); it is built from source and needs a
Fortran compiler. Without it the peer rows say so (``MISSING``) and the other rows run.
"""
import math
import resource
import statistics
import time

# how a peer row says that the peer is absent (the other rows still run; the command exits 0)
MISSING = "clawpack not installed: pip install '.[peer]' (needs gfortran: apt-get install gfortran)"

# name -> PyClaw classic solver settings
METHODS = {
    "pyclaw-ctu": {"order": 1, "transverse_waves": 1},
    "pyclaw-ctu-2": {"order": 2, "transverse_waves": 1, "limiter": "MC"},
}
# the bench row each peer row is compared with (the ratio line)
COUNTERPART = {"pyclaw-ctu": "dgmpm-ctu", "pyclaw-ctu-2": "dgmpm-ctu"}
EQUATIONS = 5          # sigma_11, sigma_22, sigma_12, u, v
OUR_EQUATIONS = 6      # DGMPM's 2D finite-strain system: velocity (2) and deformation gradient (4)
CFL = 0.9
NUM_GHOST = 2


def available():
    """Whether Clawpack's PyClaw and its compiled elasticity Riemann solvers are installed (found,
    not imported: importing PyClaw configures logging, see `_pyclaw`)."""
    from importlib.util import find_spec

    try:
        return all(find_spec(name) is not None for name in ("clawpack.pyclaw", "clawpack.riemann.vc_elasticity_2D"))
    except (ImportError, ValueError):
        return False


def _pyclaw():
    """``clawpack.pyclaw`` and ``clawpack.riemann``, imported without touching the working directory:
    PyClaw's import opens (and truncates) ``pyclaw.log`` in the current directory for its logging;
    import it from a temporary directory and close that file."""
    import logging
    import os
    import sys
    import tempfile

    if "clawpack.pyclaw" not in sys.modules:
        cwd = os.getcwd()
        with tempfile.TemporaryDirectory(prefix="skdgmpm-pyclaw-") as tmp:
            os.chdir(tmp)
            try:
                import clawpack.pyclaw  # noqa: F401
            finally:
                os.chdir(cwd)
            for logger in [logging.getLogger(), *logging.Logger.manager.loggerDict.values()]:
                for handler in list(getattr(logger, "handlers", [])):
                    if isinstance(handler, logging.FileHandler) and handler.baseFilename.startswith(tmp):
                        logger.removeHandler(handler)
                        handler.close()
    from clawpack import pyclaw, riemann
    return pyclaw, riemann


def version():
    try:
        from importlib.metadata import version as _version
        return _version("clawpack")
    except Exception:           # a source checkout without metadata
        return "unknown"


def problem(scene):
    """The bench scene translated for linear elasticity: a dict of the plate, the Lame constants,
    the density, the P-wave speed and each side's condition."""
    from .errors import InputError

    if scene.get("dim") != 2:
        raise InputError("the peer runs 2D scenes only")
    mat = scene.get("material")
    E, nu, rho = float(mat["E"]), float(mat["nu"]), float(mat["rho"])
    lam = E * nu / ((1 + nu) * (1 - 2 * nu))          # plane strain, like vc_elasticity_2D
    mu = E / (2 * (1 + nu))
    size = [float(v) for v in scene.get("grid.size")]
    cells = [int(v) for v in scene.get("grid.cells")]
    origin = [float(v) for v in scene.get("grid.origin", [0.0, 0.0])]
    bc = scene.get("bc")
    sides = {}
    for side in ("left", "right", "bottom", "top"):
        kind = bc[side]["kind"]
        if kind not in ("free", "symmetry"):
            raise InputError(f"peer: bc.{side} kind {kind!r} has no PyClaw translation (free, symmetry)")
        sides[side] = kind
    driven = None
    for name, spec in (scene.get("boundaries") or {}).items():
        cond = bc.get(name)
        if cond is None:
            continue
        box = spec.get("box", {})
        if (cond["kind"] != "mixed" or list(cond.get("traction", {})) != ["y"]
                or list(cond.get("velocity", {})) != ["x"] or box.get("x") != [origin[0], origin[0]]):
            raise InputError(f"peer: boundary {name!r}: only a shear-free normal velocity on part of the "
                             "left face has a PyClaw translation here")
        driven = {"y": [float(v) for v in box["y"]], "velocity": float(cond["velocity"]["x"])}
    return {"lam": lam, "mu": mu, "rho": rho, "cp": math.sqrt((lam + 2 * mu) / rho), "cs": math.sqrt(mu / rho),
            "size": size, "cells": cells, "origin": origin, "sides": sides, "driven": driven}


def _boundary_conditions(prob, y_with_ghost):
    """PyClaw custom ghost-cell functions (lower, upper) for the four sides of ``prob``."""
    g = NUM_GHOST
    S11, S22, S12, U, V = range(5)
    normal = {"x": (S11, U), "y": (S22, V)}         # (normal stress, normal velocity) per direction
    mask = None
    if prob["driven"] is not None:
        y0, y1 = prob["driven"]["y"]
        mask = (y_with_ghost >= y0) & (y_with_ghost <= y1)       # rows of the driven part
        velocity = prob["driven"]["velocity"]

    def flip(ghost, kind, axis):
        stress, vel = normal[axis]
        ghost[S12] *= -1.0                  # zero shear (traction) in every case here
        if kind == "free":
            ghost[stress] *= -1.0
        else:                               # symmetry: zero normal velocity
            ghost[vel] *= -1.0

    def lower(state, dim, t, qbc, auxbc, num_ghost):
        if dim.name == "x":
            qbc[:, :g, :] = qbc[:, 2 * g - 1:g - 1:-1, :]
            ghost = qbc[:, :g, :]
            if mask is None:
                flip(ghost, prob["sides"]["left"], "x")
            else:
                free = ghost[:, :, ~mask]
                flip(free, prob["sides"]["left"], "x")
                ghost[:, :, ~mask] = free
                ghost[S12, :, mask] *= -1.0
                ghost[U, :, mask] = 2.0 * velocity - ghost[U, :, mask]
        else:
            qbc[:, :, :g] = qbc[:, :, 2 * g - 1:g - 1:-1]
            flip(qbc[:, :, :g], prob["sides"]["bottom"], "y")

    def upper(state, dim, t, qbc, auxbc, num_ghost):
        if dim.name == "x":
            qbc[:, -g:, :] = qbc[:, -g - 1:-2 * g - 1:-1, :]
            flip(qbc[:, -g:, :], prob["sides"]["right"], "x")
        else:
            qbc[:, :, -g:] = qbc[:, :, -g - 1:-2 * g - 1:-1]
            flip(qbc[:, :, -g:], prob["sides"]["top"], "y")

    return lower, upper


def build(prob, order=1, transverse_waves=1, limiter=None, cfl=CFL):
    """PyClaw solver and solution for ``prob`` (see `problem`), at rest, fixed time step."""
    pyclaw, riemann = _pyclaw()
    solver = pyclaw.ClawSolver2D(riemann.vc_elasticity_2D)
    solver.order = order
    solver.transverse_waves = transverse_waves
    solver.dimensional_split = False
    if limiter is not None:
        solver.limiters = getattr(pyclaw.limiters.tvd, limiter)
    (lx, ly), (nx, ny), (ox, oy) = prob["size"], prob["cells"], prob["origin"]
    x = pyclaw.Dimension(ox, ox + lx, nx, name="x")
    y = pyclaw.Dimension(oy, oy + ly, ny, name="y")
    domain = pyclaw.Domain([x, y])
    state = pyclaw.State(domain, solver.num_eqn, 5)
    state.q[...] = 0.0
    for k, key in enumerate(("rho", "lam", "mu", "cp", "cs")):
        state.aux[k, ...] = prob[key]
    lower, upper = _boundary_conditions(prob, y.centers_with_ghost(NUM_GHOST))
    solver.bc_lower = [pyclaw.BC.custom, pyclaw.BC.custom]
    solver.bc_upper = [pyclaw.BC.custom, pyclaw.BC.custom]
    solver.user_bc_lower, solver.user_bc_upper = lower, upper
    solver.aux_bc_lower = [pyclaw.BC.extrap, pyclaw.BC.extrap]
    solver.aux_bc_upper = [pyclaw.BC.extrap, pyclaw.BC.extrap]
    solver.dt_variable = False
    solver.dt_initial = solver.dt = cfl * min(lx / nx, ly / ny) / prob["cp"]   # (the controller's copy)
    solver.cfl_max, solver.cfl_desired = 1.0, cfl
    solution = pyclaw.Solution(state, domain)
    solver.setup(solution)
    return solver, solution


def measure_here(method, n, steps, warmup):
    """One peer benchmark in this process (the bench spawns it): a bench row (dict)."""
    import numpy as np

    from .bench import scene_for

    settings = METHODS[method]
    t0 = time.perf_counter()
    tiny_solver, tiny = build(problem(scene_for(COUNTERPART[method], 4)), **settings)  # imports, the Fortran
    tiny_solver.evolve_to_time(tiny)
    startup = time.perf_counter() - t0
    base_rss = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss
    prob = problem(scene_for(COUNTERPART[method], n))
    t0 = time.perf_counter()
    solver, solution = build(prob, **settings)
    setup = time.perf_counter() - t0
    times, cpu = [], []
    for k in range(warmup + steps):
        t0, c0 = time.perf_counter(), time.process_time()
        solver.evolve_to_time(solution)                 # one step at the fixed dt
        if k >= warmup:
            times.append(time.perf_counter() - t0)
            cpu.append(time.process_time() - c0)
    step = statistics.median(times)
    q = solution.state.q
    cells = int(q.shape[1] * q.shape[2])
    peak = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss      # KiB on Linux
    return {"method": method, "cells": cells, "threads": 1, "particles": 0, "dofs": cells,
            "peer": f"clawpack {version()}", "equations": EQUATIONS,
            "startup_s": startup, "setup_s": setup, "step_s": step, "setup_in_steps": setup / step,
            "us_per_cell_step": 1e6 * step / cells,
            "cpu_us_per_cell_step": 1e6 * statistics.median(cpu) / cells, "s_per_dof_step": step / cells,
            "s_per_dof_stage": step / cells, "particles_per_s": 0.0,
            "peak_MiB": peak / 1024, "peak_over_base_MiB": (peak - base_rss) / 1024,
            "bytes_per_cell": 1024 * (peak - base_rss) / cells, "stage_s": {},
            "dt": float(solver.dt), "t": float(solution.t), "finite": bool(np.isfinite(q).all()),
            "max_speed": float(np.sqrt(q[3] ** 2 + q[4] ** 2).max())}


def measure_pair_here(method, n, steps, warmup):
    """The peer ``method`` and its counterpart (`COUNTERPART`, on one thread) built on the same n x n
    plate in this process (the bench spawns it), stepping in turn (`bench.alternate`): ``warmup``
    pairs, then ``bench.pairs_for(steps)`` timed pairs in ABBA order, each step's CPU and wall time
    recorded. Returns a paired row (dict): the quartiles of the per-pair ratios ours / peer and the
    ratio of the medians."""
    import numpy as np

    from . import parallel
    from .bench import Stepping, alternate, pairs_for, ratios, scene_for
    from .build import build as build_ours

    parallel.set_threads(1)             # the peer is serial: cost per core against cost per core
    ours = COUNTERPART[method]
    scene = scene_for(ours, n)
    step_ours = Stepping(build_ours(scene))
    solver, solution = build(problem(scene), **METHODS[method])
    pairs = pairs_for(steps)
    cpu, wall = alternate((step_ours, lambda: solver.evolve_to_time(solution)), pairs, warmup)   # [ours, peer]
    row = {"method": f"{ours}/{method}", "pair": [ours, method], "peer": f"clawpack {version()}",
           "cells": n * n, "threads": 1, "pairs": pairs, "warmup": warmup, "order": "ABBA"}
    for clock, times in (("cpu", cpu), ("wall", wall)):
        r = ratios(times[0], times[1])
        ours_s, peer_s = np.median(times, axis=1)
        row.update({f"{clock}_ratio_median": r["median"], f"{clock}_ratio_q25": r["q25"],
                    f"{clock}_ratio_q75": r["q75"], f"{clock}_medians_ratio": r["medians_ratio"],
                    f"{clock}_step_s": {"ours": float(ours_s), "peer": float(peer_s)},
                    f"{clock}_s": {"ours": times[0].tolist(), "peer": times[1].tolist()}})
    return row


def missing_row(method, n):
    return {"method": method, "cells": n * n, "threads": 1, "error": MISSING, "missing": True}


def format_ratio(rows, paired=()):
    """For each peer row, our counterpart's one-thread CPU time per cell and step over the peer's
    (same size): how many times slower (> 1) or faster (< 1) we are per core; after it, the paired
    measurement of the same size if any (`measure_pair_here`: steps alternating in one process)."""
    ours = {(r["method"], r["cells"]): r for r in rows if "error" not in r and r.get("threads", 1) == 1}
    pairs = {(p["pair"][1], p["cells"]): p for p in paired}
    lines = []
    for r in rows:
        if r["method"] not in METHODS or "error" in r:
            continue
        other = ours.get((COUNTERPART[r["method"]], r["cells"]))
        if other is not None:
            a, b = other["cpu_us_per_cell_step"], r["cpu_us_per_cell_step"]
            lines.append(f"{other['method']} / {r['method']} ({r.get('peer', 'clawpack')}), {r['cells']} cells, "
                         f"one thread: {a / b:.2f} (CPU {a:.3f} / {b:.3f} us per cell and step; "
                         f"per equation {a / OUR_EQUATIONS:.3f} / {b / EQUATIONS:.3f})")
        if (r["method"], r["cells"]) in pairs:
            lines.append(format_pair(pairs.pop((r["method"], r["cells"]))))
    return "\n".join([*lines, *map(format_pair, pairs.values())])


def format_pair(p):
    """One line of a paired row: the median per-pair CPU ratio ours / peer, its quartiles, the ratio
    of the two medians."""
    head = f"{p['pair'][0]} / {p['pair'][1]}, {p['cells']} cells, paired, alternating steps in one process"
    if "error" in p:
        return f"{head}: failed: {p['error']}"
    ours, theirs = p["cpu_step_s"]["ours"], p["cpu_step_s"]["peer"]
    return (f"{head}: {p['cpu_ratio_median']:.2f} (median of {p['pairs']} per-pair CPU ratios, {p['order']} order; "
            f"quartiles {p['cpu_ratio_q25']:.2f}-{p['cpu_ratio_q75']:.2f}; ratio of the medians "
            f"{p['cpu_medians_ratio']:.2f}: CPU {1e3 * ours:.2f} / {1e3 * theirs:.2f} ms per step)")
