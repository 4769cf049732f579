"""`skdgmpm bench` runs end to end at tiny size (timings themselves are never asserted)."""
import json
import os

import numpy as np
import pytest

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
    # and the speed-up of arithmetic on each, the other bound of a pass's scaling
    assert set(data["machine"]["arithmetic_speedup"]) == {"1", "2"}
    assert data["machine"]["arithmetic_speedup"]["1"] == 1.0 and data["machine"]["arithmetic_speedup"]["2"] > 0
    assert "arithmetic (exp, sqrt on" in text
    # and what an empty chunked pass costs on each (the hand-off of its chunks to the threads)
    assert set(data["machine"]["handoff_s"]) == {"1", "2"} and min(data["machine"]["handoff_s"].values()) > 0
    assert "hand-off (a pass of next to no work on every thread" in text and "2 threads" in text
    # and each core's speed alone, turn by turn (one line where there are several)
    cores = {str(c) for c in os.sched_getaffinity(0)} if hasattr(os, "sched_getaffinity") else set()
    assert set(data["machine"]["cores_alone_s"]) == cores
    assert ("cores alone (the arithmetic probe's share pinned" in text) == (len(cores) > 1)
    # and the same method on both counts in one process, its line after the rows' speed-up
    (scaling,) = data["threads_paired"]
    assert "error" not in scaling and scaling["threads"] == [1, 2] and scaling["pairs"] == bench.PAIRS
    rows_line = text.index("dgmpm-dcu 64 cells: 1 thread ")
    assert text.index("dgmpm-dcu 64 cells, paired, alternating thread counts in one process: 2 threads x") > rows_line


def test_paired_thread_scaling_steps_one_simulation(monkeypatch):
    """The paired scaling switches the thread count between the steps of one simulation, each timed
    step after `SETTLE` untimed ones on its own count: its fields are sane, and its final state has
    the bits of the same steps all on one thread. The chunk length is lowered so that 8 x 8 is
    split into chunks, as 256^2 is."""
    from skdgmpm import parallel
    from skdgmpm.build import build

    monkeypatch.setattr(parallel, "MIN_ROWS", 16)
    previous = parallel.set_threads(3)
    try:
        row = bench.measure_threads_here("dgmpm-ctu", 8, [1, 2], steps=3, warmup=1)
        assert parallel.threads() == 3                          # the setting is restored
        assert row["cells"] == 64 and row["threads"] == [1, 2] and row["order"] == "ABBA"
        assert row["pairs"] == bench.pairs_for(3) == bench.PAIRS and row["settle"] == bench.SETTLE >= 1
        for clock in ("wall", "cpu", "switch_wall"):
            assert set(row[f"{clock}_s"]) == {"1", "2"} and set(row[f"{clock}_speedup"]) == {"2"}
            assert all(len(ts) == row["pairs"] and min(ts) > 0 for ts in row[f"{clock}_s"].values())
            s = row[f"{clock}_speedup"]["2"]
            assert 0 < s["q25"] <= s["median"] <= s["q75"] < np.inf and 0 < s["medians_ratio"] < np.inf
            assert all(0 < t < np.inf for t in row[f"{clock}_step_s"].values())
        # the arithmetic probe in the same rounds, and the step's speed-up as a share of its
        assert set(row["probe_s"]) == {"1", "2"} and all(len(ts) == row["pairs"] for ts in row["probe_s"].values())
        p, share = row["probe_speedup"]["2"], row["share_of_probe"]["2"]
        probe = 2 * np.array(row["probe_s"]["1"]) / row["probe_s"]["2"]     # two threads: twice the work
        assert np.isclose(p["median"], np.median(probe), rtol=1e-12)
        per_round = (np.array(row["wall_s"]["1"]) / row["wall_s"]["2"]) / probe
        assert np.isclose(share["median"], np.median(per_round), rtol=1e-12)
        disc = build(bench.scene_for("dgmpm-ctu", 8))
        measured = bench.alternate_threads(disc, [1, 2], 4, warmup=1)
        assert measured.wall.shape == measured.switched.shape == (2, 4) and measured.probe is None
        alternated = measured.state
        parallel.set_threads(1)
        ordinary = build(bench.scene_for("dgmpm-ctu", 8))
        state = ordinary.initial
        for _ in range(2 * (1 + bench.SETTLE) * (4 + 1)):
            state = ordinary.stepper.step(state)
    finally:
        parallel.set_threads(previous)
    assert alternated.step == state.step == 2 * (1 + bench.SETTLE) * 5 and alternated.t == state.t
    assert np.all(np.isfinite(state.U)) and np.array_equal(alternated.U, state.U)


