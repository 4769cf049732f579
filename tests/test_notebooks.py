"""Every notebook in notebooks/ runs end to end in a fresh kernel, as a person would run it, and
the list below names them all: a notebook added without a test, or listed but gone, fails."""
import json
import sys
from pathlib import Path

import nbformat
import pytest
from nbclient import NotebookClient

FOLDER = Path(__file__).resolve().parent.parent / "notebooks"
NOTEBOOKS = [
    "01_quick_start.ipynb",
    "02_comparing_methods.ipynb",
    "03_scene_from_a_mesh_file.ipynb",
]


def test_every_notebook_is_listed_and_stored_without_outputs():
    assert sorted(p.name for p in FOLDER.glob("*.ipynb")) == sorted(NOTEBOOKS)
    for name in NOTEBOOKS:
        nb = nbformat.read(FOLDER / name, as_version=4)
        nbformat.validate(nb)
        code = [c for c in nb.cells if c.cell_type == "code"]
        assert code and all(not c.outputs and c.execution_count is None for c in code), name
        assert nb.cells[0].cell_type == "markdown" and nb.cells[0].source.startswith("# "), name


@pytest.fixture
def kernel_env(tmp_path, monkeypatch):
    """A 'python3' kernel of this very interpreter (ahead of any user-level kernel of that name),
    the notebook's temporary files under tmp_path, and Jupyter's own matplotlib backend."""
    spec = tmp_path / "jupyter" / "kernels" / "python3"
    spec.mkdir(parents=True)
    (spec / "kernel.json").write_text(json.dumps({
        "argv": [sys.executable, "-m", "ipykernel_launcher", "-f", "{connection_file}"],
        "display_name": "Python 3 (skdgmpm tests)", "language": "python"}))
    monkeypatch.setenv("JUPYTER_PATH", str(tmp_path / "jupyter"))
    monkeypatch.setenv("TMPDIR", str(tmp_path))
    monkeypatch.delenv("MPLBACKEND", raising=False)


@pytest.mark.parametrize("name", NOTEBOOKS)
def test_notebook_runs_end_to_end(name, kernel_env):
    nb = nbformat.read(FOLDER / name, as_version=4)
    NotebookClient(nb, timeout=240, kernel_name="python3",
                   resources={"metadata": {"path": str(FOLDER)}}).execute()   # raises on any error
    outputs = [o for c in nb.cells if c.cell_type == "code" for o in c.outputs]
    assert not [o for o in outputs if o.output_type == "error"]
    assert any("image/png" in o.get("data", {}) for o in outputs), "a notebook shows pictures"
