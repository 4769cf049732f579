"""Run health (skdgmpm.health): every run records min J and the smallest acoustic-tensor
eigenvalue; hitting J <= 0, loss of hyperbolicity or a non-finite value stops the run with a
message naming step, time, particle, cell, quantity and value, and keeps the last good state."""
import csv
import json
import warnings

import meshio
import numpy as np
import pytest

from skdgmpm.cli import main
from skdgmpm.run import run

# (scene, overrides, expected start of the message, quantity named in it)
CONDITIONS = {
    # linear elastic bar pushed at 20 km/s (about 4 c): F11 = 1 - v / c < 0 in the first cell
    "J <= 0": ("bar_elastic_1d", ['bc.left={kind = "velocity", value = [20000.0]}', "grid.cells=20", "exact={}"],
               "inverted material (det F <= 0) at step 1,", "J = "),
    # SVK bar compressed by 8e10 Pa > (lam + 2 mu) / (3 sqrt 3) = 5.18e10 Pa: F11 < 1 / sqrt 3
    "hyperbolicity": ("bar_svk_1d", ["bc.left.value=[8e10]", "grid.cells=20", "exact={}"],
                      "loss of hyperbolicity at step 2,", "smallest acoustic-tensor eigenvalue -"),
    # SVK bar pulled by 1e150 Pa: the cubic stress overflows in the first step
    "non-finite": ("bar_svk_tension_1d", ["bc.left.value=[-1e150]", "grid.cells=20", "exact={}"],
                   "non-finite values at step 1,", "P11 = inf"),
}


@pytest.mark.parametrize("condition", sorted(CONDITIONS))
def test_each_condition_stops_the_run_with_its_message_and_keeps_the_last_good_state(condition, tmp_path):
    scene, overrides, start, quantity = CONDITIONS[condition]
    out = tmp_path / "run"
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)          # the overflow itself
        r = run(scene, overrides, out=out, progress=False)
    assert r.status == "unstable"
    assert r.message.startswith(start), r.message
    for part in ("t = ", " s, particle 0 in cell 0 (X = [0.15])", quantity):
        assert part in r.message, (part, r.message)
    step = int(start.split("step ")[1].rstrip(","))
    # the last good state: the step before, finite and admissible, on disk and in the result
    assert r.state.step == step - 1 and np.all(np.isfinite(r.state.U))
    summary = json.loads((out / "summary.json").read_text())
    assert summary["status"] == "unstable" and summary["message"] == r.message
    assert summary["steps"] == step - 1
    last = sorted(out.glob("particles_*.vtu"))[-1]
    F = meshio.read(last).point_data["F"]
    assert np.all(np.isfinite(F)) and np.allclose(F[:, 0], r.fields()["F11"])
    with open(out / "energy.csv") as fh:
        rows = list(csv.DictReader(fh))
    assert {"min_J", "min_acoustic", "total"} <= set(rows[0])
    assert len(rows) == step and float(rows[0]["min_J"]) == 1.0
    assert all(float(row["min_J"]) > 0 and float(row["min_acoustic"]) > 0 for row in rows)


def test_cli_prints_the_message_and_exits_with_status_3(tmp_path, capsys):
    scene, overrides, start, _ = CONDITIONS["J <= 0"]
    argv = ["run", scene, "--out", str(tmp_path / "run"), "--quiet"]
    for o in overrides:
        argv += ["--set", o]
    assert main(argv) == 3
    err = capsys.readouterr().err
    assert start in err and "last good state kept in" in err


def test_a_healthy_run_records_min_j_and_the_smallest_acoustic_eigenvalue():
    """Compression of a neo-Hookean plate: min J drops below 1, the smallest acoustic eigenvalue
    stays positive, both recorded at every step and summarised."""
    r = run("plate_impact_neohookean_2d", ["grid.cells=[8,6]", "run.t_end=2e-4"], progress=False)
    h = r.history
    assert r.status == "ok" and len(h["min_J"]) == r.state.step + 1
    assert h["min_J"][0] == 1.0 and h["min_J"][-1] < 0.95
    assert np.all(h["min_acoustic"] > 0)
    s = r.summary()["health"]
    assert s["min_J_min"] == h["min_J"].min() and s["min_acoustic_min"] == h["min_acoustic"].min()


