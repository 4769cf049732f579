"""Small-strain J2 (von Mises) plasticity with linear isotropic hardening: additive split, radial
return [METHOD §10]; and the parameters and batched plumbing it shares with `HenckyJ2`."""

from dataclasses import dataclass

import numpy as np
from numba import njit

from . import linear_elastic
from .base import Material, PointLaw, _check_parameter
from .linear_elastic import LinearElastic

_I = np.eye(3)
# the symmetric-tensor columns of the history after "eqp": components 11, 22, 33, 12, 13, 23
_SYMMETRIC = ((0, 0), (1, 1), (2, 2), (0, 1), (0, 2), (1, 2))


@njit(cache=True, inline="always")
def write_symmetric_block(T, d, t11, t22, t33, t12, t13, t23):
    """Write the d-block of the symmetric tensor with components t11 ... t23 into T (d, d)."""
    T[0, 0] = t11
    if d > 1:
        T[0, 1], T[1, 0], T[1, 1] = t12, t12, t22
    if d > 2:
        T[0, 2], T[2, 0], T[1, 2], T[2, 1], T[2, 2] = t13, t13, t23, t23, t33


@njit(cache=True, inline="always")
def stress_update_point(F, prm, h_n, h, P, d):
    """Radial return at one embedded F (3, 3) of t_{n+1}: d-block P (d, d) of P = sigma and the
    history h (7,) from that of t_n, h_n (7,) = (eqp, eps_p 11, 22, 33, 12, 13, 23) (read before
    h is written, so the two may be one array); prm = (mu, lam, sigma_y, H)."""
    mu, lam, sigma_y, H = prm[0], prm[1], prm[2], prm[3]
    # trial elastic strain eps - eps_p_n, eps = sym(F - I); tr eps_p = 0, so its trace is tr eps
    e11, e22, e33 = F[0, 0] - 1.0 - h_n[1], F[1, 1] - 1.0 - h_n[2], F[2, 2] - 1.0 - h_n[3]
    e12 = 0.5 * (F[0, 1] + F[1, 0]) - h_n[4]
    e13 = 0.5 * (F[0, 2] + F[2, 0]) - h_n[5]
    e23 = 0.5 * (F[1, 2] + F[2, 1]) - h_n[6]
    tr = e11 + e22 + e33
    m, two_mu = tr / 3.0, 2.0 * mu
    s11, s22, s33 = two_mu * (e11 - m), two_mu * (e22 - m), two_mu * (e33 - m)
    s12, s13, s23 = two_mu * e12, two_mu * e13, two_mu * e23
    q = np.sqrt(1.5 * (s11 * s11 + s22 * s22 + s33 * s33 + 2.0 * (s12 * s12 + s13 * s13 + s23 * s23)))
    f = q - (sigma_y + H * h_n[0])
    for k in range(7):
        h[k] = h_n[k]
    if f > 0.0:
        dg = f / (3.0 * mu + H)           # eqp increment: the closed form for linear hardening
        r = 1.5 * dg / q                  # d eps_p = r s_trial, along the normal, sqrt(2/3)|d eps_p| = dg
        h[0] += dg
        h[1], h[2], h[3] = h[1] + r * s11, h[2] + r * s22, h[3] + r * s33
        h[4], h[5], h[6] = h[4] + r * s12, h[5] + r * s13, h[6] + r * s23
        c = 1.0 - two_mu * r              # the deviator shrinks radially onto the yield surface
        s11, s22, s33, s12, s13, s23 = c * s11, c * s22, c * s33, c * s12, c * s13, c * s23
    p = (lam + two_mu / 3.0) * tr
    write_symmetric_block(P, d, s11 + p, s22 + p, s33 + p, s12, s13, s23)


@njit(cache=True, inline="always")
def tangent_point(F, prm, C, d):
    """The elastic tangent (`linear_elastic.tangent_point`, prm[:2] = (mu, lam)): the history-free
    tangent the Riemann solver and the wave-speed check use, d-block into C (d, d, d, d)."""
    linear_elastic.tangent_point(F, prm, C, d)


@njit(cache=True)
def _stress_updates(F, prm, h_n, h, P):
    for p in range(len(F)):
        stress_update_point(F[p], prm, h_n[p], h[p], P[p], 3)