@pytest.mark.parametrize("method, J_min", [("dgmpm-ctu-j2", 0.9), ("ader-dgmpm-3", 0.5)])
def test_plate_outlasts_a_paired_measurement(method, J_min):
    """The rows' plate steps as long as a paired measurement on 1, 2, 4, 8 and 16 threads takes
    (5 x (1 + SETTLE) x (30 + 2) steps) and stays admissible. Before, the edge of the driven zone, where 1000
    m/s meets the free face, inverted on every grid and the paired row failed: the small-strain
    J2 law after 51 steps on this 16 x 16 grid (69 on 32 x 32, 54 on 128 x 128 and 256 x 256;
    now driven at plate_impact_j2_2d's 50 m/s), unlimited ADER-DGMPM S3T3 after 49 on 16 x 16,
    32 x 32 and 64 x 64 (now with the Barth-Jespersen limiter)."""
    from skdgmpm.build import build

    disc = build(bench.scene_for(method, 16))
    state = disc.initial
    for _ in range(5 * (1 + bench.SETTLE) * (bench.PAIRS + 2)):
        state = disc.stepper.step(state)
    assert np.all(np.isfinite(state.U)) and state.health["min_J"] > J_min


def test_paired_scaling_line():
    """Pure formatting, fabricated numbers: the rows' speed-up, then the paired one of the same size."""
    rows = [{"method": "ader-dgmpm-1", "cells": 65536, "threads": 1, "step_s": 0.16},
            {"method": "ader-dgmpm-1", "cells": 65536, "threads": 2, "step_s": 0.1}]
    pair = {"method": "ader-dgmpm-1", "cells": 65536, "threads": [1, 2], "pairs": 30, "order": "ABBA",
            "wall_speedup": {"2": {"q25": 1.55, "median": 1.624, "q75": 1.7, "medians_ratio": 1.61}},
            "wall_step_s": {"1": 0.1523, "2": 0.0946}}
    rows_line, pair_line = bench.format_scaling(rows, [pair]).splitlines()
    assert rows_line == "ader-dgmpm-1 65536 cells: 1 thread 160.00 ms (x1.00), 2 threads 100.00 ms (x1.60)"
    assert pair_line == ("ader-dgmpm-1 65536 cells, paired, alternating thread counts in one process: 2 threads "
                         "x1.62 (quartiles 1.55-1.70; ratio of the medians 1.61: 152.30 / 94.60 ms per step); "
                         "medians of 30 per-round speed-ups, ABBA order")
    assert bench.format_scaling(rows[:1], [pair]) == pair_line        # the rows failed: still said
    pair.update(probe_speedup={"2": {"q25": 1.6, "median": 1.7, "q75": 1.8, "medians_ratio": 1.7}},
                share_of_probe={"2": {"q25": 0.9, "median": 0.954, "q75": 0.99, "medians_ratio": 0.95}})
    assert bench.format_threads_pair(pair) == pair_line + ("; in the same rounds the arithmetic probe gave 2 threads "
                                                           "x1.70, the step 0.95 of it (quartiles 0.90-0.99)")
    pair.update(switch_wall_speedup={"2": {"q25": 1.4, "median": 1.512, "q75": 1.6, "medians_ratio": 1.5}})
    assert bench.format_threads_pair(pair) == pair_line + (", each after a step on its own count (the first after each "
                                                           "switch: x1.51); in the same rounds the arithmetic probe "
                                                           "gave 2 threads x1.70, the step 0.95 of it (quartiles "
                                                           "0.90-0.99)")
    failed = {"method": "ader-dgmpm-1", "cells": 64, "threads": [1, 2], "error": "boom"}
    assert bench.format_scaling([], [failed]).endswith("alternating thread counts in one process: failed: boom")


