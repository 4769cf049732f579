"""Material laws evaluated on d-dimensional states, one law per particle (or node) group."""
from dataclasses import dataclass
from functools import cached_property

import numpy as np
from numba import njit

from skdgmpm.materials.points import law_table, stress_point

from .system import embed, scratch


@njit(cache=True)
def _states(laws, params, index, U, rho, Q):
    d = 2 if U.shape[1] == 6 else (1 if U.shape[1] == 2 else 3)
    if d == 2:                          # a literal d: the loops unrolled
        _states_d(laws, params, index, U, rho, Q, 2)
    else:
        _states_d(laws, params, index, U, rho, Q, d)


@njit(cache=True, inline="always")
def _states_d(laws, params, index, U, rho, Q, d):
    dd = d * d
    F, P = scratch((3, 3)), scratch((d, d))
    for k in range(len(U)):
        for i in range(3):
            for a in range(3):
                F[i, a] = U[k, i * d + a] if i < d and a < d else (1.0 if i == a else 0.0)
        m = index[k]
        stress_point(laws[m], params[m], F, P, d)
        for i in range(d):
            for a in range(d):
                Q[k, i * d + a] = P[i, a]
            Q[k, dd + i] = U[k, dd + i] / rho[k]


@dataclass(frozen=True)
class MaterialSet:
    """The scene's materials and, for a batch of points, which one applies (``index`` (n,))."""

    materials: tuple

    def _apply(self, method, F, index, shape, d, *args):
        F3 = embed(F)
        if len(self.materials) == 1:                 # no masks, no copies
            return getattr(self.materials[0], method)(F3, *args)[(slice(None),) + (slice(0, d),) * len(shape)]
        out = np.empty((len(F),) + shape)
        for k, mat in enumerate(self.materials):
            sel = index == k
            if sel.any():
                out[sel] = getattr(mat, method)(F3[sel], *args)[(slice(None),) + (slice(0, d),) * len(shape)]
        return out

    @cached_property
    def laws(self):
        """The compiled point laws' table (`skdgmpm.materials.points.law_table`)."""
        return law_table(self.materials)

    def state(self, U, index, rho):
        """Q = [P(F), p / rho0] from states U = [F, p] (n, d*d + d) and densities rho (n,): one
        compiled pass over the points (no embedded copies, masks or per-law batches)."""
        Q = np.empty(U.shape)
        _states(*self.laws, np.asarray(index, dtype=np.int64), U, np.asarray(rho, dtype=float), Q)
        return Q

    def stress(self, F, index):
        """First Piola-Kirchhoff P(F): (n, d, d) -> (n, d, d)."""
        d = F.shape[1]
        return self._apply("first_piola", F, index, (d, d), d)

    def tangent(self, F, index):
        """C = dP/dF restricted to the d-dimensional system: (n, d, d, d, d)."""
        d = F.shape[1]
        return self._apply("tangent_block", F, index, (d, d, d, d), d, d)

    def energy(self, F, index):
        """Stored energy density per reference volume (n,)."""
        F3 = embed(F)
        out = np.empty(len(F))
        for k, mat in enumerate(self.materials):
            sel = index == k
            out[sel] = mat.energy(F3[sel])
        return out

    def cauchy(self, F, index):
        """Cauchy stress sigma = P F^T / J of the embedded 3x3 state: (n, 3, 3)."""
        F3 = embed(F)
        out = np.empty((len(F), 3, 3))
        for k, mat in enumerate(self.materials):
            sel = index == k
            out[sel] = mat.cauchy(F3[sel])
        return out
