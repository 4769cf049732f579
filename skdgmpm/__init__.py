"""skdgmpm: Discontinuous Galerkin Material Point Method for impacts on solids, on scikit-fem."""
__version__ = "0.1.0"
