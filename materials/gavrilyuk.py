"""Quadratic volumetric energy plus the rank-one convex isochoric family of Gavrilyuk et al.
[L23 eq 13-23]."""

from dataclasses import dataclass

import numpy as np
from numba import njit

from .base import Material, PointLaw, _check_parameter, _inverse_transpose, admissible_inverse, cofactor


@njit(cache=True, inline="always")
def _kinematics(F):
    """(ok, J, F^-T as a row-major 9-tuple, I1 = tr(F^T F), J^(-2/3)) at one embedded F (3, 3),
    those of F = I where J <= 0 (ok False), as `admissible_inverse`."""
    ok, J, G = _inverse_transpose(F)
    I1 = 0.0
    for i in range(3):
        for a in range(3):
            f = F[i, a] if ok else (1.0 if i == a else 0.0)
            I1 += f * f
    return ok, J, G, I1, J ** (-2 / 3)


@njit(cache=True, inline="always")
def stress_point(F, prm, P, d):
    """d-block P (d, d) of `Gavrilyuk.first_piola` at one embedded F (3, 3) (the values at F = I
    where J <= 0); prm = (kappa, w1, w2)."""
    kappa, w1, w2 = prm[0], prm[1], prm[2]
    ok, J, G, I1, s = _kinematics(F)
    c_vol, c_iso = kappa * (J - 1.0) * J, w1 + 2 * w2 * (s * I1)
    for i in range(d):
        for a in range(d):
            f = F[i, a] if ok else (1.0 if i == a else 0.0)
            P[i, a] = c_vol * G[3 * i + a] + c_iso * (s * (2 * f - 2 / 3 * I1 * G[3 * i + a]))


@njit(cache=True, inline="always")
def tangent_point(F, prm, C, d):
    """The d-block C (d, d, d, d) of the tangent at one embedded F (3, 3) (I where J <= 0, as
    `admissible_inverse`); prm = (kappa, w1, w2). See `Gavrilyuk` for the formula."""
    kappa, w1, w2 = prm[0], prm[1], prm[2]
    ok, J, G, I1, s = _kinematics(F)
    I1b = s * I1
    c_vol, c_vol_x = kappa * ((2 * J - 1) * J), kappa * ((J - 1) * J)
    c_iso = w1 + 2 * w2 * I1b
    for i in range(d):
        for a in range(d):
            F_ia = F[i, a] if ok else (1.0 if i == a else 0.0)
            G_ia = G[3 * i + a]
            dI_ia = s * (2 * F_ia - 2 / 3 * I1 * G_ia)
            for j in range(d):
                for b in range(d):
                    F_jb = F[j, b] if ok else (1.0 if j == b else 0.0)
                    G_jb, G_ib, G_ja = G[3 * j + b], G[3 * i + b], G[3 * j + a]
                    GG, GG_x = G_ia * G_jb, G_ib * G_ja
                    d2I1b = s * (-2 / 3 * (2 * (F_ia * G_jb) - 2 / 3 * I1 * GG) + 2.0 * ((i == j) * (a == b))
                                 - 4 / 3 * (G_ia * F_jb) + 2 / 3 * I1 * GG_x)
                    dI_jb = s * (2 * F_jb - 2 / 3 * I1 * G_jb)
                    C[i, a, j, b] = (c_vol * GG - c_vol_x * GG_x) + c_iso * d2I1b + 2 * w2 * (dI_ia * dI_jb)


@njit(cache=True, inline="always")
def energy_point(F, prm, h, W, d):
    """W[0] = kappa/2 (J - 1)^2 + w1 (I1b - 3) + w2 (I1b^2 - 9) at one embedded F (3, 3), I1b =
    J^(-2/3) tr(F^T F), +inf where J <= 0; prm = (kappa, w1, w2)."""
    kappa, w1, w2 = prm[0], prm[1], prm[2]
    ok, J, _, I1, s = _kinematics(F)
    if ok:
        I1b = s * I1
        W[0] = 0.5 * kappa * (J - 1.0) ** 2 + w1 * (I1b - 3.0) + w2 * (I1b * I1b - 9.0)
    else:
        W[0] = np.inf


@dataclass(frozen=True, kw_only=True)
class Gavrilyuk(Material):
    """W = kappa/2 (J - 1)^2 + mu/4 [-2a (I1b - 3) + (1 + a)/3 (I1b^2 - 9)] [L23 eq 16-17].

    I1b = J^(-2/3) tr(F^T F); kappa = E / (3 (1 - 2 nu)), mu = E / (2 (1 + nu)); a = -1
    (default) is the neo-Hookean shear energy mu/2 (I1b - 3) of L23 eq 19.

    L23 eq 18 defines the second invariant as I2b = (tr(Cb)^2 - tr(Cb^2))/2, which equals 3, not
    9, at F = I; with it the small-strain shear modulus is mu (1 - 5a)/6 (negative for a > 1/5,
    so not hyperbolic on the range a in [-1, 1/2] claimed next to it). The value 9 is that of
    I1b^2, and with I1b^2 the shear modulus is mu for every a: we take that reading (tested:
    isotropic tangent lam, mu at F = I, hyperbolic on the whole range at large strain). The
    scenes use a = -1, where the two readings coincide.

    P = kappa (J - 1) H + (w1 + 2 w2 I1b) dI1b/dF with H = J F^-T (cofactor), w1 = -mu a / 2,
    w2 = mu (1 + a) / 12 and dI1b/dF = J^(-2/3) (2F - 2/3 I1 G), G = F^-T. The tangent
    differentiates once more (dG_ia/dF_jb = -G_ib G_ja). Like the neo-Hookean law, states with
    J <= 0 give the values at F = I and `is_hyperbolic` returns False (tangent: `tangent_point`).
    Shapes as in `skdgmpm.materials.base`.
    """

    a: float = -1.0

    def __post_init__(self):
        super().__post_init__()
        _check_parameter("a", self.a, -1.0 - 1e-12, 0.5 + 1e-12)

    def _kinematics(self, F):
        F, G, J, ok = admissible_inverse(F)
        I1 = np.einsum("...ia,...ia->...", F, F)
        I1b = J ** (-2 / 3) * I1
        dI1b = (J ** (-2 / 3))[..., None, None] * (2 * F - 2 / 3 * I1[..., None, None] * G)
        return F, J, G, I1, I1b, dI1b, ok

    @property
    def _weights(self):
        """Coefficients of I1b and I1b^2 in the isochoric energy."""
        return -0.5 * self.mu * self.a, self.mu * (1.0 + self.a) / 12.0

    def first_piola(self, F):
        F, J, G, I1, I1b, dI1b, _ = self._kinematics(F)
        w1, w2 = self._weights
        return ((self.bulk * (J - 1.0) * J)[..., None, None] * G
                + (w1 + 2 * w2 * I1b)[..., None, None] * dI1b)

    law_id = 3
    point_law = PointLaw(tangent_point, stress=stress_point, energy=energy_point)

    @property
    def law_parameters(self):
        return (self.bulk, *self._weights)

    def is_hyperbolic(self, F, N):
        return super().is_hyperbolic(F, N) & (cofactor(np.asarray(F, dtype=float))[1] > 0.0)
