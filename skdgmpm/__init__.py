"""skdgmpm: Discontinuous Galerkin Material Point Method for impacts on solids, on scikit-fem."""
from pathlib import Path as _Path

__version__ = "0.1.0"

# In a source checkout used without installing, forms/, materials/ and cases/ sit beside this
# package: let them resolve as skdgmpm.forms, skdgmpm.materials, skdgmpm.cases as installed.
_root = _Path(__file__).resolve().parent.parent
if not (_Path(__file__).parent / "forms").is_dir() and (_root / "forms" / "__init__.py").is_file():
    __path__.append(str(_root))


def _kernel_cache_dir():
    """Where numba caches the compiled kernels: a directory keyed on the package's sources.

    numba checks a cached kernel only against the file that defines it, not the files whose
    functions it inlines (riemann.py, materials/*.py, system.scratch): after editing those, a
    shared cache would silently run the old code. A key over every source file makes each edit
    compile afresh (one to two minutes) instead. Base: $NUMBA_CACHE_DIR if set, else
    $XDG_CACHE_HOME/skdgmpm or ~/.cache/skdgmpm; None where it cannot be created (numba's default).
    """
    import hashlib
    import importlib.util
    import os

    import numba

    folders = [_Path(__file__).parent]
    for sub in ("materials", "forms"):          # installed inside the package or beside it
        spec = importlib.util.find_spec(f"{__name__}.{sub}")
        folders += [_Path(p) for p in (spec.submodule_search_locations or [])] if spec else []
    digest = hashlib.sha1()
    for folder in dict.fromkeys(folders):
        for path in sorted(folder.glob("*.py")):
            digest.update(path.name.encode())
            digest.update(path.read_bytes())
    base = numba.config.CACHE_DIR or os.path.join(
        os.environ.get("XDG_CACHE_HOME") or os.path.join(os.path.expanduser("~"), ".cache"), "skdgmpm")
    path = os.path.join(base, f"kernels-{digest.hexdigest()[:16]}")
    try:
        os.makedirs(path, exist_ok=True)
    except OSError:
        return None
    numba.config.CACHE_DIR = path
    return path


kernel_cache = _kernel_cache_dir()       # before any kernel module is imported
