"""Linear stability of the 2D DGMPM step (skdgmpm.stability2d) and the run's check against it."""

import json
import re
import warnings

import numpy as np
import pytest

from skdgmpm import stability as st1
from skdgmpm import stability2d as st
from skdgmpm.cli import main
from skdgmpm.build import build
from skdgmpm.errors import InputError
from skdgmpm.guards import check_cfl
from skdgmpm.run import run
from skdgmpm.scene import load_scene

ALONG_X = np.stack([np.linspace(-np.pi, np.pi, 64, endpoint=False), np.zeros(64)], axis=1)


def test_ctu_with_one_particle_a_cell_reaches_cfl_one():
    """R18 §4.4, §7.4: the transverse corrections lift the 2D CFL of one particle a cell to 1:
    the step at CFL 1 amplifies no mode (to rounding), at 1.02 one grows."""
    assert st.spectral_radius(st.step_blocks(1, "euler", "ctu", 1.0)) <= 1 + 1e-9
    assert st.spectral_radius(st.step_blocks(1, "euler", "ctu", 1.02)) > 1.01


@pytest.mark.parametrize("per_cell, integrator, transverse", [
    (1, "euler", "ctu"), (1, "euler", "dcu"), (2, "euler", "dcu"), (2, "rk2", "dcu"), (3, "euler", "dcu")])
def test_modes_along_x_have_the_limit_of_the_1d_analysis(per_cell, integrator, transverse):
    """Independent computation: a mode constant in y meets no jump across the horizontal faces, so
    the 2D DCU step acts on it as the 1D step of the same layout, whose limit `skdgmpm.stability`
    builds from R18's matrices for scalar advection (P and S waves each advect at their speed,
    the P wave sets the CFL). So does CTU's with one particle a cell: the corrections an x-face
    sends through a cell's bottom and top faces are equal, and one particle averages its nodes.
    (With several, the corrections give the cell a slope in y: CTU's plane modes have a lower
    limit than 1D's, 2 x 2 Euler 1.0005 at 0.69.) Stable at the 1D limit, unstable 0.02 above it."""
    layout = list((np.arange(per_cell) + 0.5) / per_cell)
    limit = st1.critical_cfl(layout, integrator, criterion="spectral")
    below = st.spectral_radius(st.step_blocks(per_cell, integrator, transverse, limit - 1e-3), theta=ALONG_X)
    above = st.spectral_radius(st.step_blocks(per_cell, integrator, transverse, limit + 0.02), theta=ALONG_X)
    assert below <= 1 + 1e-9 < 1 + 1e-4 < above


@pytest.mark.parametrize("key, nu", [("1 euler dcu", 0.3), ("1 rk2 ctu", 0.3), ("1 rk2 ctu", 0.0),
                                     ("2 rk2 dcu", 0.49)])
def test_the_table_the_run_reads_is_what_the_analysis_computes(key, nu):
    """stability_2d.json (python -m skdgmpm.stability2d) against the analysis run again."""
    table = json.loads(st.TABLE.read_text(encoding="utf-8"))
    stored = table["limits"][key][table["nu"].index(nu)]
    n, integrator, transverse = key.split()
    assert st.bracket(int(n), integrator, transverse, nu) == pytest.approx(stored, abs=1e-6)


def test_the_table_says_what_the_2d_analysis_found():
    """Euler with CTU and RK2 with DCU reach 1 with one particle a cell; DCU with Euler and CTU
    with RK2 do not: R18's 0.7 for DCU (§7.3, "by testing") lies above DCU's limit."""
    nus = [0.0, 0.3, 0.45]
    assert all(st.limit(1, "euler", "ctu", [nu])[1] > 1.0 for nu in nus)
    assert all(st.limit(1, "rk2", "dcu", [nu])[1] > 1.0 for nu in nus)
    assert all(st.limit(1, "euler", "dcu", [nu])[0] < 0.7 for nu in nus)
    assert all(st.limit(1, "rk2", "ctu", [nu])[0] < 0.76 for nu in nus)
    # between two ratios of the table, and over two materials: the lower limit
    assert st.limit(1, "rk2", "ctu", [0.32]) == min(st.limit(1, "rk2", "ctu", [0.3]), st.limit(1, "rk2", "ctu", [0.35]),
                                                   key=lambda pair: pair[1])
    assert st.limit(1, "euler", "dcu", [0.3, 0.45]) == st.limit(1, "euler", "dcu", [0.45])
    assert st.limit(1, "euler", "dcu", [0.495]) is None and st.limit(4, "euler", "dcu", [0.3]) is None


