"""Finite-strain J2 plasticity: F = Fe Fp, Hencky (logarithmic) elastic energy, radial return in
principal logarithmic stretches with the exponential map (Simo's algorithm) [METHOD §10]."""

from dataclasses import dataclass

import numpy as np
from numba import njit

from skdgmpm.kernel_cache import scratch

from . import neo_hookean
from .base import PointLaw, _inverse_transpose, admissible_inverse
from .j2_plasticity import _SYMMETRIC, J2Material
from .j2_plasticity import history_column as _column
from .neo_hookean import NeoHookean

_I = np.eye(3)


@njit(cache=True, inline="always")
def _jacobi_rotation(A, V, p, q):
    """One Jacobi rotation of the symmetric A (3, 3) that zeroes A[p, q], accumulated into the
    columns of V (Numerical Recipes §11.1: the diagonal updated as a_pp - t a_pq, no cancellation).
    On a block-diagonal A (A02 = A12 = 0) the rotation (0, 1) is the closed-form 2x2
    eigen-decomposition and leaves the off-block entries exactly zero."""
    apq = A[p, q]
    if apq == 0.0:
        return
    theta = 0.5 * (A[q, q] - A[p, p]) / apq
    t = 1.0 / (abs(theta) + np.sqrt(theta * theta + 1.0))    # the smaller root: a rotation <= pi/4
    if theta < 0.0:
        t = -t
    c = 1.0 / np.sqrt(t * t + 1.0)
    s = t * c
    A[p, p] -= t * apq
    A[q, q] += t * apq
    A[p, q], A[q, p] = 0.0, 0.0
    r = 3 - p - q
    arp, arq = A[r, p], A[r, q]
    A[r, p] = A[p, r] = c * arp - s * arq
    A[r, q] = A[q, r] = s * arp + c * arq
    for k in range(3):
        vkp, vkq = V[k, p], V[k, q]
        V[k, p], V[k, q] = c * vkp - s * vkq, s * vkp + c * vkq


@njit(cache=True, inline="always")
def _eigh(A, V):
    """Eigen-decomposition of the symmetric A (3, 3) in place: eigenvalues on A's diagonal,
    orthonormal eigenvectors in V's columns; cyclic Jacobi sweeps (no heap, robust when eigenvalues
    coincide; one rotation when A is block diagonal, as every embedded 1D/2D state is)."""
    for i in range(3):
        for j in range(3):
            V[i, j] = 1.0 if i == j else 0.0
    for _ in range(50):
        off = abs(A[0, 1]) + abs(A[0, 2]) + abs(A[1, 2])
        if not off > 1e-18 * (abs(A[0, 0]) + abs(A[1, 1]) + abs(A[2, 2])):
            break
        _jacobi_rotation(A, V, 0, 1)
        _jacobi_rotation(A, V, 0, 2)
        _jacobi_rotation(A, V, 1, 2)


@njit(cache=True, inline="always")
def _copy_inputs(F, prm, h, F_c, prm_c, h_c):
    """F (3, 3), prm (4,) and a history h (7,) copied into the caller's stack scratch F_c, prm_c,
    h_c, which a called body takes: the caller's own arrays then do not escape into the call
    (`points.tangent_call`)."""
    for i in range(3):
        for a in range(3):
            F_c[i, a] = F[i, a]
    for k in range(4):
        prm_c[k] = prm[k]
    for k in range(7):
        h_c[k] = h[k]


@njit(cache=True, inline="always")
def stress_update_point(F, prm, h_n, h, P, d):
    """Return mapping at one embedded F (3, 3) of t_{n+1}: d-block P (d, d) of P = tau F^-T and
    the history h (7,) from that of t_n, h_n (7,) = (eqp, Cp^-1 11, 22, 33, 12, 13, 23) (read before
    h is written, so the two may be one array); prm = (mu, lam, sigma_y, H). Where det F <= 0, P is
    that of F = I with the virgin state (zero) and the history stays h_n (never NaN).

    The law's code is called (`_return_mapping`), not inlined: inlined through the law table's
    overload (`points.stress_update_point`, built up to three times per kernel) its IR, with the
    Jacobi sweeps, was copied so often that each kernel took 30-40 s to type (docs/bench/session40.md
    §5); called, it compiles once for every kernel. The arrays go through stack copies, so that
    the caller's own do not escape into the call (`points.tangent_call`), and P whole (3, 3): the
    call takes no size, so it compiles once for every dimension (a literal d would be a signature of
    its own)."""
    F_c, prm_c, h_n_c, h_c, P_c = scratch((3, 3)), scratch((4,)), scratch((7,)), scratch((7,)), scratch((3, 3))
    _copy_inputs(F, prm, h_n, F_c, prm_c, h_n_c)
    _return_mapping(F_c, prm_c, h_n_c, h_c, P_c)
    for k in range(7):
        h[k] = h_c[k]
    for i in range(d):
        for a in range(d):
            P[i, a] = P_c[i, a]


