"""Compressible neo-Hookean hyperelasticity [WG08 eq 54]."""

from dataclasses import dataclass

import numpy as np
from numba import njit

from .base import Material, PointLaw, _inverse_transpose, cofactor


@njit(cache=True, inline="always")
def stress_point(F, prm, P, d):
    """d-block P (d, d) of P = mu (F - G) + lam ln(J) G, G = F^-T, at one embedded F (3, 3) (the
    values at F = I where J <= 0); prm = (mu, lam)."""
    ok, J, G = _inverse_transpose(F)
    _stress(F, ok, G, prm[1] * np.log(J), prm[0], P, d)


@njit(cache=True, inline="always")
def _stress(F, ok, G, lam_lnJ, mu, P, d):
    for i in range(d):
        for a in range(d):
            f = F[i, a] if ok else (1.0 if i == a else 0.0)
            P[i, a] = mu * (f - G[3 * i + a]) + lam_lnJ * G[3 * i + a]


@njit(cache=True)
def _first_piola(F, mu, lam, P):
    """P at every point: F (n, 3, 3) into P (n, 3, 3) (one compiled loop with the kinematics: the
    numpy chain cost ~10 passes over the points)."""
    for p in range(len(F)):
        stress_point(F[p], (mu, lam), P[p], 3)


@njit(cache=True, inline="always")
def tangent_point(F, prm, C, d):
    """C_iajb = mu delta_ij delta_ab + c G_ib G_ja + lam G_ia G_jb, c = mu - lam ln J, of one
    embedded F (3, 3) into the d-block C (d, d, d, d); prm = (mu, lam). An embedded F is block
    diagonal (F33 = 1), so is G = F^-T: the d-block of C only involves the d-block of G."""
    _, J, G = _inverse_transpose(F)
    _tangent(G, np.log(J), prm[0], prm[1], C, d)


@njit(cache=True, inline="always")
def _tangent(G, ln_J, mu, lam, C, d):
    c = mu - lam * ln_J
    for i in range(d):
        for a in range(d):
            for j in range(d):
                for b in range(d):
                    C[i, a, j, b] = (mu * ((i == j) * (a == b)) + c * (G[3 * i + b] * G[3 * j + a])
                                     + lam * (G[3 * i + a] * G[3 * j + b]))


@njit(cache=True, inline="always")
def stress_tangent_point(F, prm, P, C, d):
    """`stress_point` and `tangent_point` at one F, the kinematics (F^-T, ln J) computed once
    (the same numbers as the two apart)."""
    mu, lam = prm[0], prm[1]
    ok, J, G = _inverse_transpose(F)
    ln_J = np.log(J)
    _stress(F, ok, G, lam * ln_J, mu, P, d)
    _tangent(G, ln_J, mu, lam, C, d)


@njit(cache=True, inline="always")
def energy_point(F, prm, h, W, d):
    """W[0] = mu/2 (tr(F^T F) - 3) - mu ln J + lam/2 (ln J)^2 at one embedded F (3, 3), +inf where
    J <= 0; prm = (mu, lam)."""
    mu, lam = prm[0], prm[1]
    ok, J, _ = _inverse_transpose(F)
    if ok:
        I1 = 0.0
        for i in range(3):
            for a in range(3):
                I1 += F[i, a] * F[i, a]
        ln_J = np.log(J)
        W[0] = 0.5 * mu * (I1 - 3.0) - mu * ln_J + 0.5 * lam * ln_J * ln_J
    else:
        W[0] = np.inf


def _points(F):
    """(n, 3, 3) contiguous float view of F (..., 3, 3) and the batch shape."""
    F = np.asarray(F, dtype=float)
    return np.ascontiguousarray(F.reshape(-1, 3, 3)), F.shape[:-2]


@dataclass(frozen=True, kw_only=True)
class NeoHookean(Material):
    """Neo-Hookean law: P = mu (F - F^-T) + lam ln(J) F^-T, J = det F.

    W = mu/2 (tr(F^T F) - 3) - mu ln J + lam/2 (ln J)^2. With G = F^-T the tangent is
    C_iajb = mu delta_ij delta_ab + (mu - lam ln J) G_ib G_ja + lam G_ia G_jb.
    ([WG08] print the transpose of P; the two agree for diagonal F.)

    The law is defined only for J > 0. Where J <= 0 (or F is not finite) the arrays stay
    NaN-free by convention: `first_piola` and `tangent` return their values at F = I (zero
    stress, isotropic tangent), `energy` returns +inf, and `is_hyperbolic` returns False, which is
    how callers must detect an inverted element. Shapes as in `skdgmpm.materials.base`.
    """

    law_id = 0
    point_law = PointLaw(tangent_point, stress=stress_point, stress_tangent=stress_tangent_point, energy=energy_point)

    @property
    def law_parameters(self):
        return (self.mu, self.lam)

    def first_piola(self, F):
        F, shape = _points(F)
        P = np.empty_like(F)
        _first_piola(F, self.mu, self.lam, P)
        return P.reshape(shape + (3, 3))

    def is_hyperbolic(self, F, N):
        return super().is_hyperbolic(F, N) & (cofactor(np.asarray(F, dtype=float))[1] > 0.0)