def _standing_wave_500_steps(keys, cfl, speed_factor, unstable):
    """The linear standing wave (symmetry on every side, nu = 0.3) run for 500 steps of CFL
    ``cfl`` (dt = cfl h / (speed_factor c_p)): stopped by the energy guard before step 480 where
    ``unstable``, else at its end."""
    c_p = np.sqrt(2e11 * 0.7 / (1.3 * 0.4) / 7800)
    t_end = float(500 * cfl * 0.1 / (speed_factor * c_p))
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        r = run("standing_wave_2d", [*keys, "method.cfl_above_limit=true", "run.frames=1", f"run.t_end={t_end!r}"],
                progress=False)
    if unstable:
        assert r.status == "unstable" and "energy created" in r.message and r.state.step < 480, r.message
    else:
        assert r.status == "ok" and r.state.step >= 499


@pytest.mark.parametrize("overrides, unstable", [
    (['method.transverse="dcu"', "method.cfl=0.64"], False),
    (['method.transverse="dcu"', "method.cfl=0.7"], True),
    (['method.transverse="ctu"', 'method.integrator="rk2"', "method.cfl=0.72"], False),
    (['method.transverse="ctu"', 'method.integrator="rk2"', "method.cfl=0.8"], True),
])
def test_a_run_above_the_2d_limit_blows_up_and_below_it_does_not(overrides, unstable):
    """The analysis predicts runs: the linear standing wave (symmetry on every side, one particle
    a cell, nu = 0.3) for 500 steps. Above the limit (DCU 0.651, RK2 with CTU 0.748) rounding
    seeds the growing checkerboard and the energy guard stops the run; below it the run ends."""
    cfl = float(overrides[-1].split("=")[1])
    _standing_wave_500_steps(["particles.per_cell=1", *overrides], cfl, 1, unstable)


@pytest.mark.parametrize("method, cfl, unstable", [
    ({"name": "ader-dgfem", "order": 1}, 0.6, False),
    ({"name": "ader-dgfem", "order": 1}, 0.7, True),
    ({"name": "rk-dgfem", "order": 1, "integrator": "rk2"}, 0.63, False),
    ({"name": "rk-dgfem", "order": 1, "integrator": "rk2"}, 0.7, True),
])
def test_the_dg_methods_limits_predict_their_runs(method, cfl, unstable):
    """The same analysis on ADER-DGFEM and RK-DGFEM P1 (their points: the Gauss points; limits
    0.620 and 0.651 at nu = 0.3, in their CFL: dt = CFL h / (3 c)), against the standing wave's
    runs of 500 steps as above."""
    limit = st.bracket(1, nu=0.3, method=method)[0]
    assert (cfl > limit) == unstable
    keys = [f'method.name="{method["name"]}"', "method.order=1", f"method.cfl={cfl}",
            *([f'method.integrator="{method["integrator"]}"'] if "integrator" in method else [])]
    _standing_wave_500_steps(keys, cfl, 3, unstable)


@pytest.mark.parametrize("key, nu", [("ader 1", 0.3), ("rk-dgfem 1 rk2", 0.45), ("ader 3", 0.3), ("ader 4", 0.3)])
def test_the_dg_rows_of_the_table_are_what_the_analysis_computes(key, nu):
    table = json.loads(st.TABLE.read_text(encoding="utf-8"))
    stored = table["dg"][key][table["nu"].index(nu)]
    assert st.bracket(1, nu=nu, method=st.DG_ROWS[key], growth=st.growth(key)) == pytest.approx(stored, abs=1e-6)


