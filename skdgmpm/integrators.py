"""Explicit one-step time integrators, each written once over the primitive every spatial operator
provides (`skdgmpm.scheme`):

    stage(U_eval, base, t, step) -> (base + step L(U_eval, t), power)

L = M^-1 R, the semi-discrete right-hand side at U_eval with boundary values at time t; ``power``
the power through the boundary of that evaluation (W). A scheme fuses the update into its pass over
the nodes (DGMPM) or forms it after the right-hand side (DGFEM, which also applies its limiter to
each stage's result). ADER-DG is not a Runge-Kutta method: its predictor-corrector step is the
scheme's own (`skdgmpm.ader`). Each returns (U at t + dt, boundary work over the step (J)).

The combinations of states between the stages are compiled passes on the threads
(`skdgmpm.parallel`), each entry computed by the same operations in the same order as the numpy
expression in its comment (the same bits, for any thread count).
"""
import numpy as np
from numba import njit

from . import parallel


def _combine(kernel, *arrays):
    """``kernel(*flat chunks, out chunk)`` over the entries of equally shaped arrays, in parallel."""
    flat = [np.ascontiguousarray(a).reshape(-1) for a in arrays]
    out = np.empty(arrays[0].shape)
    o = out.reshape(-1)
    parallel.chunked(len(o), kernel, "r" * (len(flat) + 1), (*flat, o))
    return out


@njit(cache=True, nogil=True)
def _mean(a, b, out):
    for i in range(len(out)):
        out[i] = 0.5 * (a[i] + b[i])


@njit(cache=True, nogil=True)
def _rk4_base(U2, U3, U4, U, out):
    for i in range(len(out)):
        out[i] = (U2[i] + 2.0 * U3[i] + U4[i] - U[i]) / 3.0


def euler(stage, U, t, dt):
    """Forward Euler [R18 eq 20], boundary values at mid-step: the step's mean for a ramp, and a
    release at t_u = n dt is not missed through round-off in t."""
    U1, power = stage(U, U, t + 0.5 * dt, dt)
    return U1, dt * power


def heun(stage, U, t, dt):
    """Heun's method (TVD-RK2) [R18 §7.1]: U1 = U + dt L(U, t), U2 = (U + U1) / 2 + dt / 2 L(U1, t + dt)."""
    U1, p1 = stage(U, U, t, dt)
    U2, p2 = stage(U1, _combine(_mean, U, U1), t + dt, 0.5 * dt)      # 0.5 * (U + U1)
    return U2, 0.5 * dt * (p1 + p2)


def rk4(stage, U, t, dt):
    """The classical fourth-order Runge-Kutta method, its stages U + c dt k_i formed by ``stage``:
    with U2 = U + dt/2 k1, U3 = U + dt/2 k2, U4 = U + dt k3, the result U + dt/6 (k1 + 2 k2 + 2 k3
    + k4) is (U2 + 2 U3 + U4 - U) / 3 + dt/6 k4."""
    U2, p1 = stage(U, U, t, 0.5 * dt)
    U3, p2 = stage(U2, U, t + 0.5 * dt, 0.5 * dt)
    U4, p3 = stage(U3, U, t + 0.5 * dt, dt)
    U5, p4 = stage(U4, _combine(_rk4_base, U2, U3, U4, U), t + dt, dt / 6.0)   # (U2 + 2 U3 + U4 - U) / 3
    return U5, dt / 6.0 * (p1 + 2.0 * p2 + 2.0 * p3 + p4)


INTEGRATORS = {"euler": euler, "rk2": heun, "rk4": rk4}
# right-hand sides one step evaluates (per-stage costs in the benchmarks)
EVALUATIONS = {"euler": 1, "rk2": 2, "rk4": 4}
