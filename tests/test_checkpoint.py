"""Checkpoint and restart (issue 17): SIGINT/SIGTERM write a checkpoint and stop with exit 75 and
a one-line message saying how to resume; ``--resume DIR`` (``skdgmpm.run.resume``) continues, and
the continued run's outputs are bit-identical to an uninterrupted run's."""
import filecmp
import json
import os
import signal
import subprocess
import sys
import time
import xml.etree.ElementTree as ET

import numpy as np
import pytest

from skdgmpm import checkpoint, first_run
from skdgmpm.build import build
from skdgmpm.cli import EXIT_INPUT, EXIT_INTERRUPTED, main
from skdgmpm.errors import InputError
from skdgmpm.run import resume, run
from skdgmpm.scene import load_scene

TIMING = ("wall_s", "startup_s", "wall_per_step_s")
# gauges every 4th step: probes.csv must come out of a resumed run byte for byte too
PROBES = ["probes.points={a = [1.0], b = [4.5]}", 'probes.fields=["v1", "P11", "sigma11"]', "probes.every=4"]
# scene, overrides: small runs of 30 to 60 steps, 6 frames
CASES = {
    "dgmpm": ("bar_elastic_1d", ["grid.cells=30", "run.t_end=4e-4", "run.frames=6",
                                 "particles.per_cell=2", "method.cfl=0.5"]),
    "ader-dgmpm": ("bar_elastic_1d", ["grid.cells=30", "run.t_end=4e-4", "run.frames=6", 'method.name="ader-dgmpm"',
                                      "method.order=1", "particles.per_cell=[0.25, 0.75]", "method.cfl=0.5"]),
    "mpm": ("bar_elastic_1d", ["grid.cells=30", "run.t_end=4e-4", "run.frames=6", 'method.name="mpm"',
                               "particles.per_cell=2", "method.cfl=0.5", "exact={}"]),
    "dgmpm-j2": ("bar_elastoplastic_1d", ["grid.cells=30", "run.t_end=4e-4", "run.frames=6"]),
    "ader-dgmpm-j2": ("bar_elastoplastic_1d", ["grid.cells=30", "run.t_end=4e-4", "run.frames=6",
                                               'method.name="ader-dgmpm"', "method.order=1",
                                               "particles.per_cell=[0.25, 0.75]", "method.cfl=0.5"]),
}
CASES = {name: (scene, overrides + PROBES + (['probes.fields=["v1", "P11", "eqp"]'] if name.endswith("j2") else []))
         for name, (scene, overrides) in CASES.items()}
# a stiffening impact: the wave speed changes from step to step, so the CFL guard's recent steps
# (dt_recent) and trend set the time steps and must come back from the checkpoint
CASES["dgmpm-impact-2d"] = ("plate_impact_neohookean_2d", [
    "grid.cells=[16, 12]", "run.t_end=1.5e-3", "run.frames=6", "probes.points={a = [0.25, 0.25], b = [3.0, 1.5]}",
    'probes.fields=["v1", "P11"]', "probes.every=4"])


def same_outputs(a, b):
    """Every frame, the .pvd, energy.csv and the grid byte for byte; summary.json but its timings."""
    names = sorted(p.name for p in a.iterdir() if not p.name.startswith(".") and p.suffix in (".vtu", ".pvd", ".csv"))
    assert names == sorted(p.name for p in b.iterdir() if not p.name.startswith(".") and p.suffix in
                           (".vtu", ".pvd", ".csv"))
    match, mismatch, errors = filecmp.cmpfiles(a, b, names, shallow=False)
    assert not mismatch and not errors, (mismatch, errors)
    sa, sb = (json.loads((d / "summary.json").read_text()) for d in (a, b))
    for k in TIMING:
        sa.pop(k), sb.pop(k)
    assert sa == sb


def kill_at(step, signum=signal.SIGTERM):
    """on_step: send ``signum`` to this process after ``step`` (a real signal, in-process)."""
    def hook(state, disc):
        if state.step == step:
            os.kill(os.getpid(), signum)
    return hook


