"""Saint-Venant-Kirchhoff hyperelasticity [R18 App. A]."""

from dataclasses import dataclass

import numpy as np
from numba import njit

from skdgmpm.kernel_cache import scratch

from .base import Material, PointLaw

_I = np.eye(3)


@njit(cache=True, inline="always")
def _green_lagrange_point(F, E):
    """E = (F^T F - I) / 2 of one embedded F (3, 3) into E (3, 3); returns tr E."""
    trE = 0.0
    for a in range(3):
        for b in range(3):
            s = 0.0
            for k in range(3):
                s += F[k, a] * F[k, b]
            E[a, b] = 0.5 * (s - (1.0 if a == b else 0.0))
        trE += E[a, a]
    return trE


@njit(cache=True, inline="always")
def stress_point(F, prm, P, d):
    """d-block P (d, d) of P = F S, S = lam tr(E) I + 2 mu E, at one embedded F (3, 3); prm =
    (mu, lam). F is block diagonal, so P's d-block only needs S's d-block (tr E is the 3D one)."""
    mu, lam = prm[0], prm[1]
    E = np.empty((3, 3))
    trE = _green_lagrange_point(F, E)
    for i in range(d):
        for a in range(d):
            s = 0.0
            for k in range(d):
                s += F[i, k] * (lam * trE * (1.0 if k == a else 0.0) + 2.0 * mu * E[k, a])
            P[i, a] = s


@njit(cache=True, inline="always")
def tangent_point(F, prm, C, d):
    """C_iajb = delta_ij S_ab + lam F_ia F_jb + mu (delta_ab B_ij + F_ib F_ja), S the second
    Piola stress, B = F F^T, of one embedded F (3, 3) into the d-block C (d, d, d, d);
    prm = (mu, lam). S and B of an embedded F are block diagonal (E33 = 0), tr E is the 3D one."""
    mu, lam = prm[0], prm[1]
    trE = 0.0
    for a in range(3):
        s = 0.0
        for k in range(3):
            s += F[k, a] * F[k, a]
        trE += 0.5 * (s - 1.0)
    for i in range(d):
        for a in range(d):
            for j in range(d):
                for b in range(d):
                    FtF, FFt = 0.0, 0.0
                    for k in range(3):
                        FtF += F[k, a] * F[k, b]
                        FFt += F[i, k] * F[j, k]
                    S_ab = lam * trE * (a == b) + 2.0 * mu * (0.5 * (FtF - (a == b)))
                    C[i, a, j, b] = ((i == j) * S_ab + lam * (F[i, a] * F[j, b])
                                     + mu * ((a == b) * FFt + F[i, b] * F[j, a]))


@njit(cache=True, inline="always")
def energy_point(F, prm, h, W, d):
    """W[0] = lam/2 tr(E)^2 + mu E:E at one embedded F (3, 3), E = (F^T F - I) / 2; prm = (mu, lam)."""
    mu, lam = prm[0], prm[1]
    E = scratch((3, 3))
    tr = _green_lagrange_point(F, E)
    ee = 0.0
    for a in range(3):
        for b in range(3):
            ee += E[a, b] * E[a, b]
    W[0] = 0.5 * lam * tr * tr + mu * ee


@dataclass(frozen=True, kw_only=True)
class SaintVenantKirchhoff(Material):
    """Saint-Venant-Kirchhoff law: P = F S, S = lam tr(E) I + 2 mu E, E = (F^T F - I) / 2.

    W = lam/2 tr(E)^2 + mu E:E. Tangent
    C_iajb = delta_ij S_ab + lam F_ia F_jb + mu (delta_ab (F F^T)_ij + F_ib F_ja).
    In uniaxial strain F = diag(F, 1, 1), P11 = (lam + 2 mu)/2 F (F^2 - 1) and the
    longitudinal wave speed along e1 is sqrt((lam + 2 mu)(3 F^2 - 1) / (2 rho)): hyperbolicity
    is lost for F <= 1/sqrt(3). Shapes as in `skdgmpm.materials.base`.
    """

    def _green_lagrange(self, F):
        return 0.5 * (np.swapaxes(F, -1, -2) @ F - _I)

    def _second_piola(self, F):
        E = self._green_lagrange(F)
        tr = np.trace(E, axis1=-2, axis2=-1)
        return self.lam * tr[..., None, None] * _I + 2.0 * self.mu * E

    def first_piola(self, F):
        F = np.asarray(F, dtype=float)
        return F @ self._second_piola(F)

    law_id = 2
    point_law = PointLaw(tangent_point, stress=stress_point, energy=energy_point)

    @property
    def law_parameters(self):
        return (self.mu, self.lam)