def test_memory_bandwidth_probe_writes_the_triad():
    """The probe times `parallel.add_scaled` into a given array: that array must hold x + a y."""
    from skdgmpm import parallel
    x, y, out = np.arange(5000.0), np.full(5000, 2.0), np.zeros(5000)
    assert parallel.add_scaled(x, 2.5, y, out) is out and np.array_equal(out, x + 2.5 * y)
    speeds = bench.memory_bandwidth((1, 2), mib=1, repeats=1)
    assert set(speeds) == {1, 2} and all(g > 0 for g in speeds.values())
    assert "x1.00" in bench.format_memory(speeds) and bench.format_memory({1: 3.0}) == ""


def test_arithmetic_probe_gives_each_thread_count_its_share(monkeypatch):
    """The arithmetic probe's pass runs as the steps' passes do (`parallel.chunked`), on as many
    threads as it is given, each thread's share the same work: the speed-up is t times one
    thread's rate over t threads' rate, 1 for one thread."""
    from skdgmpm import parallel

    seen, chunked = [], parallel.chunked
    monkeypatch.setattr(parallel, "chunked", lambda n, *a: seen.append(parallel.team(n)) or chunked(n, *a))
    speedups = bench.arithmetic((1, 2), rounds=2, repeats=1)
    assert seen == [1, 1, 2, 2] and speedups[1] == 1.0 and speedups[2] > 0
    line = bench.format_arithmetic(speedups)
    assert "1 thread x1.00" in line and "2 threads x" in line and bench.format_arithmetic({1: 1.0}) == ""
    # relative to one thread in whatever order the counts come (--threads 2,1)
    assert bench.arithmetic((2, 1), rounds=2, repeats=1)[1] == 1.0


def test_cores_alone_probe_times_each_core_in_turn():
    """Each core this process may use gets one timed share per turn, on a thread pinned to it; the
    line gives the slowest core's time over the fastest's and what all cores together can gain
    over the fastest (fabricated turns: core 1 x1.5, x1, x2 the time of core 0)."""
    if not hasattr(os, "sched_setaffinity"):
        pytest.skip("threads cannot be pinned here")
    times = bench.cores_alone(turns=2, rounds=2)
    assert set(times) == set(os.sched_getaffinity(0)) and all(len(v) == 2 and min(v) > 0 for v in times.values())
    line = bench.format_cores_alone({0: [1.0, 1.0, 1.0], 1: [1.5, 1.0, 2.0]})
    # spread 1.5, 1, 2 (median 1.5); gain 1 + 1/1.5, 2, 1.5 (median 1.67)
    assert "slowest took x1.50 the fastest's time (median; x1.00-2.00)" in line
    assert "gain at most x1.67 (x1.50-2.00)" in line
    assert bench.format_cores_alone({0: [1.0]}) == ""


def test_unknown_benchmark_is_a_clear_error():
    assert main(["bench", "--methods", "dgmpm-xyz", "--sizes", "8", "--quiet"]) == 2
    assert "ader-dgmpm-1" in ", ".join(bench.METHODS)


def test_handoff_probe_splits_an_empty_pass_over_each_count(monkeypatch):
    """The hand-off probe's pass of next to no work runs as the steps' passes do (`parallel.
    chunked`) on each thread count (the cost it measures is the hand-off to that many), and its
    line says one cost per count."""
    from skdgmpm import parallel

    seen, chunked = [], parallel.chunked
    monkeypatch.setattr(parallel, "chunked", lambda n, *a: seen.append(parallel.team(n)) or chunked(n, *a))
    costs = bench.handoff((1, 2, 3), calls=2, gap=0.0)
    assert set(costs) == {1, 2, 3} and all(c > 0 for c in costs.values()) and seen == [1, 1, 2, 2, 3, 3]
    line = bench.format_handoff(costs)
    assert "1 thread " in line and "2 threads " in line and "3 threads " in line and bench.format_handoff({1: 1e-6}) == ""


