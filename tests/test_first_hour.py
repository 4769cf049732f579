"""A newcomer's first hour (issue 18): the README's set-up commands, run as written, twice.

The README's first command is ``pip install . && skdgmpm run bar_elastic_1d``. The ``pip install .``
part is skipped here (the tests run inside an install already, and installing again would take
minutes and need the network); its ``skdgmpm run bar_elastic_1d`` part is run as a subprocess of
the installed console script in a fresh, empty folder, twice: the second run must not stop on the
first one's output folder, and neither may touch a folder that is not the tool's fresh default.
"""
import json
import os
import shutil
import subprocess
import sys
from pathlib import Path

import pytest


def skdgmpm():
    exe = shutil.which("skdgmpm") or str(Path(sys.executable).with_name("skdgmpm"))
    if not Path(exe).exists():
        pytest.skip("the skdgmpm console script is not installed")
    return exe


def readme_run(cwd, *extra):
    return subprocess.run([skdgmpm(), "run", "bar_elastic_1d", *extra], cwd=cwd, capture_output=True,
                          text=True, timeout=600)


def test_readme_set_up_commands_twice(tmp_path):
    first = readme_run(tmp_path)
    assert first.returncode == 0, first.stderr
    assert first.stdout.splitlines()[0].endswith("-> runs/bar_elastic_1d")
    second = readme_run(tmp_path)
    assert second.returncode == 0, second.stderr
    assert second.stdout.splitlines()[0].endswith("-> runs/bar_elastic_1d-2")
    assert "Traceback" not in first.stderr + second.stderr
    for name in ("bar_elastic_1d", "bar_elastic_1d-2"):
        summary = json.loads((tmp_path / "runs" / name / "summary.json").read_text())
        assert summary["status"] == "ok" and summary["case"] == "bar_elastic_1d"
        for png in ("energy.png", "profile.png"):
            assert (tmp_path / "runs" / name / png).is_file(), (name, png)


def test_default_folder_never_touches_a_users_files(tmp_path):
    """A folder the user made where the next default would be is skipped, even with --force
    (--force only ever replaces an explicit --out)."""
    mine = tmp_path / "runs" / "bar_elastic_1d"
    mine.mkdir(parents=True)
    (mine / "notes.txt").write_text("mine")
    (tmp_path / "runs" / "bar_elastic_1d-2").mkdir()          # empty: used, nothing to lose
    proc = readme_run(tmp_path, "--set", "run.t_end=1e-4", "--force", "--quiet")
    assert proc.returncode == 0, proc.stderr
    assert proc.stdout.splitlines()[0].endswith("-> runs/bar_elastic_1d-2")
    assert (mine / "notes.txt").read_text() == "mine" and sorted(p.name for p in mine.iterdir()) == ["notes.txt"]
    assert (tmp_path / "runs" / "bar_elastic_1d-2" / "summary.json").is_file()


def test_numbered_default(tmp_path):
    from skdgmpm.outdir import numbered

    base = tmp_path / "runs" / "s"
    assert numbered(base) == base and not base.exists()        # nothing created
    for name in ("s", "s-2"):
        (tmp_path / "runs" / name).mkdir(parents=True)
        (tmp_path / "runs" / name / "f").write_text("")
    assert numbered(base) == tmp_path / "runs" / "s-3"


# ------------------------------------------------------------------ skdgmpm scenes show | copy | schema

def cli(capsys, *argv):
    from skdgmpm.cli import main
    rc = main([str(a) for a in argv])
    captured = capsys.readouterr()
    return rc, captured.out, captured.err


def test_scenes_show_prints_the_scene(capsys, tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)                     # no ./cases: the installed package's scenes
    rc, out, err = cli(capsys, "scenes", "show", "lasat_2d")
    assert rc == 0 and err == ""
    assert 'law = "gavrilyuk"' in out and 'mesh = "lasat_30.msh"' in out


