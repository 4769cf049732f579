"""Slope limiters (L23 §3.3): bounds of eq 39 restored in troubled cells, smooth fields untouched."""
import numpy as np
import pytest

from skdgmpm.build import build
from skdgmpm.run import run
from skdgmpm.scene import load_scene


def stepper(order, limiter, scene="bar_elastic_1d", cells="grid.cells=12"):
    return build(load_scene(scene, ['method.name="ader-dgfem"', f"method.order={order}",
                                    f'method.limiter="{limiter}"', cells])).stepper


@pytest.mark.parametrize("kind", ["barth-jespersen", "venkatakrishnan"])
@pytest.mark.parametrize("order", [1, 2, 3])
def test_limited_cells_respect_the_neighbour_bounds(kind, order):
    """A step in F11 projected on Q_P oscillates; after limiting, the solution at every limiting
    point lies within [min, max] of the neighbouring cell averages (eq 39)."""
    st = stepper(order, kind)
    X = st.gauss.X[:, 0]
    U = np.zeros((len(X), 2))
    U[:, 0] = 1.0 + 1e-3 * (np.floor(X / 0.7) % 2)    # a square wave, jumps across the cells
    dofs = st.project(U)
    lim = st.slope_limiter
    limited, n = lim(dofs)
    assert n >= 1
    mean = lim.averages(limited)
    for T, cell, _ in lim.rows:
        values = T @ limited
        nb = [np.r_[c, lim.pairs[lim.pairs[:, 0] == c, 1], lim.pairs[lim.pairs[:, 1] == c, 0]] for c in cell]
        T_b, cell_b = lim.boundary_rows                  # plus the cell's own boundary values
        own = [(T_b @ limited)[cell_b == c] for c in cell]
        lo = np.array([np.vstack([mean[k], o]).min(axis=0) for k, o in zip(nb, own)])
        hi = np.array([np.vstack([mean[k], o]).max(axis=0) for k, o in zip(nb, own)])
        assert np.all(values >= lo - 1e-12) and np.all(values <= hi + 1e-12)
    assert np.allclose(lim.averages(limited), lim.averages(dofs))            # conservative


def _neighbour_bounds(lim, dofs):
    """[min, max] of eq 39 per cell: the face neighbours' averages, the cell's own and its
    values on the body's boundary (computed here with loops, apart from the limiter's code)."""
    mean = lim.averages(dofs)
    lo, hi = mean.copy(), mean.copy()
    for a, b in lim.pairs:
        lo[a], hi[a] = np.minimum(lo[a], mean[b]), np.maximum(hi[a], mean[b])
        lo[b], hi[b] = np.minimum(lo[b], mean[a]), np.maximum(hi[b], mean[a])
    T_b, cell_b = lim.boundary_rows
    for c, value in zip(cell_b, T_b @ dofs):
        lo[c], hi[c] = np.minimum(lo[c], value), np.maximum(hi[c], value)
    return mean, lo, hi


def oblique_step(order, kind):
    """2D: a jump of F11 across an oblique line and a sine in p1 cut off along another line, on
    8 x 8 cells of P = ``order``: troubled cells whose neighbours' gradient (eq 40) is much steeper
    than their own DG slope."""
    st = stepper(order, kind, "standing_wave_2d", "grid.cells=[8,8]")
    X = st.gauss.X / st.gauss.X.max(axis=0)
    U = np.zeros((len(X), 6))
    U[:, 0] = 1.0 + 1e-3 * (X[:, 0] + 0.3 * X[:, 1] > 0.5)
    U[:, 3] = 1.0
    U[:, 4] = np.sin(7 * X[:, 0]) * (X[:, 1] > 0.4)
    return st, st.project(U)


@pytest.mark.parametrize("kind", ["barth-jespersen", "venkatakrishnan", "barth-jespersen-scaled",
                                  "venkatakrishnan-scaled"])
