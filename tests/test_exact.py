"""Tests of the exact solutions (skdgmpm.exact) for the bars of [R18 §7.1-7.2, App. A]."""

import math

import numpy as np
import pytest
from scipy.integrate import quad

from skdgmpm.errors import InputError
from skdgmpm.exact import EXACT, ElasticBarStep, SVKBarRiemann, error_norms, make_exact

STEEL = dict(E=2e11, rho=7800.0)
T = 1e9  # compressive load magnitude of [R18 §7.1]


def col(x):
    return np.asarray(x, dtype=float).reshape(-1, 1)


@pytest.fixture
def bar():
    return ElasticBarStep(length=6.0, traction=-T, **STEEL)


# ---------------------------------------------------------------- elastic bar
def test_bar_incident_wave(bar):
    c, L = bar.c, bar.length
    t = 0.4 * L / c
    x = np.linspace(0, L, 601)
    f = bar.fields(col(x), t)
    behind = x <= c * t
    assert np.allclose(f["P11"][behind], -T) and np.allclose(f["P11"][~behind], 0.0)
    assert np.allclose(f["v1"][behind], T / (bar.rho * c)) and np.all(f["v1"][behind] > 0)
    assert np.allclose(f["v1"][~behind], 0.0)
    assert np.allclose(f["F11"], 1 + f["P11"] / bar.E)
    assert set(f) >= {"P11", "v1", "F11"} and f["P11"].shape == x.shape


def test_bar_reflection_at_fixed_end(bar):
    c, L = bar.c, bar.length
    t = 1.5 * L / c  # reflected front at X = L/2
    x = np.linspace(0, L, 601)
    f = bar.fields(col(x), t)
    refl = x >= L / 2
    assert np.allclose(f["P11"][refl], -2 * T) and np.allclose(f["v1"][refl], 0.0)
    assert np.allclose(f["P11"][~refl], -T)
    assert np.allclose(f["v1"][~refl], T / (bar.rho * c))


def test_bar_fixed_end_at_rest_and_left_end_loaded(bar):
    c, L = bar.c, bar.length
    ts = np.linspace(0, 9 * L / c, 257)
    vL = [bar.fields(col([L]), t)["v1"][0] for t in ts]
    P0 = [bar.fields(col([0.0]), t)["P11"][0] for t in ts]
    assert np.allclose(vL, 0.0, atol=1e-9)
    assert np.allclose(P0, -T)


def test_bar_period_and_displacement(bar):
    c, L = bar.c, bar.length
    x = np.linspace(0.013, L - 0.011, 97)
    t = 0.77 * L / c
    f, g = bar.fields(col(x), t), bar.fields(col(x), t + 3 * 4 * L / c)
    for k in f:
        assert np.allclose(f[k], g[k], rtol=1e-9, atol=1e-12 * max(1, abs(f[k]).max()))
    # u1: du/dX = F - 1 and du/dt = v away from fronts; u(L) = 0 always
    for t in (0.3 * L / c, 1.7 * L / c, 2.6 * L / c, 3.3 * L / c):
        h, dt = 1e-6, 1e-6 * L / c
        front = np.mod(c * t, L)
        xs = x[(np.abs(x - front) > 0.05) & (np.abs(x - (L - front)) > 0.05)]
        f = bar.fields(col(xs), t)
        dudx = (bar.fields(col(xs + h), t)["u1"] - bar.fields(col(xs - h), t)["u1"]) / (2 * h)
        dudt = (bar.fields(col(xs), t + dt)["u1"] - bar.fields(col(xs), t - dt)["u1"]) / (2 * dt)
        assert np.allclose(dudx, f["F11"] - 1, rtol=1e-5, atol=1e-6 * T / bar.E)
        assert np.allclose(dudt, f["v1"], rtol=1e-5, atol=1e-6 * T / (bar.rho * c))
        assert abs(bar.fields(col([L]), t)["u1"][0]) < 1e-15


# ---------------------------------------------------------------- SVK bar
def svk(traction, **kw):
    return SVKBarRiemann(nu=0.3, traction=traction, **STEEL, **kw)


def test_svk_stress_components():
    s = svk(-2e10)
    assert s.wave == "rarefaction" and s.F_star < 1
    assert math.isclose(float(s.Pi(s.F_star)), -2e10, rel_tol=1e-12)
    f = s.fields(col(np.linspace(0, 6, 50)), 1e-3)
    F = f["F11"]
    assert np.allclose(f["P22"], s.lam / (F * (s.lam + 2 * s.mu)) * f["P11"])  # R18 eq A.5


