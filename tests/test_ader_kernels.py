"""The ADER corrector's fused face passes against the batched path (traces as scipy products, the
law's batched tangent, `riemann.godunov_fluxes`; on the boundary `riemann.impedance`,
`bcs.BoundaryGhosts.star`, `riemann.normal_flux`) summed over the time nodes, in 1D and 2D; the
boundary pass also from RK-DGFEM's dofs (the law at the trace), on one thread and on three."""
import numpy as np
import pytest
import scipy.sparse as sp

from skdgmpm import parallel, system
from skdgmpm.ader_kernels import interior_flux_sum
from skdgmpm.bcs import BoundaryGhosts, make_bc
from skdgmpm.build import build
from skdgmpm.riemann import godunov_fluxes, impedance, normal_flux
from skdgmpm.scene import load_scene

CASES = {"ader-dgmpm 2D": ("plate_impact_neohookean_2d", ['method.name="ader-dgmpm"', "grid.cells=[6, 5]",
                                                          "particles.per_cell=[0.25, 0.75]"]),
         "ader-dgfem 2D P2": ("standing_wave_2d", ['method.name="ader-dgfem"', "method.order=2", "grid.cells=[3, 3]"]),
         "ader-dgfem 1D": ("bar_elastic_1d", ['method.name="ader-dgfem"', "method.order=2", "grid.cells=5"])}


@pytest.mark.parametrize("case", CASES)
def test_interior_pass_is_the_time_weighted_godunov_flux(case):
    scene, options = CASES[case]
    st = build(load_scene(scene, options)).stepper
    d, n_t, nc = st.d, len(st.tau), st.d * st.d + st.d
    rng = np.random.default_rng(1)
    n_points = st.K.shape[1]                           # the predictor's points
    u_hat = np.zeros((n_t, n_points, nc))
    u_hat[..., : d * d] = np.eye(d).ravel() + 0.02 * rng.standard_normal((n_t, n_points, d * d))
    q_hat = rng.standard_normal((n_t, n_points, nc)) * np.r_[1e8 * np.ones(d * d), np.ones(d)]
    f = st.interior
    flux = np.empty((len(f), nc))
    mat_L, mat_R, rho_L, rho_R = st.interior_sides[:4]
    assert parallel.chunked(*interior_flux_sum(*st.traces[:2], u_hat, q_hat, rho_L, rho_R, f.normal, mat_L, mat_R,
                                               *st.laws, st.w_tau, flux)) == -1
    expected = np.zeros_like(flux)
    for s in range(n_t):
        sides = []
        for (indptr, indices, data), material, rho in zip(st.traces[:2], (mat_L, mat_R), (rho_L, rho_R)):
            T = sp.csr_matrix((data, indices, indptr), shape=(len(indptr) - 1, n_points))
            F = (T @ u_hat[s])[:, : d * d].reshape(-1, d, d)
            sides += [T @ q_hat[s], st.materials.tangent(F, material), rho]
        expected += st.w_tau[s] * godunov_fluxes(*sides, f.normal)[0]
    assert np.allclose(flux, expected, rtol=1e-12, atol=1e-12 * np.abs(expected).max())


CONDITIONS = [{"kind": "velocity", "value": [3.0, -1.0], "ramp": 2e-6},
              {"kind": "traction", "value": [1e8, 2e7], "release": 1e-6},
              {"kind": "free"}, {"kind": "symmetry"}, {"kind": "normal_velocity", "value": 4.0},
              {"kind": "transmissive"}, {"kind": "mixed", "velocity": {"x": 1.0}, "traction": {"y": -3e7}}]
BOUNDARY_CASES = {**CASES, "rk-dgfem 2D P2": ("plate_impact_neohookean_2d", [
    'method.name="rk-dgfem"', "method.order=2", 'method.integrator="rk2"', "grid.cells=[4, 3]"])}


def _every_condition(st):
    """The stepper's boundary faces dealt round every kind of condition (1D: each axis's value)."""
    b, d = st.boundary, st.d
    specs = CONDITIONS if d == 2 else [{**c, "value": c["value"][:1]} if isinstance(c.get("value"), list) else c
                                       for c in CONDITIONS if c["kind"] not in ("mixed", "normal_velocity")]
    group = np.arange(len(b)) % len(specs)
    st.ghosts = BoundaryGhosts([(group == k, make_bc(spec, d)) for k, spec in enumerate(specs)], b.normal)


@pytest.mark.parametrize("case", BOUNDARY_CASES)
def test_boundary_pass_is_the_time_weighted_ghost_flux(case, monkeypatch):
    """`riemann.boundary_fluxes` (the stepper's `boundary_pass`, run alone) against the batched path,
    every kind of condition on the faces, the nodes' times on both sides of a release and along a
    ramp; ADER from its predictor (u_hat, q_hat), RK-DGFEM from its dofs with the law at the trace.
    The same bits on one thread and three (chunks of 2 rows)."""
    scene, options = BOUNDARY_CASES[case]
    st = build(load_scene(scene, options)).stepper
    _every_condition(st)
    d, nc, b = st.d, st.d * st.d + st.d, st.boundary
    rk = not hasattr(st, "tau")
    rng = np.random.default_rng(2)
    T_B = st.boundary_side[2] if rk else st.traces[2]
    n_points = T_B[1].max() + 1 if rk else st.K.shape[1]
    times, weights = (np.array([0.5e-6]), np.ones(1)) if rk else (np.linspace(0.5e-6, 1.5e-6, len(st.tau)), st.w_tau)
    u = np.zeros((len(times), n_points, nc))
    u[..., : d * d] = np.eye(d).ravel() + 0.02 * rng.standard_normal((len(times), n_points, d * d))
    u[..., d * d:] = 1e4 * rng.standard_normal((len(times), n_points, d))
    q = None if rk else rng.standard_normal(u.shape) * np.r_[1e8 * np.ones(d * d), np.ones(d)]

    monkeypatch.setattr(parallel, "MIN_ROWS", 16)
    made = []
    for threads in (1, 3):
        previous = parallel.set_threads(threads)
        try:
            run, (flux, t_s, v_s) = st.boundary_pass(T_B, u, q, times, weights)
            assert parallel.chunked(*run) == -1
            made.append((flux, st.boundary_powers(t_s, v_s)))
        finally:
            parallel.set_threads(previous)
    (flux, powers), (flux_3, powers_3) = made
    assert np.array_equal(flux, flux_3) and powers == powers_3

    material, rho, _ = st.boundary_side
    T = sp.csr_matrix((T_B[2], T_B[1], T_B[0]), shape=(len(b), n_points))
    expected = np.zeros_like(flux)
    for s, (time, w) in enumerate(zip(times, weights)):
        U_f = T @ u[s]
        F = U_f[:, : d * d].reshape(-1, d, d)
        Q = st.materials.state(U_f, material, rho) if rk else T @ q[s]
        P, v_L = system.split(Q, d)
        t_L = np.einsum("fia,fa->fi", P, b.normal)
        t_s, v_s = st.ghosts.star(time, t_L, v_L, impedance(st.materials.tangent(F, material), b.normal, rho))
        expected += w * normal_flux(t_s, v_s, b.normal)
        power = float(np.sum(b.measure * np.einsum("fi,fi->f", t_s, v_s)))    # numpy's, summed otherwise
        assert powers[s] == pytest.approx(power, rel=1e-12, abs=1e-300)
    np.testing.assert_allclose(flux, expected, rtol=1e-12, atol=1e-12 * np.abs(expected).max())
    assert np.abs(expected).max() > 0