def test_ader_p4_has_a_knee_in_2d_too():
    """As in 1D: at nu = 0.3 the 2D step grows slowly just below the tabulated knee and fast just
    above it."""
    lo, hi = st.dg_limit("ader 4", [0.3])
    slow, fast = (st.spectral_radius(st.step_blocks(1, cfl=c, nu=0.3, method=st.DG_ROWS["ader 4"])) - 1
                  for c in (lo - 0.02, hi + 0.02))
    assert 1e-9 < slow < 1e-4 < 1e-2 < fast


@pytest.mark.parametrize("order, per_cell", [(1, [0.25, 0.75]), (2, [0.25, 0.5, 0.75])])
def test_ader_dgmpm_has_the_limits_of_ader_dgfem(order, per_cell):
    """With P + 1 particles a direction (L23's S1, S2) the reconstruction interpolates the
    particles and the step has ADER-DGFEM's nonzero eigenvalues: the run reads its limit from
    ADER-DGFEM's row."""
    pair = st.bracket(per_cell, nu=0.3, method={"name": "ader-dgmpm", "order": order})
    assert pair == pytest.approx(st.dg_limit(f"ader {order}", [0.3]), abs=1e-6)


def test_the_run_refuses_a_dg_cfl_above_the_2d_limit():
    with pytest.raises(InputError, match=r"method.cfl = 0.7 exceeds the 2D von Neumann limit 0.620 of ader-dgfem P1, "
                                         r"nu = 0.3 \(skdgmpm stability --dim 2 --method ader-dgfem --order 1\)"):
        run("standing_wave_2d", ['method.name="ader-dgfem"', "method.order=1", "method.cfl=0.7"], progress=False)
    with pytest.raises(InputError, match=r"exceeds the 2D von Neumann limit 0.651 of rk-dgfem P1 with rk2"):
        run("standing_wave_2d", ['method.name="rk-dgfem"', "method.order=1", 'method.integrator="rk2"',
                                 "method.cfl=0.66"], progress=False)
    # L23's S3T3 (ADER-DGMPM, 4 x 4 particles a cell at 1/5 .. 4/5) reads ADER-DGFEM P3's row
    with pytest.raises(InputError, match=r"method.cfl = 0.5 exceeds the 2D von Neumann limit 0.466 of ader-dgmpm P3"):
        run("standing_wave_2d", ['method.name="ader-dgmpm"', "method.order=3", "particles.per_cell=[0.2, 0.4, 0.6, 0.8]",
                                 "method.cfl=0.5"], progress=False)


@pytest.mark.parametrize("method, reference", [
    ({"name": "rk-dgfem", "order": 1, "integrator": "rk2"}, 3 * 0.333),
    ({"name": "rk-dgfem", "order": 1, "integrator": "rk4"}, 3 * 0.464),
    ({"name": "rk-dgfem", "order": 2, "integrator": "rk4"}, 5 * 0.235),
    ({"name": "rk-dgfem", "order": 3, "integrator": "rk4"}, 7 * 0.145),
])
def test_the_1d_reading_gives_cockburn_and_shus_limits(method, reference):
    """Independent reference: Cockburn & Shu (J. Sci. Comput. 16, 2001, Table 2.2), the L2 CFL
    limits of RK-DG with upwind fluxes for linear advection, to three digits: P1 with RK2 1/3,
    with RK4 0.464, P2 with RK4 0.235, P3 with RK4 0.145, in c dt / h; our CFL is (2P + 1) times
    that. The bar's two waves are two such advections."""
    lo, hi = st.bracket(1, nu=0.0, hi=2.0, method=method, dim=1)
    assert lo - 0.005 * (2 * method["order"] + 1) <= reference <= hi + 0.005 * (2 * method["order"] + 1)


