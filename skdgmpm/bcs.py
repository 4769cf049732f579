"""Boundary conditions by ghost states [R18 §4.5], selected by boundary name.

A ghost state copies the free quantities of the interior state and is solved for the imposed ones
so that the stationary state Q* of the Riemann problem (interior, ghost) honours the condition.
With the interior's linearisation on both sides, Q* lies on the interior's left-going
characteristic ``t* - t_L = Z (v* - v_L)``; each condition below fixes, in an orthonormal frame,
either the velocity or the traction component, which determines (t*, v*) exactly. The ghost state
itself is then ``(2 t* - t_L, v_L)`` (velocity copied) and is never needed explicitly.

Values may depend on time through a `Schedule` (step at t = 0, release at t_u, linear ramp).
"""
from dataclasses import dataclass, field

import numpy as np
from numba import njit

from .equations import _solve, traction
from .errors import InputError
from .kernel_cache import kernel_factory, scratch

AXES = "xyz"


@dataclass(frozen=True)
class Schedule:
    """Amplitude a(t) multiplying a boundary value (after a release, imposed values are zero).

    ``release`` (s): a(t) = 1 before, 0 from then on; ``ramp`` (s): a(t) = min(t / ramp, 1).
    """

    release: float = np.inf
    ramp: float = 0.0

    def __call__(self, t):
        a = min(t / self.ramp, 1.0) if self.ramp > 0 else 1.0
        return a if t < self.release else 0.0


def _frame(N, local):
    """(nf, d, d) rows = frame directions: global axes, or (normal, tangent) when ``local``."""
    nf, d = N.shape
    if not local or d == 1:
        return np.broadcast_to(np.eye(d), (nf, d, d)) if not local else N[:, None, :].copy()
    T = np.stack([-N[:, 1], N[:, 0]], axis=1)
    return np.stack([N, T], axis=1)


def star_state(frame, imposes_velocity, values, t_L, v_L, Z):
    """Solve for (t*, v*) with ``t* - Z v* = t_L - Z v_L`` and, for each frame direction k,
    ``e_k . v* = values[k]`` if ``imposes_velocity[k]`` else ``e_k . t* = values[k]``.

    frame (nf, d, d), imposes_velocity (nf, d) or (d,) bool, values (nf, d) or (d,), states
    (nf, d), Z (nf, d, d). One compiled pass over the faces (a 2d x 2d system each,
    `equations._solve`).
    """
    nf, d = v_L.shape
    t_s, v_s = np.empty((nf, d)), np.empty((nf, d))
    if nf:
        _star_states(d)(np.ascontiguousarray(np.broadcast_to(frame, (nf, d, d)), dtype=float),
                        np.ascontiguousarray(np.broadcast_to(imposes_velocity, (nf, d)), dtype=np.bool_),
                        np.ascontiguousarray(np.broadcast_to(values, (nf, d)), dtype=float),
                        t_L, v_L, Z, t_s, v_s)
    return t_s, v_s


@kernel_factory
def _star_states(d):                    # a literal d: the 2d x 2d system unrolled
    def star_states(frame, velocity, values, t_L, v_L, Z, t_s, v_s):
        for f in range(len(t_L)):
            star_face(frame, velocity, values, f, t_L[f], v_L[f], Z[f], t_s[f], v_s[f], d)
    return star_states


@njit(cache=True, inline="always")
def star_face(frame, velocity, values, f, t_L, v_L, Z, t_s, v_s, d):
    """(t*, v*) of face f into t_s, v_s (d,): its 2d x 2d system (`equations._solve`), its frame,
    imposed components and values read in row f of `star_state`'s arrays (entries, not row
    views: a view is reference counted, which cost the boundary pass more than its arithmetic).
    Also the boundary pass of first-order DGMPM (`dgmpm_kernels.boundary_faces`)."""
    A, b, x = scratch((2 * d, 2 * d)), scratch((2 * d,)), scratch((2 * d,))
    for i in range(d):                  # unknowns x = [t*, v*]
        zv = 0.0
        for j in range(d):
            A[i, j] = 1.0 if i == j else 0.0
            A[i, d + j] = -Z[i, j]
            zv += Z[i, j] * v_L[j]
            A[d + i, j] = 0.0 if velocity[f, i] else frame[f, i, j]
            A[d + i, d + j] = frame[f, i, j] if velocity[f, i] else 0.0
        b[i] = t_L[i] - zv
        b[d + i] = values[f, i]
    _solve(A, b, x, 2 * d)
    for i in range(d):
        t_s[i], v_s[i] = x[i], x[d + i]


