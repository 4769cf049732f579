"""L23 §5.1's convergence square, read consistently (METHOD.md, note after §9): symmetry on the
left and top faces, free right and bottom faces; the paper's initial strain is then the standing
shear mode u = U0 (sin sin, cos cos)(pi X/2, pi Y/2) cos(omega t), an exact solution
(`skdgmpm.exact.SquareShearMode`). The full study (Ne = 5 ... 40, P = 1, 2, 3, N_t = N_e and at
a fixed t = 1e-4 s) is in docs/results.md; here the exact field itself, the rates at CI size and
the end time of N_t = N_e steps."""
import numpy as np
import pytest

from skdgmpm.exact import SquareShearMode
from skdgmpm.run import run
from skdgmpm.study import convergence

MODE = SquareShearMode(E=2e11, nu=0.3, rho=7800.0, amplitude=5e-4)


def test_the_mode_solves_linear_elastodynamics_with_the_swapped_faces():
    """Independent of the engine: finite differences of the closed form. rho dv/dt = div P inside,
    dF/dt = grad v, and on each face the condition of its kind: u1 = P21 = 0 (left, symmetry),
    u2 = P12 = 0 (top, symmetry), P11 = P21 = 0 (right, free), P22 = P12 = 0 (bottom, free).
    At t = 0 the strain is the paper's, f (e1 x e1 - e2 x e2)."""
    rng = np.random.default_rng(1)
    X, t, e = rng.uniform(0.1, 0.9, (20, 2)), 3.1e-5, 1e-6
    f = lambda X, t: MODE.fields(X, t)                       # noqa: E731
    dt = 1e-9
    dvdt = {k: (f(X, t + dt)[k] - f(X, t - dt)[k]) / (2 * dt) for k in ("v1", "v2")}
    dx = lambda k, a: (f(X + e * np.eye(2)[a], t)[k] - f(X - e * np.eye(2)[a], t)[k]) / (2 * e)  # noqa: E731
    scale = MODE.rho * MODE.omega ** 2 * MODE.amplitude
    assert np.allclose(MODE.rho * dvdt["v1"], dx("P11", 0) + dx("P12", 1), rtol=0, atol=1e-5 * scale)
    assert np.allclose(MODE.rho * dvdt["v2"], dx("P21", 0) + dx("P22", 1), rtol=0, atol=1e-5 * scale)
    dFdt = lambda k: (f(X, t + dt)[k] - f(X, t - dt)[k]) / (2 * dt)  # noqa: E731
    for i, a in ((0, 0), (0, 1), (1, 0), (1, 1)):
        assert np.allclose(dFdt(f"F{i + 1}{a + 1}"), dx(f"v{i + 1}", a), rtol=0,
                           atol=1e-5 * MODE.omega * MODE.amplitude)
    s = np.linspace(0, 1, 11)
    faces = {"left": np.c_[0 * s, s], "top": np.c_[s, 1 + 0 * s], "right": np.c_[1 + 0 * s, s],
             "bottom": np.c_[s, 0 * s]}
    zero = {"left": ("u1", "P21"), "top": ("u2", "P12"), "right": ("P11", "P21"), "bottom": ("P22", "P12")}
    for face, keys in zero.items():
        values = f(faces[face], t)
        for k in keys:
            assert np.abs(values[k]).max() < 1e-12 * max(1.0, np.abs(f(X, 0)[k]).max())
    at0 = f(X, 0.0)
    strain = MODE.amplitude * np.pi / 2 * np.cos(np.pi * X[:, 0] / 2) * np.sin(np.pi * X[:, 1] / 2)
    assert np.allclose(at0["eps11"], strain) and np.allclose(at0["eps22"], -strain)
    assert np.allclose(at0["eps12"], 0.0) and np.allclose(at0["v1"], 0.0)


@pytest.mark.parametrize("method, order, rate", [("rk-dgfem/rk2", 1, 1.8), ("rk-dgfem/rk4", 1, 1.8),
                                                 ("ader-dgfem", 1, 1.8), ("ader-dgmpm", 1, 1.8),
                                                 ("ader-dgmpm", 2, 2.7), ("ader-dgfem", 2, 2.7),
                                                 ("ader-dgfem", 3, 3.5), ("ader-dgmpm", 3, 3.4)])
def test_p_plus_one_rates_at_a_fixed_time(method, order, rate):
    """5 -> 10 cells at t = 1e-4 s (docs/results.md, docs/convergence_square_t1e-4_full.csv,
    measured in P11 / v1: 1.91-2.06 at P = 1, 2.94-3.10 at P = 2, ADER-DGFEM 3.77 / 4.04 and
    ADER-DGMPM 3.68 / 3.99 at P = 3)."""
    rows = convergence("convergence_square", [method], [order], [5, 10], overrides=["run.t_end=1e-4"],
                       fields=["P11", "v1"], progress=False)
    assert all(r["status"] == "ok" for r in rows)
    assert rows[1]["rate_P11"] > rate and rows[1]["rate_v1"] > rate


def test_n_t_equals_n_e_steps_of_eq_67():
    """run.steps = "cells": N_e steps of dt = CFL h / ((2P + 1) c_p) [L23 eq 67], so the end time
    CFL L / ((2P + 1) c_p) does not depend on N_e; --set run.t_end fixes the time instead."""
    E, nu, rho = 2e11, 0.3, 7800.0
    c_p = np.sqrt(E * (1 - nu) / ((1 + nu) * (1 - 2 * nu)) / rho)
    for cells, order in ((5, 1), (10, 1), (5, 2)):
        r = run("convergence_square", [f"grid.cells=[{cells}, {cells}]", 'method.name="ader-dgfem"',
                                       f"method.order={order}"], progress=False)
        assert r.state.step == cells
        assert r.state.t == pytest.approx(0.2 / ((2 * order + 1) * c_p), rel=1e-6)
        assert r.summary()["t_end"] == pytest.approx(r.state.t)
    fixed = run("convergence_square", ["run.t_end=2e-5", 'method.name="ader-dgfem"'], progress=False)
    assert fixed.state.t == pytest.approx(2e-5)


def test_the_printed_reading_runs_as_a_variant():
    r = run("convergence_square_printed", ["run.t_end=1e-5"], progress=False)
    assert r.status == "ok" and not r.errors