@pytest.mark.parametrize("per_cell, integrator", [(2, "euler"), (3, "euler"), (2, "rk2")])
def test_the_1d_reading_of_dgmpm_gives_the_1d_analysis(per_cell, integrator):
    """The engine's 1D DGMPM step against `skdgmpm.stability` (R18's matrices, scalar advection):
    the bracket holds its spectral limit."""
    lo, hi = st.bracket(per_cell, integrator, "ctu", nu=0.0, hi=2.0, dim=1)
    limit = st1.critical_cfl(list((np.arange(per_cell) + 0.5) / per_cell), integrator, criterion="spectral")
    assert lo - 1e-3 <= limit <= hi + 1e-3


def _ader_dg_advection(p, cfl, theta):
    """Independent computation: the amplification matrix of ADER-DG for u_t + u_x = 0 on cells of
    width 1 (Dumbser's scheme as L23 §3-4 states it, written here from scratch): the nodal
    Lagrange basis of the P + 1 Gauss-Legendre points, the local predictor exact for linear
    advection (its time average sum_k (-dt D)^k / (k + 1)!, D the cell's derivative matrix: the
    Cauchy-Kovalevskaya series ends at k = P), the upwind flux, dt = CFL / (2P + 1)."""
    from math import factorial

    from numpy.polynomial import legendre, polynomial

    x, w = legendre.leggauss(p + 1)
    x, w = 0.5 * (x + 1), 0.5 * w
    coef = np.linalg.inv(np.vander(x, p + 1, increasing=True)).T
    phi = lambda t: np.array([polynomial.polyval(t, c) for c in coef])
    dphi = lambda t: np.array([polynomial.polyval(t, polynomial.polyder(c)) for c in coef])
    dt = cfl / (2 * p + 1)
    average = sum(np.linalg.matrix_power(-dt * dphi(x).T, k) / factorial(k + 1) for k in range(p + 1))
    right, left = phi(np.array([1.0]))[:, 0], phi(np.array([0.0]))[:, 0]
    residual = (dphi(x) * w - np.outer(right, right) + np.exp(-1j * theta) * np.outer(left, right)) @ average
    return np.eye(p + 1) + dt * residual / w[:, None]


@pytest.mark.parametrize("order", [1, 2, 3, 4, 5])
def test_the_1d_ader_step_has_the_amplification_of_an_independent_ader_dg(order):
    """The engine's 1D ADER-DGFEM step of order P (the elastic bar: two advections at +-c),
    read as a Bloch symbol, against `_ader_dg_advection`: the same spectral radius at CFL 0.3 and
    0.8, to rounding, for P = 1..5. P >= 4 grow at every CFL (1 + 1.1e-6 a step at 0.3 for P = 4,
    1 + 1.3e-5 for P = 5, also in 40-digit arithmetic): a property of the scheme, which the
    table therefore leaves out."""
    theta = np.linspace(-np.pi, np.pi, 256, endpoint=False)
    for cfl in (0.3, 0.8):
        ours = st.spectral_radius(st.step_blocks(1, cfl=cfl, nu=0.0, method={"name": "ader-dgfem", "order": order},
                                                 dim=1))
        reference = max(np.abs(np.linalg.eigvals(_ader_dg_advection(order, cfl, t))).max() for t in theta)
        assert ours == pytest.approx(reference, abs=1e-9)
    reference_03 = max(np.abs(np.linalg.eigvals(_ader_dg_advection(order, 0.3, t))).max() for t in theta)
    assert (reference_03 > 1 + 1e-9) == (order >= 4), reference_03


