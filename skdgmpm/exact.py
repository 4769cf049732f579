"""Exact solutions of the 1D bar problems of [R18 §7.1-7.2, App. A] and error norms.

Both problems solve the 1D total-Lagrangian system

    dF/dt - dv/dX = 0,        rho dv/dt - dP/dX = 0,

at reference positions ``X`` (shape ``(n, d)``, only ``X[:, 0]`` is used; a 1-D array is
accepted too). ``fields(X, t)`` returns a dict of 1-D arrays (one value per point) with at
least ``"P11"`` (first Piola-Kirchhoff stress, Pa), ``"v1"`` (m/s) and ``"F11"``.

Convention at discontinuities: a point lying exactly on a front (or a fan edge) takes the state
behind it, i.e. the side connected to the loaded end. Times must be ``t >= 0``.
"""

from __future__ import annotations

import math
from dataclasses import MISSING, dataclass, field, fields as dc_fields

import numpy as np
from scipy.optimize import brentq

from skdgmpm.errors import InputError
from skdgmpm.manufactured import MANUFACTURED

__all__ = ["EXACT", "ElasticBarStep", "ElastoplasticBarStep", "SVKBarRiemann", "error_norms", "make_exact",
           "relative_errors"]


def _check(cls, key, value, ok, what):
    """Raise a one-line InputError unless ``value`` is a finite real number with ``ok(value)``."""
    try:
        good = not isinstance(value, bool) and math.isfinite(float(value)) and ok(float(value))
    except (TypeError, ValueError):
        good = False
    if not good:
        raise InputError(f"{cls.__name__}: bad value for '{key}': {value!r} (expected {what})")
    return float(value)


def _positions(X):
    X = np.asarray(X, dtype=float)
    if X.ndim == 2 and X.shape[1] >= 1:
        return X[:, 0]
    if X.ndim == 1:
        return X
    raise InputError(f"exact solution: bad shape for 'X': {X.shape} (expected (n, d))")


def _time(t):
    t = float(t)
    if not (math.isfinite(t) and t >= 0.0):
        raise InputError(f"exact solution: bad value for 't': {t!r} (expected t >= 0)")
    return t


@dataclass(frozen=True, kw_only=True)
class ElasticBarStep:
    """Linear elastic bar ``0 <= X <= L`` under a traction step at ``X = 0``, fixed at ``X = L``.

    Uniaxial stress: ``P11 = E (F11 - 1)``, ``c = sqrt(E / rho)``, impedance ``Z = rho c``
    [R18 §7.1]. At rest for ``t < 0``; for ``t >= 0`` the left end carries ``P11 = traction``
    (negative: compression, e.g. ``-1e9``) and the right end ``v = 0``.

    The d'Alembert solution is a sum of step fronts (method of images). Front ``j = 0, 1, ...``
    leaves an end at ``t = j L / c``; even ``j`` run right (``X = c t - j L``), odd ``j`` run
    left (``X = (j + 1) L - c t``). Stress jumps are ``traction * (+1, +1, -1, -1)`` repeating
    (the fixed end doubles the stress, the loaded end restores ``P11 = traction``); the velocity
    jump is ``-dP / Z`` for right-going and ``+dP / Z`` for left-going fronts. Hence behind the
    incident front ``v = -traction / Z`` (> 0 in compression), behind the first reflection
    ``P11 = 2 traction`` and ``v = 0``. The motion has period ``4 L / c`` (at ``c t = 4 L`` the
    bar is at rest and unstrained), which is used to evaluate any ``t`` with four fronts.

    Parameters
    ----------
    length, E, rho : float
        Bar length (m), Young's modulus (Pa), density (kg/m^3), all > 0.
    traction : float
        Imposed ``P11`` at ``X = 0`` (Pa).
    """

    length: float
    E: float
    rho: float
    traction: float

    def __post_init__(self):
        for key in ("length", "E", "rho"):
            object.__setattr__(self, key, _check(type(self), key, getattr(self, key),
                                                 lambda x: x > 0, "a number > 0"))
        object.__setattr__(self, "traction", _check(type(self), "traction", self.traction,
                                                    lambda x: True, "a finite number"))

    @property
    def c(self):
        """Wave speed ``sqrt(E / rho)`` (m/s)."""
        return math.sqrt(self.E / self.rho)

    def fields(self, X, t):
        """Exact fields at reference positions ``X`` and time ``t``.

        Returns
        -------
        dict
            ``"P11"``, ``"v1"``, ``"F11"`` and ``"u1"`` (displacement, ``u1(L) = 0``).
        """
        x = _positions(X)
        L, c, T = self.length, self.c, self.traction
        Z = self.rho * c
        tau = math.fmod(c * _time(t), 4.0 * L)  # c t reduced to one period
        j = np.arange(4)
        dP = T * np.array([1.0, 1.0, -1.0, -1.0])
        right = j % 2 == 0
        dv = np.where(right, -dP / Z, dP / Z)
        dist = j * L + np.where(right, x[:, None], L - x[:, None])  # c t at which front j passes
        behind = tau >= dist
        lag = np.where(behind, (tau - dist) / c, 0.0)  # time since front j passed
        P = behind @ dP
        return {"P11": P, "v1": behind @ dv, "F11": 1.0 + P / self.E, "u1": lag @ dv}