@pytest.mark.parametrize("case", sorted(CASES))
def test_an_interrupted_run_resumed_is_bit_identical(tmp_path, case):
    scene, overrides = CASES[case]
    whole = run(scene, overrides, out=tmp_path / "whole", progress=False)
    assert whole.status == "ok" and whole.state.step >= 10
    stop = whole.state.step // 2 + 1
    cut = run(scene, overrides, out=tmp_path / "cut", progress=False, on_step=kill_at(stop))
    assert cut.status == "interrupted" and cut.state.step == stop
    assert "stopped by SIGTERM" in cut.message and f"skdgmpm run --resume {tmp_path / 'cut'}" in cut.message
    assert (tmp_path / "cut" / checkpoint.NAME).is_file()
    assert json.loads((tmp_path / "cut" / "summary.json").read_text())["status"] == "interrupted"
    again = resume(tmp_path / "cut", progress=False)
    assert again.status == "ok" and again.state.step == whole.state.step
    assert not (tmp_path / "cut" / checkpoint.NAME).exists()          # finished: nothing to resume
    same_outputs(tmp_path / "whole", tmp_path / "cut")
    assert np.array_equal(again.state.U, whole.state.U) and np.array_equal(again.state.history, whole.state.history)
    for k in whole.history:
        assert np.array_equal(again.history[k], whole.history[k], equal_nan=True), k
    assert len(again.frames) == len(whole.frames)                     # the earlier ones read back from disk
    for f, g in zip(again.frames, whole.frames):
        assert f.step == g.step and np.array_equal(f.U, g.U) and np.array_equal(f.Q, g.Q)
    if case.endswith("j2"):
        assert whole.state.history.shape[1] > 0 and whole.state.history[:, 0].max() > 0     # it flowed
    if case.startswith("ader"):
        assert again.summary()["picard"] == whole.summary()["picard"]
    assert (tmp_path / "cut" / "probes.csv").is_file()
    assert np.array_equal(again.probes.table(), whole.probes.table())


def test_a_periodic_checkpoint_survives_a_crash(tmp_path):
    """run.checkpoint_every = 5 steps; the run dies at step 13 (frames after the checkpoint on
    disk): the resumed run is bit-identical all the same."""
    scene, overrides = CASES["dgmpm"]
    overrides = overrides + ["run.checkpoint_every=5"]
    run(scene, overrides, out=tmp_path / "whole", progress=False)

    def crash(state, disc):
        if state.step == 13:
            raise RuntimeError("power cut")

    with pytest.raises(RuntimeError):
        run(scene, overrides, out=tmp_path / "cut", progress=False, on_step=crash)
    assert json.loads((tmp_path / "cut" / "summary.json").read_text())["status"] == "failed"
    assert checkpoint.read(tmp_path / "cut").state.step == 10
    assert resume(tmp_path / "cut", progress=False).status == "ok"
    same_outputs(tmp_path / "whole", tmp_path / "cut")


