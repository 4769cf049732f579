"""Command line and API happy paths: list, run (files on disk), stability, scene paths, warnings."""
import csv
import json
import shutil
import subprocess
import sys
import warnings
import xml.etree.ElementTree as ET
from importlib import resources
from pathlib import Path

import meshio
import numpy as np
import pytest

from skdgmpm.cli import main
from skdgmpm.errors import InputError
from skdgmpm.run import Result, run

CASES = Path(str(resources.files("skdgmpm.cases")))
ENERGY_HEADER = ["step", "t", "kinetic", "stored", "dissipated", "total", "external_work", "balance", "min_J", "min_acoustic"]


def cli(capsys, *argv):
    rc = main([str(a) for a in argv])
    captured = capsys.readouterr()
    return rc, captured.out, captured.err


def test_list_shows_every_scene(capsys):
    rc, out, err = cli(capsys, "list")
    assert rc == 0 and err == ""
    listed = [line.split()[0] for line in out.splitlines()]
    scenes = sorted(p.stem for p in CASES.glob("*.toml"))
    assert scenes and sorted(listed) == scenes
    for line in out.splitlines():
        assert line.split()[1] in ("1D", "2D")


@pytest.fixture(scope="module")
def bar_run(tmp_path_factory):
    """One small run of bar_elastic_1d through the CLI, shared by the checks below."""
    base = tmp_path_factory.mktemp("bar")
    out = base / "DIR"
    with pytest.MonkeyPatch.context() as mp:
        mp.chdir(base)
        rc = main(["run", "bar_elastic_1d", "--set", "grid.cells=30", "--set", "run.t_end=3e-4",
                   "--out", str(out), "--quiet"])
    assert rc == 0
    return base, out


def test_run_writes_the_outputs(bar_run):
    base, out = bar_run
    for name in ("grid.vtu", "particles.pvd", "energy.csv", "summary.json"):
        assert (out / name).is_file(), name
    assert not (base / "DIR.partial").exists()
    assert not (base / "runs").exists()                   # --out is honoured


def test_run_pvd_references_existing_frames(bar_run):
    _, out = bar_run
    root = ET.parse(out / "particles.pvd").getroot()
    assert root.tag == "VTKFile" and root.get("type") == "Collection"
    entries = root.findall("./Collection/DataSet")
    assert len(entries) >= 2
    times = [float(e.get("timestep")) for e in entries]
    assert times[0] == 0.0 and np.all(np.diff(times) > 0)
    assert times[-1] == pytest.approx(3e-4, rel=1e-9)
    for k, e in enumerate(entries):
        assert e.get("file") == f"particles_{k:04d}.vtu"
        assert (out / e.get("file")).is_file()
    frames = sorted(p.name for p in out.glob("particles_*.vtu"))
    assert frames == [e.get("file") for e in entries]


def test_run_energy_csv(bar_run):
    _, out = bar_run
    with open(out / "energy.csv") as fh:
        rows = list(csv.reader(fh))
    assert rows[0] == ENERGY_HEADER
    values = np.array(rows[1:], dtype=float)
    assert np.all(np.isfinite(values))
    assert np.all(np.diff(values[:, 0]) == 1) and np.all(np.diff(values[:, 1]) > 0)
    col = {k: values[:, i] for i, k in enumerate(ENERGY_HEADER)}
    np.testing.assert_allclose(col["total"], col["kinetic"] + col["stored"] + col["dissipated"], rtol=1e-9)
    assert np.all(col["dissipated"] == 0.0)             # an elastic law dissipates nothing


def test_run_summary(bar_run):
    _, out = bar_run
    summary = json.loads((out / "summary.json").read_text())
    for key in ("case", "method", "order", "dim", "cells", "particles", "dofs", "steps",
                "t_end", "wall_s", "startup_s", "wall_per_step_s", "errors"):
        assert key in summary, key
    assert summary["case"] == "bar_elastic_1d" and summary["method"] == "dgmpm"
    assert summary["status"] == "ok" and "message" not in summary
    assert (summary["dim"], summary["cells"], summary["particles"], summary["order"]) == (1, 30, 30, 1)
    assert summary["dofs"] == 30 * 2 * 2                  # 2 nodes per cell, [F11, p1]
    assert summary["steps"] > 0 and summary["wall_s"] >= 0 and summary["startup_s"] > 0
    assert summary["t_end"] == pytest.approx(3e-4, rel=1e-9)
    assert summary["errors"]
    for field, norms in summary["errors"].items():
        assert set(norms) >= {"L1_rel", "L2_rel", "Linf", "relative_to"}, field
        assert all(np.isfinite(norms[k]) for k in ("L1_rel", "L2_rel", "Linf"))