@njit(cache=True, inline="always")
def _elastic_trial(F, h_n, A, V):
    """The eigenvalues of be_trial = F Cp^-1 F^T on A's diagonal and its eigenvectors in V's
    columns (A, V (3, 3) scratch), Cp^-1 that of the history h_n (7,)."""
    W = scratch((3, 3))
    for i in range(3):                  # W = F Cp^-1_n, then A = be_trial = W F^T (symmetric)
        for b in range(3):
            s = 0.0
            for k in range(3):
                s += F[i, k] * h_n[_column(k, b)]
            W[i, b] = s
    for i in range(3):
        for j in range(i, 3):
            s = 0.0
            for b in range(3):
                s += W[i, b] * F[j, b]
            A[i, j] = s
            A[j, i] = s
    _eigh(A, V)


@njit(cache=True)
def _stored(F, prm, h):
    """`energy_point`'s body, compiled on its own (the Jacobi sweeps, as `_return_mapping`)."""
    mu, lam = prm[0], prm[1]
    ok, _, _ = _inverse_transpose(F)
    if not ok:
        return np.inf
    A, V = scratch((3, 3)), scratch((3, 3))
    _elastic_trial(F, h, A, V)
    e0, e1, e2 = 0.5 * np.log(A[0, 0]), 0.5 * np.log(A[1, 1]), 0.5 * np.log(A[2, 2])
    tr = e0 + e1 + e2
    m = tr / 3.0
    return mu * ((e0 - m) ** 2 + (e1 - m) ** 2 + (e2 - m) ** 2) + 0.5 * (lam + 2.0 * mu / 3.0) * tr * tr


@njit(cache=True, inline="always")
def energy_point(F, prm, h, W, d):
    """W[0] = mu |dev log Ve|^2 + kappa/2 (tr log Ve)^2 at one embedded F (3, 3), log Ve = 1/2 log be,
    be = F Cp^-1 F^T with Cp^-1 of the history h (7,) in force, +inf where det F <= 0; prm = (mu,
    lam, sigma_y, H). Called through stack copies, as `stress_update_point`."""
    F_c, prm_c, h_c = scratch((3, 3)), scratch((4,)), scratch((7,))
    _copy_inputs(F, prm, h, F_c, prm_c, h_c)
    W[0] = _stored(F_c, prm_c, h_c)


@njit(cache=True)
def _return_mapping(F, prm, h_n, h, P):
    """`stress_update_point`'s body, compiled on its own: P (3, 3) whole, each entry its own sum
    (its d-block the same bits for any d)."""
    mu, lam, sigma_y, H = prm[0], prm[1], prm[2], prm[3]
    ok, _, G = _inverse_transpose(F)
    for k in range(7):
        h[k] = h_n[k]
    if not ok:
        for i in range(3):
            for a in range(3):
                P[i, a] = 0.0
        return
    A, V, W = scratch((3, 3)), scratch((3, 3)), scratch((3, 3))
    _elastic_trial(F, h_n, A, V)
    e0, e1, e2 = 0.5 * np.log(A[0, 0]), 0.5 * np.log(A[1, 1]), 0.5 * np.log(A[2, 2])
    # the small-strain radial return on principal log strains and Kirchhoff stresses
    tr = e0 + e1 + e2
    m, two_mu = tr / 3.0, 2.0 * mu
    s0, s1, s2 = two_mu * (e0 - m), two_mu * (e1 - m), two_mu * (e2 - m)
    q = np.sqrt(1.5 * (s0 * s0 + s1 * s1 + s2 * s2))
    f = q - (sigma_y + H * h_n[0])
    plastic = f > 0.0
    if plastic:
        dg = f / (3.0 * mu + H)
        r = 1.5 * dg / q
        h[0] += dg
        e0, e1, e2 = e0 - r * s0, e1 - r * s1, e2 - r * s2     # tr unchanged: isochoric flow
        c = 1.0 - two_mu * r
        s0, s1, s2 = c * s0, c * s1, c * s2
    p = (lam + two_mu / 3.0) * tr
    t0, t1, t2 = p + s0, p + s1, p + s2
    for i in range(3):                  # W = tau, the Kirchhoff stress, coaxial with be_trial
        for j in range(3):
            W[i, j] = t0 * V[i, 0] * V[j, 0] + t1 * V[i, 1] * V[j, 1] + t2 * V[i, 2] * V[j, 2]
    for i in range(3):
        for a in range(3):
            s = 0.0
            for k in range(3):
                s += W[i, k] * G[3 * k + a]
            P[i, a] = s
    if plastic:                         # Cp^-1 = F^-1 be F^-T, be = sum exp(2 eps_A) n_A n_A^T
        b0, b1, b2 = np.exp(2.0 * e0), np.exp(2.0 * e1), np.exp(2.0 * e2)
        for i in range(3):              # W = be
            for j in range(3):
                W[i, j] = b0 * V[i, 0] * V[j, 0] + b1 * V[i, 1] * V[j, 1] + b2 * V[i, 2] * V[j, 2]
        for i in range(3):              # A = be G (F^-1 = G^T)
            for b in range(3):
                s = 0.0
                for j in range(3):
                    s += W[i, j] * G[3 * j + b]
                A[i, b] = s
        for a in range(3):
            for b in range(a, 3):
                s = 0.0
                for i in range(3):
                    s += G[3 * i + a] * A[i, b]
                h[_column(a, b)] = s


