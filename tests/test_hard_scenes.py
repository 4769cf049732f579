"""The hard scenes (L23 §5.2-5.3 from gmsh mesh files, R18 §7.4 with the high-order methods) at
coarse resolution to a fixed time, against stored numbers; the stability study (bisection on the
CFL) and the comparison figures end to end.

Stored numbers are this code's own results (regression values, to 1 % of each field's range: see
the test), recorded with the physical checks next to them: compression behind the front of the order of the load, particles
following the imposed velocity, J < 1 under compression, and the run health record.
"""
import csv

import numpy as np
import pytest

from skdgmpm.cli import main
from skdgmpm.run import run
from skdgmpm.stability_study import critical_cfl, trial

PLATE = ["grid.cells=[8,6]", "run.t_end=2e-4", "method.cfl=0.35", 'method.limiter="barth-jespersen"']
CASES = {   # name: (scene, overrides, stored (steps, min sigma11, max sigma11, min v1, max v1, min J, total energy))
    # LASAT-like, 12 x 12 structured quads, ADER-DGMPM S1T1 + Barth-Jespersen (the scene's method)
    "lasat_2d": ("lasat_2d", ['grid.mesh="lasat_12.msh"', "run.t_end=1e-4"],
                 (21, -5695463186.860507, 581737.3041298223, -0.132599986095332, 124.14523038366121,
                  0.9790199130536639, 43582771.59351933)),
    # multi-holed cell, 233 unstructured quads of about 2 mm, ADER-DGMPM S1T1, CFL 0.2, with
    # Barth-Jespersen (the scene's method until the limited runs were found to stop at ~9e-6 s)
    "multiholed_cell_2d": ("multiholed_cell_2d", ['grid.mesh="multiholed_cell_2mm.msh"', "run.t_end=5e-8",
                                                  'method.limiter="barth-jespersen"'],
                           (13, -5015727380.283518, 9705.790073971064, -106.81240241346669, 0.00019501329179061764,
                            0.9816755171641134, 969.4272542745196)),
    # the same as the scene ships it: no limiter (the unlimited front overshoots at 13 steps)
    "multiholed_cell_2d unlimited": ("multiholed_cell_2d", ['grid.mesh="multiholed_cell_2mm.msh"', "run.t_end=5e-8"],
                                     (13, -7811824658.352254, 1228814609.2234044, -166.48330606493485,
                                      26.324937804812205, 0.9716982391494103, 2240.708712280867)),
    # R18 §7.4 plate, 8 x 6 cells, with ADER-DGMPM and the two DGFEM baselines (S1T1)
    "plate ader-dgmpm": ("plate_impact_neohookean_2d", [*PLATE, 'method.name="ader-dgmpm"', "method.order=1",
                                                        "particles.per_cell=[0.25, 0.75]"],
                         (24, -52814654661.75875, 4120785.387205611, -1.69873833842389, 1064.8005996997929,
                          0.8383579863064898, 7639692736.085257)),
    "plate ader-dgfem": ("plate_impact_neohookean_2d", [*PLATE, 'method.name="ader-dgfem"', "method.order=1"],
                         (24, -53278193083.294556, 4193901.3962595016, -2.295491609902975, 1071.6386640160458,
                          0.8343629582958902, 7672573238.609201)),
    "plate rk-dgfem": ("plate_impact_neohookean_2d", [*PLATE, 'method.name="rk-dgfem"', 'method.integrator="rk2"',
                                                      "method.order=1"],
                       (24, -53528594779.65279, 12728758.488952592, -1.640860356677528, 1008.6631778617001,
                        0.8301184320135602, 7621785649.162655)),
}