def test_repeated_paired_scaling_lines():
    """Pure formatting, fabricated numbers: with --repeat, one paired line per repeat, then each
    count's median speed-up repeat by repeat and the lowest; a failed repeat is said and left out."""
    def pair(k, median):
        return {"method": "dgmpm-ctu", "cells": 65536, "threads": [1, 2], "pairs": 30, "order": "ABBA", "repeat": k,
                "wall_speedup": {"2": {"q25": 1.5, "median": median, "q75": 1.9, "medians_ratio": median}},
                "wall_step_s": {"1": 0.012, "2": 0.012 / median}}
    failed = {"method": "dgmpm-ctu", "cells": 65536, "threads": [1, 2], "error": "boom", "repeat": 3}
    lines = bench.format_scaling([], [pair(1, 1.804), pair(2, 1.61), failed]).splitlines()
    assert len(lines) == 4
    assert lines[0].startswith("dgmpm-ctu 65536 cells, paired, alternating thread counts in one process (repeat 1): "
                               "2 threads x1.80")
    assert lines[1].startswith("dgmpm-ctu 65536 cells, paired, alternating thread counts in one process (repeat 2): "
                               "2 threads x1.61")
    assert lines[2].endswith("(repeat 3): failed: boom")
    assert lines[3] == "dgmpm-ctu 65536 cells, paired, 2 of 3 repeats: 2 threads x1.80 x1.61 (lowest x1.61)"


def test_bench_repeats_the_paired_scaling(tmp_path, capsys):
    path = tmp_path / "bench.json"
    assert main(["bench", "--sizes", "8", "--methods", "dgmpm-dcu", "--steps", "1", "--warmup", "1",
                 "--threads", "1,2", "--repeat", "2", "--json", str(path), "--quiet"]) == 0
    text = capsys.readouterr().out
    data = json.load(open(path))
    assert [(p["method"], p["repeat"]) for p in data["threads_paired"]] == [("dgmpm-dcu", 1), ("dgmpm-dcu", 2)]
    assert all("error" not in p and p["pairs"] == bench.PAIRS for p in data["threads_paired"])
    assert "(repeat 2): 2 threads x" in text and "dgmpm-dcu 64 cells, paired, 2 of 2 repeats: 2 threads x" in text


def test_bench_repeat_must_be_a_positive_whole_number(capsys):
    from skdgmpm.cli import EXIT_INPUT

    assert main(["bench", "--repeat", "0"]) == EXIT_INPUT        # before any measurement
    assert capsys.readouterr().err.strip() == "error: --repeat 0: expected a whole number >= 1"
    with pytest.raises(SystemExit) as stop:                        # not a number: argparse's one line
        main(["bench", "--repeat", "two"])
    assert stop.value.code == 2
    assert capsys.readouterr().err.strip().splitlines()[-1] == ("skdgmpm bench: error: argument --repeat: invalid int "
                                                                "value: 'two'")


def test_serial_share_times_every_threaded_pass_once(monkeypatch):
    """bench/serial_share.py: with its hooks, a DCU step's compiled chunk loops (MIN_ROWS 16, so
    that 32^2 runs them on two threads: the law's pass, which forms the particles' rows, the
    faces, and `parallel.chunked`'s, the boundary faces among them) are timed from the calling
    thread, a pass inside another counted once; what is left of the step is its share outside
    them."""
    import importlib.util
    import time
    from pathlib import Path
    from skdgmpm import parallel

    path = Path(__file__).parent.parent / "bench" / "serial_share.py"
    spec = importlib.util.spec_from_file_location("serial_share", path)
    script = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(script)
    clock = script.Clock()
    nested = clock.wrap(lambda: clock.wrap(lambda: time.sleep(0.02))())
    nested()
    assert clock.depth == 0 and 0.02 <= clock.seconds < 0.04          # once, not twice
    monkeypatch.setattr(parallel, "MIN_ROWS", 16)
    calls = []
    wrap = clock.wrap
    monkeypatch.setattr(clock, "wrap", lambda call: wrap(
        lambda *a, **k: calls.append(getattr(call, "__name__", "")) or call(*a, **k)))
    script.hook(clock, monkeypatch.setattr)
    try:
        wall, inside, outside = script.share("dgmpm-dcu", 32, 3, 2, clock)
    finally:
        parallel.set_threads(None)
    if parallel._compiled_layer():      # law's pass; interior and boundary faces together: each step
        assert calls.count("chunked") >= 3 + 3 and calls.count("together") >= 3 + 3, calls    # the 3 warm-up steps too
    assert 0 < inside < wall and 0 < outside < wall         # medians over the steps, each its own