@dataclass(frozen=True, kw_only=True)
class SVKBarRiemann:
    """Saint-Venant-Kirchhoff half-space ``X >= 0`` in uniaxial strain under a traction step.

    ``P11 = Pi(F) = K/2 F (F^2 - 1)``, ``P22 = lam/2 (F^2 - 1)`` [R18 eq A.5], ``K = lam + 2 mu``
    from ``E, nu``; longitudinal speed ``c(F) = sqrt(K (3 F^2 - 1) / (2 rho))`` [R18 eq A.8],
    real for ``F > 1/sqrt(3)`` [R18 eq A.10]. Initially at rest (``F = 1, v = 0``); for
    ``t >= 0`` the traction ``Pi = traction`` is held at ``X = 0``. The solution is one 2-wave
    from the loaded state ``F*`` (``Pi(F*) = traction``, the root with ``F* > 1/sqrt(3)``; none
    when ``traction <= Pi(1/sqrt(3)) = -K / (3 sqrt(3))``: loss of hyperbolicity, InputError) to
    the rest state:

    * compression (``F* < 1``): ``c`` grows with ``F``, so a centred rarefaction. For
      ``c(F*) t <= X <= c(1) t`` the state solves ``c(F) = xi = X/t``, i.e.
      ``F(xi) = sqrt((2 rho xi^2 / K + 1) / 3)``. [R18 eq A.23] as printed,
      ``sqrt(2 rho xi^2 / (3 K) + 1)``, misplaces the 1/3 (it gives ``F(c(1)) != 1``); the
      formula here is derived directly from ``xi = c(F)``. Velocity along the 2-integral curve
      through the rest state: ``dv = -c(F) dF``, ``v(F) = int_F^1 c(s) ds``, in closed form
      with ``int sqrt(3 s^2 - 1) ds = s/2 sqrt(3 s^2 - 1) - ln(sqrt(3) s + sqrt(3 s^2 - 1)) /
      (2 sqrt(3))`` (this agrees with [R18 eq A.22]).
    * tension (``F* > 1``): a shock of speed ``s = sqrt(Pi(F*) / (rho (F* - 1)))
      = sqrt(K F* (F* + 1) / (2 rho))`` and ``v* = -s (F* - 1)`` (Rankine-Hugoniot
      [R18 eq A.12-A.16]); the Lax condition ``c(F*) > s > c(1)`` holds for every ``F* > 1``.

    Parameters
    ----------
    E, nu, rho : float
        Young's modulus (Pa, > 0), Poisson ratio (in (-1, 0.5)), density (kg/m^3, > 0).
    traction : float
        Imposed ``P11`` at ``X = 0`` (Pa): negative is compression.
    length : float or None
        Optional bar length (m): not used by the solution, which is exact for a finite bar
        until ``t_max = length / (fastest wave speed)``.
    """

    E: float
    nu: float
    rho: float
    traction: float
    length: float | None = None
    lam: float = field(init=False)
    mu: float = field(init=False)
    K: float = field(init=False)
    F_star: float = field(init=False)
    v_star: float = field(init=False)
    wave: str = field(init=False)
    speeds: tuple = field(init=False)

    def __post_init__(self):
        cls, put = type(self), lambda k, v: object.__setattr__(self, k, v)
        put("E", _check(cls, "E", self.E, lambda x: x > 0, "a number > 0"))
        put("rho", _check(cls, "rho", self.rho, lambda x: x > 0, "a number > 0"))
        put("nu", _check(cls, "nu", self.nu, lambda x: -1 < x < 0.5, "a number in (-1, 0.5)"))
        put("traction", _check(cls, "traction", self.traction, lambda x: True, "a finite number"))
        if self.length is not None:
            put("length", _check(cls, "length", self.length, lambda x: x > 0, "a number > 0"))
        lam = self.E * self.nu / ((1 + self.nu) * (1 - 2 * self.nu))
        mu = self.E / (2 * (1 + self.nu))
        K = lam + 2 * mu
        put("lam", lam), put("mu", mu), put("K", K)
        T = self.traction
        if T <= -K / (3 * math.sqrt(3)):
            raise InputError(f"{cls.__name__}: bad value for 'traction': {T!r} (loss of "
                             f"hyperbolicity: needs traction > -(lam+2mu)/(3 sqrt 3) = "
                             f"{-K / (3 * math.sqrt(3)):.6g})")
        # solve Pi(1 + e) = T for e = F - 1 (keeps relative accuracy for tiny loads)
        g = lambda e: 0.5 * K * e * (2 + 3 * e + e * e) - T  # noqa: E731
        e = 0.0 if T == 0 else brentq(g, 1 / math.sqrt(3) - 1, (2 * abs(T) / K) ** (1 / 3),
                                      xtol=1e-300, rtol=4 * np.finfo(float).eps, maxiter=500)
        Fs = 1.0 + e
        put("F_star", Fs)
        if Fs < 1:
            put("wave", "rarefaction")
            put("speeds", (float(self.c(Fs)), float(self.c(1.0))))
            put("v_star", float(self.integral_curve_velocity(Fs)))
        else:  # tension, or no load (zero-strength wave at c(1))
            s = math.sqrt(K * Fs * (Fs + 1) / (2 * self.rho))
            put("wave", "shock")
            put("speeds", (s, s))
            put("v_star", -s * e)

    def Pi(self, F):
        """Axial stress ``P11 = K/2 F (F^2 - 1)``."""
        F = np.asarray(F, dtype=float)
        return 0.5 * self.K * F * (F * F - 1)

    def c(self, F):
        """Longitudinal wave speed ``sqrt(K (3 F^2 - 1) / (2 rho))``."""
        F = np.asarray(F, dtype=float)
        return np.sqrt(self.K * (3 * F * F - 1) / (2 * self.rho))

    def integral_curve_velocity(self, F):
        """Velocity on the 2-integral curve through the rest state: ``int_F^1 c(s) ds``."""
        F = np.asarray(F, dtype=float)

        def G(s):  # antiderivative of sqrt(3 s^2 - 1)
            r = np.sqrt(3 * s * s - 1)
            return 0.5 * s * r - np.log(math.sqrt(3) * s + r) / (2 * math.sqrt(3))

        return math.sqrt(self.K / (2 * self.rho)) * (G(1.0) - G(F))

    def fan_F(self, xi):
        """``F`` inside the rarefaction fan: the root of ``c(F) = xi``."""
        xi = np.asarray(xi, dtype=float)
        return np.sqrt((2 * self.rho * xi * xi / self.K + 1) / 3)

    @property
    def t_max(self):
        """Time until the fastest wave reaches ``X = length`` (``inf`` without a length)."""
        return math.inf if self.length is None else self.length / self.speeds[1]

    def fields(self, X, t):
        """Exact fields at reference positions ``X`` and time ``t``.

        Returns
        -------
        dict
            ``"P11"``, ``"P22"``, ``"v1"`` and ``"F11"``.
        """
        x, t = _positions(X), _time(t)
        lo, hi = self.speeds
        star = x <= lo * t
        fan = ~star & (x < hi * t)  # empty for a shock (lo == hi)
        F = np.where(star, self.F_star, 1.0)
        v = np.where(star, self.v_star, 0.0)
        if np.any(fan):
            Ff = self.fan_F(x[fan] / t)
            F[fan], v[fan] = Ff, self.integral_curve_velocity(Ff)
        return {"P11": self.Pi(F), "P22": 0.5 * self.lam * (F * F - 1), "v1": v, "F11": F}


