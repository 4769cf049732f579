"""Bad input and runtime failures: one-line errors, exit codes, no half-written output.

Input errors (``InputError``) make the CLI exit with status 2 after printing one line that names
the file (when there is one), the key and the value; the ``--out`` directory is then never
created (nor ``<out>.partial``) and an existing one is left untouched. Runtime failures (lost
hyperbolicity, non-finite values) exit with status 3, name the step, time and particle, and keep
the last good state on disk with ``summary.json`` status "unstable".
"""
import csv
import json
import re
import subprocess
import sys
import xml.etree.ElementTree as ET
from importlib import resources
from pathlib import Path

import meshio
import numpy as np
import pytest

from skdgmpm.cli import main
from skdgmpm.errors import InputError
from skdgmpm.run import run
from skdgmpm.scene import load_scene

CASES = Path(str(resources.files("skdgmpm.cases")))
TINY = ["--set", "grid.cells=20", "--set", "run.t_end=1e-5", "--quiet"]
STOP = re.compile(r"at step (\d+), t = ([0-9.eE+-]+) s(?:, particle (\d+))?")   # no particle: energy created


def cli(capsys, *argv):
    """Run the CLI in-process: (exit status, stdout, stderr)."""
    rc = main([str(a) for a in argv])
    captured = capsys.readouterr()
    return rc, captured.out, captured.err


def one_line_error(err, *words):
    """The error output is exactly one line 'error: ...' containing ``words``; returns it."""
    assert "Traceback" not in err
    assert err.endswith("\n") and err.count("\n") == 1, f"not one line: {err!r}"
    line = err.rstrip("\n")
    assert line.startswith("error: "), line
    for word in words:
        assert word in line, f"{word!r} not in {line!r}"
    return line


def assert_no_output(out):
    assert not out.exists(), f"{out} was written"
    assert not out.with_name(out.name + ".partial").exists()


def scene_text(name, drop_table=None, replace=()):
    """Text of ``cases/<name>.toml`` with a table (up to the next one) left out and replacements."""
    text = (CASES / f"{name}.toml").read_text()
    if drop_table:
        text = re.sub(rf"(?ms)^\[{re.escape(drop_table)}\]\n.*?(?=^\[|\Z)", "", text)
    for old, new in replace:
        assert old in text, old
        text = text.replace(old, new)
    return text


