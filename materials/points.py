"""Compiled point laws: one material's stress or tangent at one point, chosen by the law's ``law_id``.

A law's point functions are its class's ``point_law`` (`base.PointLaw`), and the law is
registered once, by its row in `materials.LAWS`: every dispatch below is made from that table. Kernels that loop over points or faces themselves (the DGMPM face and particle
passes, the health check) evaluate the law inside their loop through `tangent_point` (1D:
`tangent_call`); a set of materials is handed to them as a table (`law_table`): one row of (law
id, parameters) per material, and each such kernel is made for the law its materials share,
where they share one (`only_law`): only that law's code is left in its loop.

A kernel made for one law types and compiles that law's code alone; one made for several
(`ANY_LAW`) compiles a chain of every registered law's branch (laws sharing a function, e.g. a
Riemann tangent, share a branch), twice per pass where it has a literal-d branch. A law's point
functions are inlined where they are declared ``inline="always"`` (the four laws of the
benchmarks: their speed matters in those passes); a law declared without is called as a
compiled function of its own, cheap to compile once, a little slower per call.
"""
import functools

import numpy as np
from numba import njit, types
from numba.extending import overload

from skdgmpm import parallel
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
    return int(laws[0]) if len(laws) and bool(np.all(laws == laws[0])) else ANY_LAW


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
# What a point function computes (``kind``) and the arguments after (F, prm) it takes: TANGENT
# (C, d), STRESS (P, d), UPDATE (h_n, h, P, d), STRESS_TANGENT (h_n, h, P, C, d).
TANGENT, STRESS, UPDATE, STRESS_TANGENT = range(4)


def _without_history(stress):
    """A hyperelastic law's stress as an update (its history, zero wide, ignored)."""
    @njit(inline="always")
    def update(F, prm, h_n, h, P, d):
        stress(F, prm, P, d)
    return update


def _at_hand(stress_tangent):
    """A law's joint stress and tangent with the arguments of STRESS_TANGENT (no history)."""
    @njit(inline="always")
    def with_history(F, prm, h_n, h, P, C, d):
        stress_tangent(F, prm, P, C, d)
    return with_history


def _apart(update, tangent):
    """STRESS_TANGENT of a law without a joint function: its update, then its tangent."""
    @njit(inline="always")
    def stress_tangent(F, prm, h_n, h, P, C, d):
        update(F, prm, h_n, h, P, d)
        tangent(F, prm, C, d)
    return stress_tangent


@functools.cache
def _function(kind, law):
    """Law ``law``'s point function of ``kind`` (None: a law with history has no STRESS)."""
    e = LAWS[law]
    update = e.update or _without_history(e.stress)
    both = _at_hand(e.stress_tangent) if e.stress_tangent else _apart(update, e.tangent)
    return (e.tangent, e.stress, update, both)[kind]


# what follows F and prm in the call of each kind's point functions
_ARGUMENTS = {TANGENT: "x, d", STRESS: "x, d", UPDATE: "h_n, h, P, d", STRESS_TANGENT: "h_n, h, P, C, d"}


def _chain(kind):
    """The dispatch of ``kind`` on a point's law id, for a kernel of several laws (ANY_LAW):
    chain(law, F, prm, ...) (the arguments of ``kind``, `_ARGUMENTS`), if/elif over the branches
    of ``kind`` (`_branches`), the last taken unasked (`law_table` admits no other id). Its source
    is written from the table: a recursive overload (typed once per path) took minutes to
    compile, and a wrapper per branch (for one signature) a third more."""
    branches, arguments = _branches(kind), _ARGUMENTS[kind]
    lines = [f"def chain(law, F, prm, {arguments}):"]
    for k, (ids, _) in enumerate(branches):
        if k < len(branches) - 1:
            lines.append(f"    {'elif' if k else 'if'} " + " or ".join(f"law == {i}" for i in ids) + ":")
        elif k:
            lines.append("    else:")
        lines.append(f"{'        ' if k or len(branches) > 1 else '    '}law_{k}(F, prm, {arguments})")
    namespace = {f"law_{k}": function for k, (_, function) in enumerate(branches)}
    exec("\n".join(lines), namespace)
    return njit(inline="always")(namespace["chain"])


def _branches(kind):
    """The chain's branches for ``kind``: (law ids, function) in the order of LAWS, the laws that
    share a function (a Riemann tangent) in one branch."""
    branches = {}
    for law in LAWS:
        function = _function(kind, law)
        if function is not None:
            branches.setdefault(function, []).append(law)
    return [(tuple(ids), function) for function, ids in branches.items()]


_CHAINS = {kind: _chain(kind) for kind in (TANGENT, STRESS, UPDATE, STRESS_TANGENT)}


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


@overload(tangent_point, inline="always", prefer_literal=True)
def _tangent_point(laws_, params_, m_, only_, F_, C_, d_):
    law = _typed_for(only_)
    if law == ANY_LAW:
        chain = _CHAINS[TANGENT]

        def impl(laws_, params_, m_, only_, F_, C_, d_):
            chain(laws_[m_], F_, _parameters(params_, m_), C_, d_)
        return impl
    tangent = LAWS[law].tangent

    def impl(laws_, params_, m_, only_, F_, C_, d_):
        tangent(F_, _parameters(params_, m_), C_, d_)
    return impl


