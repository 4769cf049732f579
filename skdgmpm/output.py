"""Run outputs: ParaView-readable VTK time series (via meshio), energy.csv, summary.json."""
import csv
import json
from pathlib import Path
from xml.sax.saxutils import quoteattr

import meshio
import numpy as np

from . import system


def particle_fields(stepper, state):
    """Named particle arrays at a state: F_ij, P_ij, v_i, sigma_ij (Cauchy, 3x3), x_i and the
    laws' internal variables by name (``eqp``, the equivalent plastic strain, ...)."""
    d = stepper.d
    F, p = system.split(state.U, d)
    P, v = system.split(state.Q, d)
    sigma = stepper.materials.cauchy(F, stepper.particles.material, state.history)
    out = _history_fields(stepper.materials, state.history)
    for i in range(d):
        out[f"v{i + 1}"] = v[:, i]
        out[f"x{i + 1}"] = state.x[:, i]
        for a in range(d):
            out[f"F{i + 1}{a + 1}"] = F[:, i, a]
            out[f"eps{i + 1}{a + 1}"] = 0.5 * (F[:, i, a] + F[:, a, i]) - (i == a)
            out[f"P{i + 1}{a + 1}"] = P[:, i, a]
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


def write_particles(path, stepper, state):
    """Particles at their current positions with U, Q, Cauchy stress and reference position.

    F is embedded in 3D as in the laws (identity out of plane); P is the d x d block, zero padded.
    """
    d = stepper.d
    F, p = system.split(state.U, d)
    P, v = system.split(state.Q, d)
    sigma = stepper.materials.cauchy(F, stepper.particles.material, state.history)
    n = len(state.x)
    data = {
        "F": system.embed(F).reshape(n, 9), "P": _tensor9(P), "cauchy": sigma.reshape(n, 9),
        "velocity": _pad3(v), "momentum": _pad3(p), "X": _pad3(stepper.particles.X),
        "volume": stepper.particles.volume, "material": stepper.particles.material.astype(float),
        **_history_fields(stepper.materials, state.history),
    }
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
    VTU keeps the float64 arrays as written. A resumed run's `Result.frames` come from here."""
    from .scheme import ParticleState

    mesh = meshio.read(path)
    d, n, data = stepper.d, len(mesh.points), mesh.point_data
    block = lambda name: np.asarray(data[name]).reshape(n, 3, 3)[:, :d, :d]      # noqa: E731
    U = system.join(block("F"), np.asarray(data["momentum"])[:, :d])
    Q = system.join(block("P"), np.asarray(data["velocity"])[:, :d])
    names = stepper.materials.history_names if stepper.materials.n_history else ()
    history = np.column_stack([data[k] for k in names]) if names else np.zeros((n, 0))
    return ParticleState(float(t), U, Q, np.ascontiguousarray(mesh.points[:, :d]), int(step), history=history)
