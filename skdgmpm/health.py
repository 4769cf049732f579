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

from skdgmpm.materials.points import only_law, tangent_call, tangent_point

from .equations import embed
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

    The four arrays are None where the pass that made the health kept its summary only (a
    step's law pass: `MaterialSet.update_and_assess`); `kept` tells.
    """

    finite: np.ndarray
    J: np.ndarray
    omega: np.ndarray
    speed: np.ndarray
    summary: tuple = None       # (first bad point or -1, min J, smallest eigenvalue) over the finite points,
                                # the fastest wave over all

    @property
    def fastest(self):
        """The fastest wave speed over the points (m/s): the time step's."""
        return self.summary[3] if self.summary is not None else float(np.max(self.speed))

    @property
    def kept(self):
        """Whether the per-point arrays are held (not the summary only)."""
        return self.J is not None

    @property
    def bad(self):
        return ~self.finite | ~(self.J > 0) | ~(self.omega > 0)

    def record(self):
        """The run-history columns: min J and the smallest acoustic eigenvalue over the points."""
        if self.summary is not None:
            return {"min_J": self.summary[1], "min_acoustic": self.summary[2]}
        ok = self.finite
        return {"min_J": float(self.J[ok].min()) if ok.any() else np.nan,
                "min_acoustic": float(self.omega[ok].min()) if ok.any() else np.nan}

    def first_failure(self, state, points, d):
        """(point index, message) for the first bad point: what failed and its value; None if all
        are admissible. Order of the checks: non-finite, then J <= 0, then hyperbolicity."""
        if self.summary is not None:
            p = self.summary[0]
        else:
            bad = self.bad
            p = int(np.flatnonzero(bad)[0]) if bad.any() else -1
        if p < 0:
            return None
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


@njit(cache=True, inline="always")
def health_point(F, C, rho, d):
    """(J, lowest, speed) of one point with embedded F (3, 3) and tangent C (d, d, d, d): J = det F,
    the smallest eigenvalue of the symmetrised acoustic tensors A(N)_ij = C_iajb N_a N_b over
    `directions` (closed forms for d <= 2; in 2D A along the axes is a block of C, along the
    diagonals half the sum of four blocks), the fastest wave sqrt(largest / rho) along the axes."""
    if d == 1:
        return F[0, 0], C[0, 0, 0, 0], np.sqrt(max(C[0, 0, 0, 0], 0.0) / rho)
    if d == 2:
        J = F[0, 0] * F[1, 1] - F[0, 1] * F[1, 0]
        lo, hi = np.inf, -np.inf
        for k in range(4):
            if k < 2:                       # along axis k: the block C[:, k, :, k]
                a00, a01, a10, a11 = C[0, k, 0, k], C[0, k, 1, k], C[1, k, 0, k], C[1, k, 1, k]
            else:                           # (E1 +- E2) / sqrt(2): (C_11 + C_22 +- (C_12 + C_21)) / 2 blocks
                sg = 1.0 if k == 2 else -1.0
                a00 = 0.5 * (C[0, 0, 0, 0] + C[0, 1, 0, 1] + sg * (C[0, 0, 0, 1] + C[0, 1, 0, 0]))
                a01 = 0.5 * (C[0, 0, 1, 0] + C[0, 1, 1, 1] + sg * (C[0, 0, 1, 1] + C[0, 1, 1, 0]))
                a10 = 0.5 * (C[1, 0, 0, 0] + C[1, 1, 0, 1] + sg * (C[1, 0, 0, 1] + C[1, 1, 0, 0]))
                a11 = 0.5 * (C[1, 0, 1, 0] + C[1, 1, 1, 1] + sg * (C[1, 0, 1, 1] + C[1, 1, 1, 0]))
            mean = 0.5 * (a00 + a11)        # eigenvalues of the symmetric part in closed form
            x, y = 0.5 * (a00 - a11), 0.5 * (a01 + a10)
            r = np.sqrt(x * x + y * y)
            lo = min(lo, mean - r)
            if k < 2:
                hi = max(hi, mean + r)
        return J, lo, np.sqrt(max(hi, 0.0) / rho)
    return _health_3d(F, C, rho)


@njit(cache=True)
def _health_3d(F, C, rho):
    """`health_point` for d = 3 (eigen-decompositions along the axes), compiled once and called
    (an inlined branch would be compiled into every 1D and 2D kernel)."""
    J = (F[0, 0] * (F[1, 1] * F[2, 2] - F[1, 2] * F[2, 1]) + F[0, 1] * (F[1, 2] * F[2, 0] - F[1, 0] * F[2, 2])
         + F[0, 2] * (F[1, 0] * F[2, 1] - F[1, 1] * F[2, 0]))
    lo, hi, A = np.inf, -np.inf, np.empty((3, 3))
    for k in range(3):
        for i in range(3):
            for j in range(3):
                A[i, j] = 0.5 * (C[i, k, j, k] + C[j, k, i, k])
        omega = np.linalg.eigvalsh(A)
        lo, hi = min(lo, omega[0]), max(hi, omega[-1])
    return J, lo, np.sqrt(max(hi, 0.0) / rho)


@njit(cache=True, inline="always")
def tally(k, ok, J, lowest, speed, first, J_min, omega_min, fastest):
    """The running summary of a chunk of points after point k: (first bad point, min J, smallest
    eigenvalue) over its finite points, as numpy's min gives them (a nan eigenvalue stays), and
    the fastest wave over all its points, as numpy's max gives it (the time step's, no pass of
    its own)."""
    if first < 0 and not (ok and J > 0 and lowest > 0):
        first = k
    if ok:
        J_min = J if J < J_min else J_min
        omega_min = lowest if (lowest < omega_min or lowest != lowest) and omega_min == omega_min else omega_min
    fastest = speed if (speed > fastest or speed != speed) and fastest == fastest else fastest
    return first, J_min, omega_min, fastest


@njit(cache=True)
def summarise(starts, results):
    """`Health.summary` of a state from its chunks' (first bad, min J, smallest eigenvalue,
    fastest wave) (`parallel.chunked`'s results (chunks, 4), in chunk order; ``starts`` the
    chunks' first rows, `parallel.chunk_starts`): the first bad point of the first chunk that has
    one; the minima over the chunks (nan where no point is finite); the maximum (nan where a
    chunk's is). Compiled: the same few comparisons in Python took 30-130 µs of a step, the
    interpreter out of the caches after the law's pass."""
    first, J_min, omega_min, fastest = -1, np.inf, np.inf, -np.inf
    omega_nan = fastest_nan = False
    for c in range(results.shape[0]):
        if first < 0 and results[c, 0] >= 0:
            first = starts[c] + int(results[c, 0])
        J_min = min(J_min, results[c, 1])   # never nan: a chunk's minimum is over its finite points
        omega_nan |= results[c, 2] != results[c, 2]
        fastest_nan |= results[c, 3] != results[c, 3]
        omega_min = min(omega_min, results[c, 2])
        fastest = max(fastest, results[c, 3])
    return (first, np.nan if J_min == np.inf else J_min,
            np.nan if omega_nan or omega_min == np.inf else omega_min, np.nan if fastest_nan else fastest)


@njit(cache=True, inline="always")
def identity_if_not(ok, F):
    """F = I where a point's values are not finite (its health is then that of the identity)."""
    if not ok:
        for i in range(3):
            for a in range(3):
                F[i, a] = 1.0 if i == a else 0.0


def with_momenta(health, p, v):
    """The health of a stress pass, of F and P (`MaterialSet.stress_update`), as the state's where
    its momenta p and velocities v are finite too, else None: the whole check (`assess`), which
    finds the first bad point and says it."""
    return health if health is not None and _all_finite(p) and _all_finite(v) else None


@njit(cache=True, nogil=True)
def _all_finite(a):
    """Whether every entry of a (n, k) array (a strided view will do) is finite: one pass, no
    temporaries."""
    for i in range(a.shape[0]):
        for k in range(a.shape[1]):
            if not np.isfinite(a[i, k]):
                return False
    return True


@kernel_factory
def _assess(d, only):                   # literals: the (d, d) loops unrolled, one law's code
    def assess(U, Q, material, laws, params, rho, finite, J, lowest, speed):
        """Per point p: finite = all of U and Q finite; J, the smallest acoustic eigenvalue
        (nan where not finite) and the fastest wave along the axes at the law's point tangent
        (`health_point`; at F = I where not finite: J = 1). Returns the chunk's `tally`."""
        F, C, u = scratch((3, 3)), scratch((d, d, d, d)), scratch((d * d + d,))
        first, J_min, omega_min, fastest = -1, np.inf, np.inf, -np.inf
        for p in range(len(U)):
            ok = True
            for k in range(d * d + d):        # U.shape[1], a literal count
                u[k] = U[p, k]              # a copy, not the view U[p]: no reference counting
                ok = ok and np.isfinite(u[k]) and np.isfinite(Q[p, k])
            finite[p] = ok
            embed(u, F, d)
            identity_if_not(ok, F)
            m = material[p]
            if d == 1:
                tangent_call(laws, params, m, only, F, C, d)
            else:
                tangent_point(laws, params, m, only, F, C, d)
            J[p], lo, speed[p] = health_point(F, C, rho[m], d)
            lowest[p] = lo if ok else np.nan
            first, J_min, omega_min, fastest = tally(p, ok, J[p], lowest[p], speed[p], first, J_min, omega_min,
                                                     fastest)
        return first, J_min, omega_min, fastest
    return assess


def assess(materials, points, U, Q):
    """`Health` of the state (U, Q) at ``points`` (with ``material``) for a `MaterialSet` (the
    law's pass computes it with the stress: `MaterialSet.update_and_assess`)."""
    n, nc = U.shape
    d = DIMENSION[nc]
    laws, params = materials.laws                                        # built once per set
    finite, J, lowest, speed = np.empty(n, dtype=np.bool_), np.empty(n), np.empty(n), np.empty(n)
    material, kernel, rho = np.asarray(points.material, dtype=np.int64), _assess(d, only_law(laws)), materials.densities
    results = parallel.chunked(n, kernel, "rrrwwwrrrr", (U, Q, material, laws, params, rho, finite, J, lowest, speed),
                               4)
    return Health(finite, J, lowest, speed, summarise(parallel.chunk_starts(n), results))