@pytest.mark.parametrize("case", sorted(CASES))
def test_hard_scene_at_coarse_resolution(case):
    scene, overrides, stored = CASES[case]
    r = run(scene, overrides, progress=False, frames=1)
    assert r.status == "ok", r.message
    f, h = r.fields(), r.history
    got = (r.state.step, f["sigma11"].min(), f["sigma11"].max(), f["v1"].min(), f["v1"].max(), h["min_J"].min(),
           h["total"][-1])
    print(case, got)
    # The limiter's troubled-cell test is a discontinuous function of the data: a pure round-off
    # change (einsum -> matmul in ADER) flips a few decisions and moves these coarse limited runs
    # by up to 1 % of a value (4 % of the small tension peak of LASAT), under 0.1 % of its field's range.
    # Each value is therefore checked to 1 % of its field's range (sigma11, v1), J to 1e-3 and the
    # energy to 1 %; the same code reproduces them to 1e-9.
    assert abs(got[0] - stored[0]) <= 1
    sigma, v = max(abs(stored[1]), abs(stored[2])), max(abs(stored[3]), abs(stored[4]))
    assert np.allclose(got[1:3], stored[1:3], rtol=0, atol=0.01 * sigma)
    assert np.allclose(got[3:5], stored[3:5], rtol=0, atol=0.01 * v)
    assert abs(got[5] - stored[5]) < 1e-3 and abs(got[6] / stored[6] - 1) < 0.01
    # physics next to the numbers: compressed (J < 1), admissible all along, no energy created: every
    # step dissipates (measured: the largest change of the balance in one step is -1.3e-3 to
    # -3.9e-3 of the work; before the limiter scaled the reconstruction's own excursion, limited
    # runs gained energy and overshot into tension: sigma11 up to +2.4e9 Pa here, now <= 1.3e7)
    assert h["min_J"].min() < 1 and np.all(h["min_acoustic"] > 0)
    assert np.all(np.diff(h["balance"]) <= 1e-9 * max(np.abs(h["external_work"]).max(), 1.0))
    if case == "lasat_2d":
        lasat_front_carries_the_pressure(r.X, f, r.scene.get("bc.impact.value")[0])


def lasat_front_carries_the_pressure(X, f, p):
    """At t = 1e-4 s the compression front is at c_P t = 0.59 m (2.4 cells of this 12 x 12 mesh):
    behind it, near the loaded face and the bottom line, P11 is the applied -p = -5e9 Pa within
    -15 % / +20 % (measured: 0.90 to 1.14 of it; ADER-DGMPM S1T1 with Barth-Jespersen overshoots
    next to the loaded face at this resolution); ahead of it the plate is at rest: the DG
    precursor decays by about 3 per cell, below 1e-3 of the load beyond X1 = 2 m (measured 2e-6)."""
    near = (X[:, 0] < 0.35) & (X[:, 1] < 0.5)
    ratio = f["P11"][near] / -p
    assert ratio.min() > 0.85 and ratio.max() < 1.2
    ahead = X[:, 0] > 2.0
    assert np.abs(f["P11"][ahead]).max() < 1e-3 * p and np.abs(f["v1"][ahead]).max() < 0.5


def test_stability_bisection_finds_the_upwind_limit():
    """First-order DGMPM with one particle per cell is the upwind scheme: stable up to CFL 1
    [R18 eq 65]. The bisection (0 < CFL <= 1.6, tol 0.05, 20 cells, to 1.2e-3 s) brackets it:
    largest passing 1.025 (the growth above 1 is slow over 20 steps), smallest failing 1.05."""
    passing, failing, trials = critical_cfl("bar_elastic_1d", ["grid.cells=20", "run.t_end=1.2e-3", "exact={}"],
                                            hi=1.6, tol=0.05)
    assert 0.95 <= passing < failing <= 1.1 and failing - passing <= 0.05
    assert {t.cfl for t in trials if not t.passed} >= {1.6, failing}


