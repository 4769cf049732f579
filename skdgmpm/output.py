"""Run outputs: ParaView-readable VTK time series (via meshio), energy.csv, summary.json."""
import csv
import json
from pathlib import Path
from xml.sax.saxutils import quoteattr

import meshio
import numpy as np

from . import system
from .errors import InputError


def particle_fields(stepper, state, rows=None, names=None):
    """Named particle arrays at a state: F_ij, P_ij, v_i, sigma_ij (Cauchy, 3x3), x_i and the
    laws' internal variables by name (``eqp``, the equivalent plastic strain, ...); of the
    particles ``rows`` only, if given (the probes'). With ``names``, the Cauchy stress only if a
    sigma_ij is among them (it calls the law: a run's errors against an exact solution without
    one neither compute it nor compile its kernels after the last step)."""
    d, sel = stepper.d, slice(None) if rows is None else rows
    F, p = system.split(state.U[sel], d)
    P, v = system.split(state.Q[sel], d)
    history = None if state.history is None else state.history[sel]
    stress = names is None or any(name.startswith("sigma") for name in names)
    sigma = stepper.materials.cauchy(F, stepper.particles.material[sel], history) if stress else None
    out = _history_fields(stepper.materials, history)
    for i in range(d):
        out[f"v{i + 1}"] = v[:, i]
        out[f"x{i + 1}"] = state.x[sel, i]
        for a in range(d):
            out[f"F{i + 1}{a + 1}"] = F[:, i, a]
            out[f"eps{i + 1}{a + 1}"] = 0.5 * (F[:, i, a] + F[:, a, i]) - (i == a)
            out[f"P{i + 1}{a + 1}"] = P[:, i, a]
    if stress:
        for i in range(3):
            for j in range(i, 3):
                out[f"sigma{i + 1}{j + 1}"] = sigma[:, i, j]
    return out


def _history_fields(materials, history):
    """{name: (n,)} of the history columns (none for hyperelastic laws)."""
    if history is None or not materials.n_history:
        return {}
    return {name: history[:, k] for k, name in enumerate(materials.history_names)}


def _pad3(a):
    out = np.zeros((len(a), 3))
    out[:, : a.shape[1]] = a
    return out


def _tensor9(T):
    n, d, _ = T.shape
    out = np.zeros((n, 3, 3))
    out[:, :d, :d] = T
    return out.reshape(n, 9)


FRAME_FIELDS = ("F", "P", "cauchy", "velocity", "momentum", "X", "volume", "material")


def frame_fields(scene, stepper):
    """The particle arrays a frame holds: ``run.fields`` (a list of names from `FRAME_FIELDS` and
    the law's history variables, e.g. "eqp"), default all of them; InputError (one line, naming
    file or --set, key and value, listing the valid names) otherwise. Positions are always written."""
    valid = FRAME_FIELDS + tuple(stepper.materials.history_names if stepper.materials.n_history else ())
    value = scene.get("run.fields")
    if value is None:
        return valid
    bad = [f for f in value if not isinstance(f, str) or f not in valid] if isinstance(value, list) else [value]
    if bad:
        raise InputError(f"{scene.where('run.fields')} = {value!r}: {bad[0]!r} is not a particle field of the "
                         f"frames (valid: {', '.join(valid)})")
    return tuple(dict.fromkeys(value))


def write_particles(path, stepper, state, fields=None):
    """Particles at their current positions with ``fields`` (default every one of `FRAME_FIELDS` and
    the history variables): U (``F``, ``momentum``), Q (``P``, ``velocity``), ``cauchy`` stress,
    reference position ``X``, ``volume``, ``material``.

    F is embedded in 3D as in the laws (identity out of plane); P is the d x d block, zero padded.
    """
    d = stepper.d
    F, p = system.split(state.U, d)
    P, v = system.split(state.Q, d)
    n = len(state.x)
    make = {
        "F": lambda: system.embed(F).reshape(n, 9), "P": lambda: _tensor9(P),
        "cauchy": lambda: stepper.materials.cauchy(F, stepper.particles.material, state.history).reshape(n, 9),
        "velocity": lambda: _pad3(v), "momentum": lambda: _pad3(p), "X": lambda: _pad3(stepper.particles.X),
        "volume": lambda: stepper.particles.volume, "material": lambda: stepper.particles.material.astype(float),
    }
    history = _history_fields(stepper.materials, state.history)
    names = tuple(make) + tuple(history) if fields is None else fields
    data = {k: make[k]() if k in make else history[k] for k in names}
    mesh = meshio.Mesh(_pad3(state.x), [("vertex", np.arange(n)[:, None])], point_data=data)
    mesh.write(path)


def write_grid(path, grid):
    """The full background grid, with the active cells flagged."""
    m = grid.mesh
    kind = "line" if m.dim() == 1 else "quad"
    active = np.zeros(m.nelements)
    active[grid.active] = 1.0
    meshio.Mesh(_pad3(m.p.T), [(kind, m.t.T)], cell_data={"active": [active]}).write(path)


def write_pvd(path, entries):
    """ParaView collection: ``entries`` = [(time, relative file name)]."""
    lines = ['<?xml version="1.0"?>',
             '<VTKFile type="Collection" version="0.1" byte_order="LittleEndian">', "  <Collection>"]
    lines += [f'    <DataSet timestep="{t:.9e}" part="0" file={quoteattr(f)}/>' for t, f in entries]
    lines += ["  </Collection>", "</VTKFile>", ""]
    Path(path).write_text("\n".join(lines))


def write_energy(path, history):
    keys = list(history)
    with open(path, "w", newline="") as fh:
        w = csv.writer(fh)
        w.writerow(keys)
        for row in zip(*(history[k] for k in keys)):
            w.writerow([f"{x:.12g}" if isinstance(x, float) else x for x in row])


def write_summary(path, summary):
    Path(path).write_text(json.dumps(summary, indent=2, default=float) + "\n")


def read_frame(path, stepper, t, step):
    """The `ParticleState` (without grid dofs) of a frame written by `write_particles`, exactly:
    VTU keeps the float64 arrays as written. A resumed run's `Result.frames` come from here; the
    fields that ``run.fields`` left out of the frames are NaN there."""
    from .scheme import ParticleState

    mesh = meshio.read(path)
    d, n, data = stepper.d, len(mesh.points), mesh.point_data
    nan = np.full((n, 9), np.nan)                  # a field left out by run.fields
    block = lambda name: np.asarray(data.get(name, nan)).reshape(n, 3, 3)[:, :d, :d]      # noqa: E731
    vector = lambda name: np.asarray(data.get(name, nan[:, :3]))[:, :d]                     # noqa: E731
    U = system.join(block("F"), vector("momentum"))
    Q = system.join(block("P"), vector("velocity"))
    names = stepper.materials.history_names if stepper.materials.n_history else ()
    history = np.column_stack([data.get(k, nan[:, 0]) for k in names]) if names else np.zeros((n, 0))
    return ParticleState(float(t), U, Q, np.ascontiguousarray(mesh.points[:, :d]), int(step), history=history)