@dataclass(frozen=True, kw_only=True)
class ElastoplasticBarStep:
    """Small-strain J2 bar ``0 <= X <= L`` in uniaxial strain under a traction step at ``X = 0``.

    Strain ``eps = diag(e, 0, 0)`` with ``e = F11 - 1`` (``F = diag(F11, 1, 1)``); isotropic
    linear elasticity (``lam, mu, K = lam + 2 mu / 3`` from ``E, nu``), von Mises yield
    ``q = sqrt(3/2 s:s) <= sigma_y + H eqp`` with linear isotropic hardening ``H >= 0`` and
    associated flow, the law of materials/j2_plasticity.py. At rest for ``t < 0``; for ``t >= 0`` the left end
    carries ``P11 = traction`` (negative: compression; at small strain ``P = sigma``). The
    solution below holds until the precursor reaches the far end, ``t_max = length / c_e``
    (whatever holds that end); later times raise an InputError.

    Derivation. Along ``eps = diag(e, 0, 0)`` the deviatoric strain is ``e diag(2, -1, -1) / 3``,
    a fixed direction, so the radial return is exact for any step along the path and the law is
    a function of ``e``. Elastic: ``sigma11 = (lam + 2 mu) e``, ``sigma22 = sigma33 = lam e``,
    ``q = 2 mu |e|``: yield at ``|e_Y| = sigma_y / (2 mu)``, ``|sigma11| = sigma_HEL =
    (lam + 2 mu) sigma_y / (2 mu)``. Plastic (``s = sgn(e) q diag(2, -1, -1) / 3``, flow
    ``eps_p = sgn(e) eqp diag(1, -1/2, -1/2)``): ``q = 2 mu |e| - 3 mu eqp = sigma_y + H eqp``
    gives ``eqp = 2 mu (|e| - |e_Y|) / (3 mu + H)`` and ``sigma11 = K e + sgn(e) 2 q / 3``,
    ``d sigma11 / de = M_p = K + 4 mu H / (3 (3 mu + H)) < lam + 2 mu``, constant: the stress
    is piecewise linear in ``e``, so each wave is a shock (no fan) of speed ``sqrt(modulus /
    rho)``, the faster one first. Each right-going front ``X = c t`` obeys ``[sigma] = -rho c
    [v]`` (momentum) and ``[v] = -c [e]`` (compatibility), ``[.]`` = ahead - behind.

    With ``s = sgn(traction)`` and ``c_e = sqrt((lam + 2 mu) / rho)``, ``c_p = sqrt(M_p /
    rho)`` (``sqrt(K / rho)`` for ``H = 0``), the regions are

    0. ``X > c_e t``: rest, ``e = v = sigma = eps_p = eqp = 0``;
    1. ``c_p t < X <= c_e t`` (elastic precursor, only if ``|traction| > sigma_HEL``):
       ``e1 = s sigma_y / (2 mu)``, ``P11 = s sigma_HEL``, ``P22 = P33 = lam e1``,
       ``v1 = -c_e e1``, ``eps_p = eqp = 0``;
    2. ``X <= c_p t`` (plastic shock): ``e2 = e1 + (traction - s sigma_HEL) / M_p``,
       ``P11 = traction``, ``v2 = v1 - c_p (e2 - e1)``, ``eqp2 = 2 mu |e2 - e1| / (3 mu + H)``,
       ``eps_p11 = s eqp2`` (``eps_p22 = eps_p33 = -eps_p11 / 2``),
       ``P22 = P33 = traction - s (sigma_y + H eqp2)``.

    Below the elastic limit (``|traction| <= sigma_HEL``) there is one elastic front at ``c_e``
    with ``e = traction / (lam + 2 mu)``, ``v = -c_e e``: the ElasticBarStep solution with
    ``E = lam + 2 mu`` before its reflection. Returned also: ``"eps11" = e`` and the
    displacement ``"u1"`` (zero ahead of the fronts, ``du1/dX = e``, ``du1/dt = v1``).

    Parameters
    ----------
    E, nu, rho : float
        Young's modulus (Pa, > 0), Poisson ratio (in (-1, 0.5)), density (kg/m^3, > 0).
    sigma_y, H : float
        Yield stress (Pa, > 0) and hardening modulus of ``q = sigma_y + H eqp`` (Pa, >= 0).
    traction : float
        Imposed ``P11`` at ``X = 0`` (Pa): negative is compression.
    length : float or None
        Bar length (m): the solution is refused after ``t_max = length / c_e``; None: a
        half-space, any ``t >= 0``.
    """

    E: float
    nu: float
    rho: float
    sigma_y: float
    H: float
    traction: float
    length: float | None = None
    lam: float = field(init=False)
    mu: float = field(init=False)
    K: float = field(init=False)
    M_p: float = field(init=False)
    sigma_HEL: float = field(init=False)
    c_e: float = field(init=False)
    c_p: float = field(init=False)
    plastic: bool = field(init=False)
    states: tuple = field(init=False, repr=False, compare=False)

    def __post_init__(self):
        cls, put = type(self), lambda k, v: object.__setattr__(self, k, v)
        for key in ("E", "rho", "sigma_y"):
            put(key, _check(cls, key, getattr(self, key), lambda x: x > 0, "a number > 0"))
        put("nu", _check(cls, "nu", self.nu, lambda x: -1 < x < 0.5, "a number in (-1, 0.5)"))
        put("H", _check(cls, "H", self.H, lambda x: x >= 0, "a number >= 0"))
        put("traction", _check(cls, "traction", self.traction, lambda x: True, "a finite number"))
        if self.length is not None:
            put("length", _check(cls, "length", self.length, lambda x: x > 0, "a number > 0"))
        E, nu, rho, sy, H, T = self.E, self.nu, self.rho, self.sigma_y, self.H, self.traction
        lam, mu = E * nu / ((1 + nu) * (1 - 2 * nu)), E / (2 * (1 + nu))
        K = lam + 2 * mu / 3
        M_e, M_p = lam + 2 * mu, K + 4 * mu * H / (3 * (3 * mu + H))
        HEL = M_e * sy / (2 * mu)
        put("lam", lam), put("mu", mu), put("K", K), put("M_p", M_p), put("sigma_HEL", HEL)
        put("c_e", math.sqrt(M_e / rho)), put("c_p", math.sqrt(M_p / rho))
        put("plastic", abs(T) > HEL)
        s = math.copysign(1.0, T)
        rest = _bar_state(0.0, 0.0, 0.0, 0.0, 0.0)
        if not self.plastic:            # one elastic front carrying the load
            e = T / M_e
            put("states", (_bar_state(e, T, lam * e, -self.c_e * e, 0.0), rest))
            return
        e1 = s * sy / (2 * mu)
        one = _bar_state(e1, s * HEL, lam * e1, -self.c_e * e1, 0.0)
        e2 = e1 + (T - s * HEL) / M_p
        eqp = 2 * mu * abs(e2 - e1) / (3 * mu + H)
        two = _bar_state(e2, T, T - s * (sy + H * eqp), one["v1"] - self.c_p * (e2 - e1), s * eqp)
        put("states", (two, one, rest))

    @property
    def speeds(self):
        """Front speeds, slowest first: ``(c_p, c_e)`` or ``(c_e,)`` below the elastic limit."""
        return (self.c_p, self.c_e) if self.plastic else (self.c_e,)

    @property
    def t_max(self):
        """Time when the precursor reaches ``X = length`` (``inf`` without a length)."""
        return math.inf if self.length is None else self.length / self.c_e

    def fields(self, X, t):
        """Exact fields at reference positions ``X`` and time ``t <= t_max``.

        Returns
        -------
        dict
            ``"P11"``, ``"P22"``, ``"P33"`` (Pa), ``"v1"`` (m/s), ``"F11"``, ``"eps11"``,
            ``"eps_p11"``, ``"eqp"`` and ``"u1"`` (m).
        """
        x, t = _positions(X), _time(t)
        if t > self.t_max * (1 + 1e-12):
            raise InputError(f"{type(self).__name__}: bad value for 't': {t!r} (the solution holds "
                             f"until the elastic front reaches X = length, t_max = {self.t_max:.6g} s)")
        fronts = np.array(self.speeds) * t              # region k: behind front k, ahead of k - 1
        region = np.searchsorted(fronts, x, side="left")  # on a front: the state behind it
        out = {k: np.array([st[k] for st in self.states])[region] for k in self.states[0]}
        # u1 = -int_X^{c_e t} e dX: the part of [X, c_e t] behind each front times its strain
        lo = np.concatenate([[-np.inf], fronts[:-1]])
        overlap = np.clip(fronts - np.maximum(x[:, None], lo), 0.0, None)
        out["u1"] = -overlap @ np.array([st["eps11"] for st in self.states[:-1]])
        return out


