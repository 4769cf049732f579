"""Outputs a user can trust (issue 17): never half-written, consistent at every moment a run can
die, a full disk reported in one line keeping what was written, one run per folder, nothing the
user owns deleted without --force."""
import csv
import errno
import json
import os
import signal
import subprocess
import sys
import time
import xml.etree.ElementTree as ET
from pathlib import Path

import meshio
import pytest

from skdgmpm import output
from skdgmpm.cli import EXIT_INPUT, EXIT_OUTPUT, main
from skdgmpm.outdir import LOCK
from skdgmpm.run import run

TINY = ["grid.cells=20", "run.t_end=3e-4", "run.frames=10"]


def cli(capsys, *argv):
    rc = main([str(a) for a in argv])
    captured = capsys.readouterr()
    return rc, captured.out, captured.err


def one_line(err, *words):
    lines = [x for x in err.splitlines() if not x.startswith("warning: ")]
    assert "Traceback" not in err and len(lines) == 1, err
    assert lines[0].startswith("error: "), lines[0]
    for w in words:
        assert w in lines[0], (w, lines[0])
    return lines[0]


def consistent(out, status=None):
    """The folder as a reader finds it: the .pvd lists only complete, readable frames, in order;
    energy.csv and summary.json are whole and agree with it; no temporary file is visible."""
    entries = ET.parse(out / "particles.pvd").getroot().findall("./Collection/DataSet")
    assert entries
    for e in entries:
        frame = meshio.read(out / e.get("file"))
        assert len(frame.points) > 0 and "F" in frame.point_data
    summary = json.loads((out / "summary.json").read_text())
    if status is not None:
        assert summary["status"] == status
    with open(out / "energy.csv") as fh:
        rows = list(csv.reader(fh))
    # written in this order, each at least as new as the next: energy.csv, summary.json, .pvd
    assert int(rows[-1][0]) >= summary["steps"]
    assert float(entries[-1].get("timestep")) <= summary["t_final"] * (1 + 1e-8)
    if (out / "probes.csv").exists():              # written between energy.csv and summary.json
        with open(out / "probes.csv") as fh:
            probes = list(csv.reader(fh))
        assert probes[0][0] == "t" and all(len(r) == len(probes[0]) for r in probes)
        t = [float(r[0]) for r in probes[1:]]
        assert t == sorted(t) and t[-1] >= summary["t_final"] * (1 - 1e-8)     # rows every step
    assert not [p.name for p in out.iterdir() if not p.name.startswith(".") and p.suffix not in
                (".vtu", ".pvd", ".csv", ".json", ".png", ".npz")]
    return entries, summary


def test_frames_go_to_a_hidden_name_then_are_renamed(tmp_path, monkeypatch):
    written = []
    real = output.write_particles

    def spy(path, stepper, state, *fields):
        written.append(Path(path))
        real(path, stepper, state, *fields)

    monkeypatch.setattr(output, "write_particles", spy)
    out = tmp_path / "out"
    run("bar_elastic_1d", TINY, out=out, progress=False)
    assert written and all(p.name.startswith(".") and p.parent == out for p in written)
    assert sorted(p.name for p in out.glob("particles_*.vtu")) == [f"particles_{k:04d}.vtu" for k in range(len(written))]
    assert not [p for p in out.iterdir() if ".tmp" in p.name]


def test_the_folder_is_consistent_after_every_step(tmp_path):
    """What a run killed between any two steps leaves: checked at every step of a run."""
    out, seen = tmp_path / "out", []

    def look(state, disc):
        entries, summary = consistent(out, "running")
        seen.append(len(entries))

    r = run("bar_elastic_1d", TINY + ["probes.points={a = [1.0]}"], out=out, progress=False, on_step=look)
    assert r.status == "ok" and len(seen) == r.state.step + 1 and seen[-1] > 5
    entries, _ = consistent(out, "ok")
    assert len(entries) == len(r.frames)