@pytest.mark.parametrize("traction", [2e10, 4e8, 1e11])
def test_svk_shock_rankine_hugoniot_and_lax(traction):
    s = svk(traction)
    assert s.wave == "shock" and s.F_star > 1
    sh, t = s.speeds[0], 1e-3
    L = s.fields(col([sh * t * (1 - 1e-9)]), t)
    R = s.fields(col([sh * t * (1 + 1e-9)]), t)
    jF, jv = R["F11"][0] - L["F11"][0], R["v1"][0] - L["v1"][0]
    jP = R["P11"][0] - L["P11"][0]
    assert math.isclose(L["P11"][0], traction, rel_tol=1e-12)
    assert math.isclose(sh * jF, -jv, rel_tol=1e-12)
    assert math.isclose(sh * s.rho * jv, -jP, rel_tol=1e-12)
    assert float(s.c(s.F_star)) > sh > float(s.c(1.0))
    assert L["v1"][0] < 0  # tension pulls material towards the loaded end


@pytest.mark.parametrize("traction", [-2e10, -4e8, -5e10])
def test_svk_rarefaction(traction):
    s = svk(traction)
    lo, hi = s.speeds
    assert s.wave == "rarefaction" and lo < hi and math.isclose(hi, math.sqrt(s.K / s.rho))
    t = 2e-4
    for edge in (lo * t, hi * t):  # F and v continuous at both fan edges
        f = s.fields(col([edge * (1 - 1e-10), edge * (1 + 1e-10)]), t)
        assert np.allclose(f["F11"][0], f["F11"][1], rtol=1e-8)
        assert np.allclose(f["v1"][0], f["v1"][1], rtol=1e-6, atol=1e-6 * s.v_star)
    xi = np.linspace(lo, hi, 41)
    assert np.allclose(s.c(s.fan_F(xi)), xi, rtol=1e-13)
    f = s.fields(col(xi * t), t)
    assert np.allclose(f["F11"], s.fan_F(xi)) and np.allclose(s.c(f["F11"]), xi, rtol=1e-12)
    # self-similar form of the PDE inside the fan: dv/dxi = -xi dF/dxi
    xm = xi[1:-1]
    h = 1e-6 * (hi - lo)
    fp, fm = s.fields(col((xm + h) * t), t), s.fields(col((xm - h) * t), t)
    assert np.allclose((fp["v1"] - fm["v1"]), -xm * (fp["F11"] - fm["F11"]), rtol=1e-5)
    assert s.v_star > 0  # compression pushes material to +X


def test_svk_integral_curve_vs_quad():
    s = svk(-2e10)
    for F in (1 / math.sqrt(3) + 1e-3, 0.6, 0.8, 0.95, 0.999, 1.0, 1.3, 2.0):
        ref, _ = quad(lambda z: float(s.c(z)), F, 1.0, epsabs=0, epsrel=1e-13)
        assert math.isclose(float(s.integral_curve_velocity(F)), ref, rel_tol=1e-10,
                            abs_tol=1e-9)


@pytest.mark.parametrize("sign", [-1.0, 1.0])
def test_svk_linear_limit_matches_elastic_step(sign):
    traction = sign * 1e4  # strains ~ 4e-8
    s = svk(traction, length=6.0)
    bar = ElasticBarStep(length=6.0, E=s.K, rho=s.rho, traction=traction)
    t = 0.5 * bar.length / bar.c
    x = np.linspace(0, 6.0, 301)
    x = x[np.abs(x - bar.c * t) > 1e-3]
    f, g = s.fields(col(x), t), bar.fields(col(x), t)
    assert np.allclose(f["P11"], g["P11"], rtol=1e-6, atol=1e-12)
    assert np.allclose(f["v1"], g["v1"], rtol=1e-6, atol=1e-15)
    assert np.allclose(f["F11"], g["F11"], rtol=1e-12)
    assert math.isclose(s.speeds[1], bar.c, rel_tol=1e-6) and s.t_max > t


def test_svk_zero_load_is_rest():
    f = svk(0.0).fields(col([0.0, 1.0]), 1e-3)
    assert np.all(f["F11"] == 1.0) and np.all(f["v1"] == 0.0)


# ---------------------------------------------------------------- registry, errors, norms
def test_registry():
    assert set(EXACT) == {"elastic_bar_step", "svk_bar_riemann", "standing_wave_2d",
                          "mms_axis_aligned", "mms_ring"}     # the last two: tests/test_manufactured.py
    b = make_exact("elastic_bar_step", length=6.0, traction=-T, **STEEL)
    assert isinstance(b, ElasticBarStep)
    with pytest.raises(AttributeError):
        b.E = 1.0  # frozen
    assert isinstance(make_exact("svk_bar_riemann", nu=0.3, traction=1e9, **STEEL),
                      SVKBarRiemann)


