"""Compressible neo-Hookean hyperelasticity [WG08 eq 54]."""

from dataclasses import dataclass

import numpy as np
from numba import njit

from .base import Material, admissible_inverse, cofactor


@njit(cache=True)
def _tangent(G, c, mu, lam, C):
    """C_iajb = mu delta_ij delta_ab + c G_ib G_ja + lam G_ia G_jb at every point: G (n, d, d),
    c (n,) into C (n, d, d, d, d) (a compiled loop: numpy's 4th-order temporaries cost ~1 us a point)."""
    if G.shape[1] == 2:                 # a literal d: the loops unrolled
        _tangent_d(G, c, mu, lam, C, 2)
    else:
        _tangent_d(G, c, mu, lam, C, G.shape[1])


@njit(cache=True, inline="always")
def _tangent_d(G, c, mu, lam, C, d):
    for p in range(len(G)):
        for i in range(d):
            for a in range(d):
                for j in range(d):
                    for b in range(d):
                        C[p, i, a, j, b] = (mu * ((i == j) * (a == b)) + c[p] * (G[p, i, b] * G[p, j, a])
                                            + lam * (G[p, i, a] * G[p, j, b]))


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

    def _kinematics(self, F):
        F, G, J, ok = admissible_inverse(F)
        return F, G, np.log(J), ok

    def first_piola(self, F):
        Fs, G, lnJ, _ = self._kinematics(F)
        return self.mu * (Fs - G) + self.lam * lnJ[..., None, None] * G

    def tangent(self, F):
        return self.tangent_block(F, 3)

    def tangent_block(self, F, d):
        # an embedded F is block diagonal (F33 = 1), so is G = F^-T: the d-block of C only
        # involves the d-block of G
        _, G, lnJ, _ = self._kinematics(F)
        shape = np.shape(G)[:-2]
        G = np.ascontiguousarray(G[..., :d, :d]).reshape(-1, d, d)
        C = np.empty((len(G), d, d, d, d))
        _tangent(G, np.ravel(self.mu - self.lam * lnJ), self.mu, self.lam, C)
        return C.reshape(shape + (d, d, d, d))

    def energy(self, F):
        Fs, _, lnJ, ok = self._kinematics(F)
        W = (0.5 * self.mu * (np.einsum("...ia,...ia->...", Fs, Fs) - 3.0)
             - self.mu * lnJ + 0.5 * self.lam * lnJ**2)
        return np.where(ok, W, np.inf)

    def is_hyperbolic(self, F, N):
        return super().is_hyperbolic(F, N) & (cofactor(np.asarray(F, dtype=float))[1] > 0.0)
