"""Manufactured solutions [WG08 §5]: a displacement chosen in advance, made exact by a body force.

A `ManufacturedSolution` is declared by its displacement ``u(X, t)`` (sympy expressions or strings
in the reference coordinates ``X, Y`` (m), the time ``t`` (s) and named parameters) and a material
of ``skdgmpm.materials`` (any law). sympy derives, once per displacement,

    F = I + grad u,   v = du/dt,   a = d2u/dt2,   dF_jb/dX_a,

and lambdifies them to vectorised numpy. The stress is the law's own ``P = first_piola(F)`` and
its divergence is taken by the chain rule with the law's analytic tangent,

    DIV P_i = dP_ia/dX_a = C_iajb(F) dF_jb/dX_a,

which is exact and works for every law without writing the law in sympy (the tangents are
tested against finite differences in tests/test_materials.py). The body force (per unit mass,
m/s^2) that makes ``u`` exact for ``dp/dt - DIV P = rho0 b`` is

    b = a - DIV P / rho0.

Plane strain in 2D (1D: uniaxial strain): F is embedded in 3D as in the laws (F33 = 1).

The registered problems of WG08 §5 (`MMSAxisAligned`, `MMSRing`, names ``"mms_axis_aligned"``
and ``"mms_ring"`` in ``skdgmpm.exact.EXACT``) take the scene's material; their objects answer
like the other exact solutions (``fields(X, t)``) and also give ``body_force(X, t)`` and
``displacement(X, t)``.
"""
from __future__ import annotations

import functools
import math
from dataclasses import dataclass

import numpy as np

from skdgmpm.errors import InputError
from skdgmpm.materials.base import Material

__all__ = ["MANUFACTURED", "MMSAxisAligned", "MMSRing", "ManufacturedSolution"]

COORDINATES = ("X", "Y", "Z")


@functools.lru_cache(maxsize=32)
def _derive(expressions):
    """Lambdified numpy functions of ``(X, Y, .., t)`` from ``srepr`` strings of u_i, cached:
    a scene's solution is built by the set-up and again by the run (sympy costs ~0.1 s)."""
    import sympy as sp

    u = [sp.sympify(e) for e in expressions]
    d = len(u)
    X = sp.symbols(COORDINATES[:d], real=True)
    t = sp.Symbol("t", real=True)
    grad = [sp.diff(ui, Xa) for ui in u for Xa in X]                       # H[i, a], row-major
    groups = {
        "u": u,
        "v": [sp.diff(ui, t) for ui in u],
        "a": [sp.diff(ui, t, 2) for ui in u],
        "H": grad,
        "dF": [sp.diff(Hib, Xa) for Hib in grad for Xa in X],              # dF[j, b, a]
    }
    return {k: sp.lambdify((*X, t), v, "numpy", cse=True) for k, v in groups.items()}


def _number(owner, key, value, ok=lambda x: True, what="a finite number"):
    """``float(value)``, or a one-line InputError naming the solution and the key."""
    try:
        good = not isinstance(value, bool) and math.isfinite(float(value)) and ok(float(value))
    except (TypeError, ValueError):
        good = False
    if not good:
        raise InputError(f"{owner}: bad value for {key!r}: {value!r} (expected {what})")
    return float(value)


