"""Probes: time histories of particle fields at named points, the gauges of an impact experiment
(a VISAR on the rear face, a stress gauge inside the body).

The scene names the points in the reference configuration and the fields:

    [probes]
    points = { rear = [0.01, 0.0], mid = [0.005, 0.0] }   # m, reference positions in the body
    fields = ["v1", "P11"]      # any field of `Result.fields()`; default: v_i and P_ii
    every = 1                   # steps between rows (default 1); step 0 and the last step always

A probe reads the particle nearest to its point in the reference configuration (for DGFEM the
Gauss point that stands in for it): the value is the one the method carries there, with no
interpolation, in every method alike, and the gauge stays glued to the same material as the
body deforms, as the experiment's gauges do. The rows are taken on steps fixed by the scene alone
(step 0, every ``every``-th step, the last), so a resumed run writes the rows an uninterrupted one
does; the run keeps them in its checkpoint and writes them as ``probes.csv`` (t, then one column
``field@point`` per point and field) with ``probes.png``.
"""
from dataclasses import dataclass, field

import numpy as np

from . import output
from .errors import InputError


@dataclass
class Probes:
    """The probes of a run and the rows recorded so far.

    ``names`` (k,) point names in the scene's order, ``points`` (k, d) the points asked for,
    ``particles`` (k,) the particle each one reads, ``X`` (k, d) its reference position,
    ``fields`` the field names, ``every`` steps between rows; ``t`` and ``rows`` (m, k * n_fields)
    the history. ``probes["rear", "v1"]`` is one column, ``probes.t`` the times.
    """

    names: tuple
    points: np.ndarray
    particles: np.ndarray
    X: np.ndarray
    fields: tuple
    every: int = 1
    t: list = field(default_factory=list)
    rows: list = field(default_factory=list)

    @property
    def columns(self):
        """The CSV header: "t", then ``field@point`` for each point, then each field."""
        return ["t"] + [f"{f}@{name}" for name in self.names for f in self.fields]

    def due(self, step):
        return step % self.every == 0

    def record(self, stepper, state):
        values = output.particle_fields(stepper, state, rows=self.particles)
        self.t.append(float(state.t))
        self.rows.append(np.array([values[f][k] for k in range(len(self.names)) for f in self.fields], dtype=float))

    def table(self):
        """(m, 1 + k * n_fields): t, then the columns of `columns`."""
        if not self.t:
            return np.zeros((0, len(self.columns)))
        return np.column_stack([np.asarray(self.t), np.vstack(self.rows)])

    def restore(self, table):
        self.t = [float(x) for x in table[:, 0]]
        self.rows = [row for row in table[:, 1:]]

    def __getitem__(self, key):
        if key == "t":
            return np.asarray(self.t)
        name, f = key
        if name not in self.names or f not in self.fields:
            raise KeyError(f"no probe {key!r} (points: {', '.join(self.names)}; fields: {', '.join(self.fields)})")
        j = self.names.index(name) * len(self.fields) + self.fields.index(f)
        return self.table()[:, 1 + j]

    def write_csv(self, path):
        table = self.table()
        lines = [",".join(self.columns)] + [",".join(f"{x:.12g}" for x in row) for row in table]
        with open(path, "w") as fh:
            fh.write("\n".join(lines) + "\n")


def from_scene(scene, disc):
    """The scene's `Probes`, or None without a ``[probes]`` table. One-line InputError (naming file
    or --set, key and value) for an empty or malformed table, a point outside the body (the cells
    that hold particles, in the reference configuration) or an unknown field."""
    spec = scene.get("probes")
    if spec is None:
        return None
    stepper, d, submesh = disc.stepper, scene.dim, disc.grid.submesh
    points = spec.get("points")
    if not isinstance(points, dict) or not points:
        raise InputError(f"{scene.where('probes.points')} = {points!r} must name at least one point, e.g. "
                         "points = {rear = [0.01, 0.0]} (m, reference configuration)")
    X = np.empty((len(points), d))
    for k, (name, value) in enumerate(points.items()):
        coords = [value] if d == 1 and _is_number(value) else value
        if not (isinstance(coords, list) and len(coords) == d and all(_is_number(c) for c in coords)
                and np.all(np.isfinite(coords))):
            raise InputError(f"{scene.where(f'probes.points.{name}')} = {value!r} must be a point of {d} finite "
                             "coordinate(s) (m)")
        X[k] = coords
        if not inside(submesh, X[k]):
            lo, hi = submesh.p.min(axis=1), submesh.p.max(axis=1)
            box = " x ".join(f"[{a:g}, {b:g}]" for a, b in zip(lo, hi))
            raise InputError(f"{scene.where(f'probes.points.{name}')} = {value!r} is outside the body (its cells "
                             f"in the reference configuration, within {box} m)") from None
    valid = tuple(output.particle_fields(stepper, disc.initial, rows=np.array([0])))
    fields = spec.get("fields", [f"v{i + 1}" for i in range(d)] + [f"P{i + 1}{i + 1}" for i in range(d)])
    bad = [f for f in fields if not isinstance(f, str) or f not in valid] if isinstance(fields, list) else [fields]
    if bad or not fields:
        what = f"{bad[0]!r} is not a particle field" if bad else "no field given"
        raise InputError(f"{scene.where('probes.fields')} = {fields!r}: {what} (valid: {', '.join(valid)})")
    every = spec.get("every", 1)
    if not (isinstance(every, int) and not isinstance(every, bool) and every >= 1):
        raise InputError(f"{scene.where('probes.every')} = {every!r} must be a whole number of steps >= 1")
    Xp = disc.particles.X
    nearest = np.array([int(np.argmin(np.sum((Xp - x) ** 2, axis=1))) for x in X])
    return Probes(tuple(points), X, nearest, Xp[nearest].copy(), tuple(dict.fromkeys(fields)), every)


def inside(mesh, x):
    """Whether the point ``x`` (d,) lies in a cell of ``mesh`` (segments, or convex counter-clockwise
    quads as every grid here is), to 1e-9 of the cells' size."""
    corners = mesh.p[:, mesh.t]                                          # (d, n_vertices, nel)
    tol = 1e-9 * np.ptp(mesh.p, axis=1).max()
    if mesh.dim() == 1:
        return bool(np.any((corners.min(axis=1)[0] - tol <= x[0]) & (x[0] <= corners.max(axis=1)[0] + tol)))
    a, b = corners, np.roll(corners, -1, axis=1)
    edge = np.linalg.norm(b - a, axis=0)
    cross = (b[0] - a[0]) * (x[1] - a[1]) - (b[1] - a[1]) * (x[0] - a[0])   # > 0: left of the edge
    return bool(np.any(np.all(cross >= -tol * edge, axis=0)))


def _is_number(x):
    return isinstance(x, (int, float)) and not isinstance(x, bool)