@pytest.mark.parametrize("name, params, word", [
    ("nope", {}, "nope"),
    ("elastic_bar_step", dict(length=6.0, traction=-T, E=2e11, rho=7800.0, nu=0.3), "nu"),
    ("elastic_bar_step", dict(length=6.0, E=2e11, rho=7800.0), "traction"),
    ("elastic_bar_step", dict(length=-1.0, traction=-T, E=2e11, rho=7800.0), "length"),
    ("elastic_bar_step", dict(length=6.0, traction="x", E=2e11, rho=7800.0), "traction"),
    ("svk_bar_riemann", dict(nu=0.5, traction=1e9, **STEEL), "nu"),
    ("svk_bar_riemann", dict(nu=0.3, traction=1e9, E=2e11, rho=0.0), "rho"),
    ("svk_bar_riemann", dict(nu=0.3, traction=-6e10, **STEEL), "hyperbolicity"),
    ("svk_bar_riemann", dict(nu=0.3, traction=1e9, length=0.0, **STEEL), "length"),
    ("svk_bar_riemann", dict(nu=0.3, traction=1e9, lam=1.0, **STEEL), "lam"),
])
def test_bad_params_raise_input_error(name, params, word):
    with pytest.raises(InputError, match=word) as info:
        make_exact(name, **params)
    assert "\n" not in str(info.value)


def test_bad_time_raises(bar):
    with pytest.raises(InputError, match="'t'"):
        bar.fields(col([1.0]), -1.0)


def test_error_norms():
    w = np.array([1.0, 2.0, 1.0])
    ex = np.array([1.0, -2.0, 0.0])
    num = ex + np.array([0.1, 0.0, -0.2])
    n = error_norms(num, ex, w)
    assert math.isclose(n["L1_rel"], 0.3 / 5.0)
    assert math.isclose(n["L2_rel"], math.sqrt(0.05 / 9.0))
    assert math.isclose(n["Linf"], 0.2)
    z = error_norms(num, np.zeros(3), w)  # exact identically zero: absolute norms
    assert math.isclose(z["L1_rel"], 1.1 + 2 * 2.0 + 0.2)
    assert math.isclose(z["L2_rel"], math.sqrt(1.21 + 2 * 4.0 + 0.04))
    assert error_norms(ex, ex, w) == {"L1_rel": 0.0, "L2_rel": 0.0, "Linf": 0.0}
    with pytest.raises(InputError):
        error_norms(num, ex, w[:2])


def test_standing_wave_solves_the_equations_and_the_symmetry_conditions():
    """Finite differences of StandingWave2D: rho dv/dt = div P, dF/dt = grad v, and on every side
    of the unit square zero normal velocity and zero shear stress."""
    from skdgmpm.exact import StandingWave2D

    sol = StandingWave2D(E=2e11, nu=0.3, rho=7800.0, amplitude=1e-4, size=(1.0, 1.0), modes=(1, 1))
    rng = np.random.default_rng(0)
    X = rng.uniform(0.1, 0.9, (20, 2))
    t, h, dt = 3e-5, 1e-6, 1e-10
    f = sol.fields(X, t)

    def d(field, axis=None):
        if axis is None:
            return (sol.fields(X, t + dt)[field] - sol.fields(X, t - dt)[field]) / (2 * dt)
        e = np.zeros(2)
        e[axis] = h
        return (sol.fields(X + e, t)[field] - sol.fields(X - e, t)[field]) / (2 * h)

    scale_p = np.abs(f["P11"]).max() * np.pi
    for i in (1, 2):
        div = d(f"P{i}1", 0) + d(f"P{i}2", 1)
        assert np.allclose(7800.0 * d(f"v{i}"), div, atol=1e-6 * scale_p)
        for a in (1, 2):
            assert np.allclose(d(f"F{i}{a}"), d(f"v{i}", a - 1), atol=1e-6 * np.abs(f["v1"]).max() * np.pi)
    s = np.linspace(0, 1, 7)
    for side in (np.column_stack([0 * s, s]), np.column_stack([1 + 0 * s, s])):
        g = sol.fields(side, t)
        assert np.allclose(g["v1"], 0, atol=1e-12) and np.allclose(g["P12"], 0, atol=1e-3)
    for side in (np.column_stack([s, 0 * s]), np.column_stack([s, 1 + 0 * s])):
        g = sol.fields(side, t)
        assert np.allclose(g["v2"], 0, atol=1e-12) and np.allclose(g["P21"], 0, atol=1e-3)