def _bar_state(e, P11, P22, v, eps_p11):
    """One constant state of the uniaxial-strain bar (eqp = |eps_p11| on this path)."""
    return {"P11": P11, "P22": P22, "P33": P22, "v1": v, "F11": 1.0 + e, "eps11": e,
            "eps_p11": eps_p11, "eqp": abs(eps_p11)}


@dataclass(frozen=True, kw_only=True)
class StandingWave2D:
    """Standing P-wave eigenmode of a linear elastic rectangle [0, lx] x [0, ly] (plane strain)
    with zero normal velocity and zero shear on all four sides (symmetry planes).

    u = A grad(phi) / |k| cos(omega t), phi = cos(kx X) cos(ky Y), kx = m pi / lx,
    ky = n pi / ly, omega = c_p |k|, c_p = sqrt((lam + 2 mu) / rho). The displacement is curl-free,
    so grad u is symmetric and the linear law P = lam tr(eps) I + 2 mu eps is exact; on X = 0, lx
    the normal displacement and the shear strain vanish (sin(kx X) = 0), likewise on Y = 0, ly.

    Parameters
    ----------
    E, nu, rho : material (Pa, -, kg/m^3); amplitude : A (m); size : (lx, ly) (m);
    modes : (m, n) half-wavelengths along X and Y.
    """

    E: float
    nu: float
    rho: float
    amplitude: float = 1e-4
    size: tuple = (1.0, 1.0)
    modes: tuple = (1, 1)

    def __post_init__(self):
        for key in ("E", "rho"):
            _check(type(self), key, getattr(self, key), lambda x: x > 0, "a number > 0")
        _check(type(self), "nu", self.nu, lambda x: -1 < x < 0.5, "a number in (-1, 0.5)")
        _check(type(self), "amplitude", self.amplitude, lambda x: True, "a finite number")

    @property
    def omega(self):
        lam = self.E * self.nu / ((1 + self.nu) * (1 - 2 * self.nu))
        mu = self.E / (2 * (1 + self.nu))
        k = math.hypot(*self.wavenumbers)
        return math.sqrt((lam + 2 * mu) / self.rho) * k

    @property
    def wavenumbers(self):
        return tuple(m * math.pi / s for m, s in zip(self.modes, self.size))

    def fields(self, X, t):
        X = np.asarray(X, dtype=float)
        if X.ndim != 2 or X.shape[1] != 2:
            raise InputError(f"StandingWave2D: X must have shape (n, 2), got {X.shape}")
        kx, ky = self.wavenumbers
        k = math.hypot(kx, ky)
        a = self.amplitude / k
        w, t = self.omega, _time(t)
        cx, sx = np.cos(kx * X[:, 0]), np.sin(kx * X[:, 0])
        cy, sy = np.cos(ky * X[:, 1]), np.sin(ky * X[:, 1])
        e11, e22 = -a * kx * kx * cx * cy * math.cos(w * t), -a * ky * ky * cx * cy * math.cos(w * t)
        e12 = a * kx * ky * sx * sy * math.cos(w * t)
        lam = self.E * self.nu / ((1 + self.nu) * (1 - 2 * self.nu))
        mu = self.E / (2 * (1 + self.nu))
        tr = e11 + e22
        return {
            "F11": 1 + e11, "F12": e12, "F21": e12, "F22": 1 + e22,
            "eps11": e11, "eps12": e12, "eps22": e22,
            "P11": lam * tr + 2 * mu * e11, "P22": lam * tr + 2 * mu * e22, "P12": 2 * mu * e12,
            "P21": 2 * mu * e12,
            "v1": a * kx * w * sx * cy * math.sin(w * t), "v2": a * ky * w * cx * sy * math.sin(w * t),
        }