def test_pass_gaps_cut_each_step_at_its_passes(monkeypatch):
    """bench/pass_gaps.py: a DCU step at 32^2 (MIN_ROWS 16: its passes on two threads) cut at its
    threaded passes, each named by its kernel, the gaps named by the passes around them, from
    the step's start to its end; gaps and passes add up to the step's wall time."""
    import importlib.util
    from pathlib import Path
    from skdgmpm import parallel

    path = Path(__file__).parent.parent / "bench" / "pass_gaps.py"
    spec = importlib.util.spec_from_file_location("pass_gaps", path)
    script = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(script)
    monkeypatch.setattr(parallel, "MIN_ROWS", 16)
    marks, steps = [], 3
    script.timestamped(marks, monkeypatch.setattr)
    try:
        gaps, passes, walls = script.measure("dgmpm-dcu", 32, steps, 2, marks)
    finally:
        parallel.set_threads(None)
    assert {"interior_pass+boundary_faces", "states"} <= set(passes), passes      # the faces in one loop
    names = list(gaps)
    assert names[0].startswith("start -> ") and names[-1].endswith(" -> end")
    for before, after in zip(names, names[1:]):             # a chain: each gap starts where the last ended
        assert before.split(" -> ")[1] == after.split(" -> ")[0]
    assert all(len(v) == steps for v in (*gaps.values(), *passes.values()))
    for k in range(steps):
        parts = sum(v[k] for v in gaps.values()) + sum(v[k] for v in passes.values())
        assert abs(parts - walls[k]) <= 1e-9 * max(1.0, walls[k]) and min(v[k] for v in gaps.values()) >= 0


def test_pass_scaling_pairs_every_pass_and_sizes_its_arrays(monkeypatch):
    """bench/pass_scaling.py: the arrays of a `chunked` call are paired with the letters of its
    spec, nested tuples alike, each buffer once; a DCU plate at 32^2 (MIN_ROWS 16: its passes on
    two threads) stepped on 1 and 2 threads in turn gives every pass and the step a time per
    round on each count, and the bytes of the passes (the arrays' sizes) of one untimed step on
    each count after them: the timed steps count nothing."""
    import collections
    import importlib.util
    from pathlib import Path
    from skdgmpm import parallel

    path = Path(__file__).parent.parent / "bench" / "pass_scaling.py"
    spec = importlib.util.spec_from_file_location("pass_scaling", path)
    script = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(script)
    a, b, c = np.zeros(10), np.zeros((4, 3)), np.zeros(7, np.int32)
    found = script.arrays(parallel._parsed("lr(wr)h(c)"), (a, (b, a), ((c, c, b),)))
    assert [(letter, x.nbytes) for letter, x in found] == [("r", 80), ("w", 96), ("c", 28)]   # a, b, c once each
    monkeypatch.setattr(parallel, "MIN_ROWS", 16)
    marks, sizes, rounds = [], collections.defaultdict(list), 4
    script.pass_gaps.timestamped(marks, monkeypatch.setattr)
    switch = script.counted(sizes, monkeypatch.setattr)
    assert switch == [False]                # made off: a step counts nothing
    try:
        times, cells = script.measure("dgmpm-dcu", 32, 2, rounds, marks, switch, warmup=1)
        assert parallel._threads is None                # the setting put back as it was, not fixed
    finally:
        parallel.set_threads(None)
    assert cells == 32 * 32
    faces = "interior_pass+boundary_faces"                      # `parallel.together`: one pass
    assert {faces, "states", "step"} <= set(times[1]) and set(times[1]) == set(times[2])
    assert all(len(v) == rounds for t in (1, 2) for v in times[t].values())
    for t in (1, 2):                        # a step holds its passes
        assert all(times[t]["step"][k] > times[t]["states"][k] + times[t][faces][k] for k in range(rounds))
    assert len(sizes[faces]) == 2 and all(streamed > 0 for streamed, _ in sizes[faces])    # both passes' arrays
    assert len(sizes["states"]) == 2 and switch == [False]      # one law's pass in each counted step, none timed
    streamed, whole = sizes["states"][0]
    assert streamed >= 2 * cells * 6 * 8 and whole > 0          # at least U and Q (n, 6), cut by rows
    split = script.between(times, 2)
    for t in (1, 2):                        # passes + rest = the step, round by round; the rest >= 0
        passes, rest = split[t]
        assert np.allclose(passes + rest, times[t]["step"], rtol=1e-12, atol=0) and rest.min() >= 0
        assert np.all(passes >= np.array(times[t]["states"]) + times[t][faces])
    fake = {1: {"a": [3.0, 5.0], "b": [1.0, 1.0], "step": [4.5, 6.5]},
            2: {"a": [2.0, 3.0], "b": [0.5, 0.5], "step": [3.0, 4.0]}}
    (p1, r1), (p2, r2) = script.between(fake, 2).values()       # worked by hand
    assert p1.tolist() == [4.0, 6.0] and p2.tolist() == [2.5, 3.5] and r1.tolist() == r2.tolist() == [0.5, 0.5]