@njit(cache=True, inline="always")
def history_column(i, j):
    """Column of a J2 law's history holding the symmetric entry (i, j) of its tensor (`_SYMMETRIC`):
    11, 22, 33, 12, 13, 23 -> 1 ... 6."""
    return 1 + i if i == j else 3 + i + j


@njit(cache=True, inline="always")
def energy_point(F, prm, h, W, d):
    """W[0] = lam/2 tr(e)^2 + mu e:e at one embedded F (3, 3), e = sym(F - I) - eps_p, with the
    plastic strain of the history h (7,) in force; prm = (mu, lam, sigma_y, H)."""
    mu, lam = prm[0], prm[1]
    tr, ee = 0.0, 0.0
    for i in range(3):
        for a in range(3):
            e = 0.5 * ((F[i, a] - (i == a)) + (F[a, i] - (i == a))) - h[history_column(i, a)]
            ee += e * e
            if i == a:
                tr += e
    W[0] = 0.5 * lam * tr * tr + mu * ee


@dataclass(frozen=True, kw_only=True)
class J2Material(Material):
    """Von Mises yield with linear isotropic hardening, the parameters and batched methods shared
    by `J2Plasticity` and `HenckyJ2`.

    Parameters
    ----------
    E, nu, rho : float
        As `Material`.
    sigma_y : float
        Initial yield stress (Pa), > 0.
    H : float
        Linear isotropic hardening modulus (Pa), >= 0: the yield stress is sigma_y + H eqp;
        H = 0 is perfect plasticity.

    Subclasses set ``history_names`` (``"eqp"`` first) and ``_stress_updates``, the law's
    compiled loop over points ``(F (n, 3, 3), prm, h_n (n, n_history), h, P (n, 3, 3))``.
    """

    sigma_y: float
    H: float

    def __post_init__(self):
        super().__post_init__()
        _check_parameter("sigma_y", self.sigma_y, 0.0, None)
        _check_parameter("H", self.H, 0.0, None, lower_closed=True)

    @property
    def law_parameters(self):
        return (self.mu, self.lam, self.sigma_y, self.H)

    def stress_update(self, F, history):
        """(P, history_new) at F (..., 3, 3) of t_{n+1} from the history (..., n_history) of t_n
        (the two batch shapes broadcast): one compiled loop over the points."""
        F = np.asarray(F, dtype=float)
        history = np.asarray(history, dtype=float)
        if history.shape[-1:] != (self.n_history,):
            raise ValueError(f"{type(self).__name__}: history of shape {history.shape}; expected "
                             f"(..., {self.n_history}) with columns {', '.join(self.history_names)}")
        shape = np.broadcast_shapes(F.shape[:-2], history.shape[:-1])
        Fp = np.ascontiguousarray(np.broadcast_to(F, shape + (3, 3)).reshape(-1, 3, 3))
        h_n = np.ascontiguousarray(np.broadcast_to(history, shape + (self.n_history,)).reshape(len(Fp), -1))
        P, h = np.empty_like(Fp), np.empty_like(h_n)
        type(self)._stress_updates(Fp, np.array(self.law_parameters), h_n, h, P)
        return P.reshape(shape + (3, 3)), h.reshape(shape + (self.n_history,))

    def first_piola(self, F):
        """P(F) from the virgin state (`initial_history`), shape ``(..., 3, 3)`` (Pa)."""
        return self.stress_update(F, self.initial_history(1)[0])[0]

    def dissipation(self, history):
        """Plastic work density sigma_y eqp + H eqp^2 / 2, shape ``(...,)`` (J/m^3): the work of
        the exact flow to that eqp; the backward-Euler return dissipates H d(eqp)^2 / 2 more per
        step, numerical dissipation >= 0."""
        eqp = np.asarray(history, dtype=float)[..., 0]
        return self.sigma_y * eqp + 0.5 * self.H * eqp**2

    @property
    def _elastic(self):
        """The elastic law whose compiled tangent this law's `tangent_point` calls."""
        raise NotImplementedError

    def tangent_block(self, F, d):
        """The d-block of the history-free tangent of `tangent_point`, that of the elastic law it
        calls (no dispatch on this law's id needed)."""
        return self._elastic.tangent_block(F, d)

    def is_hyperbolic(self, F, N):
        return self._elastic.is_hyperbolic(F, N)


