"""RK-DGFEM (the Gauss-quadrature baseline of L23) on the same forms, Riemann solver and boundary
conditions: convergence rates against the exact standing wave, stability on the bar scenes."""
import numpy as np
import pytest
from skfem import CellBasis, LinearForm, MeshLine, asm

from skdgmpm.dgfem import dg_element
from skdgmpm.elements import ElementLineLagrange
from skdgmpm.run import run


def rk_dgfem(scene, order, integrator="rk4", cfl=0.5, extra=()):
    return run(scene, ['method.name="rk-dgfem"', f"method.order={order}",
                       f'method.integrator="{integrator}"', f"method.cfl={cfl}", *extra], progress=False)


@pytest.mark.parametrize("order", [1, 2, 3])
def test_standing_wave_rates_are_p_plus_1(order, record_property):
    """Exact P-wave eigenmode (skdgmpm.exact.StandingWave2D): L2 errors of eps11, P11 and v1 at the
    Gauss points fall like h^(P+1) (L23 §5.1: rates P + 1 for SPTP)."""
    errors = {n: rk_dgfem("standing_wave_2d", order, extra=[f"grid.cells=[{n},{n}]"]).errors
              for n in (4, 8)}
    rates = {k: np.log2(errors[4][k]["L2_rel"] / errors[8][k]["L2_rel"]) for k in ("eps11", "P11", "v1")}
    record_property("rates", rates)
    assert all(r >= order + 1 - 0.2 for r in rates.values()), rates


def test_tvd_rk2_first_order_space_second_order_rate():
    errors = [rk_dgfem("standing_wave_2d", 1, "rk2", 0.3, [f"grid.cells=[{n},{n}]"]).errors["P11"]["L2_rel"]
              for n in (4, 8)]
    assert np.log2(errors[0] / errors[1]) > 1.8


@pytest.mark.parametrize("order", [2, 3, 4])
def test_line_lagrange_element_is_nodal_and_reproduces_polynomials(order):
    """Nodal basis (Phi_i(x_j) = delta_ij), so int_cell dPhi_i/dx = Phi_i(1) - Phi_i(0) is -1 at the
    left vertex, +1 at the right vertex and 0 inside; projections reproduce x^P exactly."""
    e = ElementLineLagrange(order)
    nodes = e.doflocs[:, 0]
    values = np.array([e.lbasis(nodes[None, :], i)[0] for i in range(order + 1)])
    assert np.allclose(values, np.eye(order + 1), atol=1e-12)
    m = MeshLine(np.linspace(0.0, 1.0, 4))
    b = CellBasis(m, dg_element(1, order), intorder=2 * order + 1)
    volume = asm(LinearForm(lambda v, w: v.grad[0]), b)[b.element_dofs]        # (nb, n_cells)
    assert np.allclose(volume[0], -1) and np.allclose(volume[1], 1) and np.allclose(volume[2:], 0)
    u = b.project(lambda x: x[0] ** order)
    X = np.asarray(b.global_coordinates())[0]
    assert np.allclose(np.asarray(b.interpolate(u)), X ** order, atol=1e-12)


@pytest.mark.parametrize("order", [1, 2, 3])
@pytest.mark.parametrize("scene", ["bar_elastic_1d", "bar_svk_1d", "bar_svk_tension_1d"])
def test_bars_run_stably_for_every_order(scene, order):
    """RK4 at CFL 0.5 of L23 eq 67 (Delta t = CFL h / ((2P+1) c)): the discontinuous loads give
    Gibbs oscillations (no limiter yet) but the runs stay stable and only dissipate energy."""
    r = rk_dgfem(scene, order, extra=["grid.cells=20"])
    assert r.status == "ok", r.message
    growth = np.diff(r.history["balance"]).max()
    assert growth <= 1e-9 * r.history["external_work"].max()
    assert r.errors["P11"]["L1_rel"] < 0.1


def _blocks_applied(blocks, cell_dofs, R, base=None, step=0.0):
    """M^-1 R cell by cell, or base + step M^-1 R, written out in Python term by term in the
    order the compiled passes sum them."""
    out = np.empty_like(R)
    n_cells, nb = cell_dofs.shape
    for c in range(n_cells):
        for k in range(nb):
            for j in range(R.shape[1]):
                s = 0.0
                for m in range(nb):
                    s += float(blocks[c, k, m]) * float(R[cell_dofs[c, m], j])
                i = cell_dofs[c, k]
                out[i, j] = s if base is None else float(base[i, j]) + step * s
    return out


SIZES = [(4, 6), (9, 6), (16, 6), (3, 2)]     # Q1, Q2 (literal sizes), Q3 and 1D P2 (read at run time)


@pytest.mark.parametrize("nb, nc", SIZES)
def test_mass_blocks_give_the_bits_of_the_row_by_row_sum(nb, nc):
    """`_apply_blocks` (M^-1 R cell by cell) against the sum written out in Python: the same bits.
    The cells' dofs are shuffled, so that a kernel that wrote a cell's rows of ``out`` before it
    had read them all, or read another cell's, would differ."""
    from skdgmpm.dgfem import _apply_blocks
    rng = np.random.default_rng(nb * nc)
    n_cells = 7
    blocks = rng.standard_normal((n_cells, nb, nb))
    cell_dofs = rng.permutation(n_cells * nb).astype(np.int32).reshape(n_cells, nb)
    R = rng.standard_normal((n_cells * nb, nc))
    out = np.full_like(R, np.nan)
    _apply_blocks(blocks, cell_dofs, R, out)
    assert np.array_equal(out, _blocks_applied(blocks, cell_dofs, R))