def test_scenes_copy_runs_from_its_folder_and_never_overwrites(capsys, tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    rc, out, _ = cli(capsys, "scenes", "copy", "partial_impact_2d", "mine")
    assert rc == 0 and "skdgmpm run mine/partial_impact_2d.toml" in out
    assert sorted(p.name for p in (tmp_path / "mine").iterdir()) == ["partial_impact_2d.toml", "plate_4x3.msh"]
    (tmp_path / "mine" / "plate_4x3.msh").write_text("my own mesh")
    rc, _, err = cli(capsys, "scenes", "copy", "partial_impact_2d", "mine")
    assert rc == 2 and "exists already (use --force to overwrite)" in err and err.count("\n") == 1
    assert (tmp_path / "mine" / "plate_4x3.msh").read_text() == "my own mesh"
    rc, _, _ = cli(capsys, "scenes", "copy", "partial_impact_2d", "mine", "--force")
    assert rc == 0 and (tmp_path / "mine" / "plate_4x3.msh").read_text() != "my own mesh"
    rc, out, err = cli(capsys, "run", "mine/partial_impact_2d.toml", "--set", "run.t_end=1e-4", "--quiet")
    assert rc == 0, err
    assert "-> runs/partial_impact_2d" in out


def test_scenes_schema_prints_every_key(capsys):
    from skdgmpm.scene_keys import KEYS
    rc, out, _ = cli(capsys, "scenes", "schema")
    assert rc == 0
    for key in KEYS:
        assert f"\n{key.name}: " in "\n" + out, key.name


def test_scenes_after_a_non_editable_install(tmp_path):
    """`pip install .` (not -e) into a folder, then show / copy from a folder without ./cases:
    the scenes and meshes are package data of skdgmpm.cases."""
    root = Path(__file__).resolve().parents[1]
    target = tmp_path / "site"
    proc = subprocess.run([sys.executable, "-m", "pip", "install", str(root), "--no-deps", "--quiet",
                           "--target", str(target)], capture_output=True, text=True, timeout=600)
    if proc.returncode != 0:
        pytest.skip(f"pip install . failed here (no build back-end from the index?): {proc.stderr[-300:]}")
    work = tmp_path / "work"
    work.mkdir()
    env = {**os.environ, "PYTHONPATH": str(target)}

    def skd(*argv):
        return subprocess.run([sys.executable, "-m", "skdgmpm.cli", *argv], cwd=work, env=env,
                              capture_output=True, text=True, timeout=600)

    where = subprocess.run([sys.executable, "-c", "import skdgmpm; print(skdgmpm.__file__)"], cwd=work, env=env,
                           capture_output=True, text=True)
    assert where.stdout.startswith(str(target))
    show = skd("scenes", "show", "bar_elastic_1d")
    assert show.returncode == 0 and str(target) in show.stdout.splitlines()[0]
    copy = skd("scenes", "copy", "lasat_2d", "mine")
    assert copy.returncode == 0, copy.stderr
    assert (work / "mine" / "lasat_30.msh").stat().st_size > 1000
    assert skd("scenes", "schema").stdout.count("material.") >= 8


# ------------------------------------------------------------------ small stumbles of the first hour

def test_list_into_head_exits_quietly(tmp_path):
    proc = subprocess.run(f"'{skdgmpm()}' list | head -1", shell=True, cwd=tmp_path, capture_output=True,
                          text=True, timeout=120)
    assert proc.stdout.startswith("bar_elastic_1d") and proc.stdout.count("\n") == 1
    assert proc.stderr == ""                      # no BrokenPipeError traceback


def test_2d_run_without_exact_solution_writes_profile_and_no_blank_line(tmp_path):
    proc = subprocess.run([skdgmpm(), "run", "partial_impact_2d", "--set", "run.t_end=1e-4"], cwd=tmp_path,
                          capture_output=True, text=True, timeout=600)
    assert proc.returncode == 0, proc.stderr
    assert proc.stdout.startswith("partial_impact_2d: ok, ")
    assert "\n\n" not in proc.stdout and not proc.stderr.startswith("\n")
    out = tmp_path / "runs" / "partial_impact_2d"
    assert (out / "profile.png").stat().st_size > 1000 and (out / "energy.png").is_file()
    summary = json.loads((out / "summary.json").read_text())
    assert summary["transverse"] == "ctu" and "errors" not in summary


def test_notebooks_extra_opens_jupyter_lab(tmp_path):
    """`pip install ".[notebooks]"` brings JupyterLab (the README says to open the notebooks in it):
    the extra lists it, and where it is installed (the test extra pulls it in) `jupyter lab`
    starts a server that serves the notebooks' folder (--allow-root: CI runs as root)."""
    import socket
    import time
    import tomllib
    import urllib.request

    root = Path(__file__).resolve().parents[1]
    extra = tomllib.loads((root / "pyproject.toml").read_text())["project"]["optional-dependencies"]["notebooks"]
    assert any(req.startswith("jupyterlab") for req in extra), extra
    exe = shutil.which("jupyter-lab") or str(Path(sys.executable).with_name("jupyter-lab"))
    if not Path(exe).exists():
        pytest.skip("jupyterlab is not installed here")
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        port = s.getsockname()[1]
    env = {**os.environ, "JUPYTER_CONFIG_DIR": str(tmp_path / "cfg"), "JUPYTER_DATA_DIR": str(tmp_path / "data"),
           "JUPYTER_RUNTIME_DIR": str(tmp_path / "rt")}
    server = subprocess.Popen([exe, "--no-browser", "--allow-root", f"--port={port}", "--ip=127.0.0.1", "--IdentityProvider.token=",
                               f"--ServerApp.root_dir={root / 'notebooks'}"], env=env, stdout=subprocess.DEVNULL,
                              stderr=subprocess.DEVNULL)
    opener = urllib.request.build_opener(urllib.request.ProxyHandler({}))     # localhost: no proxy
    try:
        deadline, body = time.time() + 90, ""
        while time.time() < deadline and not body:
            try:
                with opener.open(f"http://127.0.0.1:{port}/api/contents", timeout=5) as reply:
                    body = reply.read().decode()
            except OSError:
                time.sleep(0.5)
        assert "01_quick_start.ipynb" in body
        with opener.open(f"http://127.0.0.1:{port}/lab", timeout=10) as reply:
            assert reply.status == 200 and "JupyterLab" in reply.read().decode()
    finally:
        server.terminate()
        server.wait(timeout=30)


def test_profile_on_an_unstructured_mesh(tmp_path):
    """One particle is lowest on an unstructured mesh: the profile runs along the horizontal line
    through it, over the particles within half a spacing of it (it used to be a zero-length
    segment: an error that stopped the run of notebook 03 once profile.png was always drawn)."""
    import warnings
    from skdgmpm.run import run

    with warnings.catch_warnings():
        warnings.simplefilter("ignore")                  # grid.size/cells beside grid.mesh
        r = run("plane_wave_svk_2d", ['grid.mesh="rectangle_2x05_unstructured.msh"', "run.t_end=2e-5"],
                out=tmp_path / "o", progress=False)
    assert r.status == "ok" and (tmp_path / "o" / "profile.png").stat().st_size > 1000
    ax = r.plot_line("P11").figure.axes[0]
    assert len(ax.lines[0].get_xdata()) >= 5


def test_quiet_run_still_says_when_it_compiles(tmp_path, monkeypatch, capsys):
    """--quiet drops the progress bar, not the one line that says the kernels compile (minutes
    without a word otherwise on a cold cache); the API's progress=False stays silent."""
    from contextlib import nullcontext

    from skdgmpm import run as run_module
    from skdgmpm.cli import main

    asked = []
    monkeypatch.setattr(run_module, "compile_notice", lambda method, d, **kw: asked.append((method, d)) or nullcontext())
    monkeypatch.chdir(tmp_path)
    assert main(["run", "bar_elastic_1d", "--set", "run.t_end=1e-4", "--quiet"]) == 0
    assert asked == [("dgmpm", 1)]
    run_module.run("bar_elastic_1d", ["run.t_end=1e-4"], progress=False)
    assert asked == [("dgmpm", 1)]
