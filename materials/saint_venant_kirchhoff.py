"""Saint-Venant-Kirchhoff hyperelasticity [R18 App. A]."""

from dataclasses import dataclass

import numpy as np

from .base import Material

_I = np.eye(3)


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

    def tangent(self, F):
        F = np.asarray(F, dtype=float)
        S = self._second_piola(F)
        B = F @ np.swapaxes(F, -1, -2)
        return (np.einsum("ij,...ab->...iajb", _I, S)
                + self.lam * np.einsum("...ia,...jb->...iajb", F, F)
                + self.mu * (np.einsum("...ij,ab->...iajb", B, _I)
                             + np.einsum("...ib,...ja->...iajb", F, F)))

    def tangent_block(self, F, d):
        # S and B of an embedded F are block diagonal (E33 = 0): the d-block is the same formula
        # on d x d arrays
        F = np.asarray(F, dtype=float)
        S = self._second_piola(F)[..., :d, :d]
        B = (F @ np.swapaxes(F, -1, -2))[..., :d, :d]
        F, Id = F[..., :d, :d], np.eye(d)
        return (np.einsum("ij,...ab->...iajb", Id, S)
                + self.lam * np.einsum("...ia,...jb->...iajb", F, F)
                + self.mu * (np.einsum("...ij,ab->...iajb", B, Id)
                             + np.einsum("...ib,...ja->...iajb", F, F)))

    def energy(self, F):
        E = self._green_lagrange(np.asarray(F, dtype=float))
        tr = np.trace(E, axis1=-2, axis2=-1)
        return 0.5 * self.lam * tr**2 + self.mu * np.einsum("...ab,...ab->...", E, E)
