"""Compiled point laws: one material's stress or tangent at one point, chosen by the law's ``law_id``.

A law's point functions are its class's ``point_law`` (`base.PointLaw`), and the law is
registered once, by its row in `materials.LAWS`: every dispatch below is made from that table.
Kernels that loop over points or faces themselves (the DGMPM face and particle passes, the health
check) evaluate the law inside their loop through `tangent_point` (1D: `tangent_call`); a set of
materials is handed to them as a table (`law_table`): one row of (law id, parameters) per
material, and each such kernel is made for the law its materials share, where they share one
(`only_law`): only that law's code is left in its loop.

A kernel made for one law types and compiles that law's code alone; one made for several
(`ANY_LAW`) compiles an if/elif on each point's law id over every registered law's branch (laws
sharing a function, e.g. a Riemann tangent, share a branch), twice per pass where it has a
literal-d branch. A law's point functions are inlined where they are declared
``inline="always"`` (the four laws of the benchmarks: their speed matters in those passes); a
law declared without is called as a compiled function of its own, cheap to compile once, a
little slower per call.
"""
import functools

import numpy as np
from numba import njit, types
from numba.extending import overload

from skdgmpm import parallel
from skdgmpm.equations import embed
from skdgmpm.kernel_cache import kernel_factory, scratch

from . import LAWS as _REGISTERED

N_PARAMETERS = 4        # the widest law_parameters


# The registered laws (`materials.LAWS`, one row per law) by ``law_id``: their point functions
# (`base.PointLaw`, the class's ``point_law``); every dispatch below is made from this table.
LAWS = {law.law_id: law.point_law for law in _REGISTERED.values()}
if len(LAWS) != len(_REGISTERED):
    raise ImportError(f"materials.LAWS: two laws share a law_id ({[law.law_id for law in _REGISTERED.values()]})")
KNOWN = tuple(LAWS)
ANY_LAW = -1


def only_law(laws):
    """The law id every material of a law table shares, or ANY_LAW. Kernels are made for it (a
    literal ``only`` handed to the dispatch below): a kernel of one law is typed and compiled with
    that law's code alone. The other laws' branches in the loop cost a fifth of the DGMPM law
    pass even where never taken (the loop's values no longer stay in registers)."""
    ids = laws.tolist()             # a few materials: counted in Python (numpy's calls showed in a step's profile)
    return ids[0] if ids and ids.count(ids[0]) == len(ids) else ANY_LAW


def _typed_for(only):
    """The law a dispatch is typed for: the literal ``only`` of a kernel made for one law, else
    ANY_LAW (the chain on each point's law id)."""
    return only.literal_value if isinstance(only, types.IntegerLiteral) else ANY_LAW


@njit(cache=True, inline="always")
def _parameters(params, m):
    """Material m's parameters copied into stack scratch: the row view params[m] handed to an
    inlined law would be reference counted at every point."""
    prm = scratch((N_PARAMETERS,))              # a literal width: the copy stays in registers
    for j in range(N_PARAMETERS):
        prm[j] = params[m, j]
    return prm


# ---------------------------------------------------------------- the dispatch, made from LAWS
# `_ARGUMENTS`: the arguments after (F, prm) of each kind of computation (``kind``) a kernel
# asks for; `_TAKES`: those of each point function of a `base.PointLaw`, the same but for a
# law's joint stress and tangent, which takes no history (a law with history has none: it
# updates, then computes its tangent).
TANGENT, STRESS, UPDATE, STRESS_TANGENT, ENERGY = range(5)
_ARGUMENTS = {TANGENT: ("C", "d"), STRESS: ("P", "d"), UPDATE: ("h_n", "h", "P", "d"),
              STRESS_TANGENT: ("h_n", "h", "P", "C", "d"), ENERGY: ("h_n", "W", "d")}
_TAKES = {"tangent": _ARGUMENTS[TANGENT], "stress": _ARGUMENTS[STRESS], "update": _ARGUMENTS[UPDATE],
          "stress_tangent": ("P", "C", "d"), "energy": _ARGUMENTS[ENERGY]}


def _statements(kind, law):
    """How law ``law`` computes ``kind``: the point functions of its `base.PointLaw` it calls in
    turn, each with the names of its arguments (None: a law with history has no STRESS). A law
    without history updates by its stress (its history, zero wide, unread); one without a joint
    stress and tangent computes them apart."""
    e = LAWS[law]

    def call(name):
        return ((getattr(e, name), ("F", "prm", *_TAKES[name])),)
    tangent = call("tangent")
    stress = None if e.stress is None else call("stress")
    update = call("update") if e.update else stress
    both = call("stress_tangent") if e.stress_tangent else update + tangent
    return (tangent, stress, update, both, call("energy"))[kind]


