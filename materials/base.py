"""The material interface: validated elastic constants and the quantities every law derives.

Shapes (once for the whole package): deformation gradients ``F`` are ``(..., 3, 3)`` with index
order ``F[..., i, alpha]``; stresses have the same shape; the tangent is
``C[..., i, alpha, j, beta] = dP[i, alpha] / dF[j, beta]``, shape ``(..., 3, 3, 3, 3)``;
normals ``N`` are ``(..., d)`` with d <= 3 (or ``(d,)``, broadcast) in the reference
configuration. A normal with d < 3 components lies in the first d axes and the acoustic tensor is
its ``(d, d)`` block: the waves of the d-dimensional system (uniaxial strain in 1D, plane strain in
2D), e.g. the 1D SVK bar is hyperbolic for F11 > 1/sqrt(3) [R18 eq A.10] although the 3D shear
waves of the same state are lost earlier.
"""

import math
from abc import ABC, abstractmethod
from dataclasses import dataclass
from numbers import Real
from typing import NamedTuple

import numpy as np
from numba import njit

from skdgmpm.errors import InputError

# Bounds per parameter: (lower, upper), open intervals; None means unbounded.
_BOUNDS = {"E": (0.0, None), "nu": (-1.0, 0.5), "rho": (0.0, None)}


def _check_parameter(name, value, lower, upper, *, lower_closed=False):
    """Raise InputError unless ``lower < value < upper`` (``lower <= value`` if ``lower_closed``)
    with ``value`` a finite real number."""
    ok = isinstance(value, Real) and not isinstance(value, bool) and math.isfinite(value)
    ok = ok and (lower is None or value > lower or (lower_closed and value == lower))
    ok = ok and (upper is None or value < upper)
    if not ok:
        low = lower is not None and f"{'>=' if lower_closed else '>'} {lower:g}"
        bounds = " and ".join(s for s in (low, upper is not None and f"< {upper:g}") if s)
        raise InputError(f"material: {name} = {value!r} must be a finite number {bounds}")


@njit(cache=True)
def _cofactor(F, cof, J):
    for p in range(len(F)):
        a, b, c = F[p, 0, 0], F[p, 0, 1], F[p, 0, 2]
        d, e, f = F[p, 1, 0], F[p, 1, 1], F[p, 1, 2]
        g, h, i = F[p, 2, 0], F[p, 2, 1], F[p, 2, 2]
        cof[p, 0, 0], cof[p, 0, 1], cof[p, 0, 2] = e * i - f * h, f * g - d * i, d * h - e * g
        cof[p, 1, 0], cof[p, 1, 1], cof[p, 1, 2] = c * h - b * i, a * i - c * g, b * g - a * h
        cof[p, 2, 0], cof[p, 2, 1], cof[p, 2, 2] = b * f - c * e, c * d - a * f, a * e - b * d
        J[p] = a * cof[p, 0, 0] + b * cof[p, 0, 1] + c * cof[p, 0, 2]


@njit(cache=True, inline="always")
def _inverse_transpose(F):
    """G = F^-T of one (3, 3) F as `admissible_inverse` computes it, as scalars: returns
    (ok, J, G) with ok = det F > 0 and G the 9-tuple of G row-major; where not ok, G = I and
    J = 1 (the values at F = I)."""
    a, b, c = F[0, 0], F[0, 1], F[0, 2]
    d, e, f = F[1, 0], F[1, 1], F[1, 2]
    g, h, i = F[2, 0], F[2, 1], F[2, 2]
    c00, c01, c02 = e * i - f * h, f * g - d * i, d * h - e * g
    J = a * c00 + b * c01 + c * c02
    if not J > 0.0:
        return False, 1.0, (1.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0)
    r = 1.0 / J                         # one division (they dominate the point laws' cost)
    return True, J, (c00 * r, c01 * r, c02 * r, (c * h - b * i) * r, (a * i - c * g) * r, (b * g - a * h) * r,
                     (b * f - c * e) * r, (c * d - a * f) * r, (a * e - b * d) * r)