@overload(tangent_points, inline="always", prefer_literal=True)
def _tangent_points(laws_, params_, m_L_, m_R_, only_, F_L_, F_R_, C_L_, C_R_, d_):
    law = _typed_for(only_)
    if law == ANY_LAW:
        chain = _CHAINS[TANGENT]

        def impl(laws_, params_, m_L_, m_R_, only_, F_L_, F_R_, C_L_, C_R_, d_):
            chain(laws_[m_L_], F_L_, _parameters(params_, m_L_), C_L_, d_)
            chain(laws_[m_R_], F_R_, _parameters(params_, m_R_), C_R_, d_)
        return impl
    tangent = LAWS[law].tangent

    def impl(laws_, params_, m_L_, m_R_, only_, F_L_, F_R_, C_L_, C_R_, d_):
        tangent(F_L_, _parameters(params_, m_L_), C_L_, d_)
        tangent(F_R_, _parameters(params_, m_R_), C_R_, d_)
    return impl


@overload(stress_point, inline="always", prefer_literal=True)
def _stress_point(laws_, params_, m_, only_, F_, P_, d_):
    law = _typed_for(only_)
    if law == ANY_LAW:
        chain = _CHAINS[STRESS]

        def impl(laws_, params_, m_, only_, F_, P_, d_):
            chain(laws_[m_], F_, _parameters(params_, m_), P_, d_)
        return impl
    stress = LAWS[law].stress

    def impl(laws_, params_, m_, only_, F_, P_, d_):
        stress(F_, _parameters(params_, m_), P_, d_)
    return impl


@overload(stress_points, inline="always", prefer_literal=True)
def _stress_points(laws_, params_, m_L_, m_R_, only_, F_L_, F_R_, P_L_, P_R_, d_):
    law = _typed_for(only_)
    if law == ANY_LAW:
        chain = _CHAINS[STRESS]

        def impl(laws_, params_, m_L_, m_R_, only_, F_L_, F_R_, P_L_, P_R_, d_):
            chain(laws_[m_L_], F_L_, _parameters(params_, m_L_), P_L_, d_)
            chain(laws_[m_R_], F_R_, _parameters(params_, m_R_), P_R_, d_)
        return impl
    stress = LAWS[law].stress

    def impl(laws_, params_, m_L_, m_R_, only_, F_L_, F_R_, P_L_, P_R_, d_):
        stress(F_L_, _parameters(params_, m_L_), P_L_, d_)
        stress(F_R_, _parameters(params_, m_R_), P_R_, d_)
    return impl


@overload(stress_update_point, inline="always", prefer_literal=True)
def _stress_update_point(laws_, params_, m_, only_, F_, h_n_, h_, P_, d_):
    law = _typed_for(only_)
    if law == ANY_LAW:
        chain = _CHAINS[UPDATE]

        def impl(laws_, params_, m_, only_, F_, h_n_, h_, P_, d_):
            chain(laws_[m_], F_, _parameters(params_, m_), h_n_, h_, P_, d_)
        return impl
    update, stress = LAWS[law].update, LAWS[law].stress
    if update is not None:
        def impl(laws_, params_, m_, only_, F_, h_n_, h_, P_, d_):
            update(F_, _parameters(params_, m_), h_n_, h_, P_, d_)
        return impl

    def impl(laws_, params_, m_, only_, F_, h_n_, h_, P_, d_):
        stress(F_, _parameters(params_, m_), P_, d_)
    return impl


@overload(stress_tangent_point, inline="always", prefer_literal=True)
def _stress_tangent_point(laws_, params_, m_, only_, F_, h_n_, h_, P_, C_, d_):
    law = _typed_for(only_)
    if law == ANY_LAW:
        chain = _CHAINS[STRESS_TANGENT]

        def impl(laws_, params_, m_, only_, F_, h_n_, h_, P_, C_, d_):
            chain(laws_[m_], F_, _parameters(params_, m_), h_n_, h_, P_, C_, d_)
        return impl
    both = LAWS[law].stress_tangent
    if both is not None:
        def impl(laws_, params_, m_, only_, F_, h_n_, h_, P_, C_, d_):
            both(F_, _parameters(params_, m_), P_, C_, d_)
        return impl

    def impl(laws_, params_, m_, only_, F_, h_n_, h_, P_, C_, d_):
        stress_update_point(laws_, params_, m_, only_, F_, h_n_, h_, P_, d_)
        tangent_point(laws_, params_, m_, only_, F_, C_, d_)
    return impl


@njit(cache=True)
def _tangent_called(laws, params, m, F, C, d):
    """`tangent_point` for any law as a function of its own, compiled once and called."""
    tangent_point(laws, params, m, ANY_LAW, F, C, d)


@njit(cache=True, inline="always")
def tangent_call(laws, params, m, F, C, d):
    """`tangent_point` of any law called, not inlined: the 1D loops call it (every law compiled
    once, not inlined at each call site: their compile time halves), the 2D ones inline
    `tangent_point` (the tangent stays in registers: the hot loops) and call it on a rare path.
    The choice is made at the top of each kernel (``if d == 1:``), where numba prunes the other
    branch before typing; inside an inlined helper both branches would be compiled. F and C go
    through stack copies: an array handed to a call escapes, and the caller's would then stay in
    memory through its whole loop (a tenth of the DGMPM law pass)."""
    F_c, C_c = scratch((3, 3)), scratch((d, d, d, d))
    for i in range(3):
        for a in range(3):
            F_c[i, a] = F[i, a]
    _tangent_called(laws, params, m, F_c, C_c, d)
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
                            f"is not one of {KNOWN}; add its row to LAWS in materials/points.py)")
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
    parallel.rows(len(flat), lambda lo, hi: kernel(laws, params, flat[lo:hi], C[lo:hi]))
    return C.reshape(shape + (d, d, d, d))
