"""Compiled point laws: one material's stress or tangent at one point, chosen by the law's ``law_id``.

Kernels that loop over points or faces themselves (the DGMPM face and particle passes, the health
check) evaluate the law inside their loop through `tangent_point` (1D: `tangent_call`); a set of materials is handed
to them as a table (`law_table`): one row of (law id, parameters) per material.

Every law inlined here is compiled into every fused pass that evaluates a law (the face passes,
the health check), twice per pass where it has a literal-d branch: compile time grows with each
law's code. The four laws of the benchmarks are inlined (their speed matters in those passes);
a law added since is called as a compiled function of its own (`inline` left at "never"), cheap
to compile once, a little slower per call. A law whose Riemann tangent is another law's shares
that law's branch (a second inlined copy of the same code would only cost compile time).
"""
import numpy as np
from numba import njit

from skdgmpm import parallel
from skdgmpm.kernel_cache import kernel_factory, scratch

from . import gavrilyuk, hencky_j2, j2_plasticity, linear_elastic, mooney_rivlin, neo_hookean, saint_venant_kirchhoff

N_PARAMETERS = 4        # the widest law_parameters
# each law's id (its class attribute ``law_id``), constants of the compiled dispatch below
NEO_HOOKEAN = neo_hookean.NeoHookean.law_id
LINEAR_ELASTIC = linear_elastic.LinearElastic.law_id
SAINT_VENANT_KIRCHHOFF = saint_venant_kirchhoff.SaintVenantKirchhoff.law_id
GAVRILYUK = gavrilyuk.Gavrilyuk.law_id
MOONEY_RIVLIN = mooney_rivlin.MooneyRivlin.law_id
J2_PLASTICITY = j2_plasticity.J2Plasticity.law_id
HENCKY_J2 = hencky_j2.HenckyJ2.law_id
KNOWN = (NEO_HOOKEAN, LINEAR_ELASTIC, SAINT_VENANT_KIRCHHOFF, GAVRILYUK, MOONEY_RIVLIN, J2_PLASTICITY, HENCKY_J2)


@njit(cache=True, inline="always")
def tangent_point(law, prm, F, C, d):
    """d-block C (d, d, d, d) of the tangent of law ``law`` with parameters ``prm`` at one
    embedded F (3, 3)."""
    if law == NEO_HOOKEAN or law == HENCKY_J2:         # hencky_j2's Riemann tangent is the neo-Hookean one
        neo_hookean.tangent_point(F, prm, C, d)
    elif law == LINEAR_ELASTIC or law == J2_PLASTICITY:  # j2_plasticity's: the linear elastic one
        linear_elastic.tangent_point(F, prm, C, d)
    elif law == SAINT_VENANT_KIRCHHOFF:
        saint_venant_kirchhoff.tangent_point(F, prm, C, d)
    elif law == MOONEY_RIVLIN:                         # a call, not inlined (see the module docstring)
        mooney_rivlin.tangent_point(F, prm, C, d)
    else:                               # GAVRILYUK (law_table admits no other id)
        gavrilyuk.tangent_point(F, prm, C, d)


@njit(cache=True)
def tangent_call(law, prm, F, C, d):
    """`tangent_point` as a function of its own, compiled once and called: the 1D loops call it
    (every law compiled once, not inlined at each call site: their compile time halves), the 2D
    ones inline `tangent_point` (the tangent stays in registers: the hot loops). The choice is made
    at the top of each kernel (``if d == 1:``), where numba prunes the other branch before typing;
    inside an inlined helper both branches would be compiled."""
    tangent_point(law, prm, F, C, d)


@njit(cache=True, inline="always")
def stress_point(law, prm, F, P, d):
    """d-block P (d, d) of the first Piola stress of hyperelastic law ``law`` with parameters
    ``prm`` at one embedded F (3, 3) (laws with history: `stress_update_point`)."""
    if law == NEO_HOOKEAN:
        neo_hookean.stress_point(F, prm, P, d)
    elif law == LINEAR_ELASTIC:
        linear_elastic.stress_point(F, prm, P, d)
    elif law == SAINT_VENANT_KIRCHHOFF:
        saint_venant_kirchhoff.stress_point(F, prm, P, d)
    elif law == MOONEY_RIVLIN:
        mooney_rivlin.stress_point(F, prm, P, d)
    else:                               # GAVRILYUK (law_table admits no other id)
        gavrilyuk.stress_point(F, prm, P, d)


@njit(cache=True, inline="always")
def stress_update_point(law, prm, F, h_n, h, P, d):
    """d-block P (d, d) of the first Piola stress at one embedded F (3, 3) at t_{n+1} from the
    internal variables h_n (n_history,) of t_n, and their update h: the return mapping of a law
    with history; a hyperelastic law ignores h_n and h (zero width)."""
    if law == J2_PLASTICITY:
        j2_plasticity.stress_update_point(F, prm, h_n, h, P, d)
    elif law == HENCKY_J2:
        hencky_j2.stress_update_point(F, prm, h_n, h, P, d)
    else:
        stress_point(law, prm, F, P, d)


@njit(cache=True, inline="always")
def stress_tangent_point(law, prm, F, h_n, h, P, C, d):
    """`stress_update_point` and `tangent_point` at one point (a pass that needs both, the law's
    with the health check): a law whose stress and tangent share their kinematics computes them
    once (neo-Hookean: F^-T and ln J)."""
    if law == NEO_HOOKEAN:
        neo_hookean.stress_tangent_point(F, prm, P, C, d)
    else:
        stress_update_point(law, prm, F, h_n, h, P, d)
        tangent_point(law, prm, F, C, d)


def law_table(materials):
    """(law ids (n_mat,), parameters (n_mat, N_PARAMETERS)) of a sequence of materials."""
    for m in materials:             # a new law must be added to the dispatch, never fall into another's
        if getattr(m, "law_id", None) not in KNOWN:
            raise TypeError(f"{type(m).__name__}: no compiled point law (law_id {getattr(m, 'law_id', None)!r} "
                            f"is not one of {KNOWN}; add it to materials/points.py)")
    laws = np.array([m.law_id for m in materials], dtype=np.int64)
    params = np.zeros((len(materials), max([N_PARAMETERS] + [len(m.law_parameters) for m in materials])))
    for k, m in enumerate(materials):
        params[k, : len(m.law_parameters)] = m.law_parameters
    return laws, params


@kernel_factory
def _tangents(d):                       # a literal d: the loops unrolled
    def tangents(law, prm, F, C):
        F_p, C_p = scratch((3, 3)), scratch((d, d, d, d))     # copies, not row views (reference counted)
        for p in range(len(F)):
            for i in range(3):
                for a in range(3):
                    F_p[i, a] = F[p, i, a]
            tangent_point(law, prm, F_p, C_p, d)
            for i in range(d):
                for a in range(d):
                    for j in range(d):
                        for b in range(d):
                            C[p, i, a, j, b] = C_p[i, a, j, b]
    return tangents


def tangent_block(material, F, d):
    """The (..., d, d, d, d) block of the tangent of ``material`` at embedded F (..., 3, 3)."""
    F = np.asarray(F, dtype=float)
    shape = F.shape[:-2]
    flat = np.ascontiguousarray(F.reshape(-1, 3, 3))
    law, prm = material.point_law
    C = np.empty((len(flat), d, d, d, d))
    kernel = _tangents(d)
    parallel.rows(len(flat), lambda lo, hi: kernel(law, prm, flat[lo:hi], C[lo:hi]))
    return C.reshape(shape + (d, d, d, d))
