"""Small-strain linear elasticity written on F [R18 §7.1], [L23 §5.1]."""

from dataclasses import dataclass

import numpy as np

from .base import Material

_I = np.eye(3)


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

    def tangent(self, F):
        F = np.asarray(F, dtype=float)
        C = (self.lam * np.einsum("ia,jb->iajb", _I, _I)
             + self.mu * (np.einsum("ij,ab->iajb", _I, _I) + np.einsum("ib,aj->iajb", _I, _I)))
        return np.broadcast_to(C, F.shape[:-2] + (3, 3, 3, 3)).copy()

    def tangent_block(self, F, d):
        # constant: one (d, d, d, d) tensor broadcast (read-only) over the batch
        C = self.tangent(np.eye(3))[:d, :d, :d, :d]
        return np.broadcast_to(C, np.shape(F)[:-2] + (d, d, d, d))

    def energy(self, F):
        eps = self._strain(F)
        tr = np.trace(eps, axis1=-2, axis2=-1)
        return 0.5 * self.lam * tr**2 + self.mu * np.einsum("...ab,...ab->...", eps, eps)
