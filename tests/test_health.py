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
