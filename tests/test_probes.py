"""Outputs a user chooses (issue 17): ``[probes]``, the time histories of fields at named points
(probes.csv, probes.png, ``Result.probes``), and ``run.fields``, the particle arrays of the frames."""
import csv
import json

import meshio
import numpy as np
import pytest

from skdgmpm.cli import EXIT_INPUT, main
from skdgmpm.output import FRAME_FIELDS
from skdgmpm.run import resume, run

from test_checkpoint import kill_at, same_outputs

GAUGES = ["probes.points={rear = [5.9], mid = [3.0], load = [0.02]}", 'probes.fields=["v1", "P11"]']


def test_probes_follow_the_exact_solution_at_cfl_1():
    """bar_elastic_1d at CFL 1 (DGMPM, 1 ppc) is exact to round-off at every step: so is the history
    at each probe, read at the particle nearest to its point (measured: v1 within 8.3e-11 m/s of
    25.3, P11 within 3.2e-3 Pa of 2e9, over the 191 rows)."""
    r = run("bar_elastic_1d", GAUGES, progress=False)
    pr = r.probes
    assert pr.names == ("rear", "mid", "load") and pr.fields == ("v1", "P11")
    assert len(pr.t) == r.state.step + 1 == 191 and pr.t[0] == 0 and pr.t[-1] == r.state.t
    np.testing.assert_allclose(pr.X[:, 0], [5.9, 2.98, 0.02])      # 3.0 lies between two: the first
    for name, X in zip(pr.names, pr.X):
        exact = [r.exact.fields(X[None], t) for t in pr.t]
        v = np.array([e["v1"][0] for e in exact])
        P = np.array([e["P11"][0] for e in exact])
        assert np.abs(v).max() > 25 and np.abs(pr[name, "v1"] - v).max() < 1e-9
        assert np.abs(P).max() >= 1e9 and np.abs(pr[name, "P11"] - P).max() < 1e-2
    rear = pr["rear", "P11"]
    assert rear[-1] == pytest.approx(-2e9, rel=1e-9)                 # the wave doubled at the fixed end


def test_probes_csv_and_png(tmp_path):
    out = tmp_path / "out"
    r = run("bar_elastic_1d", GAUGES + ["probes.every=20", "grid.cells=30", "run.t_end=4e-4"], out=out,
            progress=False)
    with open(out / "probes.csv") as fh:
        rows = list(csv.reader(fh))
    assert rows[0] == ["t", "v1@rear", "P11@rear", "v1@mid", "P11@mid", "v1@load", "P11@load"]
    steps = r.state.step
    assert len(rows) - 1 == len(range(0, steps + 1, 20)) + (steps % 20 != 0)   # step 0, every 20th, the last
    table = np.array(rows[1:], dtype=float)
    np.testing.assert_allclose(table, r.probes.table(), rtol=1e-11, atol=1e-300)
    assert (out / "probes.png").stat().st_size > 1000


def test_probes_in_every_method_read_their_points():
    """MPM reads its particles, RK-DGFEM its Gauss points (they stand for the particles), 2D too."""
    for overrides in (['method.name="mpm"', "method.cfl=0.5"],
                      ['method.name="rk-dgfem"', 'method.integrator="rk2"', "method.order=1", "method.cfl=0.3"]):
        r = run("bar_elastic_1d", GAUGES + overrides, progress=False, max_steps=30)
        X = r.X[r.probes.particles]
        assert np.array_equal(X, r.probes.X) and np.all(np.abs(X[:, 0] - [5.9, 3.0, 0.02]) <= 0.04)
        assert r.probes["load", "P11"][-1] == pytest.approx(r.fields()["P11"][r.probes.particles[2]])
    r = run("plate_impact_neohookean_2d", ["grid.cells=[8, 6]", "probes.points={a = [0.1, 0.1], b = [3.9, 2.9]}",
                                           'probes.fields=["v1", "sigma11"]'], progress=False, max_steps=4)
    assert r.probes.table().shape == (5, 5) and r.probes["a", "v1"][-1] > 900      # driven at 1000 m/s


