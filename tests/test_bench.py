"""`skdgmpm bench` runs end to end at tiny size (timings themselves are never asserted)."""
import json

import numpy as np

from skdgmpm import bench
from skdgmpm.cli import main


def test_bench_command_prints_table_and_writes_json(tmp_path, capsys):
    path = tmp_path / "bench.json"
    assert main(["bench", "--sizes", "8", "--methods", "dgmpm-ctu,rk-dgfem-1", "--steps", "2", "--warmup", "1",
                 "--threads", "1", "--json", str(path), "--quiet"]) == 0
    text = capsys.readouterr().out
    assert "dgmpm-ctu" in text and "rk-dgfem-1" in text and "failed" not in text
    data = json.load(open(path))
    assert data["machine"]["cpus"] >= 1 and len(data["rows"]) == 2
    row = data["rows"][0]
    assert row["cells"] == 64 and row["dofs"] == 4 * 64 and row["step_s"] > 0 and row["peak_MiB"] > 0
    assert row["cpu_us_per_cell_step"] > 0 and row["startup_s"] > 0
    # one health check per attempt of the CFL guard: at least one per step, a repeat adds one
    assert all(r["attempts_per_step"] >= 1 and r["step_mean_s"] > 0 for r in data["rows"])
    assert "attempts per step (CFL guard)" in text


def test_bench_measures_each_thread_count(tmp_path, capsys):
    path = tmp_path / "bench.json"
    assert main(["bench", "--sizes", "8", "--methods", "dgmpm-dcu", "--steps", "1", "--warmup", "1",
                 "--threads", "1,2", "--json", str(path), "--quiet"]) == 0
    text = capsys.readouterr().out
    data = json.load(open(path))
    assert [r["threads"] for r in data["rows"]] == [1, 2]
    assert "speed-up over one thread" in text and "2 threads" in text
    # the machine's memory bandwidth on each thread count, beside the scaling it bounds
    assert set(data["machine"]["memory_GBps"]) == {"1", "2"} and min(data["machine"]["memory_GBps"].values()) > 0
    assert "memory (x + a y" in text and "GB/s" in text


def test_memory_bandwidth_probe_writes_the_triad():
    """The probe times `parallel.add_scaled` into a given array: that array must hold x + a y."""
    from skdgmpm import parallel
    x, y, out = np.arange(5000.0), np.full(5000, 2.0), np.zeros(5000)
    assert parallel.add_scaled(x, 2.5, y, out) is out and np.array_equal(out, x + 2.5 * y)
    speeds = bench.memory_bandwidth((1, 2), mib=1, repeats=1)
    assert set(speeds) == {1, 2} and all(g > 0 for g in speeds.values())
    assert "x1.00" in bench.format_memory(speeds) and bench.format_memory({1: 3.0}) == ""


def test_unknown_benchmark_is_a_clear_error():
    assert main(["bench", "--methods", "dgmpm-xyz", "--sizes", "8", "--quiet"]) == 2
    assert "ader-dgmpm-1" in ", ".join(bench.METHODS)
