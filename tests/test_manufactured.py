"""Manufactured solutions of WG08 (skdgmpm.manufactured) and the body force in every DG method.

The derived body force is checked against the closed form of METHOD §8 (axis-aligned) and against
an independent sympy derivation with the neo-Hookean P written symbolically (ring); the methods
are then run on mms_axis_aligned_2d and must converge at their theoretical rates, which they can
only do with the source: without it the errors are far larger.

Amplitude of the convergence runs: A = 0.02 m, not WG08's 0.1. At A = 0.1 the corner (1, 1) is
compressed to J ~ 0.6, where the neo-Hookean energy is not convex in F: the Hessian C restricted
to the rotation mode F12 = -F21 has the eigenvalue mu - (mu - lam ln J) / J < 0 (-1.9 mu there).
The (F, p) system only keeps that mode still through curl grad v = 0, which the discrete gradient
does not honour at the grid scale, so the unlimited high-order DG methods grow it at a rate ~ c/h
(frozen-state Jacobian, RK-DGFEM P1: largest real eigenvalue 2.3e3 1/s on 4 x 4 cells, 5.0e3 on
8 x 8, localised at the corner, eigenvector F12 = -F21; zero for the linear law). At A = 0.02 the
growth stays below the truncation error over the tests' 1/16 period. The limitation is recorded by
the strict xfail below.
"""
import functools

import numpy as np
import pytest
import sympy as sp

from skdgmpm.build import build
from skdgmpm.errors import InputError
from skdgmpm.manufactured import ManufacturedSolution, MMSAxisAligned, MMSRing
from skdgmpm.materials import make_material
from skdgmpm.run import compute_errors
from skdgmpm.scene import exact_solution, load_scene

WG08 = dict(E=1e7, rho=1000.0)                 # Pa, kg/m^3
AMPLITUDE = 0.02                               # m, convergence runs (module docstring)
T_END = 0.00125                                # s: c pi t = pi / 8, no field is zero


def neo_hookean(nu):
    return make_material("neo_hookean", nu=nu, **WG08)


# ---------------------------------------------------------------- the derived fields
def test_axis_aligned_body_force_is_the_closed_form_of_method_8():
    """b = (pi^2 u_X / rho0 [lam / F_XX^2 (1 - K) + mu (1 + 1 / F_XX^2) - E], same for Y),
    K = ln(F_XX F_YY), at random points and times (over a period and beyond)."""
    law = neo_hookean(0.3)
    mms = MMSAxisAligned(material=law, amplitude=0.1)
    lam, mu, E, rho = law.lam, law.mu, law.E, law.rho
    rng = np.random.default_rng(8)
    for t in rng.uniform(0.0, 0.05, 6):
        X = rng.random((64, 2))
        F, u = mms.deformation_gradient(X, t), mms.displacement(X, t)
        K = np.log(F[:, 0, 0] * F[:, 1, 1])
        closed = np.stack([np.pi**2 * u[:, k] / rho * (lam / F[:, k, k]**2 * (1 - K)
                                                       + mu * (1 + 1 / F[:, k, k]**2) - E)
                           for k in range(2)], axis=1)
        b = mms.body_force(X, t)
        assert b.shape == (64, 2)
        assert np.abs(b - closed).max() <= 1e-10 * np.abs(closed).max()