def cofactor(F):
    """Cofactor matrix cof F = det(F) F^-T and det F of ``(..., 3, 3)`` arrays, in closed form
    (a compiled loop over the points; det F = 0 gives cof F anyway)."""
    F = np.asarray(F, dtype=float)
    flat = np.ascontiguousarray(F.reshape(-1, 3, 3))
    cof, J = np.empty_like(flat), np.empty(len(flat))
    _cofactor(flat, cof, J)
    return cof.reshape(F.shape), J.reshape(F.shape[:-2])[()]


def admissible_inverse(F):
    """``(F_safe, G, J, ok)`` for laws defined only for J > 0: F with I substituted where
    J = det F <= 0 (so nothing downstream turns NaN), G = F_safe^-T, its determinant J and the
    mask J > 0 of the given F."""
    F = np.asarray(F, dtype=float)
    cof, J = cofactor(F)
    ok = J > 0.0
    if not ok.all():
        F = np.where(ok[..., None, None], F, np.eye(3))
        cof, J = cofactor(F)
    return F, cof / J[..., None, None], J, ok


class PointLaw(NamedTuple):
    """A law's compiled point functions (njit, for any d; F embedded (3, 3), prm its
    ``law_parameters``), its class's ``point_law``: ``tangent(F, prm, C, d)``, the d-block of the
    tangent the Riemann solver and the wave-speed check use (possibly another law's function: the
    laws then share a branch of the dispatch); ``energy(F, prm, h, W, d)``: W[0] = the stored
    (recoverable) energy density at F with the internal variables h in force (zero wide for a
    hyperelastic law), +inf where the law is undefined (J <= 0); and either ``stress(F, prm, P,
    d)`` (hyperelastic) or ``update(F, prm, h_n, h, P, d)`` (a law with history: its return
    mapping); ``stress_tangent(F, prm, P, C, d)`` where computing both at once is cheaper than
    apart. `materials.points` makes every kernel's dispatch from these."""

    tangent: object
    energy: object
    stress: object = None
    update: object = None
    stress_tangent: object = None


