"""The compiled kernels' disk cache is keyed on every source file of the package: numba checks a
cached kernel only against its own file, so an edit of a file whose functions it inlines
(materials/*.py, riemann.py) must lead to a fresh cache, never to the old compiled code."""
import shutil
import subprocess
import sys
from pathlib import Path

import numba

import skdgmpm

ROOT = Path(skdgmpm.__file__).resolve().parent.parent


def cache_dir_of(checkout, env_home):
    """skdgmpm.kernel_cache as a fresh interpreter importing ``checkout`` (uninstalled) sees it."""
    out = subprocess.run([sys.executable, "-c", "import skdgmpm; print(skdgmpm.kernel_cache)"], cwd=checkout,
                         env={"PYTHONPATH": str(checkout), "XDG_CACHE_HOME": str(env_home), "PATH": ""},
                         capture_output=True, text=True, check=True)
    return out.stdout.strip()


def test_numba_caches_where_the_package_says():
    assert skdgmpm.kernel_cache is not None and numba.config.CACHE_DIR == skdgmpm.kernel_cache
    assert Path(skdgmpm.kernel_cache).name.startswith("kernels-")


def test_editing_an_inlined_law_changes_the_cache_key(tmp_path):
    checkout = tmp_path / "checkout"
    for sub in ("skdgmpm", "materials", "forms"):
        shutil.copytree(ROOT / sub, checkout / sub, ignore=shutil.ignore_patterns("__pycache__"))
    before = cache_dir_of(checkout, tmp_path / "cache")
    assert before.startswith(str(tmp_path / "cache" / "skdgmpm" / "kernels-"))
    assert cache_dir_of(checkout, tmp_path / "cache") == before                    # stable
    law = checkout / "materials" / "neo_hookean.py"
    law.write_text(law.read_text() + "\n# edited\n")
    assert cache_dir_of(checkout, tmp_path / "cache") != before