@functools.lru_cache(maxsize=None)
def symbolic_ring():
    """Independent route, written here in sympy: the ring displacement in Cartesian form
    u = A cos(c pi t) g(R) X / R, its dF/dX and d2u/dt2, and the neo-Hookean
    P = mu (F - F^-T) + lam ln J F^-T (plane strain, F33 = 1, F^-T by the adjugate) with its
    derivative dP/dF taken by sympy, not the hand-written tangent of materials/. Returns numpy
    functions of (X, Y, t) and of (F11, F12, F21, F22, mu, lam)."""
    X, Y, t = sp.symbols("X Y t", real=True)
    ri, ro = sp.Rational(2, 5), sp.Rational(3, 5)
    k = ro - 3 * ri
    c3, c2, c1 = -2 / (ro**2 * k), 3 * (ro + ri) / (ro**2 * k), -6 * ri / (ro * k)
    R = sp.sqrt(X**2 + Y**2)
    radial = ro / 10 * sp.cos(100 * sp.pi * t) * (c3 * R**3 + c2 * R**2 + c1 * R)   # A = 0.1 R_O, c = 100
    u = sp.Matrix([radial * X / R, radial * Y / R])
    H = u.jacobian([X, Y])
    kinematics = sp.lambdify((X, Y, t), [*H, *[sp.diff(H[j, b], Xa) for j in range(2) for b in range(2)
                                              for Xa in (X, Y)], *sp.diff(u, t, 2)], "numpy")
    F = sp.Matrix(2, 2, sp.symbols("F11 F12 F21 F22", real=True))
    mu, lam = sp.symbols("mu lam", real=True)
    J = F.det()
    G = sp.Matrix([[F[1, 1], -F[1, 0]], [-F[0, 1], F[0, 0]]]) / J
    P = mu * (F - G) + lam * sp.log(J) * G
    dP = [sp.diff(P[i, a], F[j, b]) for i in range(2) for a in range(2) for j in range(2) for b in range(2)]
    return kinematics, sp.lambdify((*F, mu, lam), dP, "numpy")


def symbolic_ring_body_force(X, t, law):
    kinematics, dP = symbolic_ring()
    n = len(X)
    k = [np.broadcast_to(np.asarray(v, dtype=float), (n,)) for v in kinematics(X[:, 0], X[:, 1], t)]
    F = np.eye(2) + np.stack(k[:4], axis=1).reshape(n, 2, 2)
    dF = np.stack(k[4:12], axis=1).reshape(n, 2, 2, 2)                          # [n, j, b, a]
    C = np.stack([np.broadcast_to(np.asarray(v, dtype=float), (n,))
                  for v in dP(*F.reshape(n, 4).T, law.mu, law.lam)], axis=1).reshape(n, 2, 2, 2, 2)
    return np.stack(k[12:], axis=1) - np.einsum("niajb,njba->ni", C, dF) / law.rho


@pytest.mark.parametrize("nu", [0.0, 0.3])
def test_ring_body_force_from_the_tangent_equals_a_symbolic_neo_hookean(nu):
    """DIV P from the law's hand-written tangent (skdgmpm.manufactured) against sympy
    differentiating a neo-Hookean P written in the test, on a displacement written again.
    nu = 0 is the registered problem; nu = 0.3 (lam != 0, same displacement, generic class)
    exercises the ln J terms."""
    registered = MMSRing(material=neo_hookean(0.0))
    mms = registered if nu == 0 else ManufacturedSolution(registered.expressions, neo_hookean(nu))
    rng = np.random.default_rng(2)
    R, theta = rng.uniform(0.4, 0.6, 80), rng.uniform(0, 2 * np.pi, 80)
    X = np.stack([R * np.cos(theta), R * np.sin(theta)], axis=1)
    for t in (0.0, 0.0031, 0.0137):
        expected = symbolic_ring_body_force(X, t, mms.material)
        assert np.abs(mms.body_force(X, t) - expected).max() <= 1e-10 * np.abs(expected).max()


def test_ring_is_traction_free_at_both_radii_and_expands_by_a():
    """nu = 0: P e_R = 0 on R = R_I and R = R_O at any time; |u(R_O, 0)| = A = 0.1 R_O."""
    mms = MMSRing(material=neo_hookean(0.0))
    theta = np.linspace(0, 2 * np.pi, 37)
    for radius in mms.radii:
        e_R = np.stack([np.cos(theta), np.sin(theta)], axis=1)
        for t in (0.0, 0.0042):
            P = mms.first_piola(radius * e_R, t)
            assert np.abs(np.einsum("nia,na->ni", P, e_R)).max() < 1e-9 * mms.material.mu
    u = mms.displacement(0.6 * e_R, 0.0)
    assert np.allclose(np.hypot(*u.T), 0.06, rtol=1e-12)


@pytest.mark.parametrize("make", [lambda: MMSAxisAligned(material=neo_hookean(0.3)),
                                  lambda: MMSRing(material=neo_hookean(0.0))])