@dataclass(frozen=True, kw_only=True)
class J2Plasticity(J2Material):
    """Small-strain J2 plasticity: eps = sym(F - I), eps = eps_e + eps_p, P = sigma =
    lam tr(eps_e) I + 2 mu eps_e, von Mises yield q = sqrt(3/2) |dev sigma| <= sigma_y + H eqp,
    associative flow, radial return (closed form for linear hardening).

    History per point: ``history_names`` = eqp, then eps_p 11, 22, 33, 12, 13, 23 (tensor
    components). Plane strain keeps eps_p33 = -(eps_p11 + eps_p22) != 0 although eps33 = 0.
    `tangent` (the Riemann solver's and wave speeds') is the elastic one of `LinearElastic`;
    `consistent_tangent` is the algorithmic dP/dF of the return mapping. Parameters and shapes as
    `J2Material` and `skdgmpm.materials.base`.
    """

    law_id = 4
    point_law = PointLaw(linear_elastic.tangent_point, update=stress_update_point, energy=energy_point)
    history_names = ("eqp", "ep11", "ep22", "ep33", "ep12", "ep13", "ep23")
    _stress_updates = _stress_updates

    @property
    def _elastic(self):
        return LinearElastic(E=self.E, nu=self.nu, rho=self.rho)

    def _plastic_strain(self, history):
        history = np.asarray(history, dtype=float)
        ep = np.empty(history.shape[:-1] + (3, 3))
        for k, (i, j) in enumerate(_SYMMETRIC):
            ep[..., i, j] = ep[..., j, i] = history[..., 1 + k]
        return ep

    def _trial(self, F, history):
        """Trial elastic strain, trial deviator s (..., 3, 3), q = sqrt(3/2)|s| and yield function."""
        G = np.asarray(F, dtype=float) - _I
        e = 0.5 * (G + np.swapaxes(G, -1, -2)) - self._plastic_strain(history)
        s = 2.0 * self.mu * (e - np.trace(e, axis1=-2, axis2=-1)[..., None, None] / 3.0 * _I)
        q = np.sqrt(1.5 * np.einsum("...ij,...ij->...", s, s))
        return e, s, q, q - (self.sigma_y + self.H * np.asarray(history, dtype=float)[..., 0])

    def consistent_tangent(self, F, history):
        """dP_{n+1}/dF_{n+1} of the return mapping from the history of t_n, shape
        ``(..., 3, 3, 3, 3)`` (Pa): Simo & Hughes' algorithmic tangent
        kappa I(x)I + 2 mu theta I_dev - 2 mu theta_bar n(x)n, theta = 1 - 3 mu d(eqp) / q_trial,
        theta_bar = 3 mu / (3 mu + H) - (1 - theta), n = s_trial / |s_trial| (theta = 1,
        theta_bar = 0: elastic), composed with eps = sym(F - I) (its minor symmetries make
        dP_ia/dF_jb = C_iajb)."""
        _, s, q, f = self._trial(F, history)
        plastic = f > 0.0
        q_safe = np.where(plastic, q, 1.0)
        dg = np.where(plastic, f / (3.0 * self.mu + self.H), 0.0)
        theta = 1.0 - 3.0 * self.mu * dg / q_safe
        theta_bar = np.where(plastic, 3.0 * self.mu / (3.0 * self.mu + self.H) - (1.0 - theta), 0.0)
        n = s / (np.sqrt(2.0 / 3.0) * q_safe)[..., None, None]
        I_sym = 0.5 * (np.einsum("ij,ab->iajb", _I, _I) + np.einsum("ib,aj->iajb", _I, _I))
        II = np.einsum("ia,jb->iajb", _I, _I)
        two_mu = 2.0 * self.mu
        return (self.bulk * II + (two_mu * theta)[..., None, None, None, None] * (I_sym - II / 3.0)
                - (two_mu * theta_bar)[..., None, None, None, None] * np.einsum("...ia,...jb->...iajb", n, n))