@pytest.mark.parametrize("overrides, warned", [
    (['method.name="ader-dgfem"', "method.order=4"], "ader-dgfem P4 grows at every CFL"),
    (['method.name="rk-dgfem"', "method.order=2", 'method.integrator="rk2"'], "rk-dgfem P2 with rk2 grows at every CFL"),
    (['method.name="rk-dgfem"', "method.order=2", 'method.integrator="rk4"'], None),
    (['method.name="ader-dgfem"', "method.order=3"], None),
])
def test_a_dg_step_that_grows_at_every_cfl_is_said_to(overrides, warned):
    """No CFL is stable for ADER with P >= 4 (above) nor for RK2 with P >= 2 (RK order below P + 1):
    such a run goes on, with a warning; RK4 at P2 and ADER at P3 have limits, and run at 0.3
    without one."""
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        run("bar_elastic_1d", [*overrides, "method.cfl=0.3", "grid.cells=8", "run.t_end=1e-4"], progress=False)
    said = [str(w.message) for w in caught if "grows at every CFL" in str(w.message)]
    assert (said[0].startswith(warned) and len(said) == 1) if warned else not said


def test_the_command_says_when_its_bracket_is_not_a_limit(capsys):
    """ADER P4 in 1D: the knee of the table (0.627), said to be one; RK2 P2, which has none: the
    bracket of growth 1e-9, said not to be a limit; ADER P3: a limit."""
    assert main(["stability", "--method", "ader-dgfem", "--order", "4"]) == 0
    out = capsys.readouterr().out
    assert "CFL limit 0.627" in out and "its knee: ader-dgfem P4 grows at every CFL" in out
    assert main(["stability", "--method", "rk-dgfem", "--order", "2", "--integrator", "rk2"]) == 0
    assert "not a limit: rk-dgfem P2 with rk2 grows at every CFL" in capsys.readouterr().out
    assert main(["stability", "--method", "ader-dgfem", "--order", "3"]) == 0
    out = capsys.readouterr().out
    assert "not a limit" not in out and "knee" not in out


def test_the_run_refuses_a_dg_cfl_above_the_1d_limit():
    """ADER-DGFEM P2 on the bar: 1D limit 0.854 (the table's dg_1d; Dumbser's ADER-DG O3 0.17 x 5)."""
    with pytest.raises(InputError, match=r"method.cfl = 0.9 exceeds the 1D von Neumann limit 0.854 of ader-dgfem P2"):
        run("bar_elastic_1d", ['method.name="ader-dgfem"', "method.order=2", "method.cfl=0.9"], progress=False)
    table = json.loads(st.TABLE.read_text(encoding="utf-8"))
    for key in ("ader 2", "ader 3", "ader 4", "rk-dgfem 3 rk4"):
        pair = st.bracket(1, nu=0.0, hi=2.0, method=st.DG_ROWS[key], dim=1, growth=st.SLOW_GROWTH.get(key, 1e-9))
        assert pair == pytest.approx(table["dg_1d"][key], abs=1e-6)
    # ADER P4's knee: slow growth just below it, fast just above (the engine's step, 1D)
    lo, hi = table["dg_1d"]["ader 4"]
    slow, fast = (st.spectral_radius(st.step_blocks(1, cfl=c, nu=0.0, method=st.DG_ROWS["ader 4"], dim=1)) - 1
                  for c in (lo - 0.03, hi + 0.03))
    assert 1e-9 < slow < 1e-5 and fast > 1e-2
    with pytest.raises(InputError, match=r"method.cfl = 0.75 exceeds the 1D von Neumann limit 0.727 of ader-dgfem P3"):
        run("bar_elastic_1d", ['method.name="ader-dgfem"', "method.order=3", "method.cfl=0.75"], progress=False)


def test_the_run_refuses_a_cfl_above_the_2d_limit():
    """The neo-Hookean plate under RK2 at its scene's CFL 1: the 1D limit (1) let it through and
    it inverted a cell at step 21; the 2D limit (0.748 at nu = 0.3) refuses it, naming both."""
    with pytest.raises(InputError, match=r"method.cfl = 1.0 exceeds the 2D von Neumann limit 0.748 of rk2 with ctu, "
                                         r"1 x 1 particles a cell, nu = 0.3"):
        run("plate_impact_neohookean_2d", ['method.integrator="rk2"'], progress=False)


