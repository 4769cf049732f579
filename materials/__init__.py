"""Constitutive laws, written once in 3D, chosen by name with `make_material`.

>>> from skdgmpm.materials import make_material
>>> steel = make_material("svk", E=200e9, nu=0.3, rho=7800.0)
"""

from dataclasses import MISSING, fields

from skdgmpm.errors import InputError

from .base import Material
from .gavrilyuk import Gavrilyuk
from .hencky_j2 import HenckyJ2
from .j2_plasticity import J2Plasticity
from .linear_elastic import LinearElastic
from .mooney_rivlin import MooneyRivlin
from .neo_hookean import NeoHookean
from .saint_venant_kirchhoff import SaintVenantKirchhoff

LAWS = {
    "linear_elastic": LinearElastic,
    "saint_venant_kirchhoff": SaintVenantKirchhoff,
    "neo_hookean": NeoHookean,
    "gavrilyuk": Gavrilyuk,
    "mooney_rivlin": MooneyRivlin,
    "j2_plasticity": J2Plasticity,
    "hencky_j2": HenckyJ2,
}
_ALIASES = {"svk": "saint_venant_kirchhoff"}
for _name, _cls in LAWS.items():
    _cls.law_name = _name          # the scene's ``law`` value, for messages

__all__ = ["LAWS", "Gavrilyuk", "HenckyJ2", "J2Plasticity", "LinearElastic", "Material", "MooneyRivlin",
           "NeoHookean", "SaintVenantKirchhoff", "make_material"]


def make_material(law, **params):
    """Build the material named ``law`` from keyword parameters.

    Parameters
    ----------
    law : str
        A key of `LAWS` or an alias (``"svk"``).
    **params
        The law's parameters (``E``, ``nu``, ``rho`` for the elastic laws, plus ``a`` for
        ``gavrilyuk``, default -1, and ``sigma_y``, ``H`` for ``j2_plasticity`` and ``hencky_j2``).

    Returns
    -------
    Material

    Raises
    ------
    InputError
        Unknown law, unknown or missing parameter, or a parameter out of range.
    """
    cls = LAWS.get(_ALIASES.get(law, law)) if isinstance(law, str) else None
    if cls is None:
        known = ", ".join(sorted([*LAWS, *_ALIASES]))
        raise InputError(f"material: law = {law!r} is unknown; known laws: {known}")
    names = [f.name for f in fields(cls) if f.init]
    for key in params:
        if key not in names:
            raise InputError(f"material: parameter {key!r} is unknown for law {law!r}; "
                             f"expected {', '.join(names)}")
    required = [f.name for f in fields(cls) if f.init and f.default is MISSING]
    missing = [name for name in required if name not in params]
    if missing:
        raise InputError(f"material: law {law!r} is missing parameter(s) {', '.join(missing)}")
    return cls(**params)