def test_step_replay_runs_a_steps_passes_again_and_puts_the_state_back(monkeypatch):
    """bench/step_replay.py: a DCU step at 32^2 (MIN_ROWS 16: its passes in compiled chunk
    loops) captured as its passes (the faces together, the law's pass); replayed on the state it
    left, saved and put back, the replay computes (the arrays it writes change) the same bits on
    1 and 2 threads, and after it the simulation goes on bit for bit as a second one never
    replayed. The measurement gives each
    kind and count a time per round, and no replayed pass stops at a failed health check."""
    import importlib.util
    from pathlib import Path
    from skdgmpm import bench, parallel
    from skdgmpm.build import build

    path = Path(__file__).parent.parent / "bench" / "step_replay.py"
    spec = importlib.util.spec_from_file_location("step_replay", path)
    script = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(script)
    monkeypatch.setattr(parallel, "MIN_ROWS", 16)
    try:
        replayed, plain = (bench.Stepping(build(bench.scene_for("dgmpm-dcu", 32))) for _ in range(2))
        bench._use_threads(2)
        replayed()
        plain()
        replay = script.Replay(replayed)
        plain()
        assert replay.names == ["interior_pass+boundary_faces", "states"] and replay.seconds > 0
        assert len(replay.passes[0]) == 2                   # the faces: `parallel.together`'s two passes
        assert replay.passes[1][2] is not None              # the law's pass: its compiled chunk loop, not `chunked`
        replay.save()
        results = []
        for t in (1, 2, 2):
            bench._use_threads(t)
            replay.restore()
            replay()
            results.append([a.copy() for a in replay.written])
        assert replay.stopped == 0
        for other in results[1:]:
            assert all(np.array_equal(a, b, equal_nan=True) for a, b in zip(results[0], other))
        assert any(not np.array_equal(a, b, equal_nan=True) for a, b in zip(results[0], replay.saved))
        replay.restore()
        for _ in range(2):
            replayed()
            plain()
        assert replayed.state.t == plain.state.t and replayed.state.step == plain.state.step
        for name in ("U", "Q", "x"):
            assert np.array_equal(getattr(replayed.state, name), getattr(plain.state, name)), name
        times, names, stopped = script.measure("dgmpm-dcu", 32, 2, 2, warmup=1)
        assert sorted(times) == sorted((kind, t) for kind in ("step", "replay") for t in (1, 2))
        assert all(len(v) == 2 and min(v) > 0 for v in times.values()) and stopped == 0
        assert names == replay.names
    finally:
        parallel.set_threads(None)