@pytest.mark.parametrize("signum", [signal.SIGINT, signal.SIGTERM])
def test_signals_from_outside_checkpoint_and_exit_75(tmp_path, signum):
    out = tmp_path / "out"
    cmd = [sys.executable, "-m", "skdgmpm.cli", "run", "bar_elastic_1d", "--out", str(out), "--quiet",
           "--set", "run.t_end=1e-2", "--set", "run.frames=400"]
    proc = subprocess.Popen(cmd, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    start = time.time()
    while not (out / "particles_0002.vtu").exists():
        assert proc.poll() is None, proc.communicate()
        assert time.time() - start < 300
        time.sleep(0.05)
    proc.send_signal(signum)
    stdout, stderr = proc.communicate(timeout=120)
    assert proc.returncode == EXIT_INTERRUPTED, stderr
    # one line, but for the first run's notice where the cache was cold (first_run.compile_notice)
    lines = [line for line in stderr.strip().splitlines() if not line.startswith(first_run.NOTICE)]
    assert len(lines) == 1 and "Traceback" not in stderr, stderr
    name = {signal.SIGINT: "SIGINT", signal.SIGTERM: "SIGTERM"}[signum]
    assert lines[0].startswith(f"stopped by {name} at step ") and lines[0].endswith(f"skdgmpm run --resume {out}")
    saved = checkpoint.read(out)
    summary = json.loads((out / "summary.json").read_text())
    assert summary["status"] == "interrupted" and summary["steps"] == saved.state.step
    done = subprocess.run([sys.executable, "-m", "skdgmpm.cli", "run", "--resume", str(out), "--quiet"],
                          capture_output=True, text=True, timeout=600)
    assert done.returncode == 0, done.stderr
    summary = json.loads((out / "summary.json").read_text())
    assert summary["status"] == "ok" and summary["t_final"] == pytest.approx(1e-2)
    entries = ET.parse(out / "particles.pvd").getroot().findall("./Collection/DataSet")
    assert len(entries) == 401 and all((out / e.get("file")).is_file() for e in entries)


def test_a_step_changes_no_stepper_state_but_the_checkpointed_one():
    """What a step leaves changed on a stepper is in checkpoint.RUN_STATE or a cache rebuilt at the
    start of every step: nothing else needs to be in a checkpoint."""
    # _work: DGMPM's work arrays (nodal state, CTU fluctuations), every entry written in a step
    # before it is read; _last_shape: MPM's shape-function arrays, rebuilt in every step; _split:
    # DGMPM's CTU split topology, built from the grid when a step first has an unrecorded cell;
    # _records_of: the arrays of the state whose cell records the last step wrote (read only by a
    # step from that very state: a resumed run's state is a new one, whose records are computed);
    # _record_arrays: DGMPM's cell records, work arrays made at set-up and written in every step
    caches = {"_kept", "history_n", "_repeated", "_work", "_last_shape", "_split", "_records_of", "_record_arrays"}
    for name, (scene, overrides) in {**CASES, "rk-dgfem": ("bar_elastic_1d", [
            "grid.cells=10", 'method.name="rk-dgfem"', 'method.integrator="rk2"', "method.order=1", "method.cfl=0.3",
            'method.limiter="barth-jespersen"'])}.items():
        disc = build(load_scene(scene, overrides))
        st = disc.stepper
        before = {k: _frozen(v) for k, v in vars(st).items()}
        state = disc.initial
        for _ in range(3):
            state = st.step(state)
        changed = {k for k, v in vars(st).items() if k not in before or not _same(before[k], _frozen(v))}
        assert changed <= set(checkpoint.RUN_STATE) | caches, (name, changed - set(checkpoint.RUN_STATE) - caches)
        assert "external_work" in changed, name


def _frozen(v):
    if isinstance(v, np.ndarray):
        return v.copy()
    if hasattr(v, "__dataclass_fields__"):
        return repr(v)
    return v if isinstance(v, (int, float, str, bool, type(None))) else id(v)


def _same(a, b):
    if isinstance(a, np.ndarray) or isinstance(b, np.ndarray):
        return isinstance(a, np.ndarray) and isinstance(b, np.ndarray) and a.shape == b.shape and np.array_equal(a, b)
    return a == b


@pytest.mark.parametrize("value", [0, -3, "soon", "10 parsecs", "-1 s", True, 2.5])
def test_bad_checkpoint_every(value, tmp_path):
    v = repr(value).lower() if isinstance(value, bool) else (f'"{value}"' if isinstance(value, str) else value)
    with pytest.raises(InputError, match="checkpoint_every"):
        run("bar_elastic_1d", ["grid.cells=10", f"run.checkpoint_every={v}"], out=tmp_path / "o", progress=False)
    assert not (tmp_path / "o").exists()


def test_resume_errors_are_one_line(capsys, tmp_path):
    (tmp_path / "done").mkdir()
    for argv, words in ((["run", "--resume", tmp_path / "nowhere"], ["no such directory"]),
                        (["run", "--resume", tmp_path / "done"], ["no checkpoint.npz"]),
                        (["run", "bar_elastic_1d", "--resume", tmp_path / "done"], ["give no scene"]),
                        (["run", "--resume", tmp_path / "done", "--set", "grid.cells=3"], ["give no scene"]),
                        (["run"], ["give a scene"])):
        assert main([str(a) for a in argv]) == EXIT_INPUT
        err = capsys.readouterr().err
        assert err.count("\n") == 1 and err.startswith("error: ") and "Traceback" not in err, err
        for w in words:
            assert w in err, (w, err)


def test_a_checkpoint_of_the_former_format_resumes(tmp_path):
    """Format 1 kept the CFL guard's last speed-up as dt_trend = 1 / speed-up; format 2 keeps the
    speed-ups of a window (dt_growth). A format-1 checkpoint resumes with its one speed-up."""
    scene, overrides = CASES["dgmpm-impact-2d"]
    overrides = overrides + ["run.checkpoint_every=5"]

    def crash(state, disc):
        if state.step == 7:
            raise RuntimeError("power cut")

    with pytest.raises(RuntimeError):
        run(scene, overrides, out=tmp_path / "cut", progress=False, on_step=crash)
    path = tmp_path / "cut" / checkpoint.NAME
    with np.load(path) as z:
        arrays = {k: z[k] for k in z.files}
    meta = json.loads(str(arrays["meta"]))
    growth = meta["stepper"].pop("dt_growth")
    meta["stepper"]["dt_trend"], meta["format"] = 1.0 / growth[-1], 1
    arrays["meta"] = np.array(json.dumps(meta))
    np.savez(path, **arrays)
    assert checkpoint.read(tmp_path / "cut").stepper["dt_growth"] == [pytest.approx(growth[-1], rel=1e-15)]
    assert resume(tmp_path / "cut", progress=False).status == "ok"