@pytest.mark.parametrize("t", [0.0, 0.0057])
def test_fields_are_consistent_with_the_displacement(make, t):
    """F = I + grad u and v = du/dt against central differences of ``displacement``; P is the
    law's; eps = sym(F) - I; x = X + u."""
    mms = make()
    rng = np.random.default_rng(0)
    R, theta = rng.uniform(0.4, 0.6, 40), rng.uniform(0, 2 * np.pi, 40)
    X = np.stack([R * np.cos(theta), R * np.sin(theta)], 1)          # in the ring, in the square
    if isinstance(mms, MMSAxisAligned):
        X = 0.5 + 0.8 * X
    f = mms.fields(X, t)
    h, dt = 1e-6, 1e-8
    for a in range(2):
        step = np.zeros(2)
        step[a] = h
        du = (mms.displacement(X + step, t) - mms.displacement(X - step, t)) / (2 * h)
        for i in range(2):
            assert np.allclose(f[f"F{i + 1}{a + 1}"], (i == a) + du[:, i], rtol=0, atol=1e-8)
    v = (mms.displacement(X, t + dt) - mms.displacement(X, t - dt)) / (2 * dt)
    F = mms.deformation_gradient(X, t)
    P = mms.material.first_piola(np.pad(F, ((0, 0), (0, 1), (0, 1))) + np.diag([0, 0, 1.0]))
    for i in range(2):
        assert np.allclose(f[f"v{i + 1}"], v[:, i], rtol=1e-6, atol=1e-6)
        assert np.allclose(f[f"x{i + 1}"], X[:, i] + f[f"u{i + 1}"])
        for a in range(2):
            assert np.allclose(f[f"P{i + 1}{a + 1}"], P[:, i, a])
            assert np.allclose(f[f"eps{i + 1}{a + 1}"], 0.5 * (F[:, i, a] + F[:, a, i]) - (i == a))


def test_axis_aligned_satisfies_symmetry_on_the_four_edges():
    """u . N = v . N = 0 on X = 0, 1 and Y = 0, 1; F, hence P, diagonal: no shear traction."""
    mms = MMSAxisAligned(material=neo_hookean(0.3))
    s = np.linspace(0, 1, 21)
    for t in (0.0, 0.003, 0.011):
        for axis in range(2):
            for edge in (0.0, 1.0):
                X = np.stack([s, s], 1)
                X[:, axis] = edge
                f = mms.fields(X, t)
                assert np.abs(f[f"u{axis + 1}"]).max() < 1e-15 and np.abs(f[f"v{axis + 1}"]).max() < 1e-13
        f = mms.fields(np.random.default_rng(1).random((50, 2)), t)
        assert np.abs(f["P12"]).max() == 0 and np.abs(f["P21"]).max() == 0


def test_bad_declarations_name_the_key():
    law = neo_hookean(0.3)
    with pytest.raises(InputError, match="'displacement' uses k"):
        ManufacturedSolution(["sin(k*X)", "0"], law)
    with pytest.raises(InputError, match="'material'"):
        ManufacturedSolution(["X", "0"], "neo_hookean")
    with pytest.raises(InputError, match="nu = 0"):
        MMSRing(material=law)
    with pytest.raises(InputError, match="'radii'"):
        MMSRing(material=neo_hookean(0.0), radii=(0.6, 0.4))


# ---------------------------------------------------------------- scenes
def test_scenes_pass_their_material_ring_and_deformed_start():
    """exact_solution builds the manufactured problem from [material] (any law) and body.ring;
    initial.exact starts from F(X, 0), v(X, 0) and the positions x = X + u(X, 0); particles fill
    the cells whose centre lies in the ring; the stepper carries the body force."""
    mms = exact_solution(load_scene("mms_axis_aligned_2d", ["material.E=4e7"]))
    assert isinstance(mms, MMSAxisAligned) and np.isclose(mms.c, 200.0)
    disc = build(load_scene("mms_ring_2d"))
    ring = exact_solution(disc.scene)
    assert ring.radii == (0.4, 0.6) and ring.centre == (0.0, 0.0)
    m = disc.grid.submesh
    r = np.hypot(*m.p[:, m.t].mean(axis=1))
    assert np.all((r >= 0.4) & (r <= 0.6)) and m.nelements == 240
    X = disc.particles.X
    assert np.allclose(disc.initial.x, X + ring.displacement(X, 0.0))
    assert disc.stepper.body_force is not None
    assert build(load_scene("standing_wave_2d")).stepper.body_force is None