@pytest.mark.parametrize("nb, nc", SIZES)
@pytest.mark.parametrize("volume_first, sourced, kind", [(False, False, "array"), (False, True, "mean"),
                                                         (True, False, "rk4"), (True, True, "array")])
def test_the_cell_pass_gives_the_bits_of_the_residual_stored_and_read_back(nb, nc, volume_first, sourced, kind):
    """`dgfem.cell_update` (each row of R formed where the cell's mass block reads it, base +
    step M^-1 R) against R stored by the passes it replaces, then the update written out in
    Python: the faces' terms as `parallel.matmul` sums them (the interior gather, then the
    boundary's added), the volume term as `system.volume_flux` does (first, and the faces' added
    to it: ADER's corrector; or after them, RK's R + V), the source added. The same bits. The base
    an array, or RK2's mean and RK4's last base (`integrators.Combination`) formed in the pass:
    the bits of numpy's combination (`integrators.formed`, the expressions the integrators once
    computed in passes of their own). Random sparse gathers and stiffness, the cells' dofs
    shuffled."""
    import scipy.sparse as sp

    from skdgmpm import parallel, system
    from skdgmpm.dgfem import cell_update
    from skdgmpm.integrators import MEAN, RK4_BASE, Combination, formed
    rng = np.random.default_rng(nb * nc + 10 * volume_first + sourced)
    d = {2: 1, 6: 2}[nc]
    n_cells, nf, nbf, n_points = 7, 19, 5, 30
    n = n_cells * nb
    blocks = rng.standard_normal((n_cells, nb, nb))
    cell_dofs = rng.permutation(n).astype(np.int32).reshape(n_cells, nb)

    def gather(cols):
        return parallel.csr(sp.random(n, cols, density=0.3, random_state=rng, format="csr"))

    interior, boundary = gather(nf), gather(nbf)
    flux, flux_b, Q = rng.standard_normal((nf, nc)), rng.standard_normal((nbf, nc)), rng.standard_normal((n_points, nc))
    measure, measure_b = rng.random(nf), rng.random(nbf)
    K = system.Stiffness([sp.random(n, n_points, density=0.2, random_state=rng, format="csr") for _ in range(d)])
    S = rng.standard_normal((n, nc)) if sourced else None
    arrays = [rng.standard_normal((n, nc)) for _ in range(4)]
    base = {"array": arrays[0], "mean": Combination(MEAN, tuple(arrays[:2])),
            "rk4": Combination(RK4_BASE, tuple(arrays))}[kind]

    out = cell_update(blocks, cell_dofs, (interior, measure, flux, boundary, measure_b, flux_b), Q, K, S, base, 0.3,
                      volume_first)
    if volume_first:
        R = system.volume_flux(Q, K)
        parallel.matmul(interior, flux, R, add=True, scale=measure)
    else:
        R = parallel.matmul(interior, flux, scale=measure)
    parallel.matmul(boundary, flux_b, R, add=True, scale=measure_b)
    if not volume_first:
        R = R + system.volume_flux(Q, K)
    if sourced:
        R += S
    if kind == "mean":
        assert np.array_equal(formed(base), 0.5 * (arrays[0] + arrays[1]))
    assert np.array_equal(out, _blocks_applied(blocks, cell_dofs, R, formed(base), 0.3))


@pytest.mark.parametrize("method", ["rk-dgfem", "ader-dgfem", "ader-dgmpm", "mpm", "dgmpm"])
def test_the_initial_state_is_assessed_by_the_steps_own_law_pass(method, monkeypatch):
    """A DG method's initial state takes Q and its health from the step's law pass
    (`MaterialSet.update_and_assess`), MPM's from its step's stress pass (`stress_update` with the
    health), not from kernels of their own (DGMPM with 2 x 2 particles per cell, whose step pass
    forms each point's state from the nodes, keeps the stand-alone ones; with one particle per
    cell, tests/test_layout.py): the same bits as the law's stand-alone pass and the stand-alone
    health check (`skdgmpm.health.assess`), and the same wave speeds for the first time step. The
    neo-Hookean manufactured solution starts from its exact state: F != I and v2 != 0 at the points."""
    from skdgmpm.build import build
    from skdgmpm.health import assess
    from skdgmpm.scene import load_scene

    keys = {"rk-dgfem": ["method.order=1", 'method.integrator="rk2"'], "mpm": []}.get(method, ["method.order=1"])
    scene = load_scene("mms_axis_aligned_2d", ["grid.cells=[6,4]", f'method.name="{method}"', *keys])
    if method != "dgmpm":                       # the stand-alone check (a kernel of its own) is not run
        monkeypatch.setattr("skdgmpm.scheme.assess", lambda *args: pytest.fail("stand-alone health check"))
    disc = build(scene)
    monkeypatch.undo()
    stepper, state = disc.stepper, disc.initial
    points = stepper.gauss if method in ("rk-dgfem", "ader-dgfem", "ader-dgmpm") else stepper.particles
    Q = stepper.materials.state(state.U, points.material, points.rho0, state.history)
    assert np.abs(Q[:, :4] - Q[0, :4]).max() > 0 and np.abs(Q[:, 5]).max() > 0     # P varies, v2 != 0
    np.testing.assert_array_equal(state.Q, Q)
    alone = assess(stepper.materials, points, state.U, state.Q)
    np.testing.assert_array_equal(state.speed, alone.speed)
    assert state.health == alone.record() and state.fastest == alone.fastest
