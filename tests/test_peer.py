"""The peer code in the bench (Clawpack/PyClaw, `skdgmpm.peer`): it runs when installed, says so when
not (timings are never asserted beyond being finite and positive)."""
import json
import math
import sys

import pytest

from skdgmpm import bench, peer
from skdgmpm.cli import main


def test_missing_peer_is_a_clear_skip_and_the_other_rows_run(monkeypatch, capsys):
    for name in ("clawpack", "clawpack.pyclaw", "clawpack.riemann.vc_elasticity_2D"):
        monkeypatch.setitem(sys.modules, name, None)        # import clawpack... -> ImportError
    assert not peer.available()
    assert main(["bench", "--sizes", "8", "--methods", "dgmpm-dcu,pyclaw-ctu", "--steps", "1", "--warmup", "1",
                 "--threads", "1", "--quiet"]) == 0
    out = capsys.readouterr().out
    assert peer.MISSING in out and "skipped: clawpack not installed: pip install '.[peer]'" in out
    assert "apt-get install gfortran" in out
    dcu = [line for line in out.splitlines() if line.startswith("dgmpm-dcu")]
    assert dcu and "failed" not in dcu[0] and "skipped" not in dcu[0]
    assert "ours / peer" not in out                         # no ratio without the peer's row


def test_peer_names_are_benchmarks():
    assert set(peer.COUNTERPART.values()) <= set(bench.METHODS)
    assert not set(peer.METHODS) & set(bench.METHODS)


def _require_clawpack():
    pytest.importorskip("clawpack.riemann.vc_elasticity_2D")  # (importing pyclaw here would write pyclaw.log)
    if not peer.available():
        pytest.skip("clawpack.pyclaw not installed")


def test_pyclaw_plane_wave_matches_the_exact_impact():
    """The translated boundary conditions: the whole left face driven at V, top and bottom symmetric:
    behind the P front sigma_11 = -rho c_p V, sigma_22 = lambda / (lambda + 2 mu) sigma_11, u = V."""
    _require_clawpack()
    from skdgmpm.scene import load_scene

    prob = peer.problem(load_scene(bench.SCENE, [*bench.BASE, "grid.cells=[64, 4]"]))
    prob["driven"]["y"] = [0.0, 4.0]
    prob["sides"]["top"] = "symmetry"
    solver, solution = peer.build(prob)
    for _ in range(30):
        solver.evolve_to_time(solution)
    q = solution.state.q
    V, s11 = prob["driven"]["velocity"], -prob["rho"] * prob["cp"] * prob["driven"]["velocity"]
    behind = slice(0, 8)            # the front is at 0.9 * 30 = 27 cells, smeared over a few (first order)
    assert abs(q[3, behind] - V).max() < 1e-6 * V
    assert abs(q[0, behind] - s11).max() < 1e-6 * abs(s11)
    assert abs(q[1, behind] - prob["lam"] / (prob["lam"] + 2 * prob["mu"]) * s11).max() < 1e-6 * abs(s11)
    assert abs(q[2]).max() == 0 and abs(q[4]).max() == 0 and abs(q[:, 31:]).max() == 0   # one cell a step
    assert math.isclose(solver.dt, 0.9 * (4.0 / 64) / prob["cp"])


def test_pyclaw_row_beside_ours(tmp_path, capsys):
    _require_clawpack()
    path = tmp_path / "bench.json"
    assert main(["bench", "--sizes", "16", "--methods", "dgmpm-ctu,pyclaw-ctu", "--steps", "2", "--warmup", "1",
                 "--threads", "1,2", "--json", str(path), "--quiet"]) == 0
    out = capsys.readouterr().out
    rows = json.load(open(path))["rows"]
    assert [(r["method"], r["threads"]) for r in rows] == [("dgmpm-ctu", 1), ("dgmpm-ctu", 2), ("pyclaw-ctu", 1)]
    row = rows[2]
    assert "error" not in row and row["cells"] == 256 and row["peer"].startswith("clawpack")
    for key in ("step_s", "cpu_us_per_cell_step", "us_per_cell_step", "setup_s", "startup_s"):
        assert math.isfinite(row[key]) and row[key] > 0, key
    assert row["finite"] and 0 < row["max_speed"] < 2000          # driven at 1000 m/s, 3 steps
    assert math.isclose(row["t"], 3 * row["dt"])
    assert "dgmpm-ctu / pyclaw-ctu (clawpack" in out and "256 cells, one thread" in out


def test_pyclaw_solves_the_bench_problem():
    """The peer's problem is the bench's: with skdgmpm's linear law, DGMPM CTU and PyClaw's CTU give
    the same velocities on the plate at 0.3 ms (front smearing apart)."""
    _require_clawpack()
    import numpy as np

    from skdgmpm.run import run
    from skdgmpm.scene import load_scene

    n, t_end = 32, 3.0e-4
    res = run(bench.SCENE, ["grid.size=[4.0, 4.0]", f"run.t_end={t_end}", f"grid.cells=[{n}, {n}]",
                            *bench.METHODS["dgmpm-ctu"], 'material.law="linear_elastic"', "run.frames=1"],
              progress=False)
    fields = res.fields()
    solver, solution = peer.build(peer.problem(load_scene(bench.SCENE, [*bench.BASE, f"grid.cells=[{n}, {n}]"])))
    steps = int(np.ceil(t_end / solver.dt))
    solver.dt = t_end / steps
    for _ in range(steps):
        solver.evolve_to_time(solution)
    q = solution.state.q
    cell = np.clip((res.X / (4.0 / n)).astype(int), 0, n - 1)
    ours = np.stack([fields["v1"], fields["v2"]])
    theirs = np.stack([q[3][cell[:, 0], cell[:, 1]], q[4][cell[:, 0], cell[:, 1]]])
    assert np.linalg.norm(ours - theirs) < 0.15 * np.linalg.norm(theirs)
    assert 900 < theirs[0][cell[:, 0] == 0].max() < 1100       # the driven face moves at ~1000 m/s
