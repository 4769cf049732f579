"""skdgmpm: Discontinuous Galerkin Material Point Method for impacts on solids, on scikit-fem.

forms/, materials/ and cases/ sit at the top of the repository and are installed as
skdgmpm.forms, skdgmpm.materials and skdgmpm.cases (pyproject.toml's package-dir mapping; in a
checkout: ``pip install -e .``). The compiled kernels are cached on disk by `kernel_cache`.
"""
from . import _uids  # noqa: F401  (numba's function numbers, unique across processes: before any compilation)
from . import cache_folders as _cache_folders
from . import kernel_cache as _kernel_cache

__version__ = "0.1.0"

_kernel_cache.install()         # numba's cache locator for this package's files (only)
_cache_folders.lock_writes()    # their saves one process at a time