def _branches(kind, laws=KNOWN):
    """The branches of ``kind``'s dispatch over ``laws``: (law ids, `_statements`) in the order of
    LAWS, the laws that compute it alike (e.g. share a Riemann tangent) in one branch."""
    branches = {}
    for law in laws:
        statements = _statements(kind, law)
        if statements is not None:
            branches.setdefault(statements, []).append(law)
    return [(tuple(ids), statements) for statements, ids in branches.items()]


@functools.cache
def _impl(kind, only, sides):
    """The body of an overload of ``kind`` for a kernel made for law ``only`` (`_typed_for`): per
    side (material, F and the kind's arguments (`_ARGUMENTS`), as the overload names them; its
    parameters are the law table, the sides' materials, ``only``, their Fs, their arguments but
    the last, d (`_signature`)), that law's point functions called, or for
    ANY_LAW an if/elif on the side's law id over the branches of ``kind`` (`_branches`), the last
    taken unasked (`law_table` admits no other id). Its source is written from the table, the
    law's functions called in it directly: every wrapper between a kernel and a law is one more
    copy of the law's code for numba to inline (a recursive overload, typed once per path, took
    minutes to compile)."""
    branches = _branches(kind, KNOWN if only == ANY_LAW else (only,))
    if not branches:                        # a law with history asked for STRESS
        raise TypeError(f"law {only} has no point function of kind {kind}")
    namespace, lines = {"_parameters": _parameters}, [f"def impl({_signature(sides)}):"]
    for s, (m, F, arguments) in enumerate(sides):
        names = dict(zip(_ARGUMENTS[kind], arguments), F=F, prm=f"prm_{s}_")
        lines.append(f"    prm_{s}_ = _parameters(params_, {m})")
        if len(branches) > 1:
            lines.append(f"    law_{s}_ = laws_[{m}]")
        for k, (ids, statements) in enumerate(branches):
            indent = "    "
            if len(branches) > 1:
                test = " or ".join(f"law_{s}_ == {i}" for i in ids)
                lines.append(f"    {'elif ' + test if k else 'if ' + test}:" if k < len(branches) - 1 else "    else:")
                indent = "        "
            for j, (function, parameters) in enumerate(statements):
                namespace[f"law_{k}_{j}"] = function
                lines.append(f"{indent}law_{k}_{j}(" + ", ".join(names[a] for a in parameters) + ")")
    exec("\n".join(lines), namespace)
    return namespace["impl"]


def _signature(sides):
    """An overload's parameters from its sides (`_impl`): the names of (laws, params), the
    sides' materials, only, their Fs, their arguments but d, d."""
    return ", ".join(("laws_", "params_", *(m for m, _, _ in sides), "only_", *(F for _, F, _ in sides),
                      *(a for _, _, arguments in sides for a in arguments[:-1]), "d_"))


# The overloads are typed for the literals of the kernel that inlines them (prefer_literal). Their
# arguments end in _ (names no kernel uses), and a face's two sides go through one overload
# (`tangent_points`, `stress_points`): an overload inlined twice in one block, or with the caller's
# names, makes numba's SSA check warn (NumbaIRAssumptionWarning; numba issues 7623, 9489).
def tangent_point(laws, params, m, only, F, C, d):
    """d-block C (d, d, d, d) of the tangent of material m of the law table (laws, params) at one
    embedded F (3, 3); ``only``: the law of every material, or ANY_LAW (`only_law`). Compiled
    code only (the overloads below)."""
    raise TypeError("tangent_point is compiled code's")


def tangent_points(laws, params, m_L, m_R, only, F_L, F_R, C_L, C_R, d):
    """`tangent_point` of both sides of a face, materials m_L and m_R. Compiled code only."""
    raise TypeError("tangent_points is compiled code's")


def stress_point(laws, params, m, only, F, P, d):
    """d-block P (d, d) of the first Piola stress of material m of the law table (laws, params),
    a hyperelastic law, at one embedded F (3, 3) (laws with history: `stress_update_point`).
    Compiled code only."""
    raise TypeError("stress_point is compiled code's")


def stress_points(laws, params, m_L, m_R, only, F_L, F_R, P_L, P_R, d):
    """`stress_point` of both sides of a face (see `tangent_points`). Compiled code only."""
    raise TypeError("stress_points is compiled code's")