@dataclass(frozen=True, kw_only=True)
class SquareInitialStrain:
    """Initial state of the L23 §5.1 convergence square (no exact solution: compare with a fine
    reference): eps = f (e1 (x) e1 - e2 (x) e2), f = U0 pi / 2 cos(pi X / 2) sin(pi Y / 2)
    (L23 eq 68-69), v = 0. Only t = 0 is defined."""

    amplitude: float = 5e-4

    def fields(self, X, t):
        if t != 0:
            raise InputError("SquareInitialStrain: only the initial state (t = 0) is known")
        X = np.asarray(X, dtype=float)
        f = self.amplitude * math.pi / 2 * np.cos(math.pi * X[:, 0] / 2) * np.sin(math.pi * X[:, 1] / 2)
        zero = np.zeros(len(X))
        return {"F11": 1 + f, "F12": zero, "F21": zero, "F22": 1 - f, "v1": zero, "v2": zero}


@dataclass(frozen=True, kw_only=True)
class SquareShearMode:
    """The L23 §5.1 convergence square read consistently (METHOD.md, note after §9): the unit
    square with symmetry on the left and top faces and free right and bottom faces holds the
    standing shear mode

        u = U0 (sin(pi X/2) sin(pi Y/2), cos(pi X/2) cos(pi Y/2)) cos(omega t),
        omega = pi sqrt(mu / (2 rho)),

    whose strain at t = 0 is the paper's eps = f (e1 (x) e1 - e2 (x) e2), f = U0 pi/2 cos(pi X/2)
    sin(pi Y/2) (tr eps = 0, so P = 2 mu eps with the linear law, div P = -mu pi^2/2 u). Every
    face is compatible with it: u1 = P21 = 0 on X = 0, u2 = P12 = 0 on Y = 1, P11 = P21 = 0 on
    X = 1, P22 = P12 = 0 on Y = 0. F = I + grad u holds the rotation W (F12 = -F21)."""

    E: float
    nu: float
    rho: float
    amplitude: float = 5e-4

    def __post_init__(self):
        for key in ("E", "rho"):
            _check(type(self), key, getattr(self, key), lambda x: x > 0, "a number > 0")
        _check(type(self), "nu", self.nu, lambda x: -1 < x < 0.5, "a number in (-1, 0.5)")

    @property
    def mu(self):
        return self.E / (2 * (1 + self.nu))

    @property
    def omega(self):
        return math.pi * math.sqrt(self.mu / (2 * self.rho))

    def fields(self, X, t):
        X = np.asarray(X, dtype=float)
        if X.ndim != 2 or X.shape[1] != 2:
            raise InputError(f"SquareShearMode: X must have shape (n, 2), got {X.shape}")
        a, k, w, t = self.amplitude, math.pi / 2, self.omega, _time(t)
        cx, sx = np.cos(k * X[:, 0]), np.sin(k * X[:, 0])
        cy, sy = np.cos(k * X[:, 1]), np.sin(k * X[:, 1])
        c, s = math.cos(w * t), math.sin(w * t)
        f = a * k * cx * sy * c                            # eps11 = -eps22
        g = a * k * sx * cy * c                            # F12 = -F21 (the rotation)
        zero = np.zeros(len(X))
        return {
            "F11": 1 + f, "F12": g, "F21": -g, "F22": 1 - f, "eps11": f, "eps12": zero, "eps22": -f,
            "P11": 2 * self.mu * f, "P22": -2 * self.mu * f, "P12": zero, "P21": zero,
            "v1": -a * w * sx * sy * s, "v2": -a * w * cx * cy * s,
            "u1": a * sx * sy * c, "u2": a * cx * cy * c,
        }


