"""Explicit one-step time integrators, each written once over the primitive every spatial operator
provides (`skdgmpm.scheme`):

    stage(U_eval, base, t, step) -> (base + step L(U_eval, t), power)

L = M^-1 R, the semi-discrete right-hand side at U_eval with boundary values at time t; ``power``
the power through the boundary of that evaluation (W). A scheme fuses the update into its pass over
the nodes (DGMPM) or over the cells' mass blocks (DGFEM, which also applies its limiter to each
stage's result). ``base`` is an array, or a `Combination` of earlier states (RK2's mean, RK4's
last base) that the scheme's update pass forms entry by entry where it reads it (`base_parts`,
`base_entry`): no pass over memory of its own, the same bits (`formed` forms it in numpy, for a
stage without such a pass). ADER-DG is not a Runge-Kutta method: its predictor-corrector step is the
scheme's own (`skdgmpm.ader`). Each returns (U at t + dt, boundary work over the step (J)).

Each entry of a combination of states is computed by the same operations in the same order as
the numpy expression in its comment (the same bits, for any thread count).
"""
from typing import NamedTuple

from numba import njit

MEAN, RK4_BASE = 1, 2           # the kinds of `Combination` (0: an array, `base_parts`)


class Combination(NamedTuple):
    """A stage's base as a combination of earlier states (arrays of one shape), formed by the
    scheme's update pass where it reads each entry (`base_entry`): ``kind`` MEAN, (a + b) / 2 of
    ``arrays`` = (a, b); RK4_BASE, (a + 2 b + c - d) / 3 of (a, b, c, d)."""
    kind: int
    arrays: tuple

    @property
    def shape(self):
        return self.arrays[0].shape


def base_parts(base):
    """(kind, four arrays) of a stage's base as an update pass takes it (`base_entry`): an array
    is kind 0, itself four times; a `Combination` its kind and arrays (padded with its first)."""
    if isinstance(base, Combination):
        return base.kind, tuple(base.arrays) + (base.arrays[0],) * (4 - len(base.arrays))
    return 0, (base, base, base, base)


@njit(cache=True, inline="always")
def base_entry(kind, bases, i, j):
    """Entry (i, j) of a stage's base from `base_parts`."""
    a, b, c, d = bases
    if kind == MEAN:
        return 0.5 * (a[i, j] + b[i, j])                        # 0.5 * (U + U1)
    if kind == RK4_BASE:
        return (a[i, j] + 2.0 * b[i, j] + c[i, j] - d[i, j]) / 3.0      # (U2 + 2 U3 + U4 - U) / 3
    return a[i, j]


def formed(base):
    """A stage's base as an array (numpy's operations of `base_entry`): for a stage whose update
    has no pass to form it in."""
    if not isinstance(base, Combination):
        return base
    a = base.arrays
    return 0.5 * (a[0] + a[1]) if base.kind == MEAN else (a[0] + 2.0 * a[1] + a[2] - a[3]) / 3.0


def euler(stage, U, t, dt):
    """Forward Euler [R18 eq 20], boundary values at mid-step: the step's mean for a ramp, and a
    release at t_u = n dt is not missed through round-off in t."""
    U1, power = stage(U, U, t + 0.5 * dt, dt)
    return U1, dt * power


def heun(stage, U, t, dt):
    """Heun's method (TVD-RK2) [R18 §7.1]: U1 = U + dt L(U, t), U2 = (U + U1) / 2 + dt / 2 L(U1, t + dt)."""
    U1, p1 = stage(U, U, t, dt)
    U2, p2 = stage(U1, Combination(MEAN, (U, U1)), t + dt, 0.5 * dt)      # 0.5 * (U + U1)
    return U2, 0.5 * dt * (p1 + p2)


def rk4(stage, U, t, dt):
    """The classical fourth-order Runge-Kutta method, its stages U + c dt k_i formed by ``stage``:
    with U2 = U + dt/2 k1, U3 = U + dt/2 k2, U4 = U + dt k3, the result U + dt/6 (k1 + 2 k2 + 2 k3
    + k4) is (U2 + 2 U3 + U4 - U) / 3 + dt/6 k4."""
    U2, p1 = stage(U, U, t, 0.5 * dt)
    U3, p2 = stage(U2, U, t + 0.5 * dt, 0.5 * dt)
    U4, p3 = stage(U3, U, t + 0.5 * dt, dt)
    U5, p4 = stage(U4, Combination(RK4_BASE, (U2, U3, U4, U)), t + dt, dt / 6.0)   # (U2 + 2 U3 + U4 - U) / 3
    return U5, dt / 6.0 * (p1 + 2.0 * p2 + 2.0 * p3 + p4)


INTEGRATORS = {"euler": euler, "rk2": heun, "rk4": rk4}
# right-hand sides one step evaluates (per-stage costs in the benchmarks)
EVALUATIONS = {"euler": 1, "rk2": 2, "rk4": 4}