def test_one_thread_paths_times_every_pass_called_from_python_and_in_the_compiled_loop(monkeypatch):
    """bench/one_thread_paths.py: on one thread a DCU plate at 32^2 (one chunk a pass) steps in
    turn with its passes called from Python (`parallel.rows`) and in the compiled chunk loop over
    the one chunk (a plan made for each pass, `rows` not called); every pass and the step get a
    time per round each way, and `parallel._compiled_bounds` is put back after."""
    import importlib.util
    from pathlib import Path
    from skdgmpm import parallel

    path = Path(__file__).parent.parent / "bench" / "one_thread_paths.py"
    spec = importlib.util.spec_from_file_location("one_thread_paths", path)
    script = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(script)
    original = parallel._compiled_bounds
    marks, rounds, called = [], 2, []
    script.pass_gaps.timestamped(marks, monkeypatch.setattr)
    rows = parallel.rows

    def counted_rows(*args, **kwargs):      # which way the step ran when a pass went to `rows`
        called.append(parallel._compiled_bounds)
        return rows(*args, **kwargs)

    monkeypatch.setattr(parallel, "rows", counted_rows)
    monkeypatch.setattr(parallel, "_PLANS", {})
    try:
        times = script.measure("dgmpm-dcu", 32, rounds, marks, warmup=1)
    finally:
        parallel.set_threads(None)
    assert parallel._compiled_bounds is original
    assert {"interior_pass+boundary_faces", "states", "step"} <= set(times["python"])
    assert set(times["python"]) == set(times["loop"])
    assert all(len(v) == rounds and min(v) > 0 for way in times.values() for v in way.values())
    assert called and all(bounds is original for bounds in called)         # rows: the Python way only
    assert "states" in {kernel.__name__ for kernel, _, _ in parallel._PLANS}
    assert ("interior_pass", "boundary_faces") in {(key[0].__name__, key[3].__name__) for key in parallel._PAIR_PLANS}


def test_compile_times_records_each_compilation_once_with_its_depth():
    """bench/compile_times.py: a function compiled while its caller compiles is recorded one
    level deeper, inside the caller's time; a signature compiled already is not recorded again,
    a new one is; the dispatcher is put back as it was."""
    import importlib.util
    from pathlib import Path
    from numba import njit
    from numba.core import dispatcher

    path = Path(__file__).parent.parent / "bench" / "compile_times.py"
    spec = importlib.util.spec_from_file_location("compile_times", path)
    script = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(script)

    @njit
    def inner(x):
        return 2.0 * x

    @njit
    def outer(x):
        return inner(x) + 1.0

    before = dispatcher.Dispatcher.compile
    with script.timed_compiles() as records:
        assert outer(1.0) == 3.0 and outer(2.0) == 5.0 and outer(3) == 7.0
    assert dispatcher.Dispatcher.compile is before
    # outer(float64) with inner(float64) inside it, outer(2.0) found made, then both for int64
    made = [(function.py_func.__name__, depth) for _, depth, function, _ in records]
    assert made == [("inner", 1), ("outer", 0)] * 2
    assert all(0 < records[k][0] <= records[k + 1][0] for k in (0, 2))     # inside its caller's time
    front, llvm = script.split(outer)
    assert front > 0 and llvm > 0 and script.name(outer).endswith("outer")


def test_trees_in_one_process_copies_a_tree_that_steps_to_the_same_bits(tmp_path):
    """bench/trees_in_one_process.py: the working tree copied as the package ``skdgmpm_rev``
    (every import renamed: none reaches back into ``skdgmpm``) steps the bench plate to the
    installed package's bits, in the same process. In a process of its own, as the script runs:
    the copy registers its own compile listener with numba (`kernel_cache.Vectorise`), which
    would stay in this one."""
    import subprocess
    import sys
    from pathlib import Path

    script = Path(__file__).parent.parent / "bench" / "trees_in_one_process.py"
    code = f"""
import importlib.util, sys
spec = importlib.util.spec_from_file_location("trees", {str(script)!r})
script = importlib.util.module_from_spec(spec)
spec.loader.exec_module(script)
package = script.copy_of(".", script.Path({str(tmp_path)!r}))
left = [p for p in package.rglob("*.py") if "from skdgmpm." in p.read_text() or "import skdgmpm\\n" in p.read_text()]
sys.path.insert(0, {str(tmp_path)!r})
(a, _), (b, _) = (script.stepping(name, "dgmpm-dcu", 16) for name in ("skdgmpm", script.NAME))
for _ in range(3):
    a()
    b()
print(len(left), type(b.stepper).__module__, a.state.U.tobytes() == b.state.U.tobytes(),
      a.state.Q.tobytes() == b.state.Q.tobytes())
"""
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True).stdout.split()
    assert out == ["0", "skdgmpm_rev.dgmpm", "True", "True"]