def test_run_frames_and_grid_read_with_meshio(bar_run):
    _, out = bar_run
    frame = meshio.read(out / "particles_0001.vtu")
    n = len(frame.points)
    assert n == 30
    for name, width in (("F", 9), ("P", 9), ("velocity", 3), ("cauchy", 9)):
        assert frame.point_data[name].shape == (n, width), name
        assert np.all(np.isfinite(frame.point_data[name]))
    F = frame.point_data["F"].reshape(n, 3, 3)
    np.testing.assert_allclose(F[:, 1:, 1:], np.broadcast_to(np.eye(2), (n, 2, 2)))
    grid = meshio.read(out / "grid.vtu")
    assert len(grid.cells[0].data) == 30


def test_run_prints_a_summary_line(capsys, tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    rc, out, err = cli(capsys, "run", "bar_elastic_1d", "--set", "grid.cells=20",
                       "--set", "run.t_end=1e-4", "--out", tmp_path / "o", "--quiet")
    assert rc == 0 and err == ""
    first = out.splitlines()[0]
    assert first.startswith("bar_elastic_1d: ok, ") and first.endswith(str(tmp_path / "o"))
    assert any("L1_rel" in line for line in out.splitlines()[1:])


def test_stability(capsys):
    rc, out, err = cli(capsys, "stability", "--layout", "0.25,0.75")
    assert rc == 0 and err == ""
    table = {line.split()[0]: line.split()[1:] for line in out.splitlines()}
    assert table["method"] == ["CFL", "limit", "max-norm", "bound"]
    assert table["euler"] == ["0.69", "0.43"]                 # Euler: CFL limit 0.69, bound 0.43
    assert table["rk2"] == ["1.00", "0.75"]
    assert "CFL limit: the von Neumann limit" in out


def test_stability_json(capsys):
    rc, out, _ = cli(capsys, "stability", "--layout", "1/4,3/4", "--json")
    assert rc == 0
    report = json.loads(out.splitlines()[-1])
    assert report["layout"] == [0.25, 0.75]
    assert round(report["euler_bound"], 2) == 0.43 and round(report["rk2_spectral"], 2) == 1.00


def test_stability_subprocess(tmp_path):
    exe = Path(sys.executable).with_name("skdgmpm")
    proc = subprocess.run([str(exe), "stability", "--layout", "0.25,0.75"], capture_output=True,
                          text=True, cwd=tmp_path, timeout=120)
    assert proc.returncode == 0 and proc.stderr == ""
    assert "0.43" in proc.stdout and "1.00" in proc.stdout


def test_scene_given_as_a_path(capsys, tmp_path, monkeypatch):
    """A .toml copied elsewhere runs; the case is named after the file; default --out is
    runs/<stem> in the working directory."""
    monkeypatch.chdir(tmp_path)
    shutil.copy(CASES / "bar_elastic_1d.toml", tmp_path / "my_bar.toml")
    rc, out, err = cli(capsys, "run", "my_bar.toml", "--set", "grid.cells=20",
                       "--set", "run.t_end=1e-4", "--quiet")
    assert rc == 0, err
    summary = json.loads((tmp_path / "runs" / "my_bar" / "summary.json").read_text())
    assert summary["case"] == "my_bar" and summary["cells"] == 20
    assert sorted(p.name for p in tmp_path.iterdir()) == ["my_bar.toml", "runs"]


def test_mesh_scene_given_as_a_path(capsys, tmp_path, monkeypatch):
    """A scene read from a path resolves its mesh file next to it."""
    monkeypatch.chdir(tmp_path)
    shutil.copy(CASES / "partial_impact_2d.toml", tmp_path / "plate.toml")
    shutil.copy(CASES / "plate_4x3.msh", tmp_path / "plate_4x3.msh")
    rc, _, err = cli(capsys, "run", tmp_path / "plate.toml", "--set", "run.t_end=1e-5",
                     "--out", tmp_path / "o", "--quiet")
    assert rc == 0, err
    summary = json.loads((tmp_path / "o" / "summary.json").read_text())
    assert summary["dim"] == 2 and summary["status"] == "ok"


def test_api_run(tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    result = run("bar_elastic_1d", overrides=["grid.cells=20"], progress=False)
    assert isinstance(result, Result)
    assert result.status == "ok" and result.out is None
    text = repr(result)
    assert "\n" not in text and text.startswith("<Result bar_elastic_1d") and "ok" in text
    assert result.state.t == pytest.approx(result.scene.get("run.t_end"), rel=1e-9)
    assert set(result.errors) and len(result.X) == 20
    assert list(tmp_path.iterdir()) == []                 # no out: nothing written


def test_cfl_above_von_neumann_limit_is_refused_or_warned_with_the_key(tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    tiny = ["grid.cells=20", "run.t_end=1e-4", "particles.per_cell=2"]
    with pytest.raises(InputError, match=r"method.cfl = 0.9 exceeds the von Neumann limit 0.69"):
        run("bar_elastic_1d", overrides=tiny + ["method.cfl=0.9"], progress=False)
    with pytest.warns(UserWarning, match="von Neumann") as record:
        run("bar_elastic_1d", overrides=tiny + ["method.cfl=0.9", "method.cfl_above_limit=true"], progress=False)
    message = str([w for w in record if "von Neumann" in str(w.message)][0].message)
    assert "method.cfl = 0.9" in message and "0.69" in message and "\n" not in message

    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        run("bar_elastic_1d", overrides=tiny + ["method.cfl=0.5"], progress=False)
    assert not [w for w in caught if "von Neumann" in str(w.message)]


@pytest.mark.filterwarnings("ignore:.*von Neumann")
def test_cli_restores_warning_format(capsys, tmp_path, monkeypatch):
    """main() prints warnings as 'warning: ...' lines, and leaves the process as it found it."""
    monkeypatch.chdir(tmp_path)
    before = warnings.formatwarning
    rc, _, _ = cli(capsys, "run", "bar_elastic_1d", "--set", "grid.cells=20",
                   "--set", "run.t_end=1e-4", "--set", "particles.per_cell=2",
                   "--set", "method.cfl=0.9", "--set", "method.cfl_above_limit=true", "--out", tmp_path / "o", "--quiet")
    assert rc == 0
    assert warnings.formatwarning is before


class VirtualClock:
    """Stands in for time.perf_counter in skdgmpm.run: time passes only in the stepper's steps,
    10 s for the first step of a stepper (compiling its kernels), 1 s for each later one."""

    def __init__(self, monkeypatch):
        import skdgmpm.run as run_module

        self.now, real_build = 0.0, run_module.build

        def build(scene):
            disc = real_build(scene)
            step = disc.stepper.step

            def timed(state, dt_max=np.inf):
                self.now += 10.0 if state.step == 0 else 1.0
                return step(state, dt_max)

            disc.stepper.step = timed
            return disc

        monkeypatch.setattr(run_module, "build", build)
        monkeypatch.setattr(run_module, "time", type("T", (), {"perf_counter": lambda: self.now}))


def test_wall_time_leaves_out_the_start_up(monkeypatch, tmp_path):
    """summary.json: startup_s holds the build and the first step (where the kernels compile or
    load), wall_s the rest of the loop; wall_per_step_s divides by the steps after the first."""
    clock = VirtualClock(monkeypatch)
    run("bar_elastic_1d", ["grid.cells=20", "run.t_end=3e-4"], out=tmp_path / "o", progress=False)
    summary = json.loads((tmp_path / "o" / "summary.json").read_text())
    steps = summary["steps"]
    assert steps > 2 and clock.now == 10.0 + (steps - 1)
    assert summary["startup_s"] == 10.0 and summary["wall_s"] == steps - 1
    assert summary["wall_per_step_s"] == 1.0


def test_a_kernel_compiled_inside_the_loop_counts_in_the_start_up(monkeypatch, tmp_path):
    """A kernel that compiles after the first step (a path that step did not take: 5 s of this
    clock in numba's compile event, at step 3) is start-up, not step time: wall_s stays the
    steps' own seconds."""
    from numba.core import event
    clock = VirtualClock(monkeypatch)

    def compile_at_step_3(state, disc):
        if state.step == 3:
            with event.trigger_event("numba:compile", data={}):
                with event.trigger_event("numba:compile", data={}):     # one compiled inside it
                    clock.now += 5.0

    run("bar_elastic_1d", ["grid.cells=20", "run.t_end=3e-4"], out=tmp_path / "o", progress=False,
        on_step=compile_at_step_3)
    summary = json.loads((tmp_path / "o" / "summary.json").read_text())
    steps = summary["steps"]
    assert steps > 3 and clock.now == 15.0 + (steps - 1)
    assert summary["startup_s"] == 15.0 and summary["wall_s"] == steps - 1


def test_a_study_times_its_runs_without_start_up(monkeypatch):
    """Every run of a study pays its own start-up (a fresh stepper, cold in this clock): the rows
    carry it in startup_s and wall_s is the warm step time times the steps."""
    from skdgmpm.study import convergence

    VirtualClock(monkeypatch)
    rows = convergence("bar_elastic_1d", ["dgmpm"], [1], [4, 8], fields=["P11"], progress=False)
    assert [r["cells"] for r in rows] == [4, 8] and rows[1]["steps"] > rows[0]["steps"] > 2
    for r in rows:
        assert r["startup_s"] == 10.0 and r["wall_s"] == r["steps"]
