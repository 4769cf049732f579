"""`skdgmpm bench` runs end to end at tiny size (timings themselves are never asserted)."""
import json

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
    rows = json.load(open(path))["rows"]
    assert [r["threads"] for r in rows] == [1, 2]
    assert "speed-up over one thread" in text and "2 threads" in text


def test_unknown_benchmark_is_a_clear_error():
    assert main(["bench", "--methods", "dgmpm-xyz", "--sizes", "8", "--quiet"]) == 2
    assert "ader-dgmpm-1" in ", ".join(bench.METHODS)