@pytest.mark.parametrize("scene, overrides", [("plate_impact_neohookean_2d", ["grid.cells=[8, 6]"]),
                                               ("plate_impact_j2_2d", ["grid.cells=[8, 6]"]),
                                               ("bar_elastic_1d", ['method.name="ader-dgmpm"', "method.cfl=0.4",
                                                                   "particles.per_cell=2", "grid.cells=20"]),
                                               ("plate_impact_neohookean_2d", ['method.name="ader-dgfem"',
                                                                               "grid.cells=[8, 6]"]),
                                               ("bar_elastoplastic_1d", ['method.name="rk-dgfem"',
                                                                         'method.integrator="rk2"', "grid.cells=20"])])
def test_a_step_keeps_the_health_summary_only_the_stand_alone_checks(scene, overrides, monkeypatch):
    """A step's law pass writes no per-point health (`Health.kept` False: four arrays no step
    reads); the state's fastest wave and health record are those of the state assessed whole
    (`health.assess`, an independent kernel), bit for bit, and so are the per-point arrays where
    the pass is asked for them."""
    from skdgmpm.build import build
    from skdgmpm.health import assess
    from skdgmpm.scene import load_scene

    disc = build(load_scene(scene, overrides))
    st, state = disc.stepper, disc.initial
    kept = []
    update = type(st.materials).update_and_assess

    def spy(self, *args, **kwargs):
        out = update(self, *args, **kwargs)
        kept.append(out[2].kept)
        return out

    monkeypatch.setattr(type(st.materials), "update_and_assess", spy)
    for _ in range(3):
        state = st.step(state)
    monkeypatch.undo()
    assert kept and not any(kept) and state.speed is None
    alone = assess(st.materials, st.particles, state.U, state.Q)
    assert state.fastest == alone.fastest and state.health == alone.record()
    assert state.health["min_J"] != 1.0                       # the load has reached the points
    motion = (state.x, state.Q[:, st.d * st.d:], 0.0)
    args = (state.U, st.particles.material, st.particles.rho0, state.history, motion)
    for points in (True, False):
        health = st.materials.update_and_assess(*args, points=points)[2]
        assert health.kept == points and health.summary == alone.summary
    with_points = st.materials.update_and_assess(*args)[2]
    for name in ("finite", "J", "omega", "speed"):
        np.testing.assert_array_equal(getattr(with_points, name), getattr(alone, name))


RK2_DGFEM, ADER_DGFEM = ['method.name="rk-dgfem"', 'method.integrator="rk2"'], ['method.name="ader-dgfem"',
                                                                                   "method.order=2", "method.cfl=0.5"]


# (ADER-DGFEM's face pass finds the lost hyperbolicity before its points do: not a point's stop)
@pytest.mark.parametrize("method, condition", [(RK2_DGFEM, "hyperbolicity"), (RK2_DGFEM, "J <= 0"),
                                               (ADER_DGFEM, "J <= 0")])
def test_a_dg_step_that_keeps_the_summary_only_stops_with_the_message_of_the_points_arrays(method, condition,
                                                                                           monkeypatch):
    """DGFEM's step keeps the law pass's health summary only; a stop then assesses the state whole
    to name its point. The message is the one the pass's own per-point arrays give (the pass
    asked to keep them: the reference), and names a Gauss point of the first bad cell."""
    from skdgmpm.constitutive import MaterialSet

    scene, overrides, start, quantity = CONDITIONS[condition]
    messages = []
    for keep in (False, True):
        if keep:                        # every law pass keeps its arrays: the message from them
            update = MaterialSet.update_and_assess
            monkeypatch.setattr(MaterialSet, "update_and_assess",
                                lambda *args, points=True, **kwargs: update(*args, points=True, **kwargs))
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", RuntimeWarning)
            r = run(scene, overrides + method, progress=False)
        assert r.status == "unstable" and r.message.startswith(start.split(" at step")[0]), r.message
        messages.append(r.message)
    assert messages[0] == messages[1] and quantity in messages[0] and " in cell 0 " in messages[0]