def stress_update_point(laws, params, m, only, F, h_n, h, P, d):
    """d-block P (d, d) of the first Piola stress at one embedded F (3, 3) at t_{n+1} from the
    internal variables h_n (n_history,) of t_n, and their update h: the return mapping of a law
    with history; a hyperelastic law ignores h_n and h (zero width). Compiled code only."""
    raise TypeError("stress_update_point is compiled code's")


def stress_tangent_point(laws, params, m, only, F, h_n, h, P, C, d):
    """`stress_update_point` and `tangent_point` at one point (a pass that needs both, the law's
    with the health check): a law whose stress and tangent share their kinematics computes them
    once (neo-Hookean: F^-T and ln J). Compiled code only."""
    raise TypeError("stress_tangent_point is compiled code's")


def energy_point(laws, params, m, only, F, h, W, d):
    """W[0] = the stored energy density of material m of the law table (laws, params) at one
    embedded F (3, 3), with the internal variables h (n_history,) in force (zero wide: none);
    +inf where the law is undefined. Compiled code only."""
    raise TypeError("energy_point is compiled code's")


# Each overload: per side (material, F, the kind's arguments) as it names them (its signature).
@overload(tangent_point, inline="always", prefer_literal=True)
def _tangent_point(laws_, params_, m_, only_, F_, C_, d_):
    return _impl(TANGENT, _typed_for(only_), (("m_", "F_", ("C_", "d_")),))


@overload(tangent_points, inline="always", prefer_literal=True)
def _tangent_points(laws_, params_, m_L_, m_R_, only_, F_L_, F_R_, C_L_, C_R_, d_):
    return _impl(TANGENT, _typed_for(only_), (("m_L_", "F_L_", ("C_L_", "d_")), ("m_R_", "F_R_", ("C_R_", "d_"))))


@overload(stress_point, inline="always", prefer_literal=True)
def _stress_point(laws_, params_, m_, only_, F_, P_, d_):
    return _impl(STRESS, _typed_for(only_), (("m_", "F_", ("P_", "d_")),))


@overload(stress_points, inline="always", prefer_literal=True)
def _stress_points(laws_, params_, m_L_, m_R_, only_, F_L_, F_R_, P_L_, P_R_, d_):
    return _impl(STRESS, _typed_for(only_), (("m_L_", "F_L_", ("P_L_", "d_")), ("m_R_", "F_R_", ("P_R_", "d_"))))


@overload(stress_update_point, inline="always", prefer_literal=True)
def _stress_update_point(laws_, params_, m_, only_, F_, h_n_, h_, P_, d_):
    return _impl(UPDATE, _typed_for(only_), (("m_", "F_", ("h_n_", "h_", "P_", "d_")),))


@overload(stress_tangent_point, inline="always", prefer_literal=True)
def _stress_tangent_point(laws_, params_, m_, only_, F_, h_n_, h_, P_, C_, d_):
    return _impl(STRESS_TANGENT, _typed_for(only_), (("m_", "F_", ("h_n_", "h_", "P_", "C_", "d_")),))


@overload(energy_point, inline="always", prefer_literal=True)
def _energy_point(laws_, params_, m_, only_, F_, h_, W_, d_):
    return _impl(ENERGY, _typed_for(only_), (("m_", "F_", ("h_", "W_", "d_")),))


@kernel_factory
def _tangent_of(only):                  # a literal: that law's code alone, ANY_LAW: every law's
    def tangent_of(laws, params, m, F, C, d):
        """`tangent_point` as a function of its own, compiled once per law and called."""
        tangent_point(laws, params, m, only, F, C, d)
    return tangent_of


def _tangent_called(laws, params, m, only, F, C, d):
    """`_tangent_of(only)` called from compiled code (the overload below). Compiled code only."""
    raise TypeError("_tangent_called is compiled code's")


@overload(_tangent_called, inline="always", prefer_literal=True)
def _tangent_called_for(laws_, params_, m_, only_, F_, C_, d_):
    kernel = _tangent_of(_typed_for(only_))     # chosen as the caller is typed, for its literal law

    def impl(laws_, params_, m_, only_, F_, C_, d_):
        kernel(laws_, params_, m_, F_, C_, d_)
    return impl


