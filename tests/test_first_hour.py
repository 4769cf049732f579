"""A newcomer's first hour (issue 18): the README's set-up commands, run as written, twice.

The README's first command is ``pip install . && skdgmpm run bar_elastic_1d``. The ``pip install .``
part is skipped here (the tests run inside an install already, and installing again would take
minutes and need the network); its ``skdgmpm run bar_elastic_1d`` part is run as a subprocess of
the installed console script in a fresh, empty folder, twice: the second run must not stop on the
first one's output folder, and neither may touch a folder that is not the tool's fresh default.
"""
import json
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