# ---------------------------------------------------------------- convergence of every method
@functools.lru_cache(maxsize=None)
def errors(method, order, cells, integrator=None, body=True, amplitude=AMPLITUDE, t_end=T_END):
    """Particle (Gauss point) L2 errors of mms_axis_aligned_2d at t_end; ``body=False`` drops
    the source."""
    overrides = [f'method.name="{method}"', f"method.order={order}", f"grid.cells=[{cells},{cells}]",
                 f"run.t_end={t_end}", f"exact.amplitude={amplitude}"]
    if integrator:
        overrides.append(f'method.integrator="{integrator}"')
    disc = build(load_scene("mms_axis_aligned_2d", overrides))
    if not body:
        disc.stepper.body_force = None
    state = disc.initial
    while state.t < t_end * (1 - 1e-12):
        state = disc.stepper.step(state, t_end - state.t)
    return {k: v["L2_rel"] for k, v in compute_errors(disc, state, exact_solution(disc.scene)).items()}


def rates(method, order, cells, **kw):
    e = [errors(method, order, n, **kw) for n in cells]
    return {k: [float(np.log2(a[k] / b[k])) for a, b in zip(e, e[1:])] for k in ("F11", "v1")}


@pytest.mark.parametrize("method, order, integrator, cells", [
    ("rk-dgfem", 1, "rk2", (4, 8, 16)),
    ("rk-dgfem", 2, "rk4", (4, 8)),
    ("ader-dgfem", 1, None, (4, 8, 16)),
    ("ader-dgmpm", 1, None, (4, 8)),
])
def test_high_order_methods_converge_at_p_plus_1(method, order, integrator, cells, record_property):
    """L2 rates between the two finest grids: v1 >= P + 1 - 0.3, F11 >= P + 1 - 0.5 (F11 is still
    pre-asymptotic there: RK-DGFEM P1 1.71 on 8 -> 16, 1.87 on 16 -> 32). Measured F11 / v1:
    RK-DGFEM P1 1.71 / 2.00, P2 2.76 / 3.30; ADER-DGFEM P1 1.78 / 1.97; ADER-DGMPM P1 1.86 / 2.01."""
    r = rates(method, order, cells, integrator=integrator)
    record_property("rates", r)
    assert r["v1"][-1] >= order + 1 - 0.3 and r["F11"][-1] >= order + 1 - 0.5, r


def test_first_order_dgmpm_converges_and_needs_the_source(record_property):
    """DGMPM (2 x 2 ppc, Euler, CFL 0.4) is first order: rates ~1 on 8 -> 16 cells (measured 1.07;
    4 cells take 2 steps). Without the body force its v1 error is 7.5 times larger on 16 cells."""
    r = rates("dgmpm", 1, (4, 8, 16))
    record_property("rates", r)
    assert all(v[-1] > 0.8 for v in r.values()), r
    assert errors("dgmpm", 1, 16, body=False)["v1"] > 4 * errors("dgmpm", 1, 16)["v1"]


@pytest.mark.parametrize("method, order, integrator", [("rk-dgfem", 1, "rk2"), ("ader-dgfem", 1, None),
                                                       ("ader-dgmpm", 1, None)])
def test_without_the_body_force_the_error_is_far_larger(method, order, integrator):
    """The source enters every stage (RK) and the predictor and corrector (ADER): on 8 x 8 cells
    the F11 and v1 errors without it are 16-28 times larger."""
    with_b, without = (errors(method, order, 8, integrator=integrator, body=b) for b in (True, False))
    assert all(without[k] > 10 * with_b[k] for k in ("F11", "v1")), (with_b, without)


@pytest.mark.xfail(strict=True, reason="known limitation: at WG08's A = 0.1 the neo-Hookean energy is "
                   "not convex in F at the compressed corner and the unlimited high-order DG methods "
                   "grow the rotation mode F12 = -F21 at a rate ~ c/h (module docstring)")
def test_high_order_rates_at_wg08_amplitude():
    r = rates("ader-dgfem", 1, (8, 16), amplitude=0.1, t_end=0.0025)
    assert all(v[-1] >= 1.7 for v in r.values()), r
