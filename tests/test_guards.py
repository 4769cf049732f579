"""Health that catches garbage (issue 17, skdgmpm.guards): a CFL above a known stability limit is
refused unless the scene says so; energy created beyond all the energy put in stops the run
(exit 3); a collapsing time step stops it (exit 3); a run that could never end is refused."""
import json

import numpy as np
import pytest

import skdgmpm.run as run_module
from skdgmpm import guards
from skdgmpm.cli import EXIT_INPUT, EXIT_UNSTABLE, main
from skdgmpm.errors import InputError
from skdgmpm.run import run

BAR = ["grid.cells=50", "particles.per_cell=2", 'method.integrator="euler"']


def cli(capsys, *argv):
    rc = main([str(a) for a in argv])
    captured = capsys.readouterr()
    return rc, captured.out, captured.err


def sets(overrides):
    return [a for o in overrides for a in ("--set", o)]


def test_cfl_above_the_von_neumann_limit_is_refused(capsys, tmp_path):
    rc, _, err = cli(capsys, "run", "bar_elastic_1d", "--out", tmp_path / "o", "--quiet",
                     *sets(BAR + ["method.cfl=1.2"]))
    assert rc == EXIT_INPUT and err.count("\n") == 1
    assert "method.cfl = 1.2 exceeds the von Neumann limit 0.69" in err and "method.cfl_above_limit = true" in err
    assert not (tmp_path / "o").exists()


def test_mpm_cfl_above_1_is_refused():
    with pytest.raises(InputError, match="MPM limit 1"):
        run("bar_elastic_1d", ['method.name="mpm"', "method.cfl=1.5", "grid.cells=20", "exact={}"], progress=False)


@pytest.mark.filterwarnings("ignore:.*von Neumann")
def test_the_garbage_run_of_the_issue_stops_on_the_energy_it_creates(capsys, tmp_path):
    """Euler at CFL 1.2 with 2 particles per cell (above 0.69), let through with the key: it used
    to end 'ok' with a balance of +9.4e9 J against 3.8e7 J of work; now exit 3, energy named, and
    the last good state kept has created no more than the energy put in."""
    out = tmp_path / "o"
    rc, _, err = cli(capsys, "run", "bar_elastic_1d", "--out", out, "--quiet",
                     *sets(BAR + ["method.cfl=1.2", "method.cfl_above_limit=true"]))
    assert rc == EXIT_UNSTABLE, err
    assert "error: energy created at step " in err and f"last good state kept in {out}" in err
    summary = json.loads((out / "summary.json").read_text())
    assert summary["status"] == "unstable" and summary["t_final"] < summary["t_end"]
    e = summary["energy"]
    assert 0 < e["external_work"] and e["balance_change"] <= guards.MARGIN * e["external_work"] + 10.0


def test_stable_runs_are_not_stopped():
    for overrides in (BAR + ["method.cfl=0.5"], ["grid.cells=30"],
                      ['method.name="mpm"', "grid.cells=30", "particles.per_cell=2", "method.cfl=0.5", "exact={}"]):
        r = run("bar_elastic_1d", overrides, progress=False)
        assert r.status == "ok", (overrides, r.message)
        assert r.history["balance"][-1] - r.history["balance"][0] < 0.1 * np.max(np.abs(r.history["external_work"]))


def test_a_run_that_could_never_end_is_refused(capsys, tmp_path):
    for override, what in (("material.E=1e300", "material.E"), ("material.rho=1e-300", "material.rho")):
        rc, _, err = cli(capsys, "run", "bar_elastic_1d", "--out", tmp_path / "o", "--quiet",
                         *sets(["grid.cells=20", override]))
        assert rc == EXIT_INPUT and err.count("\n") == 1, err
        assert "run.t_end" in err and "run.step_limit = 10000000" in err and what in err
    rc, _, err = cli(capsys, "run", "bar_elastic_1d", "--quiet", "--out", tmp_path / "o",
                     *sets(["grid.cells=20", "run.step_limit=10"]))
    assert rc == EXIT_INPUT and "run.step_limit = 10" in err
    assert not (tmp_path / "o").exists()


def _shrinking_steps(monkeypatch, factor_at):
    """Make the stepper's Delta t shrink from a step on: ``factor_at(step)`` scales dt_max."""
    real_build = run_module.build

    def build(scene):
        disc = real_build(scene)
        step = disc.stepper.step

        def shrunk(state, dt_max=np.inf):
            dt = disc.stepper.time_step(state)
            return step(state, min(dt_max, dt * factor_at(state.step)))

        disc.stepper.step = shrunk
        return disc

    monkeypatch.setattr(run_module, "build", build)


def test_a_collapsing_time_step_stops_the_run(monkeypatch, tmp_path):
    _shrinking_steps(monkeypatch, lambda step: 1.0 if step < 5 else 1e-4)
    r = run("bar_elastic_1d", ["grid.cells=20"], out=tmp_path / "o", progress=False)
    assert r.status == "unstable" and r.state.step == 5
    assert r.message.startswith("time step collapsed at step 6,") and "below 0.001 of the first step's" in r.message


def test_the_step_limit_stops_the_run(monkeypatch):
    _shrinking_steps(monkeypatch, lambda step: 0.25)
    r = run("bar_elastic_1d", ["grid.cells=20", "run.step_limit=60"], progress=False)
    assert r.status == "unstable" and r.state.step == 59 and "step limit reached at step 60" in r.message


def test_energy_rows_on_the_steps_the_scene_fixes():
    """run.energy_every = 5: the energy history (energy.csv) has the initial state, every 5th step,
    the frames' steps and the last one; the default on a small scene is every step."""
    r = run("bar_elastic_1d", ["run.energy_every=5", "run.frames=3"], progress=False)
    steps = list(r.history["step"])
    frames = [f.step for f in r.frames]
    assert steps[0] == 0 and steps[-1] == r.state.step
    assert set(steps) == {0, r.state.step} | {k for k in range(1, r.state.step + 1) if k % 5 == 0} | set(frames)
    small = run("bar_elastic_1d", ["run.t_end=1e-5"], progress=False)
    assert list(small.history["step"]) == list(range(small.state.step + 1))
    with pytest.raises(InputError, match="run.energy_every"):
        run("bar_elastic_1d", ["run.energy_every=0"], progress=False)