@njit(cache=True, inline="always")
def ghost_face(ghosts, f, q, n, Z, t_L, v_L, t_s, v_s, d):
    """Face f's interior traction t_L = P n and velocity v_L (d,) from its state row q = [P, v]
    (nc,) and its stationary state (t*, v*) into t_s, v_s (d,): the interior's where its condition
    imposes nothing, else `star_face` (impedance Z (d, d)). ``ghosts`` = (frame (nf, d, d), imposes
    velocity (nf, d), values at the time (nf, d), copies the interior (nf,)), `BoundaryGhosts`'s.
    The boundary passes of first-order DGMPM (`dgmpm_kernels.boundary_faces`) and of the DG methods
    (`riemann.boundary_fluxes`)."""
    frame, velocity, values, copy = ghosts
    traction(q, n, t_L, d)
    for i in range(d):
        v_L[i] = q[d * d + i]
    if copy[f]:                     # nothing imposed: the ghost is the interior
        for i in range(d):
            t_s[i], v_s[i] = t_L[i], v_L[i]
    else:
        star_face(frame, velocity, values, f, t_L, v_L, Z, t_s, v_s, d)


@dataclass(frozen=True)
class BoundaryCondition:
    """Base class: a kind says, in `ghost_rule`, which velocity or traction components it imposes
    in which frame (its values scaled by the schedule); ``star(t, t_L, v_L, Z, N)`` is then the
    boundary stationary state (t*, v*) (`star_state`), the same for every kind."""

    schedule: Schedule = field(default_factory=Schedule, kw_only=True)

    def ghost_rule(self, N):
        """(frame (nf, d, d), imposes_velocity (d,) bool, values (d,) before the schedule) at
        faces of outward normals N (nf, d); None: the ghost is the interior (nothing imposed)."""
        raise NotImplementedError

    def star(self, time, t_L, v_L, Z, N):
        rule = self.ghost_rule(N)
        if rule is None:
            return t_L.copy(), v_L.copy()
        frame, imposes_velocity, values = rule
        return star_state(frame, imposes_velocity, values * self.schedule(time), t_L, v_L, Z)

    def constraints(self, N):
        """Frame (nf, d, d) and which of its velocity / traction components are imposed ((d,)
        bools each), read from `ghost_rule`; corrections of the boundary flux may only change the
        free ones."""
        rule = self.ghost_rule(N)
        if rule is None:                    # nothing imposed
            d = N.shape[1]
            return _frame(N, False), np.zeros(d, bool), np.zeros(d, bool)
        frame, imposes_velocity, _ = rule
        return frame, imposes_velocity, ~imposes_velocity


@dataclass(frozen=True)
class Mixed(BoundaryCondition):
    """Per global axis, an imposed velocity or traction component (m/s or Pa)."""

    velocity: dict = field(default_factory=dict)
    traction: dict = field(default_factory=dict)

    def ghost_rule(self, N):
        d = N.shape[1]
        imposes_velocity = np.array([AXES[k] in self.velocity for k in range(d)])
        values = np.array([self.velocity.get(AXES[k], self.traction.get(AXES[k], 0.0))
                           for k in range(d)], dtype=float)
        return _frame(N, False), imposes_velocity, values


FREE = Mixed()
"""Traction-free surface: the condition of boundary faces that have none."""


def Velocity(value, schedule=Schedule()):
    """Imposed velocity vector (m/s)."""
    return Mixed(velocity=dict(zip(AXES, map(float, value))), schedule=schedule)


def Traction(value, schedule=Schedule()):
    """Imposed traction vector t = P N (Pa); zero is a free surface."""
    return Mixed(traction=dict(zip(AXES, map(float, value))), schedule=schedule)


@dataclass(frozen=True)
class NormalVelocity(BoundaryCondition):
    """Imposed velocity along the outward normal (m/s), zero tangential traction.

    ``value = 0`` is a symmetry plane (sliding wall).
    """

    value: float = 0.0

    def ghost_rule(self, N):
        d = N.shape[1]
        values = np.zeros(d)
        values[0] = self.value
        return _frame(N, True), np.arange(d) == 0, values


def Symmetry(schedule=Schedule()):
    return NormalVelocity(0.0, schedule=schedule)


@dataclass(frozen=True)
class Transmissive(BoundaryCondition):
    """Ghost = interior: waves leave without reflection (exact for normal incidence)."""

    def ghost_rule(self, N):
        return None


