"""skdgmpm: Discontinuous Galerkin Material Point Method for impacts on solids, on scikit-fem."""
from pathlib import Path as _Path

__version__ = "0.1.0"

# In a source checkout used without installing, forms/, materials/ and cases/ sit beside this
# package: let them resolve as skdgmpm.forms, skdgmpm.materials, skdgmpm.cases as installed.
_root = _Path(__file__).resolve().parent.parent
if not (_Path(__file__).parent / "forms").is_dir() and (_root / "forms" / "__init__.py").is_file():
    __path__.append(str(_root))
