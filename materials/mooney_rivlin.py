"""Compressible Mooney-Rivlin hyperelasticity (the neo-Hookean law plus a second-invariant term).

Its point functions are compiled functions of their own, called (not inlined) by the fused passes
(see `materials.points`): a law added to the engine costs its own compile time only."""

from dataclasses import dataclass

import numpy as np
from numba import njit

from .base import Material, PointLaw, _check_parameter, _inverse_transpose, cofactor


@njit(cache=True, inline="always")
def _invariants(F):
    """(ok, J, G, I1, C, B) of one embedded F: G = F^-T as a 9-tuple, I1 = tr(F^T F), C = F^T F and
    B = F F^T as (3, 3) arrays; where J <= 0 the values at F = I (as `_inverse_transpose`)."""
    ok, J, G = _inverse_transpose(F)
    C, B = np.zeros((3, 3)), np.zeros((3, 3))
    for a in range(3):
        for b in range(3):
            c, e = 0.0, 0.0
            for k in range(3):
                f_ka = F[k, a] if ok else (1.0 if k == a else 0.0)
                f_kb = F[k, b] if ok else (1.0 if k == b else 0.0)
                f_ak = F[a, k] if ok else (1.0 if a == k else 0.0)
                f_bk = F[b, k] if ok else (1.0 if b == k else 0.0)
                c += f_ka * f_kb
                e += f_ak * f_bk
            C[a, b], B[a, b] = c, e
    return ok, J, G, C[0, 0] + C[1, 1] + C[2, 2], C, B


@njit(cache=True)
def stress_point(F, prm, P, d):
    """d-block P (d, d) of P = 2 c1 F + 2 c2 (I1 F - F C) - m G + lam ln(J) G at one embedded F;
    prm = (c1, c2, m, lam)."""
    c1, c2, m, lam = prm[0], prm[1], prm[2], prm[3]
    ok, J, G, I1, C, _ = _invariants(F)
    g = lam * np.log(J) - m
    for i in range(d):
        for a in range(d):
            FC = 0.0
            for k in range(3):
                FC += (F[i, k] if ok else (1.0 if i == k else 0.0)) * C[k, a]
            f = F[i, a] if ok else (1.0 if i == a else 0.0)
            P[i, a] = 2.0 * c1 * f + 2.0 * c2 * (I1 * f - FC) + g * G[3 * i + a]


@njit(cache=True)
def tangent_point(F, prm, C, d):
    """C_iajb = 2 c1 d_ij d_ab + 2 c2 (2 F_ia F_jb + I1 d_ij d_ab - d_ij C_ab - F_ib F_ja - B_ij d_ab)
    + (m - lam ln J) G_ib G_ja + lam G_ia G_jb into the d-block C (d, d, d, d); prm = (c1, c2, m, lam).
    An embedded F is block diagonal, so are C, B and G (I1 is the 3D trace)."""
    c1, c2, m, lam = prm[0], prm[1], prm[2], prm[3]
    ok, J, G, I1, Cr, B = _invariants(F)
    c = m - lam * np.log(J)
    for i in range(d):
        for a in range(d):
            F_ia = F[i, a] if ok else (1.0 if i == a else 0.0)
            for j in range(d):
                for b in range(d):
                    F_jb = F[j, b] if ok else (1.0 if j == b else 0.0)
                    F_ib = F[i, b] if ok else (1.0 if i == b else 0.0)
                    F_ja = F[j, a] if ok else (1.0 if j == a else 0.0)
                    dij, dab = 1.0 if i == j else 0.0, 1.0 if a == b else 0.0
                    C[i, a, j, b] = (2.0 * c1 * dij * dab
                                     + 2.0 * c2 * (2.0 * F_ia * F_jb + I1 * dij * dab - dij * Cr[a, b]
                                                   - F_ib * F_ja - B[i, j] * dab)
                                     + c * (G[3 * i + b] * G[3 * j + a]) + lam * (G[3 * i + a] * G[3 * j + b]))


@njit(cache=True)
def _first_piola(F, prm, P):
    for p in range(len(F)):
        stress_point(F[p], prm, P[p], 3)


@njit(cache=True, inline="always")
def energy_point(F, prm, h, W, d):
    """W[0] = c1 (I1 - 3) + c2 (I2 - 3) - m ln J + lam/2 (ln J)^2 at one embedded F (3, 3), I1 and I2
    the invariants of C = F^T F, +inf where J <= 0; prm = (c1, c2, m, lam)."""
    c1, c2, m, lam = prm[0], prm[1], prm[2], prm[3]
    ok, J, _, I1, C, _ = _invariants(F)
    if ok:
        CC = 0.0
        for a in range(3):
            for b in range(3):
                CC += C[a, b] * C[a, b]
        I2 = 0.5 * (I1 * I1 - CC)
        ln_J = np.log(J)
        W[0] = c1 * (I1 - 3.0) + c2 * (I2 - 3.0) - m * ln_J + 0.5 * lam * ln_J * ln_J
    else:
        W[0] = np.inf


@dataclass(frozen=True, kw_only=True)
class MooneyRivlin(Material):
    """Compressible Mooney-Rivlin law:
    W = c1 (I1 - 3) + c2 (I2 - 3) - m ln J + lam/2 (ln J)^2, m = 2 c1 + 4 c2 (stress free at F = I),
    I1 = tr C, I2 = (I1^2 - tr C^2) / 2, C = F^T F.

    Parameters E, nu, rho as every law, and ``beta`` in [0, 1): the share of the small-strain shear
    modulus mu carried by the I2 term, c2 = beta mu / 2, c1 = (1 - beta) mu / 2; lam = lam_0 - 4 c2
    with lam_0 the Lame constant of (E, nu), so that the tangent at F = I is the isotropic one of
    (E, nu) for every beta (beta = 0 is the neo-Hookean law). P = 2 c1 F + 2 c2 (I1 F - F C) - m G
    + lam ln(J) G, G = F^-T; tangent in `tangent_point`. States with J <= 0 give the values at
    F = I and are not hyperbolic (as the neo-Hookean law). Shapes as in `skdgmpm.materials.base`.
    """

    beta: float = 0.5

    law_id = 6
    point_law = PointLaw(tangent_point, stress=stress_point, energy=energy_point)

    def __post_init__(self):
        super().__post_init__()
        _check_parameter("beta", self.beta, -1e-300, 1.0)

    @property
    def law_parameters(self):
        c2 = 0.5 * self.beta * self.mu
        c1 = 0.5 * self.mu - c2
        return (c1, c2, 2.0 * c1 + 4.0 * c2, self.lam - 4.0 * c2)

    def first_piola(self, F):
        F = np.asarray(F, dtype=float)
        flat = np.ascontiguousarray(F.reshape(-1, 3, 3))
        P = np.empty_like(flat)
        _first_piola(flat, np.array(self.law_parameters), P)
        return P.reshape(F.shape)

    def is_hyperbolic(self, F, N):
        return super().is_hyperbolic(F, N) & (cofactor(np.asarray(F, dtype=float))[1] > 0.0)
