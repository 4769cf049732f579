"""Plain MPM (hat functions) on R18 §7.1's elastic bar (150 cells, one centred particle each,
1e9 Pa on the left end, right end fixed), against an independent numpy MPM written here.

R18 Fig. 6 shows MPM-USL at CFL 0.5 running through the incident and reflected waves. With the
particles moving over the grid (MPM as usual) it cannot: every particle of the loaded zone moves
by the same u = v t (v = T / (rho c) = 25.3 m/s), so all of them reach a node at once when
u = h / 2, t = 7.9e-4 s, and the cell-crossing error of the hat functions blows the stress up
there, at every CFL (it is the displacement, not the time step, that decides). R18 states that
"the linearized geometrical framework holds": the particles stay at their reference positions,
and then USL at CFL 0.5 runs to the end, as in the paper (``method.geometry = "linearised"``).
"""
import numpy as np
import pytest

from skdgmpm.run import run

E, RHO, LENGTH, CELLS, LOAD = 2e11, 7800.0, 6.0, 150, 1e9
MPM_USL_HAT = ['method.name="mpm"', 'method.update="usl"', 'method.shape="hat"']


def numpy_usl(cfl, t_end, move):
    """MPM-USL, hat functions, FLIP, one centred particle per cell, the traction carried by the
    first particle, the right node fixed; P = E (F - 1) (linear elastic, nu = 0). Returns
    (t, P11 at the particles) at t_end or where |P| exceeds 20 times the load."""
    h, c = LENGTH / CELLS, np.sqrt(E / RHO)
    x = (np.arange(CELLS) + 0.5) * h
    V0 = np.full(CELLS, h)
    m_p, v_p, F = RHO * V0, np.zeros(CELLS), np.ones(CELLS)
    P = np.zeros(CELLS)
    t, rows = 0.0, np.arange(CELLS)
    while t < t_end * (1 - 1e-12):
        dt = min(cfl * h / np.max(c + np.abs(v_p)), t_end - t)
        i = np.clip(np.floor(x / h).astype(int), 0, CELLS - 1)
        xi = x / h - i
        S, G = np.zeros((CELLS, CELLS + 1)), np.zeros((CELLS, CELLS + 1))
        S[rows, i], S[rows, i + 1] = 1 - xi, xi
        G[rows, i], G[rows, i + 1] = -1 / h, 1 / h
        m = S.T @ m_p
        v = (S.T @ (m_p * v_p)) / m
        v[-1] = 0.0
        f = -G.T @ (P * F * V0) + S[0] * LOAD
        v_new = v + dt * f / m
        v_new[-1] = 0.0
        v_p = v_p + dt * (S @ ((v_new - v) / dt))
        if move:
            x = x + dt * (S @ v_new)
        F = F + dt * (G @ v_new) * F
        P = E * (F - 1.0)
        t += dt
        if np.abs(P).max() > 20 * LOAD:
            break
    return t, P


def test_usl_hat_runs_in_the_linearised_geometry_as_r18_shows():
    """CFL 0.5 to t_end (the reflected wave): the engine equals the independent numpy MPM to
    round-off, and the stress oscillates about the exact profile (L1 3.6 % of it, measured)."""
    r = run("bar_elastic_1d", [*MPM_USL_HAT, 'method.geometry="linearised"', "method.cfl=0.5"], progress=False)
    assert r.status == "ok"
    t, P = numpy_usl(0.5, r.state.t, move=False)
    assert t == pytest.approx(r.state.t, rel=1e-12)
    assert np.max(np.abs(r.fields()["P11"] - P)) < 1e-10 * LOAD          # measured 1.1e-13
    assert r.errors["P11"]["L1_rel"] < 0.05


def test_usl_hat_moving_particles_blow_up_when_they_cross_the_nodes():
    """The updated geometry stops (energy created, then J or stress out of range) as u = h / 2
    is reached, t = 7.9e-4 s, at CFL 0.3 as at 0.5; so does the numpy MPM with moving particles."""
    u_half = 0.5 * LENGTH / CELLS / (LOAD / (RHO * np.sqrt(E / RHO)))
    for cfl in (0.3, 0.5):
        r = run("bar_elastic_1d", [*MPM_USL_HAT, f"method.cfl={cfl}"], progress=False)
        assert r.status == "unstable"
        assert 0.85 * u_half < r.state.t < 1.05 * u_half
        t, P = numpy_usl(cfl, 1.5e-3, move=True)
        assert 0.85 * u_half < t < 1.05 * u_half and np.abs(P).max() > 20 * LOAD
