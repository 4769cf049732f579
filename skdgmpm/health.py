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

from skdgmpm.materials.points import tangent_call, tangent_point

from .equations import acoustic, embed
from . import parallel
from .kernel_cache import kernel_factory, scratch
from .system import DIMENSION


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


@kernel_factory
def _assess(d):                         # a literal d: the (d, d) loops unrolled
    def assess(U, Q, material, laws, params, rho, N, n_axes, finite, J, lowest, speed):
        """Per point p: finite = all of U and Q finite; J = det F (1 where not finite); the
        eigenvalues of the symmetrised acoustic tensors of the tangent at F (I where not finite)
        along the directions N (a tuple of n_dir d-tuples): the smallest over all of them into
        ``lowest`` (nan where not finite), the fastest wave sqrt(largest / rho) over the first
        ``n_axes`` into ``speed``. One pass: the law's point tangent (`materials.points`), closed
        forms for d <= 2."""
        F, C, A, u = scratch((3, 3)), scratch((d, d, d, d)), scratch((d, d)), scratch((d * d + d,))
        for p in range(len(U)):
            ok = True
            for k in range(d * d + d):        # U.shape[1], a literal count
                u[k] = U[p, k]              # a copy, not the view U[p]: no reference counting
                ok = ok and np.isfinite(u[k]) and np.isfinite(Q[p, k])
            finite[p] = ok
            if ok:
                embed(u, F, d)
            else:                           # I where not finite
                for i in range(3):
                    for a in range(3):
                        F[i, a] = 1.0 if i == a else 0.0
            if d == 1:
                J[p] = F[0, 0]
            elif d == 2:
                J[p] = F[0, 0] * F[1, 1] - F[0, 1] * F[1, 0]
            else:
                J[p] = (F[0, 0] * (F[1, 1] * F[2, 2] - F[1, 2] * F[2, 1])
                        + F[0, 1] * (F[1, 2] * F[2, 0] - F[1, 0] * F[2, 2])
                        + F[0, 2] * (F[1, 0] * F[2, 1] - F[1, 1] * F[2, 0]))
            m = material[p]
            if d == 1:
                tangent_call(laws[m], params[m], F, C, d)
            else:
                tangent_point(laws[m], params[m], F, C, d)
            lo, hi = np.inf, -np.inf
            for k in range(len(N)):
                acoustic(C, N[k], 1.0, A, d)
                if d == 1:
                    small = large = A[0, 0]
                elif d == 2:                # eigenvalues of the symmetric part in closed form
                    mean = 0.5 * (A[0, 0] + A[1, 1])
                    x, y = 0.5 * (A[0, 0] - A[1, 1]), 0.5 * (A[0, 1] + A[1, 0])
                    r = np.sqrt(x * x + y * y)
                    small, large = mean - r, mean + r
                else:
                    omega = np.linalg.eigvalsh(0.5 * (A + A.T))
                    small, large = omega[0], omega[-1]
                lo = min(lo, small)
                if k < n_axes:
                    hi = max(hi, large)
            lowest[p] = lo if ok else np.nan
            speed[p] = np.sqrt(max(hi, 0.0) / rho[m])
    return assess


def assess(materials, points, U, Q):
    """`Health` of the state (U, Q) at ``points`` (with ``material``) for a `MaterialSet`."""
    n, nc = U.shape
    d = DIMENSION[nc]
    laws, params = materials.laws                                        # built once per set
    rho = np.array([m.rho for m in materials.materials])
    finite, J, lowest, speed = np.empty(n, dtype=np.bool_), np.empty(n), np.empty(n), np.empty(n)
    N = tuple(tuple(float(x) for x in n) for n in directions(d))       # a literal count: unrolled
    material, kernel = np.asarray(points.material, dtype=np.int64), _assess(d)
    parallel.rows(n, lambda lo, hi: kernel(U[lo:hi], Q[lo:hi], material[lo:hi], laws, params, rho, N, d,
                                           finite[lo:hi], J[lo:hi], lowest[lo:hi], speed[lo:hi]))
    return Health(finite, np.where(finite, J, 1.0), lowest, speed)