@pytest.fixture
def here(tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    return tmp_path


# ------------------------------------------------------------------------ input errors (exit 2)
@pytest.mark.parametrize("overrides, words", [
    (["grid.cellz=3"], ["--set", "grid.cellz", "not a known key"]),
    (['grid.cells="many"'], ["grid.cells", "'many'", "wrong type"]),
    (["grid.cells=many"], ["grid.cells", "'many'", "wrong type"]),
    (['material.E="steel"'], ["material.E", "'steel'", "wrong type"]),
    (["material.rho=0"], ["bar_elastic_1d.toml", "material", "rho = 0", "> 0"]),
    (["material.E=-1"], ["bar_elastic_1d.toml", "material", "E = -1", "> 0"]),
    (["material.nu=0.5"], ["bar_elastic_1d.toml", "nu = 0.5"]),
    (['material.law="rubber"'], ["bar_elastic_1d.toml", "law = 'rubber'", "unknown",
                                 "linear_elastic"]),
    (["material.G=1"], ["material.G", "not a known key"]),
    (["material.sigma_y=1e8"], ["bar_elastic_1d.toml", "'sigma_y'", "unknown for law 'linear_elastic'"]),
    (['material.law="j2_plasticity"', "material.sigma_y=0", "material.H=0"],
     ["bar_elastic_1d.toml", "sigma_y = 0", "> 0"]),
    (['material.law="hencky_j2"', "material.sigma_y=1e8", "material.H=-1"], ["bar_elastic_1d.toml", "H = -1", ">= 0"]),
    (['material.law="j2_plasticity"', "material.sigma_y=1e8"], ["bar_elastic_1d.toml", "missing", "H"]),
    (['material.law="j2_plasticity"', "material.sigma_y=1e8", "material.H=0", "particles.per_cell=2",
      'method.integrator="rk2"'], ["--set method.integrator", "'rk2'", "'j2_plasticity'", "euler"]),
    (["bc.nowhere.kind=free"], ["bar_elastic_1d.toml", "bc.nowhere", "'nowhere'",
                                "known: left, right"]),
    (["bc.left.kind=blah"], ["bar_elastic_1d.toml", "bc.left.kind", "'blah'"]),
    (["bc.left=3"], ["bc.left = 3", "table"]),
    (['bc.left.release="x"'], ["bc.left.release", "'x'"]),
    (["run.t_end=0"], ["run.t_end = 0"]),
    (["run.t_end=inf"], ["run.t_end = inf"]),
    (["run.frames=-3"], ["run.frames = -3"]),
    (["method.cfl=3"], ["method.cfl = 3"]),
    (['method.integrator="rk4"'], ["--set method.integrator", "'rk4'"]),
    (['method.name="fem"'], ["method.name", "'fem'", "mpm"]),
    (["dim=3"], ["dim = 3"]),
    (["particles.per_cell=0"], ["--set particles.per_cell = 0"]),
    (['particles.per_cell=["a"]'], ["particles.per_cell", "'a'"]),
    (['initial.velocity=["a"]'], ["initial.velocity", "'a'"]),
    (["initial.velocity=[1.0, 2.0]"], ["initial.velocity", "1 number"]),
    (["initial.F=[[-1.0]]"], ["bar_elastic_1d.toml", "initial", "not admissible"]),
    (["initial.F=[[1e300]]"], ["initial", "non-finite"]),
    (["initial.velocity=[1e300]"], ["initial", "non-finite energy"]),
    (['grid.origin=["a"]'], ["grid.origin", "'a'"]),
    (["exact.load=nowhere"], ["exact.load", "'nowhere'"]),
    (["exact.load=right"], ["exact.load", "'right'", "velocity"]),
    (["grid"], ["--set", "'grid'", "KEY=VALUE"]),
    (["grid.cells.x=3"], ["grid.cells.x", "not a table"]),
])
def test_bad_override(capsys, here, overrides, words):
    out = here / "out"
    argv = ["run", "bar_elastic_1d", "--out", out, "--quiet"]
    for item in overrides:
        argv += ["--set", item]
    rc, stdout, err = cli(capsys, *argv)
    assert rc == 2
    one_line_error(err, *words)
    assert stdout == ""
    assert_no_output(out)


def test_unknown_scene(capsys, here):
    rc, _, err = cli(capsys, "run", "no_such_scene", "--out", here / "out")
    assert rc == 2
    one_line_error(err, "'no_such_scene'", "unknown", "bar_elastic_1d")
    assert_no_output(here / "out")


def test_missing_scene_file_and_bad_toml(capsys, here):
    rc, _, err = cli(capsys, "run", "missing.toml", "--out", here / "out")
    assert rc == 2
    one_line_error(err, "missing.toml", "not found")
    (here / "broken.toml").write_text("dim = 1\n[grid\n")
    rc, _, err = cli(capsys, "run", "broken.toml", "--out", here / "out")
    assert rc == 2
    one_line_error(err, "broken.toml", "not valid TOML", "line 2")
    assert_no_output(here / "out")


@pytest.mark.parametrize("name, edit, expected", [
    ("typo.toml", ("cells = 150", "cellz = 3"), ("grid.cellz", "not a known key")),          # unknown key
    ("typed.toml", ("E = 2.0e11", 'E = "steel"'), ("material.E", "'steel'")),              # bad type
])
def test_bad_key_or_value_in_scene_file(capsys, here, name, edit, expected):
    path = here / name
    path.write_text(scene_text("bar_elastic_1d", replace=[edit]))
    rc, _, err = cli(capsys, "run", path, "--out", here / "out")
    assert rc == 2
    one_line_error(err, str(path), *expected)
    assert_no_output(here / "out")


def test_missing_mesh_file(capsys, here):
    path = here / "nomesh.toml"
    path.write_text(scene_text("partial_impact_2d",
                               replace=[('mesh = "plate_4x3.msh"', 'mesh = "nope.msh"')]))
    rc, _, err = cli(capsys, "run", path, "--out", here / "out")
    assert rc == 2
    one_line_error(err, str(path), "grid.mesh", "'nope.msh'", "not found")
    assert_no_output(here / "out")


def test_boundary_not_in_the_grid(capsys, here):
    path = here / "nowhere.toml"
    path.write_text(scene_text("bar_elastic_1d") + '\n[bc.nowhere]\nkind = "free"\n')
    rc, _, err = cli(capsys, "run", path, "--out", here / "out", *TINY)
    assert rc == 2
    one_line_error(err, str(path), "bc.nowhere", "known: left, right")
    assert_no_output(here / "out")


def test_boundary_not_in_the_mesh_file(capsys, here):
    """The named boundaries of a gmsh file (physical groups) are the known ones."""
    rc, _, err = cli(capsys, "run", "partial_impact_2d", "--set", "bc.nowhere.kind=free",
                     "--out", here / "out", "--quiet")
    assert rc == 2
    one_line_error(err, "partial_impact_2d.toml", "bc.nowhere", "impact")
    assert_no_output(here / "out")


def test_particle_outside_the_grid(capsys, here):
    (here / "points.csv").write_text("0.1\n0.5\n7.0\n1.0\n")
    path = here / "points.toml"
    path.write_text(scene_text("bar_elastic_1d",
                               replace=[("per_cell = 1 ", 'file = "points.csv" ')]))
    rc, _, err = cli(capsys, "run", path, "--out", here / "out", *TINY)
    assert rc == 2
    one_line_error(err, "points.csv", "particle 2", "7.0", "outside the grid")
    assert_no_output(here / "out")


def test_particle_alone_on_a_cell_corner(capsys, here):
    """A cell whose only particle sits on its corner leaves three of its nodes without mass
    (S_ip = 0 there): DGMPM's nodal projection would divide by zero (it once raised
    ZeroDivisionError from the kernel); a one-line error names the file's key and the particle."""
    centres = [(0.25 + 0.5 * i, 0.25 + 0.5 * j) for i in range(8) for j in range(6)]
    centres[0] = (0.0, 0.0)                     # cell 0's only particle, on the grid's corner
    (here / "points.csv").write_text("".join(f"{x},{y}\n" for x, y in centres))
    path = here / "points.toml"
    path.write_text(scene_text("plate_impact_neohookean_2d", replace=[("[particles]\nper_cell = 1", '[particles]\nfile = "points.csv"')]))
    rc, _, err = cli(capsys, "run", path, "--out", here / "out", "--set", "grid.cells=[8, 6]", "--set", "run.t_end=1e-5",
                     "--quiet")
    assert rc == 2
    one_line_error(err, "particles.file", "cell 0", "#0 at (0.0, 0.0)", "no mass")
    assert_no_output(here / "out")


def test_particle_file_missing(capsys, here):
    path = here / "points.toml"
    path.write_text(scene_text("bar_elastic_1d",
                               replace=[("per_cell = 1 ", 'file = "absent.csv" ')]))
    rc, _, err = cli(capsys, "run", path, "--out", here / "out", *TINY)
    assert rc == 2
    one_line_error(err, str(path), "particles.file", "'absent.csv'", "not found")


def test_exact_solution_needs_a_hyperbolic_load(capsys, here):
    """bar_svk_1d with a load beyond the SVK limit: the exact solution (R18 App. A) does not
    exist, which is reported before the run as an input error."""
    rc, _, err = cli(capsys, "run", "bar_svk_1d", "--set", "bc.left.value=[1.5e11]",
                     "--out", here / "out", *TINY)
    assert rc == 2
    one_line_error(err, "bar_svk_1d.toml", "exact", "traction", "hyperbolicity")
    assert_no_output(here / "out")


@pytest.mark.parametrize("layout, word", [("1.5,0.2", "'1.5'"), ("0.5,0.25", "'0.25'"),
                                          ("a,b", "'a'"), ("0", "'0'")])
def test_bad_layout(capsys, layout, word):
    rc, out, err = cli(capsys, "stability", "--layout", layout)
    assert rc == 2
    one_line_error(err, "--layout", word)
    assert out == ""


def test_api_raises_input_error(here):
    with pytest.raises(InputError, match=r"grid\.cellz"):
        load_scene("bar_elastic_1d", ["grid.cellz=3"])
    with pytest.raises(InputError, match=r"material: rho = 0 ") as info:
        run("bar_elastic_1d", overrides=["material.rho=0"], out=here / "out", progress=False)
    assert "\n" not in str(info.value)
    assert_no_output(here / "out")


def test_subprocess_exit_status_and_one_line(tmp_path):
    """The installed executable: status 2, one line on stderr, nothing on disk."""
    exe = Path(sys.executable).with_name("skdgmpm")
    out = tmp_path / "out"
    proc = subprocess.run([str(exe), "run", "bar_elastic_1d", "--set", "grid.cellz=3",
                           "--out", str(out)], capture_output=True, text=True, cwd=tmp_path,
                          timeout=120)
    assert proc.returncode == 2
    one_line_error(proc.stderr, "grid.cellz")
    assert_no_output(out)


# ---------------------------------------------------------------- existing output directory
def test_existing_out_is_refused_then_replaced_with_force(capsys, here):
    out = here / "out"
    out.mkdir()
    (out / "mine.txt").write_text("precious\n")
    before = (out / "mine.txt").stat().st_mtime_ns

    rc, _, err = cli(capsys, "run", "bar_elastic_1d", "--out", out, *TINY)
    assert rc == 2
    one_line_error(err, str(out), "--force")
    assert sorted(p.name for p in out.iterdir()) == ["mine.txt"]
    assert (out / "mine.txt").read_text() == "precious\n"
    assert (out / "mine.txt").stat().st_mtime_ns == before
    assert not (here / "out.partial").exists()

    # --force with bad input: still refused before anything is touched
    rc, _, err = cli(capsys, "run", "bar_elastic_1d", "--out", out, "--force",
                     "--set", "material.E=-1", *TINY)
    assert rc == 2
    one_line_error(err, "E = -1")
    assert sorted(p.name for p in out.iterdir()) == ["mine.txt"]

    rc, stdout, err = cli(capsys, "run", "bar_elastic_1d", "--out", out, "--force", *TINY)
    assert rc == 0, err
    assert not (out / "mine.txt").exists()
    assert (out / "summary.json").is_file()
    assert not (here / "out.partial").exists()


def test_empty_out_is_used_and_file_out_refused(capsys, here):
    (here / "empty").mkdir()
    rc, _, err = cli(capsys, "run", "bar_elastic_1d", "--out", here / "empty", *TINY)
    assert rc == 0, err
    assert (here / "empty" / "summary.json").is_file()
    (here / "afile").write_text("x")
    rc, _, err = cli(capsys, "run", "bar_elastic_1d", "--out", here / "afile", "--force", *TINY)
    assert rc == 2
    one_line_error(err, "afile", "not a directory")
    assert (here / "afile").read_text() == "x"


# ------------------------------------------------------------------ runtime failures (exit 3)
def check_stopped_run(rc, err, out):
    """Exit 3, one error line naming step, time and particle; the last good state on disk."""
    assert rc == 3
    assert "Traceback" not in err
    errors = [line for line in err.splitlines() if not line.startswith("warning: ")]
    assert len(errors) == 1, err
    line = errors[0]
    assert line.startswith("error: ") and line.endswith(f"; last good state kept in {out}")
    stop = STOP.search(line)
    assert stop, line
    step, t_stop, particle = int(stop[1]), float(stop[2]), int(stop[3] or 0)

    assert out.is_dir() and not out.with_name(out.name + ".partial").exists()
    summary = json.loads((out / "summary.json").read_text())
    assert summary["status"] == "unstable"
    assert summary["message"] in line
    assert summary["steps"] == step - 1                # the last good state precedes the stop
    assert summary["t_final"] < t_stop
    assert 0 <= particle < summary["particles"]

    with open(out / "energy.csv") as fh:
        rows = list(csv.reader(fh))
    assert rows[0] == ["step", "t", "kinetic", "stored", "dissipated", "total", "external_work", "balance",
                       "min_J", "min_acoustic"]
    values = np.array(rows[1:], dtype=float)
    assert np.all(np.isfinite(values))
    assert values[-1, 0] == summary["steps"]

    entries = ET.parse(out / "particles.pvd").getroot().findall("./Collection/DataSet")
    last = entries[-1]
    assert float(last.get("timestep")) == pytest.approx(summary["t_final"], rel=1e-8, abs=1e-300)
    frame = meshio.read(out / last.get("file"))
    assert len(frame.points) == summary["particles"]
    assert np.all(np.isfinite(frame.points))
    for name, data in frame.point_data.items():
        assert np.all(np.isfinite(data)), name
    return stop, summary


def test_loss_of_hyperbolicity_svk(capsys, here):
    """SVK under strong compression: F11 < 1/sqrt(3) [R18 eq A.10]. The scene is bar_svk_1d
    without its exact solution (which refuses that load, see above)."""
    path = here / "svk_crush.toml"
    path.write_text(scene_text("bar_svk_1d", drop_table="exact"))
    out = here / "out"
    rc, stdout, err = cli(capsys, "run", path, "--set", "bc.left.value=[1.5e11]",
                          "--set", "grid.cells=20", "--out", out, "--quiet")
    stop, summary = check_stopped_run(rc, err, out)
    assert "loss of hyperbolicity" in summary["message"]
    assert f"{summary['steps']} steps to t = {summary['t_final']:.6g} s" in stdout     # reached, not t_end
    assert "unstable" in stdout


@pytest.mark.filterwarnings("ignore:.*von Neumann", "ignore::RuntimeWarning")
def test_instability_blows_up(capsys, here):
    """CFL 1.9 with two particles per cell (von Neumann limit 0.69 with Euler), let through with
    method.cfl_above_limit, blows up; the growing oscillation is caught by the energy it creates
    (skdgmpm.guards) before a particle is inverted."""
    out = here / "out"
    rc, stdout, err = cli(capsys, "run", "bar_elastic_1d", "--set", "particles.per_cell=2",
                          "--set", "method.cfl=1.9", "--set", "run.t_end=2e-3", "--set", "method.cfl_above_limit=true",
                          "--set", "grid.cells=20", "--out", out, "--quiet")
    stop, summary = check_stopped_run(rc, err, out)
    assert summary["message"].startswith("energy created at step ")


@pytest.mark.filterwarnings("ignore:.*von Neumann", "ignore::RuntimeWarning")
def test_non_finite_values(capsys, here):
    """An absurd load overflows in the first step: reported as non-finite values."""
    out = here / "out"
    rc, stdout, err = cli(capsys, "run", "bar_elastic_1d", "--set", "bc.left.value=[1e308]",
                          "--set", "particles.per_cell=2", "--set", "method.cfl=1.9",
                          "--set", "method.cfl_above_limit=true", "--set", "grid.cells=20", "--out", out, "--quiet")
    stop, summary = check_stopped_run(rc, err, out)
    assert "non-finite values" in summary["message"]


@pytest.mark.filterwarnings("ignore:.*von Neumann", "ignore::RuntimeWarning")
def test_instability_through_the_api(here):
    result = run("bar_elastic_1d", overrides=["particles.per_cell=2", "method.cfl=1.9", "method.cfl_above_limit=true",
                                              "run.t_end=2e-3", "grid.cells=20"],
                 progress=False)
    assert result.status == "unstable"
    assert STOP.search(result.message)
    assert np.all(np.isfinite(result.state.U)) and np.all(np.isfinite(result.state.Q))
    assert "\n" not in repr(result) and "unstable" in repr(result)
    assert list(here.iterdir()) == []


def test_loss_of_hyperbolicity_in_the_riemann_solver(capsys, here):
    """With RK2 the second stage evaluates the law at the grid nodes, and the Riemann solver is
    the first to see the lost hyperbolicity: its message names a face, not a particle, and the
    driver adds the step and the time of the last good state."""
    path = here / "svk_crush.toml"
    path.write_text(scene_text("bar_svk_1d", drop_table="exact"))
    out = here / "out"
    rc, stdout, err = cli(capsys, "run", path, "--set", "bc.left.value=[1.5e11]",
                          "--set", 'method.integrator="rk2"', "--set", "grid.cells=20",
                          "--out", out, "--quiet")
    assert rc == 3
    line = one_line_error(err, "loss of hyperbolicity", "last good state kept in")
    assert re.search(r"(particle \d+|face \d+ during step \d+ \(from t = [0-9.eE+-]+ s\))", line)
    summary = json.loads((out / "summary.json").read_text())
    assert summary["status"] == "unstable" and summary["message"] in line
    frame = meshio.read(out / "particles_0000.vtu")
    assert all(np.all(np.isfinite(v)) for v in frame.point_data.values())
