"""The ADER corrector's fused face pass against the batched path (traces as scipy products, the
law's batched tangent, `riemann.godunov_fluxes`) summed over the time nodes, in 1D and 2D."""
import numpy as np
import pytest
import scipy.sparse as sp

from skdgmpm.ader_kernels import interior_flux_sum
from skdgmpm.build import build
from skdgmpm.riemann import godunov_fluxes
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
    assert interior_flux_sum(*st.traces[:2], u_hat, q_hat, *st.face_rho[:2], f.normal, *st.face_material[:2],
                             *st.laws, st.w_tau, flux) == -1
    expected = np.zeros_like(flux)
    for s in range(n_t):
        sides = []
        for (indptr, indices, data), material, rho in zip(st.traces[:2], st.face_material, st.face_rho):
            T = sp.csr_matrix((data, indices, indptr), shape=(len(indptr) - 1, n_points))
            F = (T @ u_hat[s])[:, : d * d].reshape(-1, d, d)
            sides += [T @ q_hat[s], st.materials.tangent(F, material), rho]
        expected += st.w_tau[s] * godunov_fluxes(*sides, f.normal)[0]
    assert np.allclose(flux, expected, rtol=1e-12, atol=1e-12 * np.abs(expected).max())
