"""Run health: the quantities that say a state is admissible, and the message when it is not.

For every point carrying the state (particles, or Gauss points for DGFEM): finite values,
J = det F > 0 and hyperbolicity, i.e. a positive definite acoustic tensor
A(N)_ij = C_iajb N_a N_b [R18 §4.2]. A is checked along the grid axes and, in 2D, the two
diagonals (a material can lose hyperbolicity off the axes first: a shear band at 45 degrees).
The fastest wave *along the grid axes* sets the time step (unchanged: Delta t = CFL h / c_max).
"""
from dataclasses import dataclass

import numpy as np
from numba import njit

from .riemann import _acoustic


def directions(d):
    """Unit normals along which hyperbolicity is checked: (n_dir, d), grid axes first."""
    axes = np.eye(d)
    if d != 2:
        return axes
    return np.vstack([axes, np.array([[1.0, 1.0], [1.0, -1.0]]) / np.sqrt(2.0)])


@dataclass
class Health:
    """Per-point health of a state.

    Attributes
    ----------
    finite : (n,) bool, all of U and Q finite
    J : (n,) det F (1 where not finite)
    omega : (n,) smallest acoustic-tensor eigenvalue over `directions` (Pa; nan where not finite)
    speed : (n,) fastest wave speed along the grid axes (m/s)
    """

    finite: np.ndarray
    J: np.ndarray
    omega: np.ndarray
    speed: np.ndarray

    @property
    def bad(self):
        return ~self.finite | ~(self.J > 0) | ~(self.omega > 0)

    def record(self):
        """The run-history columns: min J and the smallest acoustic eigenvalue over the points."""
        ok = self.finite
        return {"min_J": float(self.J[ok].min()) if ok.any() else np.nan,
                "min_acoustic": float(self.omega[ok].min()) if ok.any() else np.nan}

    def first_failure(self, state, points, d):
        """(point index, message) for the first bad point: what failed and its value; None if all
        are admissible. Order of the checks: non-finite, then J <= 0, then hyperbolicity."""
        bad = self.bad
        if not bad.any():
            return None
        p = int(np.flatnonzero(bad)[0])
        where = (f"at step {state.step}, t = {state.t:.6g} s, particle {p} in cell {int(points.cell[p])} "
                 f"(X = {np.round(points.X[p], 6).tolist()})")
        if not self.finite[p]:
            names = [f"F{i + 1}{a + 1}" for i in range(d) for a in range(d)] + [f"p{i + 1}" for i in range(d)]
            names_q = [f"P{i + 1}{a + 1}" for i in range(d) for a in range(d)] + [f"v{i + 1}" for i in range(d)]
            row = np.concatenate([state.U[p], state.Q[p]])
            k = int(np.flatnonzero(~np.isfinite(row))[0])
            return p, f"non-finite values {where}: {(names + names_q)[k]} = {row[k]}"
        if not self.J[p] > 0:
            return p, f"inverted material (det F <= 0) {where}: J = {self.J[p]:.6g}"
        return p, (f"loss of hyperbolicity {where}: smallest acoustic-tensor eigenvalue "
                   f"{self.omega[p]:.6g} Pa")


@njit(cache=True)
def _acoustic_extremes(C, N, n_axes, lowest, highest):
    """Eigenvalues of the symmetrised acoustic tensors of every point (C (n, d, d, d, d)) along
    the directions N (n_dir, d): the smallest over all of them into ``lowest`` (n,), the largest
    over the first ``n_axes`` into ``highest`` (n,). Closed form for d <= 2, LAPACK otherwise."""
    if N.shape[1] == 2:                 # a literal d: the (d, d) loops unrolled
        _acoustic_extremes_d(C, N, n_axes, lowest, highest, 2)
    else:
        _acoustic_extremes_d(C, N, n_axes, lowest, highest, N.shape[1])


@njit(cache=True, inline="always")
def _acoustic_extremes_d(C, N, n_axes, lowest, highest, d):
    A = np.empty((d, d))
    for p in range(C.shape[0]):
        lo, hi = np.inf, -np.inf
        for k in range(N.shape[0]):
            _acoustic(C[p], N[k], 1.0, A, d)
            if d == 1:
                small = large = A[0, 0]
            elif d == 2:
                m = 0.5 * (A[0, 0] + A[1, 1])
                r = np.hypot(0.5 * (A[0, 0] - A[1, 1]), 0.5 * (A[0, 1] + A[1, 0]))
                small, large = m - r, m + r
            else:
                omega = np.linalg.eigvalsh(0.5 * (A + A.T))
                small, large = omega[0], omega[-1]
            lo = min(lo, small)
            if k < n_axes:
                hi = max(hi, large)
        lowest[p], highest[p] = lo, hi


@njit(cache=True)
def _screen(U, Q, finite, F, J):
    """Per point: finite = all of U and Q finite; F = U's deformation gradient there, I elsewhere;
    J = det F (closed form for d <= 3), in one pass."""
    d = F.shape[1]
    for p in range(len(U)):
        ok = True
        for k in range(U.shape[1]):
            ok = ok and np.isfinite(U[p, k]) and np.isfinite(Q[p, k])
        finite[p] = ok
        for i in range(d):
            for a in range(d):
                F[p, i, a] = U[p, i * d + a] if ok else (1.0 if i == a else 0.0)
        f = F[p]
        if d == 1:
            J[p] = f[0, 0]
        elif d == 2:
            J[p] = f[0, 0] * f[1, 1] - f[0, 1] * f[1, 0]
        else:
            J[p] = (f[0, 0] * (f[1, 1] * f[2, 2] - f[1, 2] * f[2, 1]) + f[0, 1] * (f[1, 2] * f[2, 0] - f[1, 0] * f[2, 2])
                    + f[0, 2] * (f[1, 0] * f[2, 1] - f[1, 1] * f[2, 0]))


def assess(materials, points, U, Q):
    """`Health` of the state (U, Q) at ``points`` (with ``material``, ``rho0``) for a `MaterialSet`."""
    n, nc = U.shape
    d = int(round((-1 + np.sqrt(1 + 4 * nc)) / 2))                      # nc = d * d + d
    finite, F, J = np.empty(n, dtype=np.bool_), np.empty((n, d, d)), np.empty(n)
    _screen(U, Q, finite, F, J)
    C = materials.tangent(F, points.material)                           # (n, d, d, d, d)
    lowest, highest = np.empty(n), np.empty(n)
    _acoustic_extremes(C, directions(d), d, lowest, highest)
    rho = np.array([m.rho for m in materials.materials])[points.material]
    speed = np.sqrt(np.clip(highest, 0.0, None) / rho)
    return Health(finite, np.where(finite, J, 1.0), np.where(finite, lowest, np.nan), speed)