@dataclass(frozen=True, kw_only=True)
class Material(ABC):
    """Isotropic elastic material, immutable, with keyword-only parameters.

    Parameters
    ----------
    E : float
        Young's modulus (Pa), > 0.
    nu : float
        Poisson's ratio, -1 < nu < 0.5.
    rho : float
        Reference mass density rho0 (kg/m^3), > 0.

    Subclasses implement `first_piola` and their compiled point functions, the class
    attribute ``point_law`` (`PointLaw`), under their ``law_id`` (with ``law_parameters``);
    the law is registered by its row in `materials.LAWS`. The batched tangent,
    acoustic tensor, wave speeds, hyperbolicity and Cauchy stress follow from them.
    """

    E: float
    nu: float
    rho: float

    def __post_init__(self):
        for name, (lower, upper) in _BOUNDS.items():
            _check_parameter(name, getattr(self, name), lower, upper)

    # -- elastic constants --------------------------------------------------------------------
    @property
    def lam(self):
        """First Lamé parameter lambda = E nu / ((1 + nu)(1 - 2 nu)) (Pa)."""
        return self.E * self.nu / ((1.0 + self.nu) * (1.0 - 2.0 * self.nu))

    @property
    def mu(self):
        """Shear modulus mu = E / (2 (1 + nu)) (Pa)."""
        return self.E / (2.0 * (1.0 + self.nu))

    @property
    def bulk(self):
        """Bulk modulus kappa = E / (3 (1 - 2 nu)) (Pa)."""
        return self.E / (3.0 * (1.0 - 2.0 * self.nu))

    # -- the law ------------------------------------------------------------------------------
    @abstractmethod
    def first_piola(self, F):
        """First Piola-Kirchhoff stress P(F), shape ``(..., 3, 3)`` (Pa)."""

    def energy(self, F, history=None):
        """Stored (recoverable) energy density W per reference volume at F (..., 3, 3), shape
        ``(...,)`` (J/m^3), with the internal variables ``history`` in force ((..., n_history) or
        one row for every point; None: the virgin state; a hyperelastic law has none); P = dW/dF
        at that history; +inf where the law is undefined (J <= 0). The law's compiled point
        energy (`PointLaw`) looped over the points (`materials.points.energy`), as a run sums it."""
        from .points import energy                  # points imports every law, hence here
        return energy(self, F, history)

    def tangent(self, F):
        """Analytic tangent C = dP/dF, shape ``(..., 3, 3, 3, 3)`` (Pa)."""
        return self.tangent_block(F, 3)

    def tangent_block(self, F, d):
        """The ``(..., d, d, d, d)`` block of the tangent at an *embedded* F (identity outside the
        first d axes), the only part a d-dimensional system uses: the law's compiled point
        tangent (`materials.points`) looped over the points."""
        from .points import tangent_block          # points imports every law, hence here
        return tangent_block(self, F, d)

    # -- internal variables (none for a hyperelastic law: zero width, no cost) ----------------
    history_names = ()
    """Names of the internal variables, one column each of a point's history array; a law with
    plastic flow puts the equivalent plastic strain ``"eqp"`` first."""

    @property
    def n_history(self):
        """Number of internal variables per point."""
        return len(self.history_names)

    def initial_history(self, n):
        """History of ``n`` points in the virgin state, shape ``(n, n_history)``."""
        return np.zeros((n, self.n_history))

    def stress_update(self, F, history):
        """(P(F_{n+1}, history_n), history_{n+1}): the return mapping of a law with internal
        variables; a hyperelastic law returns P(F) and the history unchanged."""
        return self.first_piola(F), history

    def dissipation(self, history):
        """Plastic work density done up to the given history, shape ``(...,)`` (J/m^3)."""
        history = np.asarray(history, dtype=float)
        return np.zeros(history.shape[:-1])

    # -- derived ------------------------------------------------------------------------------
    def acoustic_tensor(self, F, N):
        """Acoustic tensor ``A[..., i, j] = C[..., i, a, j, b] N[..., a] N[..., b]``, shape
        ``(..., d, d)`` for ``N`` of shape ``(..., d)`` (Pa)."""
        N = np.asarray(N, dtype=float)
        d = N.shape[-1]
        if not 1 <= d <= 3:
            raise InputError(f"material: normal with {d} components; expected 1, 2 or 3")
        C = self.tangent(F)[..., :d, :d, :d, :d]
        return np.einsum("...iajb,...a,...b->...ij", C, N, N)

    def wave_speeds(self, F, N):
        """Wave speeds along ``N``, sqrt(eig(A) / rho), shape ``(..., d)``, sorted descending (m/s).

        Non-positive eigenvalues (lost hyperbolicity) give speed 0, not NaN: check
        `is_hyperbolic` to detect them.
        """
        A = self.acoustic_tensor(F, N)
        omega = np.linalg.eigvalsh(0.5 * (A + np.swapaxes(A, -1, -2)))[..., ::-1]
        return np.sqrt(np.clip(omega, 0.0, None) / self.rho)

    def max_wave_speed(self, F, N):
        """Largest wave speed along ``N``, shape ``(...,)`` (m/s)."""
        return self.wave_speeds(F, N)[..., 0]

    def is_hyperbolic(self, F, N):
        """True where the acoustic tensor along ``N`` is positive definite, shape ``(...,)``."""
        A = self.acoustic_tensor(F, N)
        omega = np.linalg.eigvalsh(0.5 * (A + np.swapaxes(A, -1, -2)))
        return omega[..., 0] > 0.0

    def cauchy(self, F, history=None):
        """Cauchy stress sigma = P F^T / J, shape ``(..., 3, 3)`` (Pa), with the internal variables
        ``history`` of the state (``None``: the virgin state). The history of a state is already
        updated to its F, so re-running the return mapping is elastic and returns the state's P."""
        F = np.asarray(F, dtype=float)
        J = cofactor(F)[1]
        P = self.first_piola(F) if history is None else self.stress_update(F, history)[0]
        return P @ np.swapaxes(F, -1, -2) / J[..., None, None]