def test_sigkill_leaves_a_readable_folder(tmp_path):
    """SIGKILL cannot be caught: what is on disk must already be consistent (no truncated frame)."""
    for k, delay in enumerate((0.3, 1.1)):
        out = tmp_path / f"out{k}"
        proc = subprocess.Popen([sys.executable, "-m", "skdgmpm.cli", "run", "bar_elastic_1d", "--out", str(out),
                                 "--quiet", "--set", "run.t_end=2e-2", "--set", "run.frames=2000"],
                                stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
        _wait_for(out / "particles_0001.vtu", proc)
        time.sleep(delay)
        proc.send_signal(signal.SIGKILL)
        proc.wait(timeout=30)
        entries, summary = consistent(out, "running")
        assert len(entries) >= 2


def _wait_for(path, proc, timeout=300):
    start = time.time()
    while not path.exists():
        assert proc.poll() is None, "the run ended early"
        assert time.time() - start < timeout
        time.sleep(0.05)


def _full_disk_after(monkeypatch, module, name, calls):
    real, count = getattr(module, name), [0]

    def fail(*args, **kwargs):
        count[0] += 1
        if count[0] > calls:
            raise OSError(errno.ENOSPC, os.strerror(errno.ENOSPC), str(args[0] if args else ""))
        return real(*args, **kwargs)

    monkeypatch.setattr(module, name, fail)


def test_a_full_disk_while_writing_a_frame_keeps_what_was_written(capsys, tmp_path, monkeypatch):
    _full_disk_after(monkeypatch, output, "write_particles", 3)
    out = tmp_path / "out"
    args = ["run", "bar_elastic_1d", "--out", out, "--quiet"] + [a for s in TINY for a in ("--set", s)]
    rc, _, err = cli(capsys, *args)
    assert rc == EXIT_OUTPUT
    one_line(err, str(out), "particles_0003.vtu", "No space left on device", "kept")
    entries, summary = consistent(out, "running")
    assert [e.get("file") for e in entries] == [f"particles_{k:04d}.vtu" for k in range(3)]
    assert not [p for p in out.iterdir() if ".tmp" in p.name]


def test_a_full_disk_while_plotting_keeps_every_other_output(capsys, tmp_path, monkeypatch):
    from skdgmpm import plots
    _full_disk_after(monkeypatch, plots, "energy", 0)
    out = tmp_path / "out"
    args = ["run", "bar_elastic_1d", "--out", out, "--quiet"] + [a for s in TINY for a in ("--set", s)]
    rc, _, err = cli(capsys, *args)
    assert rc == EXIT_OUTPUT
    one_line(err, "plots", "No space left on device", "every other output is complete")
    entries, summary = consistent(out, "ok")
    assert len(entries) >= 2 and "errors" in summary and (out / "particles.pvd").is_file()


def test_a_second_run_into_a_folder_in_use_is_refused(capsys, tmp_path):
    out = tmp_path / "out"
    proc = subprocess.Popen([sys.executable, "-m", "skdgmpm.cli", "run", "bar_elastic_1d", "--out", str(out),
                             "--quiet", "--set", "run.t_end=2e-2", "--set", "run.frames=2000"],
                            stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True)
    try:
        _wait_for(out / "particles_0001.vtu", proc)
        for extra in ([], ["--force"]):
            rc, _, err = cli(capsys, "run", "bar_elastic_1d", "--out", out, "--quiet", *extra)
            assert rc == EXIT_INPUT
            one_line(err, str(out), "in use by another run", f"pid {proc.pid}")
        assert (out / "particles_0001.vtu").is_file()          # --force removed nothing
        rc, _, err = cli(capsys, "run", "--resume", out, "--quiet")
        assert rc == EXIT_INPUT
        one_line(err, "in use by another run", f"pid {proc.pid}")
    finally:
        proc.send_signal(signal.SIGTERM)
        proc.wait(timeout=120)
    consistent(out, "interrupted")


def test_a_stale_lock_does_not_block(tmp_path):
    """The lock of a run that was killed (SIGKILL) dies with it: its file alone blocks nothing."""
    out = tmp_path / "out"
    out.mkdir()
    (out / LOCK).write_text('{"pid": 1}')
    assert run("bar_elastic_1d", TINY, out=out, progress=False).status == "ok"
    assert not (out / LOCK).exists()


def test_a_users_partial_folder_is_left_alone(capsys, tmp_path):
    mine = tmp_path / "out.partial"
    mine.mkdir()
    (mine / "notes.txt").write_text("mine\n")
    rc, _, err = cli(capsys, "run", "bar_elastic_1d", "--out", tmp_path / "out", "--quiet",
                     *[a for s in TINY for a in ("--set", s)])
    assert rc == 0, err
    assert (mine / "notes.txt").read_text() == "mine\n" and sorted(os.listdir(mine)) == ["notes.txt"]
    assert (tmp_path / "out" / "summary.json").is_file()


@pytest.mark.parametrize("where", ["file", "readonly", "proc"])
def test_an_impossible_out_is_a_one_line_error(capsys, tmp_path, where):
    if where == "file":
        (tmp_path / "afile").write_text("x")
        out = tmp_path / "afile" / "out"
    elif where == "readonly":
        if os.geteuid() == 0:
            pytest.skip("root writes into read-only directories")
        ro = tmp_path / "ro"
        ro.mkdir(mode=0o500)
        out = ro / "out"
    else:
        out = Path("/proc/skdgmpm_out")
    rc, _, err = cli(capsys, "run", "bar_elastic_1d", "--out", out, "--quiet", "--set", "grid.cells=20")
    assert rc == EXIT_INPUT
    one_line(err, f"--out {out}")
    assert not out.exists()