def test_the_refusal_names_the_transverse_correction_that_runs_the_cfl():
    """A 2D scene at CFL 1 with the method's defaults (DGMPM, Euler, DCU) is refused; the
    message says that CTU's limit is 1 (and RK2's refusal at CFL 1 that DCU's is)."""
    with pytest.raises(InputError, match=r"limit 0.651 of euler with dcu, .*; with method.transverse = \"ctu\" "
                                         r"it is 1.0:"):
        run("standing_wave_2d", ["particles.per_cell=1", "method.cfl=1.0"], progress=False)
    with pytest.raises(InputError, match=r"limit 0.748 of rk2 with ctu, .*; with method.transverse = \"dcu\" it is"):
        run("plate_impact_neohookean_2d", ['method.integrator="rk2"'], progress=False)


def _without_cfl(name, overrides):
    scene = load_scene(name).with_overrides(overrides)
    del scene.data["method"]["cfl"]
    return scene


@pytest.mark.parametrize("name, overrides, cfl, why", [
    ("standing_wave_2d", ["particles.per_cell=1"], 0.58,
     r"0.9 of the 2D von Neumann limit 0.651 of euler with dcu, 1 x 1 particles a cell, nu = 0.3 .*"
     r"with method.transverse = \"ctu\" it is 1.0"),
    ("standing_wave_2d", ["particles.per_cell=1", 'method.transverse="ctu"'], 1.0, None),
    ("bar_elastic_1d", [], 1.0, None),
    ("bar_elastic_1d", ["particles.per_cell=2"], 0.61, r"0.9 of the von Neumann limit 0.69 of layout \[0.25, 0.75\]"),
    ("bar_elastic_1d", ['method.name="ader-dgfem"', "method.order=2"], 0.76,
     r"0.9 of the 1D von Neumann limit 0.854 of ader-dgfem P2"),
    ("bar_elastic_1d", ['method.name="ader-dgfem"', "method.order=3"], 0.65,
     r"0.9 of the 1D von Neumann limit 0.727 of ader-dgfem P3"),
    ("bar_elastic_1d", ['method.name="ader-dgfem"', "method.order=4"], 0.56,
     r"0.9 of the 1D von Neumann limit 0.627 of ader-dgfem P4 \(below it a step grows by at most 0.0001"),
    ("bar_elastic_1d", ['method.name="mpm"'], 1.0, None),
    ("standing_wave_2d", ['method.name="rk-dgfem"', "method.order=3", 'method.integrator="rk4"'], 0.59,
     r"0.9 of the 2D von Neumann limit 0.656 of rk-dgfem P3 with rk4, nu = 0.3"),
    ("standing_wave_2d", ['method.name="ader-dgfem"', "method.order=4"], 0.36,
     r"0.9 of the 2D von Neumann limit 0.402 of ader-dgfem P4 \(below it a step grows by at most 0.0001, "
     r"beyond it by far more\), nu = 0.3"),
], ids=["2d-dcu", "2d-ctu", "1d-one-particle", "1d-two-particles", "1d-ader-p2", "1d-ader-p3", "1d-ader-p4", "mpm",
        "2d-rk-p3", "2d-ader-p4"])
def test_a_scene_without_a_cfl_takes_one_below_the_methods_limit(name, overrides, cfl, why):
    """Unset, method.cfl is 1 where the method's known limit admits it (CFL 1 exactness of one
    particle a cell in 1D, CTU in 2D), else 0.9 of that limit, rounded down to 0.01: 0.9 x 0.651,
    0.9 x 0.6861 (R18's two particles a cell, `skdgmpm.stability`), 0.9 x 0.854. The check then
    passes it, and the discretisation says why."""
    disc = build(_without_cfl(name, [*overrides, "grid.cells=8" if name == "bar_elastic_1d" else "grid.cells=[4, 4]"]))
    assert disc.stepper.cfl == cfl
    if why is None:
        assert disc.cfl_default is None
    else:
        assert re.match(why, disc.cfl_default) and disc.stepper.cfl < check_cfl(disc)


