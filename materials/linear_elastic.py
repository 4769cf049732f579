"""Small-strain linear elasticity written on F [R18 §7.1], [L23 §5.1]."""

from dataclasses import dataclass

import numpy as np
from numba import njit

from .base import Material, PointLaw

_I = np.eye(3)


@njit(cache=True, inline="always")
def stress_point(F, prm, P, d):
    """d-block P (d, d) of `LinearElastic.first_piola` at one embedded F (3, 3); prm = (mu, lam)."""
    mu, lam = prm[0], prm[1]
    tr = 0.0
    for k in range(3):
        tr += F[k, k] - 1.0
    for i in range(d):
        for a in range(d):
            eps = 0.5 * ((F[i, a] - (i == a)) + (F[a, i] - (i == a)))
            P[i, a] = lam * tr * (1.0 if i == a else 0.0) + 2.0 * mu * eps


@njit(cache=True, inline="always")
def tangent_point(F, prm, C, d):
    """C_iajb = lam delta_ia delta_jb + mu (delta_ij delta_ab + delta_ib delta_aj), the same at
    every F: the d-block into C (d, d, d, d); prm = (mu, lam)."""
    mu, lam = prm[0], prm[1]
    for i in range(d):
        for a in range(d):
            for j in range(d):
                for b in range(d):
                    C[i, a, j, b] = lam * ((i == a) * (j == b)) + mu * ((i == j) * (a == b) + (i == b) * (a == j))


@njit(cache=True, inline="always")
def energy_point(F, prm, h, W, d):
    """W[0] = lam/2 tr(eps)^2 + mu eps:eps at one embedded F (3, 3), eps = sym(F - I); prm = (mu, lam)."""
    mu, lam = prm[0], prm[1]
    tr, ee = 0.0, 0.0
    for i in range(3):
        tr += F[i, i] - 1.0
        for a in range(3):
            eps = 0.5 * ((F[i, a] - (i == a)) + (F[a, i] - (i == a)))
            ee += eps * eps
    W[0] = 0.5 * lam * tr * tr + mu * ee


@dataclass(frozen=True, kw_only=True)
class LinearElastic(Material):
    """Linear elastic law: P = lam tr(eps) I + 2 mu eps, eps = sym(F - I).

    W = lam/2 tr(eps)^2 + mu eps:eps. The tangent is constant and isotropic. Shapes as in
    `skdgmpm.materials.base`.
    """

    def _strain(self, F):
        H = np.asarray(F, dtype=float) - _I
        return 0.5 * (H + np.swapaxes(H, -1, -2))

    def first_piola(self, F):
        eps = self._strain(F)
        tr = np.trace(eps, axis1=-2, axis2=-1)
        return self.lam * tr[..., None, None] * _I + 2.0 * self.mu * eps

    law_id = 1
    point_law = PointLaw(tangent_point, stress=stress_point, energy=energy_point)

    @property
    def law_parameters(self):
        return (self.mu, self.lam)