@pytest.mark.parametrize("d", [1, 2])
def test_the_law_pass_assesses_the_state_as_the_stand_alone_check_and_numpy_do(d):
    """`MaterialSet.update_and_assess` (health and positions beside the stress, one pass) gives the same arrays
    as `health.assess` on its result, and both the numbers of an independent computation: J = det F,
    numpy's eigenvalues of the symmetrised acoustic tensors C_iajb N_a N_b of the law's batched
    tangent along `directions`, the fastest along the axes; two laws, one point not finite."""
    from types import SimpleNamespace
    from skdgmpm import system
    from skdgmpm.constitutive import MaterialSet
    from skdgmpm.health import Health, assess, directions
    from skdgmpm.materials import NeoHookean, SaintVenantKirchhoff

    rng = np.random.default_rng(3)
    n = 40
    materials = MaterialSet((NeoHookean(E=200e9, nu=0.3, rho=7800.0), SaintVenantKirchhoff(E=70e9, nu=0.33, rho=2700.0)))
    index = rng.integers(0, 2, n)
    F = np.eye(d)[None] + 0.15 * rng.standard_normal((n, d, d))
    U = system.join(F, rng.standard_normal((n, d)))
    U[7, 0] = np.nan
    rho0 = materials.densities[index]
    x, v_old, dt = rng.standard_normal((n, d)), rng.standard_normal((n, d)), 1e-3
    Q, _, fused, x_new = materials.update_and_assess(U, index, rho0, None, (x, v_old, dt))
    np.testing.assert_array_equal(x_new, x + 0.5 * dt * (v_old + Q[:, d * d:]))     # trapezoidal, same bits
    alone = assess(materials, SimpleNamespace(material=index), U, Q)
    for name in ("finite", "J", "omega", "speed"):
        np.testing.assert_array_equal(getattr(fused, name), getattr(alone, name), err_msg=name)
    # the passes' summaries (first bad point, minima over the finite points) = numpy's of the arrays
    arrays = Health(fused.finite, fused.J, fused.omega, fused.speed)
    assert fused.summary == alone.summary
    assert fused.record() == arrays.record() and fused.summary[0] == int(np.flatnonzero(arrays.bad)[0]) == 7
    assert fused.fastest == arrays.fastest == np.max(fused.speed)       # the time step's, from the pass

    ok = np.arange(n) != 7
    assert list(fused.finite) == list(ok) and np.isnan(fused.omega[7])
    C = materials.tangent(F[ok], index[ok])
    A = np.einsum("piajb,ka,kb->pkij", C, directions(d), directions(d))
    omega = np.linalg.eigvalsh(0.5 * (A + A.transpose(0, 1, 3, 2)))
    np.testing.assert_allclose(fused.J[ok], np.linalg.det(F[ok]), rtol=1e-14)
    np.testing.assert_allclose(fused.omega[ok], omega[..., 0].min(axis=1), rtol=1e-12, atol=1e-12 * np.abs(omega).max())
    speed = np.sqrt(np.maximum(omega[:, :d, -1].max(axis=1), 0.0) / materials.densities[index[ok]])
    np.testing.assert_allclose(fused.speed[ok], speed, rtol=1e-14)


@pytest.mark.parametrize("d", [1, 2, 3])
def test_the_stress_pass_assesses_f_and_p_as_the_stand_alone_check(d):
    """`MaterialSet.stress_update(..., assess=True)` (MPM: the health beside the stress, one pass)
    gives the stress and history of the pass without it, bit for bit, and the health arrays and
    summary of `health.assess` on the state [F, p], [P, v] with p, v finite; three laws, one with
    internal variables that flow, one point not finite."""
    from types import SimpleNamespace
    from skdgmpm import system
    from skdgmpm.constitutive import MaterialSet
    from skdgmpm.health import assess
    from skdgmpm.materials import J2Plasticity, NeoHookean, SaintVenantKirchhoff

    rng = np.random.default_rng(5)
    n = 60
    materials = MaterialSet((NeoHookean(E=200e9, nu=0.3, rho=7800.0), SaintVenantKirchhoff(E=70e9, nu=0.33, rho=2700.0),
                             J2Plasticity(E=200e9, nu=0.3, rho=7800.0, sigma_y=2e8, H=1e9)))
    index = rng.integers(0, 3, n)
    F = np.eye(d)[None] + 0.05 * rng.standard_normal((n, d, d))
    F[11, 0, 0] = np.inf
    history = materials.initial_history(index)
    P_alone, h_alone = materials.stress_update(F, index, history)
    P, h, fused = materials.stress_update(F, index, history, assess=True)
    np.testing.assert_array_equal(P, P_alone)
    np.testing.assert_array_equal(h, h_alone)
    assert h[index == 2, 0].max() > 0                                   # the J2 points flowed
    v = rng.standard_normal((n, d))
    U, Q = system.join(F, materials.densities[index][:, None] * v), system.join(P, v)
    alone = assess(materials, SimpleNamespace(material=index), U, Q)
    for name in ("finite", "J", "omega", "speed"):
        np.testing.assert_array_equal(getattr(fused, name), getattr(alone, name), err_msg=name)
    assert fused.summary == alone.summary and fused.summary[0] == 11