@pytest.mark.parametrize("override, words", [
    ("probes.points={rear = [7.0]}", ["probes.points.rear", "[7.0]", "outside the body", "[0, 6]"]),
    ("probes.points={rear = [-0.5]}", ["probes.points.rear", "outside the body"]),
    ("probes.points={rear = [1.0, 2.0]}", ["probes.points.rear", "1 finite coordinate"]),
    ('probes.points={rear = ["x"]}', ["probes.points.rear", "'x'"]),
    ("probes.points={rear = [nan]}", ["probes.points.rear", "nan"]),
    ("probes.points={}", ["probes.points", "at least one point"]),
    ("probes.points=[1.0]", ["probes.points", "wrong type"]),
    ('probes.fields=["v9"]', ["probes.fields", "'v9'", "valid: ", "P11"]),
    ("probes.fields=[]", ["probes.fields", "no field"]),
    ("probes.every=0", ["probes.every", "0", ">= 1"]),
    ("probes.every=1.5", ["probes.every", "wrong type"]),
    ("probes.where=1", ["probes.where", "not a known key"]),
    ('run.fields=["stress"]', ["run.fields", "'stress'", "valid: F, P, cauchy, velocity"]),
    ('run.fields="P"', ["run.fields", "wrong type"]),
    ("run.fields=[1]", ["run.fields", "1 is not a particle field"]),
])
def test_bad_probes_and_fields_are_one_line_errors(capsys, tmp_path, override, words):
    base = ["probes.points={rear = [5.9]}"] if not override.startswith("probes.points") else []
    out = tmp_path / "o"
    argv = ["run", "bar_elastic_1d", "--out", out, "--quiet", "--set", "grid.cells=20"]
    for o in base + [override]:
        argv += ["--set", o]
    assert main([str(a) for a in argv]) == EXIT_INPUT
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and err.startswith("error: --set") and "Traceback" not in err, err
    for w in words:
        assert w in err, (w, err)
    assert not out.exists()


def test_a_point_outside_the_body_in_2d(capsys, tmp_path):
    """partial_impact_2d's plate is 4 x 3 m: (4.5, 1) is off it; so is a point in an inactive cell."""
    rc = main(["run", "plate_impact_neohookean_2d", "--out", str(tmp_path / "o"), "--set", "grid.cells=[8, 6]",
               "--set", "probes.points={gauge = [4.5, 1.0]}"])
    err = capsys.readouterr().err
    assert rc == EXIT_INPUT and "probes.points.gauge = [4.5, 1.0] is outside the body" in err and err.count("\n") == 1
    rc = main(["run", "mms_ring_2d", "--out", str(tmp_path / "o"), "--set", "probes.points={hole = [0.0, 0.0]}"])
    err = capsys.readouterr().err
    assert rc == EXIT_INPUT and "outside the body" in err, err


def test_run_fields_chooses_the_arrays_of_the_frames(tmp_path):
    run("bar_elastoplastic_1d", ["grid.cells=20", "run.t_end=1e-4", "run.frames=2"], out=tmp_path / "all",
        progress=False)
    assert list(meshio.read(tmp_path / "all" / "particles_0002.vtu").point_data) == [*FRAME_FIELDS, "eqp", "ep11",
                                                                                    "ep22", "ep33", "ep12",
                                                                                    "ep13", "ep23"]
    run("bar_elastoplastic_1d", ["grid.cells=20", "run.t_end=1e-4", "run.frames=2",
                                 'run.fields=["velocity", "eqp", "velocity"]'], out=tmp_path / "some", progress=False)
    mesh = meshio.read(tmp_path / "some" / "particles_0002.vtu")
    assert list(mesh.point_data) == ["velocity", "eqp"] and len(mesh.points) == 20
    assert (tmp_path / "some" / "particles.pvd").is_file()


def test_probes_and_run_fields_resume_bit_identical(tmp_path):
    """Stopped by SIGTERM mid-run with probes every 3 steps and frames holding two fields: the resumed
    run's probes.csv, frames and energy are those of the uninterrupted run, byte for byte; the
    frames read back for Result.frames hold NaN where run.fields left a field out."""
    overrides = GAUGES + ["probes.every=3", "grid.cells=30", "run.t_end=4e-4", "run.frames=6",
                          'run.fields=["P", "velocity"]', "particles.per_cell=2", "method.cfl=0.5"]
    whole = run("bar_elastic_1d", overrides, out=tmp_path / "whole", progress=False)
    cut = run("bar_elastic_1d", overrides, out=tmp_path / "cut", progress=False, on_step=kill_at(11))
    assert cut.status == "interrupted" and cut.probes.t[-1] <= cut.state.t
    again = resume(tmp_path / "cut", progress=False)
    same_outputs(tmp_path / "whole", tmp_path / "cut")
    assert np.array_equal(again.probes.table(), whole.probes.table())
    early = again.frames[1]
    assert np.isnan(early.U).all() and np.array_equal(early.Q, whole.frames[1].Q)
    assert json.loads((tmp_path / "cut" / "summary.json").read_text())["status"] == "ok"