class ManufacturedSolution:
    """A displacement field ``u(X, t)`` with the body force that makes it exact.

    Parameters
    ----------
    displacement : sequence of d str or sympy expressions
        ``u_i`` (m) in the reference coordinates ``X, Y`` (``X`` only in 1D), the time ``t`` and
        the names of ``parameters``; d = 1 (uniaxial strain) or 2 (plane strain).
    material : skdgmpm.materials.Material
        Any law: P and its tangent come from it.
    parameters : dict, optional
        Numbers substituted for the other names (e.g. ``{"A": 0.1, "c": 100.0}``).

    Examples
    --------
    >>> from skdgmpm.materials import make_material
    >>> law = make_material("neo_hookean", E=1e7, nu=0.3, rho=1000.0)
    >>> mms = ManufacturedSolution(["A*sin(pi*X)*cos(t)", "0"], law, {"A": 0.1})
    >>> mms.body_force(np.array([[0.5, 0.5]]), 0.0).shape
    (1, 2)
    """

    def __init__(self, displacement, material, parameters=None):
        import sympy as sp

        name = type(self).__name__
        if not isinstance(material, Material):
            raise InputError(f"{name}: bad value for 'material': {material!r} (expected a Material)")
        if isinstance(displacement, str) or not 1 <= len(displacement) <= 2:
            raise InputError(f"{name}: bad value for 'displacement': {displacement!r} "
                             f"(expected 1 or 2 components)")
        d = len(displacement)
        names = {k: sp.Symbol(k, real=True) for k in (*COORDINATES[:d], "t")}
        values = {sp.Symbol(k): _number(name, k, v) for k, v in (parameters or {}).items()}
        try:
            u = [sp.sympify(e, locals=names).subs(values) for e in displacement]
        except (sp.SympifyError, TypeError) as exc:
            raise InputError(f"{name}: bad value for 'displacement': {displacement!r} ({exc})") from None
        unknown = set().union(*(e.free_symbols for e in u)) - set(names.values())
        if unknown:
            raise InputError(f"{name}: 'displacement' uses {', '.join(sorted(map(str, unknown)))}: "
                             f"not a coordinate ({', '.join(names)}) nor a parameter")
        self.material = material
        self.d = d
        self.expressions = tuple(u)
        self._f = _derive(tuple(sp.srepr(e) for e in u))

    # ---------------------------------------------------------------- evaluation
    def _eval(self, key, X, t):
        """Group ``key`` at points X (n, d) and time t: (n, k) array."""
        X = np.asarray(X, dtype=float)
        if X.ndim != 2 or X.shape[1] != self.d:
            raise InputError(f"{type(self).__name__}: X must have shape (n, {self.d}), got {X.shape}")
        values = self._f[key](*X.T, float(t))
        return np.stack([np.broadcast_to(np.asarray(v, dtype=float), (len(X),)) for v in values], axis=1)

    def displacement(self, X, t):
        """u (m), shape (n, d)."""
        return self._eval("u", X, t)

    def velocity(self, X, t):
        """v = du/dt (m/s), shape (n, d)."""
        return self._eval("v", X, t)

    def acceleration(self, X, t):
        """a = d2u/dt2 (m/s^2), shape (n, d)."""
        return self._eval("a", X, t)

    def deformation_gradient(self, X, t):
        """F = I + grad u, shape (n, d, d), ``F[:, i, alpha]``."""
        d = self.d
        return np.eye(d) + self._eval("H", X, t).reshape(-1, d, d)

    def first_piola(self, X, t):
        """P = P(F) of the material (Pa), shape (n, d, d)."""
        d = self.d
        return self.material.first_piola(_embed(self.deformation_gradient(X, t)))[:, :d, :d]

    def divergence_P(self, X, t):
        """DIV P_i = C_iajb(F) dF_jb/dX_a (Pa/m), shape (n, d): chain rule, exact for any law."""
        d = self.d
        C = self.material.tangent(_embed(self.deformation_gradient(X, t)))[:, :d, :d, :d, :d]
        dF = self._eval("dF", X, t).reshape(-1, d, d, d)                      # [n, j, b, a]
        return np.einsum("niajb,njba->ni", C, dF)

    def body_force(self, X, t):
        """b = a - DIV P / rho0 (m/s^2), shape (n, d): the source rho0 b of dp/dt - DIV P = rho0 b."""
        return self.acceleration(X, t) - self.divergence_P(X, t) / self.material.rho

    def fields(self, X, t):
        """Named arrays (n,) as the other exact solutions give them: ``F11``.., ``eps11``..
        (sym(F) - I), ``P11``.., ``v1``.., the displacement ``u1``.. and the current position
        ``x1``.. = X + u (its Linf error is the WG08 error, eq 64-65)."""
        d = self.d
        F = self.deformation_gradient(X, t)
        P = self.material.first_piola(_embed(F))[:, :d, :d]
        u, v = self.displacement(X, t), self.velocity(X, t)
        out = {}
        for i in range(d):
            out[f"u{i + 1}"], out[f"v{i + 1}"] = u[:, i], v[:, i]
            out[f"x{i + 1}"] = np.asarray(X, dtype=float)[:, i] + u[:, i]
            for a in range(d):
                out[f"F{i + 1}{a + 1}"] = F[:, i, a]
                out[f"eps{i + 1}{a + 1}"] = 0.5 * (F[:, i, a] + F[:, a, i]) - (i == a)
                out[f"P{i + 1}{a + 1}"] = P[:, i, a]
        return out


def _embed(F):
    """(n, d, d) -> (n, 3, 3), identity out of plane (plane strain / uniaxial strain)."""
    n, d, _ = F.shape
    F3 = np.broadcast_to(np.eye(3), (n, 3, 3)).copy()
    F3[:, :d, :d] = F
    return F3