INITIAL = {"square_initial_strain": SquareInitialStrain}


EXACT = {"elastic_bar_step": ElasticBarStep, "svk_bar_riemann": SVKBarRiemann,
         "elastoplastic_bar_step": ElastoplasticBarStep,
         "standing_wave_2d": StandingWave2D, "square_shear_mode": SquareShearMode, **MANUFACTURED}     # manufactured: built from the scene's material


def make_exact(name, **params):
    """Build the exact solution registered as ``name`` from keyword parameters.

    Raises
    ------
    InputError
        Unknown name, unknown or missing parameter, or bad value.
    """
    if name not in EXACT:
        raise InputError(f"exact solution: unknown name {name!r} (known: {', '.join(EXACT)})")
    cls = EXACT[name]
    known = {f.name: f for f in dc_fields(cls) if f.init}
    for key, value in params.items():
        if key not in known:
            raise InputError(f"exact solution {name!r}: unknown parameter {key!r} = {value!r} "
                             f"(known: {', '.join(known)})")
    missing = [k for k, f in known.items() if k not in params
               and f.default is MISSING and f.default_factory is MISSING]
    if missing:
        raise InputError(f"exact solution {name!r}: missing parameter {missing[0]!r}")
    return cls(**params)


def error_norms(numerical, exact, weights, scale=None):
    """Weighted error norms of a 1-D field (e.g. weights = particle volumes).

    ``L1_rel = sum w |e| / S1``, ``L2_rel = sqrt(sum w e^2) / S2`` with ``e = numerical - exact``
    and ``(S1, S2) = scale``, by default the norms of the exact field itself,
    ``S1 = sum w |u|``, ``S2 = sqrt(sum w u^2)``; ``Linf = max |e|`` (absolute). When a
    denominator is zero (an identically zero exact field, and no scale), ``L1_rel`` and
    ``L2_rel`` hold the absolute norms ``sum w |e|`` and ``sqrt(sum w e^2)`` instead.
    `relative_errors` gives each field the scale of its kind.

    Returns
    -------
    dict
        ``{"L1_rel": float, "L2_rel": float, "Linf": float}``.
    """
    a, b, w = (np.asarray(z, dtype=float) for z in (numerical, exact, weights))
    if not (a.ndim == 1 and a.shape == b.shape == w.shape):
        raise InputError(f"error_norms: shapes of numerical, exact, weights must be equal and "
                         f"1-D, got {a.shape}, {b.shape}, {w.shape}")
    if np.any(w < 0):
        raise InputError("error_norms: bad value for 'weights': negative entries")
    e = np.abs(a - b)
    d1, d2 = _norms(b, w) if scale is None else scale
    return {
        "L1_rel": float(np.sum(w * e) / (d1 if d1 > 0 else 1.0)),
        "L2_rel": float(np.sqrt(np.sum(w * e * e)) / (d2 if d2 > 0 else 1.0)),
        "Linf": float(e.max(initial=0.0)),
    }