@njit(cache=True, inline="always")
def tangent_point(F, prm, C, d):
    """The neo-Hookean tangent (`neo_hookean.tangent_point`, prm[:2] = (mu, lam)) at the total F:
    the history-free tangent the Riemann solver and the wave-speed check use, d-block into
    C (d, d, d, d). Polyconvex, so hyperbolic at every F with J > 0, and equal to the Hencky
    tangent at small strain (both the isotropic lam, mu tensor at F = I)."""
    neo_hookean.tangent_point(F, prm, C, d)


@njit(cache=True)
def _stress_updates(F, prm, h_n, h, P):
    for p in range(len(F)):
        stress_update_point(F[p], prm, h_n[p], h[p], P[p], 3)


@dataclass(frozen=True, kw_only=True)
class HenckyJ2(J2Material):
    """Finite-strain J2 plasticity: F = Fe Fp, W = mu |dev log Ve|^2 + kappa/2 (tr log Ve)^2,
    von Mises yield on the Kirchhoff stress tau, q = sqrt(3/2) |dev tau| <= sigma_y + H eqp,
    plastically incompressible (det Fp = 1).

    History per point: ``history_names`` = eqp, then Cp^-1 = Fp^-1 Fp^-T, components 11, 22, 33,
    12, 13, 23 (I in the virgin state). Simo's algorithm: be_trial = F Cp^-1_n F^T, principal log
    stretches eps_A = 1/2 log eig(be_trial), tau_A = lam tr(eps) + 2 mu eps_A, radial return on
    dev tau in principal space (closed form for linear hardening; the exponential map keeps
    det Cp^-1 fixed), be = sum exp(2 eps_A) n_A n_A^T, Cp^-1 = F^-1 be F^-T, P = tau F^-T. At small
    strain it is `J2Plasticity`. `tangent` (the Riemann solver's and wave speeds') is the
    neo-Hookean one of `tangent_point`; `consistent_tangent` is the algorithmic dP/dF of the
    return mapping. States with J <= 0 give P = 0 and keep their history, `energy` +inf and
    `is_hyperbolic` False. Parameters and shapes as `J2Material` and `skdgmpm.materials.base`.
    """

    law_id = 5
    point_law = PointLaw(neo_hookean.tangent_point, update=stress_update_point, energy=energy_point)
    history_names = ("eqp", "Cpi11", "Cpi22", "Cpi33", "Cpi12", "Cpi13", "Cpi23")
    _stress_updates = _stress_updates

    @property
    def _elastic(self):
        return NeoHookean(E=self.E, nu=self.nu, rho=self.rho)

    def initial_history(self, n):
        h = np.zeros((n, self.n_history))
        h[:, 1:4] = 1.0
        return h

    def _plastic_metric(self, history):
        """Cp^-1 (..., 3, 3) from the history (..., 7)."""
        history = np.asarray(history, dtype=float)
        Cpi = np.empty(history.shape[:-1] + (3, 3))
        for k, (i, j) in enumerate(_SYMMETRIC):
            Cpi[..., i, j] = Cpi[..., j, i] = history[..., 1 + k]
        return Cpi

    def _trial(self, F, history):
        """F (I where J <= 0), G = F^-T, the mask J > 0, Cp^-1 and be_trial's eigenvalues
        (..., 3) and eigenvectors (..., 3, 3) (columns)."""
        F, G, _, ok = admissible_inverse(F)
        Cpi = self._plastic_metric(history)
        Cpi = np.where(ok[..., None, None], Cpi, _I)
        be = F @ Cpi @ np.swapaxes(F, -1, -2)
        lam_A, N = np.linalg.eigh(0.5 * (be + np.swapaxes(be, -1, -2)))
        return F, G, ok, Cpi, lam_A, N

    def consistent_tangent(self, F, history):
        """dP_{n+1}/dF_{n+1} of the return mapping from the history of t_n, shape
        ``(..., 3, 3, 3, 3)`` (Pa), analytic.

        tau = sum tau_A(lambda) n_A n_A^T is an isotropic function of be_trial (eigenvalues
        lambda_A, eigenvectors n_A), so
        d tau = sum_AB (a_AB / (2 lambda_B)) (n_B.d be.n_B) n_A n_A^T
        + sum_(A != B) c_AB (n_A.d be.n_B) n_A n_B^T, with a_AB = d tau_A / d eps_B the small-strain
        algorithmic tangent in principal space (K + 2 mu theta (delta_AB - 1/3)
        - 2 mu theta_bar n_A n_B, see `J2Plasticity.consistent_tangent`) and
        c_AB = (tau_A - tau_B) / (lambda_A - lambda_B) = theta mu log(lambda_A / lambda_B) /
        (lambda_A - lambda_B) (radial return scales every dev tau_A by the same theta; evaluated
        with log1p, so it tends to theta mu / lambda as the eigenvalues coincide, which they do
        in uniaxial strain and at rest). Then d be = dF Cp^-1 F^T + F Cp^-1 dF^T and
        dP = d tau G - tau G dF^T G, G = F^-T. Where J <= 0: the tangent at F = I, virgin.
        """
        F, G, ok, Cpi, lam_A, N = self._trial(F, history)
        eqp = np.where(ok, np.asarray(history, dtype=float)[..., 0], 0.0)
        e = 0.5 * np.log(lam_A)
        tr = e.sum(axis=-1)
        s = 2.0 * self.mu * (e - tr[..., None] / 3.0)
        q = np.sqrt(1.5 * (s**2).sum(axis=-1))
        f = q - (self.sigma_y + self.H * eqp)
        plastic = f > 0.0
        q_safe = np.where(plastic, q, 1.0)
        dg = np.where(plastic, f / (3.0 * self.mu + self.H), 0.0)
        theta = 1.0 - 3.0 * self.mu * dg / q_safe
        theta_bar = np.where(plastic, 3.0 * self.mu / (3.0 * self.mu + self.H) - (1.0 - theta), 0.0)
        n = s / (np.sqrt(2.0 / 3.0) * q_safe)[..., None]
        tau_A = self.bulk * tr[..., None] + theta[..., None] * s
        two_mu, d3 = 2.0 * self.mu, np.eye(3)
        a = (self.bulk + (two_mu * theta)[..., None, None] * (d3 - 1.0 / 3.0)
             - (two_mu * theta_bar)[..., None, None] * n[..., :, None] * n[..., None, :])
        dtau_dlam = a / (2.0 * lam_A[..., None, :])
        # c_AB = theta mu log(x/y)/(x - y) = theta mu log1p(r)/(r y), r = x/y - 1
        x, y = lam_A[..., :, None], lam_A[..., None, :]
        r = x / y - 1.0
        ratio = np.where(r == 0.0, 1.0, np.log1p(r) / np.where(r == 0.0, 1.0, r))
        c = (self.mu * theta)[..., None, None] * ratio / y * (1.0 - d3)
        D = (np.einsum("...AB,...iA,...kA,...mB,...lB->...ikml", dtau_dlam, N, N, N, N)
             + np.einsum("...AB,...iA,...kB,...mA,...lB->...ikml", c, N, N, N, N))
        FC = F @ Cpi
        # d be_ml / dF_jb = delta_mj FC_lb + FC_mb delta_lj
        dtau = np.einsum("...ikjl,...lb->...ikjb", D, FC) + np.einsum("...ikmj,...mb->...ikjb", D, FC)
        tau = np.einsum("...A,...iA,...kA->...ik", tau_A, N, N)
        return (np.einsum("...ikjb,...ka->...iajb", dtau, G)
                - np.einsum("...ik,...kb,...ja->...iajb", tau, G, G))