def test_trial_that_outruns_its_step_budget_fails():
    """A trial that has not reached t_end within its step budget fails and says so (in a study the
    budget is 10 x the baseline's steps: a collapsing time step would otherwise grind for hours);
    within the budget the same run passes."""
    scene = ["grid.cells=20", "run.t_end=1.2e-3", "exact={}"]
    full = trial("bar_elastic_1d", scene, 0.5)
    assert full.passed and full.steps > 6
    cut = trial("bar_elastic_1d", scene, 0.5, max_steps=full.steps // 2)
    assert not cut.passed and cut.steps == full.steps // 2
    assert cut.reason.startswith(f"time step collapsed: {full.steps // 2} steps without reaching t_end")
    assert trial("bar_elastic_1d", scene, 0.5, max_steps=full.steps).passed


def test_cfl_limit_and_compare_figures_commands(tmp_path, capsys):
    """Both study commands end to end on tiny runs."""
    out = tmp_path / "cfl"
    assert main(["cfl-limit", "bar_elastic_1d", "--methods", "dgmpm,rk-dgfem/rk2 S1", "--limiters", "none",
                 "--set", "grid.cells=10", "--set", "run.t_end=2e-4", "--set", "exact={}", "--tol", "0.4",
                 "--workers", "1", "--out", str(out), "--quiet"]) == 0
    table = (out / "cfl_limit.md").read_text()
    assert "| bar_elastic_1d | dgmpm | none |" in table and "rk-dgfem/rk2 S1" in table
    with open(out / "trials.csv") as fh:
        assert len(list(csv.DictReader(fh))) >= 4
    out = tmp_path / "figures"
    # the plate's CFL 1 is DGMPM's; S1's 2D limits are 0.620 (ADER) and 0.651 (RK2): the run refuses 1
    assert main(["compare-figures", "plate_impact_neohookean_2d", "--groups", "S1,dgmpm", "--set",
                 "grid.cells=[6,4]", "--set", "figures.times=[2e-5]", "--set", "method.cfl=0.5", "--workers", "1",
                 "--out", str(out), "--quiet"]) == 0
    names = {p.name for p in out.iterdir()}
    assert {"line_sigma11.png", "line_v1.png", "lines.csv", "runs.csv", "map_sigma11_t2e-05.png"} <= names
    with open(out / "runs.csv") as fh:
        runs = list(csv.DictReader(fh))
    assert len(runs) == 4 and all(row["status"] == "ok" for row in runs)
    assert "spread" in capsys.readouterr().out


@pytest.mark.slow
def test_multiholed_cell_runs_to_its_end_time():
    """The multi-holed cell as shipped (no limiter) on the 2 mm mesh reaches t_end = 1.2e-5 s
    (after the reflection on the left face) admissible and without creating energy: the balance
    (total - boundary work) never rises above 1e-4 of the work done. With Barth-Jespersen the same
    run stops with J <= 0 near 9e-6 s (README stability table), so this fails if the scene's
    method or the scheme regresses."""
    r = run("multiholed_cell_2d", ['grid.mesh="multiholed_cell_2mm.msh"'], progress=False, frames=1)
    assert r.status == "ok", r.message
    h = r.history
    assert r.state.t == pytest.approx(1.2e-5, rel=1e-12)
    assert h["min_J"].min() > 0.85 and np.all(h["min_acoustic"] > 0)      # measured 0.880
    assert h["balance"].max() <= 1e-4 * h["external_work"].max()


@pytest.mark.slow
def test_scaled_invariant_limiter_takes_the_multiholed_cell_to_its_end_time():
    """With the scaled frame-invariant limiter ADER-DGMPM reaches t_end on the 2 mm mesh and the
    balance never rises (the limiter only removes energy); with eq 41's reconstruction the same run
    stops with J <= 0 at 1.17e-5 s (frame-invariant) or 9.5e-6 s (componentwise), README stability
    table. Measured: min J 0.853, balance -75 % of the work at t_end (unlimited: 0.880, -67 %)."""
    r = run("multiholed_cell_2d", ['grid.mesh="multiholed_cell_2mm.msh"',
                                   'method.limiter="barth-jespersen-invariant-scaled"'], progress=False, frames=1)
    assert r.status == "ok", r.message
    h = r.history
    assert r.state.t == pytest.approx(1.2e-5, rel=1e-12)
    assert h["min_J"].min() > 0.8 and np.all(h["min_acoustic"] > 0)
    assert h["balance"].max() <= 1e-4 * h["external_work"].max()
    assert r.disc.stepper.limited_cells > 0
