"""Material laws evaluated on d-dimensional states, one law per particle (or node) group."""
from dataclasses import dataclass

import numpy as np

from .system import embed


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
