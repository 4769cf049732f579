"""Compressible neo-Hookean hyperelasticity [WG08 eq 54]."""

from dataclasses import dataclass

import numpy as np

from .base import Material, admissible_inverse, cofactor

_I = np.eye(3)


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
        _, G, lnJ, _ = self._kinematics(F)
        c = (self.mu - self.lam * lnJ)[..., None, None, None, None]
        return (self.mu * np.einsum("ij,ab->iajb", _I, _I)
                + c * np.einsum("...ib,...ja->...iajb", G, G)
                + self.lam * np.einsum("...ia,...jb->...iajb", G, G))

    def tangent_block(self, F, d):
        # an embedded F is block diagonal (F33 = 1), so is G = F^-T: the d-block of C only
        # involves the d-block of G
        _, G, lnJ, _ = self._kinematics(F)
        G = G[..., :d, :d]
        c = (self.mu - self.lam * lnJ)[..., None, None, None, None]
        Id = np.eye(d)
        return (self.mu * np.einsum("ij,ab->iajb", Id, Id)
                + c * np.einsum("...ib,...ja->...iajb", G, G)
                + self.lam * np.einsum("...ia,...jb->...iajb", G, G))

    def energy(self, F):
        Fs, _, lnJ, ok = self._kinematics(F)
        W = (0.5 * self.mu * (np.einsum("...ia,...ia->...", Fs, Fs) - 3.0)
             - self.mu * lnJ + 0.5 * self.lam * lnJ**2)
        return np.where(ok, W, np.inf)

    def is_hyperbolic(self, F, N):
        return super().is_hyperbolic(F, N) & (cofactor(np.asarray(F, dtype=float))[1] > 0.0)