class BoundaryGhosts:
    """The stationary states of every boundary face of a grid in one compiled pass
    (`star_state`), each face under its group's condition: what `BoundaryCondition.star` does
    group by group, with the frames and imposed components gathered once (a step then computes
    only the schedules' amplitudes). ``groups``: [(faces mask (nb,), condition)], each face in
    one group; N (nb, d) the outward normals."""

    def __init__(self, groups, N):
        nb, d = N.shape
        self.frame = np.broadcast_to(np.eye(d), (nb, d, d)).copy()
        self.velocity = np.ones((nb, d), dtype=np.bool_)
        self.values = np.zeros((nb, d))
        self.group = np.zeros(nb, dtype=np.int64)
        self.copy = np.zeros(nb, dtype=np.bool_)
        self.schedules = []
        for g, (sel, bc) in enumerate(groups):
            rule = bc.ghost_rule(N[sel])
            if rule is None:
                self.copy[sel] = True
            else:
                self.frame[sel], self.velocity[sel], self.values[sel] = rule
            self.group[sel] = g
            self.schedules.append(bc.schedule)
        self.any_copy = bool(self.copy.any())
        self._at = None                 # (amplitudes, values) of the last values_at

    def values_at(self, time):
        """The imposed values (nb, d) at ``time`` (each group's schedule applied): the same array
        while the amplitudes stay as they were (every step of a constant load), never written."""
        amplitude = tuple(schedule(time) for schedule in self.schedules)
        kept = self._at
        if kept is None or kept[0] != amplitude:
            values = self.values * np.array(amplitude)[self.group][:, None]
            self._at = kept = (amplitude, values)
        return kept[1]

    def star(self, time, t_L, v_L, Z):
        """(t*, v*) (nb, d) of every boundary face at ``time``."""
        t_L, v_L, Z = (np.ascontiguousarray(a, dtype=float) for a in (t_L, v_L, Z))
        t_s, v_s = star_state(self.frame, self.velocity, self.values_at(time), t_L, v_L, Z)
        if self.any_copy:
            t_s[self.copy], v_s[self.copy] = t_L[self.copy], v_L[self.copy]
        return t_s, v_s


KINDS = ("velocity", "traction", "free", "symmetry", "normal_velocity", "transmissive", "mixed")


def make_bc(spec, d, where="boundary"):
    """Build a condition from a scene table, e.g. ``{kind = "traction", value = [-1e9]}``."""
    spec = dict(spec)
    kind = spec.pop("kind", None)
    if kind not in KINDS:
        raise InputError(f"{where}.kind = {kind!r}: expected one of {', '.join(KINDS)}")
    schedule = Schedule(release=float(spec.pop("release", np.inf)), ramp=float(spec.pop("ramp", 0.0)))

    def vector(key):
        value = spec.pop(key, None)
        if value is None:
            raise InputError(f"{where}.{key} is missing for kind = {kind!r}")
        array = np.atleast_1d(np.asarray(value, dtype=float)) if _numeric(value) else None
        if array is None or array.shape != (d,):
            raise InputError(f"{where}.{key} = {value!r} must be {d} number(s)")
        return array

    if kind == "velocity":
        bc = Velocity(vector("value"), schedule)
    elif kind == "traction":
        bc = Traction(vector("value"), schedule)
    elif kind == "free":
        bc = Traction(np.zeros(d), schedule)
    elif kind == "symmetry":
        bc = Symmetry(schedule)
    elif kind == "normal_velocity":
        bc = NormalVelocity(float(spec.pop("value", 0.0)), schedule=schedule)
    elif kind == "transmissive":
        bc = Transmissive(schedule=schedule)
    else:
        parts = {}
        for key in ("velocity", "traction"):
            table = dict(spec.pop(key, {}))
            for axis, value in table.items():
                if axis not in AXES[:d] or not _numeric(value):
                    raise InputError(f"{where}.{key}.{axis} = {value!r}: expected axis in "
                                     f"{AXES[:d]} and a number")
            parts[key] = {k: float(v) for k, v in table.items()}
        overlap = set(parts["velocity"]) & set(parts["traction"])
        if overlap or len(parts["velocity"]) + len(parts["traction"]) != d:
            raise InputError(f"{where}: mixed needs exactly one of velocity/traction per axis "
                             f"{AXES[:d]}, got velocity={parts['velocity']} traction={parts['traction']}")
        bc = Mixed(**parts, schedule=schedule)
    if spec:
        raise InputError(f"{where}: unknown key {next(iter(spec))!r} for kind = {kind!r}")
    return bc


def _numbers(value):
    """Numbers (not strings, not booleans), or nested lists of them."""
    if isinstance(value, (list, tuple)):
        return all(_numbers(v) for v in value)
    return isinstance(value, (int, float, np.number)) and not isinstance(value, (bool, np.bool_))


def _numeric(value):
    """Finite numbers, or lists of them: ["1e9"] is a string, not a number (np.asarray would
    convert it)."""
    if not _numbers(value):
        return False
    try:
        arr = np.asarray(value, dtype=float)
    except (TypeError, ValueError):
        return False
    return bool(np.all(np.isfinite(arr)))
