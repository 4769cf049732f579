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
    # both asked for: one paired row more, in its own list, and its line after the rows' ratio
    (pair,) = json.load(open(path))["paired"]
    assert pair["pair"] == ["dgmpm-ctu", "pyclaw-ctu"] and pair["cells"] == 256 and "error" not in pair
    assert "dgmpm-ctu / pyclaw-ctu, 256 cells, paired, alternating steps in one process: " in out


def test_paired_measurement_alternates_steps_in_one_process():
    _require_clawpack()
    pair = bench.measure_pair("pyclaw-ctu", 8, steps=3, warmup=1)
    assert "error" not in pair, pair.get("error")
    assert pair["method"] == "dgmpm-ctu/pyclaw-ctu" and pair["cells"] == 64 and pair["threads"] == 1
    assert pair["pairs"] == bench.pairs_for(3) == bench.PAIRS and pair["order"] == "ABBA"
    for clock in ("cpu", "wall"):
        assert all(len(pair[f"{clock}_s"][side]) == pair["pairs"] for side in ("ours", "peer"))
        assert all(t > 0 for side in ("ours", "peer") for t in pair[f"{clock}_s"][side])
        q25, median, q75 = (pair[f"{clock}_ratio_{q}"] for q in ("q25", "median", "q75"))
        assert 0 < q25 <= median <= q75 and math.isfinite(q75)
        assert 0 < pair[f"{clock}_medians_ratio"] < math.inf
    assert bench.pairs_for(31) == 32 and bench.pairs_for(40) == 40    # even: ABBA balanced


def test_ratio_line_of_a_paired_row():
    """Pure formatting, fabricated numbers: the rows' ratio, then the paired one of the same size."""
    rows = [{"method": "dgmpm-ctu", "cells": 65536, "threads": 1, "cpu_us_per_cell_step": 0.2},
            {"method": "pyclaw-ctu", "cells": 65536, "threads": 1, "cpu_us_per_cell_step": 0.16,
             "peer": "clawpack 5.14.0"}]
    pair = {"method": "dgmpm-ctu/pyclaw-ctu", "pair": ["dgmpm-ctu", "pyclaw-ctu"], "cells": 65536, "threads": 1,
            "pairs": 30, "order": "ABBA", "cpu_ratio_q25": 0.98, "cpu_ratio_median": 1.031, "cpu_ratio_q75": 1.08,
            "cpu_medians_ratio": 1.02, "cpu_step_s": {"ours": 0.0124, "peer": 0.01216}}
    rows_line, pair_line = peer.format_ratio(rows, [pair]).splitlines()
    assert rows_line.startswith("dgmpm-ctu / pyclaw-ctu (clawpack 5.14.0), 65536 cells, one thread: 1.25 ")
    assert pair_line == ("dgmpm-ctu / pyclaw-ctu, 65536 cells, paired, alternating steps in one process: 1.03 "
                         "(median of 30 per-pair CPU ratios, ABBA order; quartiles 0.98-1.08; "
                         "ratio of the medians 1.02: CPU 12.40 / 12.16 ms per step)")
    assert peer.format_ratio(rows[:1], [pair]) == pair_line          # the peer's row failed: still said
    failed = {"method": "dgmpm-ctu/pyclaw-ctu", "pair": ["dgmpm-ctu", "pyclaw-ctu"], "cells": 64, "error": "boom"}
    assert peer.format_ratio([], [failed]).endswith("paired, alternating steps in one process: failed: boom")


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