@pytest.mark.parametrize("order", [1, 2])
def test_limited_reconstruction_keeps_the_bounds_in_2d(kind, order):
    """Eq 43's excursion is the one of the reconstruction that alpha scales (eq 41): the limited
    solution lies within the bounds at every limiting point. (Computed from the DG solution's own
    excursion instead, alpha let the limited values overshoot the bounds by 24 % of their range
    here, and limited impacts gained energy.)"""
    st, dofs = oblique_step(order, kind)
    lim = st.slope_limiter
    limited, n = lim(dofs)
    assert n >= 10
    mean, lo, hi = _neighbour_bounds(lim, dofs)
    scale = np.maximum((hi - lo).max(axis=0), np.abs(mean).max(axis=0)) + 1e-300       # per component
    for T, cell, _ in lim.rows:
        values = T @ limited
        assert np.all((values - hi[cell]) / scale <= 1e-9) and np.all((lo[cell] - values) / scale <= 1e-9)
    assert np.allclose(lim.averages(limited), mean, rtol=0, atol=1e-12)


@pytest.mark.parametrize("kind", ["barth-jespersen-invariant", "venkatakrishnan-invariant",
                                  "barth-jespersen-invariant-scaled"])
def test_invariant_limiter_keeps_the_projected_bounds(kind):
    """Frame-invariant kinds: at every limiting point of a limited cell, the excursion of each
    block (F, p) from the average, projected on its own direction, stays below the largest
    neighbour difference projected on it (the bound the factor is built from)."""
    st, dofs = oblique_step(1, kind)
    lim = st.slope_limiter
    limited, n = lim(dofs)
    assert n >= 10
    mean = lim.averages(dofs)
    others = {c: [mean[c]] for c in range(len(mean))}       # neighbour averages, own boundary values
    for a, b in lim.pairs:
        others[a].append(mean[b])
        others[b].append(mean[a])
    T_b, cell_b = lim.boundary_rows
    for c, value in zip(cell_b, T_b @ dofs):
        others[c].append(value)
    for T, cell, _ in lim.rows:
        excursion = T @ limited - mean[cell]
        for block in (slice(0, 4), slice(4, 6)):
            for r, c in enumerate(cell):
                delta = excursion[r, block]
                size = np.linalg.norm(delta)
                if size < 1e-12:
                    continue
                bound = max(0.0, max((u[block] - mean[c, block]) @ delta / size for u in others[c]))
                assert size <= bound + 1e-9 * np.abs(mean[:, block]).max() or np.array_equal(
                    limited[st.cell_dofs[c]], dofs[st.cell_dofs[c]])             # untroubled: its own DG values


@pytest.mark.parametrize("kind", ["barth-jespersen-scaled", "barth-jespersen-invariant-scaled"])
@pytest.mark.parametrize("order", [1, 2])
def test_scaled_kinds_only_shrink_the_cells_own_deviation(kind, order):
    """-scaled kinds: in a limited cell every Gauss-point value is u_bar + alpha (u_h - u_bar) with
    0 <= alpha <= 1 per component (per block for -invariant): no component gets steeper, its sign
    pattern inside the cell is kept, and the kinetic energy |p|^2 of a cell never grows."""
    st, dofs = oblique_step(order, kind)
    lim = st.slope_limiter
    limited, n = lim(dofs)
    mean = lim.averages(dofs)[:, None, :]
    before = (st.B @ dofs).reshape(lim.nel, lim.nq, -1) - mean
    now = (st.B @ limited).reshape(lim.nel, lim.nq, -1) - mean
    assert n >= 10
    with np.errstate(invalid="ignore", divide="ignore"):
        ratio = np.where(np.abs(before) > 1e-12, now / before, 1.0)
    factor = ratio.min(axis=1)                              # one factor per cell and component
    assert np.all((factor >= -1e-12) & (factor <= 1 + 1e-12))
    assert np.allclose(now, factor[:, None, :] * before, rtol=0, atol=1e-12 * np.abs(before).max())
    kinetic = lambda dev: np.einsum("eq,eqc->e", lim.w, dev[:, :, 4:] ** 2)   # noqa: E731
    assert np.all(kinetic(now) <= kinetic(before) * (1 + 1e-12))