@njit(cache=True, inline="always")
def tangent_call(laws, params, m, only, F, C, d):
    """`tangent_point` called, not inlined: the 1D loops call it (a law's code compiled once, not
    inlined at each call site: their compile time halves), the 2D ones inline `tangent_point`
    (the tangent stays in registers: the hot loops) and call it on a rare path. The function
    called is made for ``only`` (`_tangent_of`): a scene of one law compiles that law alone (for
    any law, the seven laws' 1D tangents took 9 s of a 1D bar's first run). The choice is made at
    the top of each kernel (``if d == 1:``), where numba prunes the other branch before typing;
    inside an inlined helper both branches would be compiled. F and C go through stack copies:
    an array handed to a call escapes, and the caller's would then stay in memory through its
    whole loop (a tenth of the DGMPM law pass)."""
    F_c, C_c = scratch((3, 3)), scratch((d, d, d, d))
    for i in range(3):
        for a in range(3):
            F_c[i, a] = F[i, a]
    _tangent_called(laws, params, m, only, F_c, C_c, d)
    for i in range(d):
        for a in range(d):
            for j in range(d):
                for b in range(d):
                    C[i, a, j, b] = C_c[i, a, j, b]


def law_table(materials):
    """(law ids (n_mat,), parameters (n_mat, N_PARAMETERS)) of a sequence of materials."""
    for m in materials:             # a new law must be registered, never fall into another's branch
        if getattr(m, "law_id", None) not in KNOWN:
            raise TypeError(f"{type(m).__name__}: no compiled point law (law_id {getattr(m, 'law_id', None)!r} "
                            f"is not one of {KNOWN}; give its class a point_law and its row in materials.LAWS)")
        if len(m.law_parameters) > N_PARAMETERS:
            raise TypeError(f"{type(m).__name__}: {len(m.law_parameters)} law_parameters, the compiled point laws "
                            f"take at most N_PARAMETERS = {N_PARAMETERS} (raise it in materials/points.py)")
    laws = np.array([m.law_id for m in materials], dtype=np.int64)
    params = np.zeros((len(materials), N_PARAMETERS))
    for k, m in enumerate(materials):
        params[k, : len(m.law_parameters)] = m.law_parameters
    return laws, params


@kernel_factory
def _tangents(d, only):                 # literals: the loops unrolled, one law's code
    def tangents(laws, params, F, C):
        F_p, C_p = scratch((3, 3)), scratch((d, d, d, d))     # copies, not row views (reference counted)
        for p in range(len(F)):
            for i in range(3):
                for a in range(3):
                    F_p[i, a] = F[p, i, a]
            tangent_point(laws, params, 0, only, F_p, C_p, d)
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
    laws, params = law_table([material])
    C = np.empty((len(flat), d, d, d, d))
    kernel = _tangents(d, only_law(laws))
    parallel.chunked(len(flat), kernel, "wwrr", (laws, params, flat, C))
    return C.reshape(shape + (d, d, d, d))


@kernel_factory
def _energies(d, only):                 # literals: F's block embedded, one law's code
    def energies(laws, params, index, F, h, W):
        F_p, W_p = scratch((3, 3)), scratch((1,))
        for p in range(len(W)):
            embed(F[p], F_p, d)
            energy_point(laws, params, index[p], only, F_p, h[p], W_p, d)
            W[p] = W_p[0]
    return energies


def energy_densities(laws, params, index, F, history):
    """The stored energy densities (n,) of n points: point p of material index[p] of the law
    table (laws, params), at F[p] ((n, d, d): the d-block of an embedded F), with the internal
    variables history[p] in force (each law reads its first n_history columns; (n, 0): none). One
    pass over the points on the threads, each writing its own density (the same bits for any
    thread count)."""
    n, d = len(F), F.shape[1]
    W = np.empty(n)
    F = np.reshape(F, (n, d * d))             # rows of a state array stay a view (`equations.embed`)
    history = np.ascontiguousarray(history, dtype=float)
    index = np.asarray(index, dtype=np.int64)
    parallel.chunked(n, _energies(d, only_law(laws)), "wwrrrr", (laws, params, index, F, history, W))
    return W


def energy(material, F, history=None):
    """`base.Material.energy`: the stored energy density of ``material`` at embedded F (..., 3, 3)
    with ``history`` in force (None: the virgin state), shape F.shape[:-2]."""
    F = np.asarray(F, dtype=float)
    shape = F.shape[:-2]
    flat = F.reshape(-1, 3, 3)
    if material.n_history:
        h = material.initial_history(1)[0] if history is None else np.asarray(history, dtype=float)
        h = np.broadcast_to(h, shape + (material.n_history,)).reshape(len(flat), material.n_history)
    else:
        h = np.empty((len(flat), 0))
    laws, params = law_table([material])
    return energy_densities(laws, params, np.zeros(len(flat), dtype=np.int64), flat, h).reshape(shape)[()]