def test_a_run_without_a_cfl_says_which_it_took(capsys):
    """The 2D scene with the method's defaults runs (it was refused at CFL 1), says the CFL it took
    and why on stderr, and its summary holds both."""
    r = run(_without_cfl("standing_wave_2d", ["particles.per_cell=1", "grid.cells=[4, 4]", "run.t_end=2e-5"]))
    err = capsys.readouterr().err
    assert r.status == "ok" and r.stepper.cfl == 0.58
    assert "note: method.cfl not set: 0.58, 0.9 of the 2D von Neumann limit 0.651" in err
    summary = r.summary()
    assert summary["cfl"] == 0.58 and summary["cfl_default"].startswith("0.9 of the 2D von Neumann limit 0.651")


def test_a_layout_the_table_lacks_falls_back_to_the_1d_limit():
    """Shifted particles (not at (k + 1/2) / n): the 1D limit of the layout, per direction."""
    with pytest.raises(InputError, match=r"exceeds the von Neumann limit .* of layout \[0.3, 0.7\]"):
        run("standing_wave_2d", ["particles.per_cell=[0.3, 0.7]", "method.cfl=0.9"], progress=False)


def test_the_command_prints_the_2d_limits(capsys):
    assert main(["stability", "--dim", "2", "--per-cell", "1", "--nu", "0.3", "--json"]) == 0
    out = capsys.readouterr().out
    limits = json.loads(out.strip().splitlines()[-1])["limits"]
    assert limits["euler"]["ctu"] > 0.998 and limits["rk2"]["dcu"] > 0.998
    assert limits["euler"]["dcu"] == pytest.approx(0.651, abs=3e-3)
    assert limits["rk2"]["ctu"] == pytest.approx(0.748, abs=3e-3)
    assert main(["stability", "--dim", "2", "--method", "ader-dgfem", "--json"]) == 0
    out = capsys.readouterr().out
    assert json.loads(out.strip().splitlines()[-1])["limits"]["cfl"] == pytest.approx(0.620, abs=3e-3)
    assert main(["stability", "--method", "rk-dgfem", "--integrator", "rk4", "--json"]) == 0    # 1D
    out = capsys.readouterr().out
    assert json.loads(out.strip().splitlines()[-1])["limits"]["cfl"] == pytest.approx(1.392, abs=3e-3)
    assert main(["stability"]) == 2
    assert "error: skdgmpm stability: --layout is required in 1D" in capsys.readouterr().err


def test_the_table_command_recomputes_the_rows_asked_and_keeps_the_others(tmp_path, capsys):
    """`python -m skdgmpm.stability2d --only dg_1d --rows "ader 2"` into a copy of the table: that
    row computed again (the same bracket), every other entry as it was; a row the table has no
    part for is refused in one line."""
    out = tmp_path / "table.json"
    out.write_text(st.TABLE.read_text(encoding="utf-8"), encoding="utf-8")
    before = json.loads(out.read_text(encoding="utf-8"))
    before["dg_1d"]["ader 2"] = [0.0, 0.0]
    out.write_text(json.dumps(before), encoding="utf-8")
    assert st.main(["--out", str(out), "--only", "dg_1d", "--rows", "ader 2"]) == 0
    after = json.loads(out.read_text(encoding="utf-8"))
    stored = json.loads(st.TABLE.read_text(encoding="utf-8"))
    assert after["dg_1d"]["ader 2"] == pytest.approx(stored["dg_1d"]["ader 2"], abs=1e-6)
    assert {k: v for k, v in after.items() if k != "dg_1d"} == {k: v for k, v in before.items() if k != "dg_1d"}
    assert {k: v for k, v in after["dg_1d"].items() if k != "ader 2"} == \
           {k: v for k, v in before["dg_1d"].items() if k != "ader 2"}
    with pytest.raises(SystemExit):
        st.main(["--out", str(out), "--only", "dgmpm", "--rows", "ader 2"])
    assert "--rows ader 2: rows of --only dg or dg_1d" in capsys.readouterr().err