@pytest.mark.parametrize("order", [1, 2, 3])
def test_smooth_field_is_left_alone(order):
    st = stepper(order, "barth-jespersen", "standing_wave_2d", "grid.cells=[6,6]")
    U = np.zeros((len(st.gauss.X), 6))
    U[:, 0] = 1 + 1e-4 * np.sin(st.gauss.X[:, 0])      # monotone and smooth: no new extremum
    U[:, 3] = 1.0
    dofs = st.project(U)
    limited, n = st.slope_limiter(dofs)
    assert n == 0 and np.array_equal(limited, dofs)


@pytest.mark.parametrize("method", ["rk-dgfem", "ader-dgfem", "ader-dgmpm"])
@pytest.mark.parametrize("order", [1, 2, 3])
def test_shock_with_limiter_runs_stably(method, order):
    """SVK tension shock (R18 §7.2.2, exact Riemann solution) at CFL 0.5 of L23 eq 67 with the
    Barth-Jespersen limiter: stable for every method and order. Measured overshoot of the 2e10 Pa
    plateau (40 cells): RK4-DGFEM 0.66/0.78/0.79 %, ADER-DGFEM 1.23/1.73/0.64 %, ADER-DGMPM
    1.24/2.02/0.62 % for P = 1/2/3 (without limiter up to 14 %; with alpha taken from the DG
    solution's excursion instead of the reconstruction's, P = 3 ADER overshot by 6-8 %). The
    overshoot is of P11 = P(F) at the points after the limiter acted on F."""
    extra = ['method.integrator="rk4"'] if method == "rk-dgfem" else []
    if method == "ader-dgmpm":
        extra.append(f"particles.per_cell={order + 1}")
    r = run("bar_svk_tension_1d", [f'method.name="{method}"', f"method.order={order}", "method.cfl=0.5",
                                   'method.limiter="barth-jespersen"', "grid.cells=40", "run.t_end=4e-4",
                                   *extra], progress=False)
    assert r.status == "ok"
    assert r.fields()["P11"].max() < 1.025 * 2e10
    assert r.errors["P11"]["L1_rel"] < 0.05


# Largest CFL of L23 eq 67 (0.05/0.1 steps) for which the energy of the exact standing wave (8 x 8,
# no limiter, two periods) ends below its start without instability, measured with
# the scans recorded in docs/results.md: RK2 (P = 1) 0.7, RK4 0.95 / 0.8 / 0.65,
# ADER-DGFEM and ADER-DGMPM 0.6 / 0.6 / 0.4. TVD-RK2 has no such CFL for P >= 2 (L23 uses RK4 there).
CFL_LIMIT = {("rk-dgfem", 1): 0.7, ("rk-dgfem", 2): 0.8, ("rk-dgfem", 3): 0.65,
             ("ader-dgfem", 1): 0.6, ("ader-dgfem", 2): 0.6, ("ader-dgfem", 3): 0.4,
             ("ader-dgmpm", 1): 0.6, ("ader-dgmpm", 2): 0.6, ("ader-dgmpm", 3): 0.4}


@pytest.mark.parametrize("scene", ["bar_elastic_1d", "bar_svk_tension_1d"])
@pytest.mark.parametrize("method, order", sorted(CFL_LIMIT))
def test_bars_run_at_the_cfl_limit(method, order, scene):
    """Every method x order runs the elastic bar and the SVK shock at its CFL limit (above),
    limiter on, without instability, and matches the exact solution in L1 within 10 %."""
    extra = [f'method.integrator="{"rk2" if order == 1 else "rk4"}"'] if method == "rk-dgfem" else []
    if method == "ader-dgmpm":
        extra.append(f"particles.per_cell={order + 1}")
    r = run(scene, [f'method.name="{method}"', f"method.order={order}", f"method.cfl={CFL_LIMIT[method, order]}",
                    'method.limiter="barth-jespersen"', "grid.cells=20", *extra], progress=False)
    assert r.status == "ok", r.message
    assert r.errors["P11"]["L1_rel"] < 0.1