@dataclass(kw_only=True, eq=False)
class MMSAxisAligned(ManufacturedSolution):
    """Axis-aligned displacement on the unit square [WG08 §5.1]:

        u = (A sin(pi X) cos(c pi t), A sin(pi Y) sin(c pi t)),   c = sqrt(E / rho0).

    F is diagonal, so P is diagonal for any isotropic law: zero shear traction, and u . N = 0 on
    the four edges of the unit square: symmetry conditions hold on every side. Period 2 / c.

    Parameters
    ----------
    material : Material (the scene's; WG08 use neo-Hookean); amplitude : A (m).
    """

    material: Material
    amplitude: float = 0.1

    def __post_init__(self):
        A = _number("mms_axis_aligned", "amplitude", self.amplitude)
        super().__init__(("A*sin(pi*X)*cos(c*pi*t)", "A*sin(pi*Y)*sin(c*pi*t)"), self.material,
                         {"A": A, "c": self.c})

    @property
    def c(self):
        """Speed sqrt(E / rho0) of the time dependence (m/s)."""
        return math.sqrt(self.material.E / self.material.rho)


@dataclass(kw_only=True, eq=False)
class MMSRing(ManufacturedSolution):
    """Expanding ring [WG08 §5.2]: radial displacement about ``centre``

        u = A cos(c pi t) g(R) e_R,   g(R) = c3 R^3 + c2 R^2 + c1 R,   c = sqrt(E / rho0),
        c3 = -2 / (R_O^2 (R_O - 3 R_I)),  c2 = 3 (R_O + R_I) / (R_O^2 (R_O - 3 R_I)),
        c1 = -6 R_I / (R_O (R_O - 3 R_I)),

    so g'(R_I) = g'(R_O) = 0 and g(R_O) = 1. With nu = 0 (lambda = 0) the radial stress of the
    laws here depends on F_RR = 1 + A cos(c pi t) g'(R) only and vanishes at both radii: the
    ring is traction free. In Cartesian form u = A cos(c pi t) (c3 R^2 + c2 R + c1) (X - X0).

    Parameters
    ----------
    material : Material with nu = 0; radii : (R_I, R_O) (m); centre : (X0, Y0) (m);
    amplitude : A (m), default 0.1 R_O.
    """

    material: Material
    radii: tuple = (0.4, 0.6)
    centre: tuple = (0.0, 0.0)
    amplitude: float = None

    def __post_init__(self):
        name = "mms_ring"
        if not (isinstance(self.radii, (list, tuple)) and len(self.radii) == 2):
            raise InputError(f"{name}: bad value for 'radii': {self.radii!r} (expected [R_I, R_O] in m)")
        ri = _number(name, "radii", self.radii[0], lambda x: x > 0, "0 < R_I < R_O")
        ro = _number(name, "radii", self.radii[1], lambda x: x > ri and abs(x - 3 * ri) > 1e-12 * x,
                     "0 < R_I < R_O, R_O != 3 R_I")
        if not (isinstance(self.centre, (list, tuple)) and len(self.centre) == 2):
            raise InputError(f"{name}: bad value for 'centre': {self.centre!r} (expected [X0, Y0] in m)")
        x0, y0 = (_number(name, "centre", x) for x in self.centre)
        A = 0.1 * ro if self.amplitude is None else _number(name, "amplitude", self.amplitude)
        if self.material.nu != 0:
            raise InputError(f"{name}: the material needs nu = 0 (lambda = 0) for a traction-free "
                             f"ring, got nu = {self.material.nu!r}")
        self.radii, self.centre, self.amplitude = (ri, ro), (x0, y0), A
        k = ro - 3 * ri
        c3, c2, c1 = -2 / (ro**2 * k), 3 * (ro + ri) / (ro**2 * k), -6 * ri / (ro * k)
        R = "sqrt((X - x0)**2 + (Y - y0)**2)"
        g_over_R = f"A*cos(c*pi*t)*(c3*{R}**2 + c2*{R} + c1)"
        super().__init__((f"{g_over_R}*(X - x0)", f"{g_over_R}*(Y - y0)"), self.material,
                         {"A": A, "c": self.c, "c1": c1, "c2": c2, "c3": c3, "x0": x0, "y0": y0})

    @property
    def c(self):
        """Speed sqrt(E / rho0) of the time dependence (m/s)."""
        return math.sqrt(self.material.E / self.material.rho)

    def radial_profile(self, R):
        """g(R) = c3 R^3 + c2 R^2 + c1 R (dimensionless; g(R_O) = 1)."""
        ri, ro = self.radii
        k = ro - 3 * ri
        R = np.asarray(R, dtype=float)
        return (-2 / (ro**2 * k)) * R**3 + 3 * (ro + ri) / (ro**2 * k) * R**2 - 6 * ri / (ro * k) * R


MANUFACTURED = {"mms_axis_aligned": MMSAxisAligned, "mms_ring": MMSRing}