def _norms(u, w):
    return float(np.sum(w * np.abs(u))), float(np.sqrt(np.sum(w * u * u)))


def field_kind(name):
    """P12 -> P, v1 -> v, sigma11 -> sigma, eqp -> eqp: the quantity a component belongs to."""
    return name.rstrip("0123456789") or name


def relative_errors(numerical, exact, weights):
    """Error norms of every field of ``exact`` found in ``numerical`` (dicts of 1-D arrays), each
    relative to the scale of its kind: the norms of the exact component of largest L2 norm among
    those of the same quantity (P11, P12, P21, P22 -> the largest of them), so that a component whose
    exact value is near zero (P12 of a plane wave) is measured against the field's scale, not
    against its own near-zero norm. ``relative_to`` names that component (the field itself when it
    is the largest; None when the whole quantity is zero: the norms are then absolute).

    Returns
    -------
    dict
        ``{field: {"L1_rel", "L2_rel", "Linf", "relative_to"}}``.
    """
    names = [k for k in exact if k in numerical]
    w = np.asarray(weights, dtype=float)
    norms = {k: _norms(np.asarray(exact[k], dtype=float), w) for k in names}
    largest = {}
    for k in names:
        kind = field_kind(k)
        if kind not in largest or norms[k][1] > norms[largest[kind]][1]:
            largest[kind] = k
    out = {}
    for k in names:
        ref = largest[field_kind(k)]
        ref = ref if norms[ref][1] > 0 else None
        out[k] = {**error_norms(numerical[k], exact[k], w, scale=norms[ref] if ref else (0.0, 0.0)),
                  "relative_to": ref}
    return out