def test_the_chunks_summaries_combine_as_one_pass_over_the_points():
    """Two threads, eight chunks each (`parallel.PIECES`): the first bad point in the last chunk,
    the minima over all (`health.summarise`), as numpy's over the whole arrays."""
    from skdgmpm import parallel, system
    from skdgmpm.constitutive import MaterialSet
    from skdgmpm.health import Health
    from skdgmpm.materials import NeoHookean

    rng = np.random.default_rng(5)
    n, d = 3 * parallel.MIN_ROWS, 2
    materials = MaterialSet((NeoHookean(E=200e9, nu=0.3, rho=7800.0),))
    F = np.eye(d)[None] + 0.1 * rng.standard_normal((n, d, d))
    F[n - 5] = np.diag([-1.0, 1.0])          # J < 0: the first bad point, in the last chunk
    U = system.join(F, rng.standard_normal((n, d)))
    previous = parallel.set_threads(2)
    try:
        assert len(parallel.chunks(n)) == 2 * parallel.PIECES
        _, _, health, _ = materials.update_and_assess(U, np.zeros(n, int), np.full(n, 7800.0), None,
                                                      (np.zeros((n, d)), np.zeros((n, d)), 1.0))
    finally:
        parallel.set_threads(previous)
    arrays = Health(health.finite, health.J, health.omega, health.speed)
    assert health.summary[0] == int(np.flatnonzero(arrays.bad)[0]) >= n // 2
    assert health.record() == arrays.record()
    assert health.fastest == np.max(health.speed) and np.argmax(health.speed) < n // 2   # not in the last chunk



def test_the_summary_names_the_first_bad_point_of_the_first_chunk_that_has_one():
    """`health.summarise`: chunk-local first bad rows made global by the chunk's start, the first
    chunk's that has one; an eigenvalue that is nan in any chunk is nan over all (numpy's min);
    the minima left at infinity (no finite point) read nan."""
    from skdgmpm.health import summarise

    starts = np.array([0, 10, 20])
    results = np.array([(-1, 1.0, 2.0, 5e3), (3, 0.5, np.nan, 4e3), (1, 0.2, 1.0, 7e3)])
    first, J_min, omega_min, fastest = summarise(starts, results)
    assert (first, J_min, fastest) == (13, 0.2, 7e3) and np.isnan(omega_min)
    none_finite = np.array([(0, np.inf, np.inf, 0.0), (-1, np.inf, np.inf, 0.0)])
    first, J_min, omega_min, fastest = summarise(starts[:2], none_finite)
    assert first == 0 and np.isnan(J_min) and np.isnan(omega_min) and fastest == 0.0

def test_the_fastest_wave_combines_as_numpys_max():
    """`health.summarise`'s fastest wave: the largest over the chunks, nan where a chunk's is
    (numpy's max of the speeds, which the time step read before the passes tallied it)."""
    from skdgmpm.health import summarise

    starts = np.array([0, 4])
    assert summarise(starts, np.array([(-1, 1.0, 2.0, 5e3), (-1, 0.9, 3.0, 6e3)])) == (-1, 0.9, 2.0, 6e3)
    assert np.isnan(summarise(starts, np.array([(-1, 1.0, 2.0, np.nan), (-1, 0.9, 3.0, 6e3)]))[3])
    assert np.isnan(np.max([np.nan, 6e3]))


def test_a_stress_pass_health_is_the_states_only_where_momenta_and_velocities_are_finite():
    """`with_momenta`: the health that a stress pass computed of F and P stands for the state's
    where p and v (which that pass does not read) are finite, in a strided view of U too; else None,
    so that the whole check runs and names the bad point (the rule of MPM's step and of the initial
    state, scheme.py)."""
    from skdgmpm.health import with_momenta

    health = object()
    U, v = np.ones((7, 6)), np.ones((7, 2))
    assert with_momenta(health, U[:, 4:], v) is health
    assert with_momenta(None, U[:, 4:], v) is None
    for bad in (np.nan, np.inf, -np.inf):
        for where in ((6, 5), (0, 4)):
            W = U.copy()
            W[where] = bad
            assert with_momenta(health, W[:, 4:], v) is None
        w = v.copy()
        w[3, 1] = bad
        assert with_momenta(health, U[:, 4:], w) is None
    U[0, 0] = np.nan                        # F's column: not the momenta's
    assert with_momenta(health, U[:, 4:], v) is health
