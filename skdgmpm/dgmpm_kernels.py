"""Compiled face passes of first-order DGMPM: one loop over a face set per right-hand side.

Each side of a face needs its state q = [P, v], 1 / rho, the law's tangent C and the impedances
Z = sqrt(rho A_n) (and Z^-1) along the face and, for CTU, along the cell's two edges adjacent to
it: its *side record* (`record_width`). The cell records keep all of it but q, which the face
passes read from Q at the cell's row (its particle, or its first node: ``rows``), where it is
already (48 bytes a 2D cell not written twice). A cell whose nodes all hold one state (bit for bit: one
particle in the cell, R18's usual layout, or a uniform field) has one record for its four faces,
computed once per right-hand side by `cell_records` (the law at the cell, the impedances along the
cell's face directions), or with one particle per cell by the law's pass that made the state
(`write_record`, `skdgmpm.constitutive`); a side whose cell's nodes differ computes its trace's record at the face
(the trace gathered through its CSR row, summed in scipy's order). The records of a cell are
computed by the same point functions as at a face (the law's `skdgmpm.materials.points`,
`equations.impedance`): the two paths differ only in where the state is read.

For every face the pass then solves the linearised Riemann problem (`skdgmpm.equations`)
and, for CTU, splits each fluctuation on the characteristic basis of the two edges of
the cell it enters as soon as it is known, writing the two parts beside the face's flux; each
edge then gathers the parts it receives (`DGMPM.interface_flux`: a CSR row gather, signs as
weights), in face order. With every cell recorded, the faces keep their fluctuations instead and
each cell splits the sums of those entering it (`cell_corrections`). Every pass writes
its own rows only, so that it runs in chunks on several threads with the same bits
(`skdgmpm.parallel`). The corrections are proportional to Delta t (G = -dt / (2 h) B+ A dU): the
interior pass stores them per unit Delta t, so that a repeated attempt of the CFL guard reuses
the whole pass; the boundary pass (its stationary states depend on time) is redone, and
`euler_update` adds -int Phi (F* + dt G) to the residual as it advances the nodes.

Face-set arrays as in `skdgmpm.faces` ((nf, d) normals, (nf,) measures); a trace is the triple
(indptr, indices, data) of its CSR matrix; a CTU topology of one face side is
(h (nf,), normals (2, nf, 2), interior edge (2, nf), boundary edge (2, nf), sign (2, nf)) as built
by `DGMPM._setup_transverse` (empty arrays for DCU); the interior pass takes (h, normals (nf, 2, 2))
of each side, face-major so that a chunk of faces is a contiguous slice.
"""
from typing import NamedTuple

import numpy as np
from numba import njit

from skdgmpm.materials.points import only_law, tangent_call, tangent_point, tangent_points

from . import parallel
from .equations import (add_normal_flux, ctu_parts, ctu_parts_opposite, ctu_split, embed, fluctuations, godunov,
                        impedance, power, traction)
from .bcs import ghost_face
from .faces import gather_row
from .health import identity_if_not
from .integrators import base_entry, base_parts
from .kernel_cache import kernel_factory, scratch
from .system import DIMENSION, volume_row


# ---------------------------------------------------------------- point pieces (one face side)
@njit(cache=True, inline="always")
def _gather(trace, f, U, Q, rho, q, F, d):
    """`faces.gather_row` (Q into q, U's F part into the embedded F) and the row applied to rho
    (returned), summed in CSR order."""
    gather_row(trace, f, U, Q, q, F, d)
    indptr, indices, data = trace
    r = 0.0
    for k in range(indptr[f], indptr[f + 1]):
        r += data[k] * rho[indices[k]]
    return r


@njit(cache=True, inline="always")
def _integrate(trace, f, scale, value, w, R):
    """R[i] += w_i T[f, i] (scale value) over row f of a trace (value an array or a tuple), with
    the node weights w = (step, inv_M): w_i = step inv_M[i]."""
    indptr, indices, data = trace
    step, inv_M = w
    for k in range(indptr[f], indptr[f + 1]):
        n, t = indices[k], data[k]
        w_n = step * inv_M[n]
        for c in range(len(value)):
            R[n, c] += w_n * (t * (scale * value[c]))


@njit(cache=True, inline="always")
def _add_boundary_edges(edge_bnd, f, G_0, G_1, corr_bnd):
    """A boundary edge j of either of the two edges gets G_e - G_(1-e) into corr_bnd[j] (its ghost
    cell, a copy of the cell, sends back the opposite edge's part)."""
    j = edge_bnd[0, f]
    if j >= 0:
        for k in range(6):
            corr_bnd[j, k] += G_0[k] - G_1[k]
    j = edge_bnd[1, f]
    if j >= 0:
        for k in range(6):
            corr_bnd[j, k] += G_1[k] - G_0[k]


# ---------------------------------------------------------------- side records
# The layout of a side record, written once: what a face reads, q (nc) and per face direction of
# the cell (``slots``) its impedance Z = sqrt(rho A_n) (d * d each); then, for CTU's split only,
# 1 / rho, the tangent C (d^4) and per face direction Z^-1 (d * d each). DCU's records stop
# after the face part (14 numbers in 2D, not 39: the bytes a record pass writes). The cell
# records keep the two parts in two arrays, ``rec`` = (face parts, split parts), and of the face
# part only the impedances (`kept_width`): q is Q's row of the cell (`_copy_state`). The face pass
# reads 64 bytes of each of its cells' record rows, in rows of 64 bytes, not of 312 (the split
# part between them would be half the lines it pulls from memory), and 48 of Q's.
@njit(cache=True, inline="always")
def face_width(d, slots):
    """Entries of a side record's face part: its state q and its impedances."""
    return d * d + d + d * d * slots


@njit(cache=True, inline="always")
def kept_width(d, slots):
    """Entries of a side record's face part that the cell records keep (their first array): the
    impedances; q is Q's row (`_copy_state`)."""
    return face_width(d, slots) - (d * d + d)


@njit(cache=True, inline="always")
def split_width(d, slots, split=True):
    """Entries of a side record's split part (the second array): 1 / rho, C, Z^-1 per face
    direction; none without ``split`` (DCU)."""
    return (1 + d ** 4 + d * d * slots) if split else 0


def record_width(d, slots, split=True):
    """Entries of one side record: its face part, and with ``split`` (CTU) its split part."""
    return face_width(d, slots) + split_width(d, slots, split)


@njit(cache=True, inline="always")
def _impedance_at(d, slot):
    """Where Z along the face direction ``slot`` starts."""
    return d * d + d + d * d * slot


@njit(cache=True, inline="always")
def _inv_rho_at(d, slots):
    return face_width(d, slots)


@njit(cache=True, inline="always")
def _tangent_at(d, slots):
    return _inv_rho_at(d, slots) + 1


@njit(cache=True, inline="always")
def _inverse_impedance_at(d, slots, slot):
    """Where Z^-1 along the face direction ``slot`` starts (a split record)."""
    return _tangent_at(d, slots) + d ** 4 + d * d * slot


@njit(cache=True, inline="always")
def _edge_slot(k, e, slots):
    """The face direction of the edge e (0, 1) of a quad cell adjacent to its local face k: the
    local faces k + 1 and k + 3 (opposite faces k, k + 2)."""
    return ((k + 1 + 2 * e) % 4) % slots


@njit(cache=True, inline="always")
def fill_record(q, rho, C, normals, r, d, slots, split):
    """The side record r of a state (q, rho) with tangent C, its impedances along the cell's face
    directions normals (slots, d), with its split part if ``split``; False where an acoustic
    tensor is not positive definite."""
    nc = d * d + d
    Z, Zi = scratch((d, d)), scratch((d, d))
    for k in range(nc):
        r[k] = q[k]
    if split:
        r[_inv_rho_at(d, slots)] = 1.0 / rho
        o = _tangent_at(d, slots)
        for i in range(d):
            for a in range(d):
                for j in range(d):
                    for b in range(d):
                        r[o] = C[i, a, j, b]
                        o += 1
    ok = True
    n = scratch((d,))
    for s in range(slots):
        for i in range(d):
            n[i] = normals[s, i]
        ok = impedance(C, n, rho, Z, Zi, d) and ok
        o, oi = _impedance_at(d, s), _inverse_impedance_at(d, slots, s)
        for i in range(d):
            for j in range(d):
                r[o + i * d + j] = Z[i, j]
                if split:
                    r[oi + i * d + j] = Zi[i, j]
    return ok


@njit(cache=True, inline="always")
def write_record(q, rho, C, normals, c, rec, state, n_c, r, d, slots, split):
    """The side record of cell c (`fill_record`, the cell's face directions normals[c]) into row c
    of rec = (face parts but q, split parts), and its record state: 1, or 2 where an acoustic
    tensor is not positive definite (`cell_records`, and the law's pass with one particle per cell,
    `skdgmpm.constitutive`). n_c (slots, d) and r (record width) are stack scratch (rows copied,
    never viewed)."""
    for s in range(slots):
        for i in range(d):
            n_c[s, i] = normals[c, s, i]
    state[c] = 1 if fill_record(q, rho, C, n_c, r, d, slots, split) else 2
    face, rest = rec
    nc, o = d * d + d, face_width(d, slots)
    for k in range(kept_width(d, slots)):       # widths from the literals: the copies unroll
        face[c, k] = r[nc + k]
    for k in range(split_width(d, slots, split)):
        rest[c, k] = r[o + k]


@njit(cache=True, inline="always")
def _copy_record(rec, c, r, d, slots, split):
    """Row c of the cell records rec = (face parts but q, split parts) into the side record r
    (stack scratch: no array view, whose reference counting would cost more than the copy), all
    but its state r[:nc] (`_copy_state`, for a reader that needs it); with a literal ``split`` the
    copies unroll."""
    face, rest = rec
    nc, o = d * d + d, face_width(d, slots)
    for k in range(kept_width(d, slots)):
        r[nc + k] = face[c, k]
    for k in range(split_width(d, slots, split)):
        r[o + k] = rest[c, k]


@njit(cache=True, inline="always")
def _copy_state(Q, row, q, d):
    """The state of a recorded cell, Q's row ``row`` (the cell's particle or first node), into
    q[:nc]: what its record would have repeated."""
    for k in range(d * d + d):
        q[k] = Q[row, k]


@njit(cache=True, inline="always")
def _copy_side(rec, state, c, slot, Q, row, q, Z, d):
    """What a face reads of recorded cell c: its state, Q's row ``row``, into q[:nc] and its
    impedance along the face direction ``slot`` into Z (10 of a 2D side record's 39 numbers);
    whether it is admissible."""
    _copy_state(Q, row, q, d)
    o = _impedance_at(d, slot) - (d * d + d)        # where the record keeps it
    face = rec[0]
    for i in range(d):
        for j in range(d):
            Z[i, j] = face[c, o + i * d + j]
    return state[c] == 1


@njit(cache=True, inline="always")
def _record_tangent(r, C, d, slots):
    """C (d, d, d, d) of a split side record."""
    o = _tangent_at(d, slots)
    for i in range(d):
        for a in range(d):
            for j in range(d):
                for b in range(d):
                    C[i, a, j, b] = r[o]
                    o += 1


@njit(cache=True, inline="always")
def _record_impedance(r, slot, Z, d):
    """Z (d, d) of a side record along the face direction ``slot``."""
    o = _impedance_at(d, slot)
    for i in range(d):
        for j in range(d):
            Z[i, j] = r[o + i * d + j]


@njit(cache=True, inline="always")
def _record_pair(r, slots, slot):
    """(Z, Z^-1) of a split 2D side record along the face direction ``slot``, as the 8-tuple
    `equations.ctu_parts` takes."""
    o, oi = _impedance_at(2, slot), _inverse_impedance_at(2, slots, slot)
    return (r[o], r[o + 1], r[o + 2], r[o + 3], r[oi], r[oi + 1], r[oi + 2], r[oi + 3])


def cell_records(dofs, U, Q, rho, cell_material, laws, params, normals, rec, state):
    """The side record of every cell whose nodes hold one state (bit for bit: one particle in the
    cell, or a uniform field), into rec = (face parts (n_cells, `face_width`), split parts
    (n_cells, `split_width`, 0 without the split)): every face of such a cell sees
    that state, so its tangent and impedances are computed once, not at each of its faces. state
    (n_cells,) int8: 0 the nodes differ (the faces compute their traces' records), 1 recorded,
    2 recorded but an acoustic tensor is not positive definite. dofs (n_cells, nodes per cell);
    normals (n_cells, slots, d) the cell's face directions; the split parts' width says whether
    the records hold them."""
    d, slots = normals.shape[2], normals.shape[1]
    split = rec[1].shape[1] > 0
    kernel = _cell_records(d, slots, dofs.shape[1], split, only_law(laws))
    parallel.chunked(len(dofs), kernel, "rwwwrwwr(rr)r", (dofs, U, Q, rho, cell_material, laws, params, normals, rec,
                                                           state))


@kernel_factory
def _cell_records(d, slots, nodes, split, only):
    nc, width = d * d + d, record_width(d, slots, split)

    def cell_records(dofs, U, Q, rho, cell_material, laws, params, normals, rec, state):
        F, C, u, q = scratch((3, 3)), scratch((d, d, d, d)), scratch((nc,)), scratch((nc,))
        n_c, r = scratch((slots, d)), scratch((width,))
        for c in range(len(dofs)):          # rows copied into stack scratch: no array views (their
            n0 = dofs[c, 0]                 # reference counting costs more than the copies)
            same = True
            for k in range(1, nodes):           # & not and: no branch per number
                n = dofs[c, k]
                same &= rho[n] == rho[n0]
                for j in range(nc):
                    same &= (U[n, j] == U[n0, j]) & (Q[n, j] == Q[n0, j])
            if not same:
                state[c] = 0
                continue
            for j in range(nc):
                u[j], q[j] = U[n0, j], Q[n0, j]
            embed(u, F, d)
            m = cell_material[c]
            if d == 1:
                tangent_call(laws, params, m, only, F, C, d)
            else:
                tangent_point(laws, params, m, only, F, C, d)
            write_record(q, rho[n0], C, normals, c, rec, state, n_c, r, d, slots, split)
    return cell_records


# ---------------------------------------------------------------- interior faces
def interior_pass(T_L, T_R, U, Q, rho, N, cell_L, cell_R, cell_material, laws, params, records, ctu, topo_L,
                  topo_R, flux, G):
    """Godunov flux of every interior face into flux (nf, nc) and, for ``ctu`` (2D), the
    transverse parts per unit Delta t of both sides' fluctuations into G (nf, 4, nc): side L's
    for its cell's two edges in G[:, 0:2], side R's in G[:, 2:4] (summed on the edges by a row
    gather, `parallel.matmul`: each face writes its own rows only). ``records`` = (rec,
    state, normals, local face of each face in cell L, in cell R, recorded, traces, rows)
    (`cell_records`; rows (n_cells,) int32: each cell's row of U and Q, where a recorded cell's
    state is read): a side whose cell is recorded reads its record, another computes its
    trace's record. With ``recorded`` (every cell is) CTU writes the two fluctuations into G (nf,
    2, nc) instead, for `cell_corrections`. ``traces``: whether a cell may be unrecorded (any
    layout but one particle per cell); without, the trace path is not compiled. One kernel serves
    a grid's every state, recorded or not: a run compiles it in its first step. G and the
    topologies are empty without CTU. Returns the pass, the faces in chunks on the threads (a
    `parallel.Pass`, to run alone or with the boundary faces': `parallel.together`), which
    returns the first face whose acoustic tensor is not positive definite, or -1."""
    rec, state, normals, k_L, k_R, recorded, traces, rows = records
    kernel = _interior_pass(N.shape[1], normals.shape[1], bool(traces), only_law(laws))
    return parallel.Pass(len(N), kernel, "ccwwwrrrwwwwwwwrrww(rr)(rr)rr",
                         (parallel.csr(T_L), parallel.csr(T_R), U, Q, rho, N, cell_L, cell_R, cell_material, laws,
                          params, rec, state, rows, normals, k_L, k_R, bool(recorded), ctu, topo_L, topo_R, flux, G),
                         "first")


@kernel_factory
def _interior_pass(d, slots, traces, only):  # literals: the loops unrolled, the trace path compiled only if needed
    nc, dd = d * d + d, d * d
    width = record_width(d, slots)

    def interior_pass(T_L, T_R, U, Q, rho, N, cell_L, cell_R, cell_material, laws, params, rec, state, rows,
                      normals, k_L, k_R, recorded, ctu, topo_L, topo_R, flux, G):
        s_L, s_R, w_L, w_R = scratch((width,)), scratch((width,)), scratch((nc,)), scratch((nc,))
        q_L, q_R, F_L, F_R = scratch((nc,)), scratch((nc,)), scratch((3, 3)), scratch((3, 3))
        C_L, C_R, Z_L, Z_R = scratch((d, d, d, d)), scratch((d, d, d, d)), scratch((d, d)), scratch((d, d))
        t_L, t_R, t_s, v_s = scratch((d,)), scratch((d,)), scratch((d,)), scratch((d,))
        n, v_L, v_R, o = scratch((d,)), scratch((d,)), scratch((d,)), scratch((nc,))
        rho_f = scratch((2,))                # each side's trace's density
        for f in range(len(N)):
            c_L, c_R = cell_L[f], cell_R[f]
            if traces:                          # each side's work in a loop over the sides: inlined once, not twice
                trace_L, trace_R = state[c_L] == 0, state[c_R] == 0     # the nodes differ: the trace's record
                for side in range(2):
                    T, q, F, trace = (T_L, q_L, F_L, trace_L) if side == 0 else (T_R, q_R, F_R, trace_R)
                    rho_f[side] = _gather(T, f, U, Q, rho, q, F, d) if trace else 1.0
                m_L, m_R = cell_material[c_L], cell_material[c_R]
                if d == 1:                          # the law called, not inlined (`points.tangent_call`)
                    if trace_L:
                        tangent_call(laws, params, m_L, only, F_L, C_L, d)
                    if trace_R:
                        tangent_call(laws, params, m_R, only, F_R, C_R, d)
                elif trace_L or trace_R:            # both sides' tangents, one inlined law (a recorded side's unused)
                    identity_if_not(trace_L, F_L)
                    identity_if_not(trace_R, F_R)
                    tangent_points(laws, params, m_L, m_R, only, F_L, F_R, C_L, C_R, d)
                ok = True                           # both sides admissible
                for side in range(2):
                    c, q, C, s, Z, k = ((c_L, q_L, C_L, s_L, Z_L, k_L[f]) if side == 0
                                        else (c_R, q_R, C_R, s_R, Z_R, k_R[f]))
                    if state[c] == 0:               # a view: rare path
                        ok &= fill_record(q, rho_f[side], C, normals[c], s, d, slots, ctu)
                    else:
                        _copy_state(Q, rows[c], s, d)
                        _copy_record(rec, c, s, d, slots, ctu)
                        ok &= state[c] == 1
                    _record_impedance(s, k % slots, Z, d)
            else:                               # every cell recorded: no trace read, no tangent needed
                ok = _copy_side(rec, state, c_L, k_L[f] % slots, Q, rows[c_L], s_L, Z_L, d)
                ok &= _copy_side(rec, state, c_R, k_R[f] % slots, Q, rows[c_R], s_R, Z_R, d)
            if not ok:
                return f
            for i in range(d):              # rows copied, not viewed (views are reference counted)
                n[i], v_L[i], v_R[i] = N[f, i], s_L[dd + i], s_R[dd + i]
            traction(s_L, n, t_L, d)
            traction(s_R, n, t_R, d)
            godunov(t_L, v_L, t_R, v_R, Z_L, Z_R, t_s, v_s, d)
            for k in range(nc):
                o[k] = 0.0
            add_normal_flux(t_s, v_s, n, 1.0, o, d)
            for k in range(nc):
                flux[f, k] = o[k]
            if d == 2 and ctu:                  # fluctuations A- dQ into L, A+ dQ into R
                fluctuations(s_L, s_R, n, t_L, t_R, o, w_L, w_R, d)
                if traces and not recorded:     # split at once
                    for side in range(2):
                        w, C, s, k, topo = ((w_L, C_L, s_L, k_L[f], topo_L) if side == 0
                                            else (w_R, C_R, s_R, k_R[f], topo_R))
                        _record_tangent(s, C, d, slots)
                        _split_into(w, C, s, k, topo, f, G, 2 * side, slots)
                else:                           # kept: each cell splits those entering it
                    for k in range(nc):
                        G[f, 0, k], G[f, 1, k] = w_L[k], w_R[k]
        return -1
    return interior_pass


@njit(cache=True, inline="always")
def _split_into(w, C, r, k, topo, f, G, part, slots):
    """`equations.ctu_parts` per unit Delta t (scale -1 / (2 h)) of a fluctuation entering one
    side of face f, local face k of the side's cell with record r: its parts for the cell's two
    edges adjacent to the face (local faces k + 1, k + 3) into G[f, part] and G[f, part + 1]."""
    h, normals = topo
    G_0, G_1 = _record_parts(w, C, r, -1.0 / (2.0 * h[f]), normals[f, 0, 0], normals[f, 0, 1], normals[f, 1, 0],
                             normals[f, 1, 1], k, slots)
    for c in range(6):
        G[f, part, c] = G_0[c]
        G[f, part + 1, c] = G_1[c]


@njit(cache=True, inline="always")
def _record_parts(w, C, r, scale, a0, a1, b0, b1, k, slots):
    """`equations.ctu_parts` of w entering a cell through its local face k, along the cell's two
    edges adjacent to it (local faces k + 1, k + 3; outward normals (a0, a1), (b0, b1)), from the
    cell's split record r (C its tangent): the two parts. With two face directions the edges are
    opposite and share one impedance (`equations.ctu_parts_opposite`)."""
    if slots == 2:
        return ctu_parts_opposite(w, C, r[_inv_rho_at(2, slots)], scale, a0, a1,
                                  _record_pair(r, slots, _edge_slot(k, 0, slots)))
    return ctu_parts(w, C, r[_inv_rho_at(2, slots)], scale, a0, a1, b0, b1,
                     _record_pair(r, slots, _edge_slot(k, 0, slots)), _record_pair(r, slots, _edge_slot(k, 1, slots)))


# ---------------------------------------------------------------- CTU parts summed by the cells
def cell_corrections(sources, scale, signs, rec, normals, W, corr_bnd):
    """The CTU corrections per unit Delta t that the cells send through their faces, every cell
    recorded (2D quads). A cell's edge (local face k) receives the parts of the fluctuations
    entering the cell through its two adjacent faces k + 1, k + 3, each scaled by -1 / (2 h) (h
    the cell's size across that face); the split B+ is linear, so their scaled sum is split once
    (`equations.ctu_parts`, the cell's record: tangent, 1 / rho, impedances), and edges k and
    k + 2 share it: two sums and four splits per cell instead of two splits per fluctuation.
    W (2 nf, nc): row 2 f + side the fluctuation entering that side of interior face f (the face
    pass's), overwritten by the part the side's cell sends through face f (the correction of face
    f is then W[2 f] - W[2 f + 1]: `face_corrections`); a boundary face b gets its part less the
    opposite face's into corr_bnd[b] (its ghost cell, a copy of the cell, sends that back). Each
    cell reads and writes only its own faces' rows. sources (n_cells, 4) int32: 2 f + side of
    each local face, or -1 - b for boundary face b; scale (n_cells, 4): -1 / (2 h) (0 at boundary
    faces, whose fluctuations the boundary pass splits); signs (n_cells, 4): the outward normal of
    local face k is signs[c, k] normals[c, k % slots]. In parallel chunks of the cells."""
    parallel.chunked(len(sources), _cell_corrections(normals.shape[1]), "rrr(rr)rww",
                     (sources, scale, signs, rec, normals, W, corr_bnd))


@kernel_factory
def _cell_corrections(slots):
    width = record_width(2, slots)

    def cell_corrections(sources, scale, signs, rec, normals, W, corr_bnd):
        r, C, w, n, S = scratch((width,)), scratch((2, 2, 2, 2)), scratch((4, 6)), scratch((4, 2)), scratch((6,))
        for c in range(len(sources)):
            _copy_record(rec, c, r, 2, slots, True)
            for k in range(4):                  # the fluctuations entering through the four faces, scaled
                s = sources[c, k]
                for i in range(6):
                    w[k, i] = scale[c, k] * W[s, i] if s >= 0 else 0.0
                for i in range(2):
                    n[k, i] = signs[c, k] * normals[c, k % slots, i]
            _record_tangent(r, C, 2, slots)
            for e in range(2):                  # edges e, e + 2 <- faces e + 1, e + 3
                for i in range(6):
                    S[i] = w[e + 1, i] + w[(e + 3) % 4, i]
                # edges e, e + 2: those adjacent to local face e + 3
                G_a, G_b = _record_parts(S, C, r, 1.0, n[e, 0], n[e, 1], n[e + 2, 0], n[e + 2, 1], e + 3, slots)
                for q in range(2):
                    s = sources[c, e + 2 * q]
                    for i in range(6):
                        g, g_o = (G_a[i], G_b[i]) if q == 0 else (G_b[i], G_a[i])
                        if s >= 0:
                            W[s, i] = g
                        else:
                            corr_bnd[-1 - s, i] = g - g_o
    return cell_corrections


def face_corrections(corr):
    """The CTU correction per unit Delta t of each interior face (nf, nc) from `interface_flux`'s
    (nf, sides, nc): the parts both cells send (sides 2: W[:, 0] - W[:, 1], `cell_corrections`),
    the gathered correction (sides 1), none (sides 0, DCU)."""
    if corr.shape[1] == 2:
        return corr[:, 0] - corr[:, 1]
    return corr[:, 0] if corr.shape[1] == 1 else np.zeros((len(corr), corr.shape[2]))


@njit(cache=True, nogil=True)
def boundary_edge_corrections(to_boundary, G, corr_bnd):
    """corr_bnd[j] += sum_k (G[part_k] - G[other_k]) for each boundary edge j, CSR rows
    ``to_boundary`` (indptr, parts, other parts): its ghost cell, a copy of the cell, sends back
    the opposite edge's part."""
    indptr, parts, other = to_boundary
    for j in range(len(indptr) - 1):
        for k in range(indptr[j], indptr[j + 1]):
            for c in range(G.shape[1]):
                corr_bnd[j, c] += G[parts[k], c] - G[other[k], c]


# ---------------------------------------------------------------- boundary faces
def boundary_faces(T, U, Q, rho, N, cell, cell_material, laws, params, ghosts, ctu, topo, records, flux, t_s, v_s,
                   parts):
    """Every boundary face's interior side (traction
    t_L, velocity v_L, impedance Z = sqrt(rho0 A_N), tangent C, density), its stationary state
    (t*, v*) into t_s, v_s (nf, d) (`bcs.ghost_face` under the face's condition, ``ghosts`` =
    (frame (nf, d, d), imposes velocity (nf, d), values at the time (nf, d), copies the interior
    (nf,)), `bcs.BoundaryGhosts`), its flux F_N(t*, v*) into flux (nf, nc) and, with ``ctu``,
    the transverse corrections per unit Delta t of the fluctuation F_N(t*, v*) - F_N(t_L, v_L)
    entering the cell along its two edges adjacent to the face into parts (nf, 2, nc)
    (`boundary_corrections` adds them where they go). ``records`` = (rec, state, normals, local
    face of each face in its cell, traces, each cell's row of U and Q) (`cell_records`, the
    state's, `interior_pass`): a face whose cell is
    recorded reads its side there (as an interior face does), another gathers its trace and
    evaluates the law's tangent (a face then costs about ten interior faces); without ``traces``
    (every cell always recorded, as `interior_pass` has it) that path is not compiled: a 2D
    kernel without it compiles in a third of the time. Each face writes its own rows:
    chunks run in parallel, each of an eighth of `parallel.MIN_ROWS` faces at least. Returns the
    pass (a `parallel.Pass`), which returns the first face whose acoustic tensor, along the face
    or (CTU) an edge, is not positive definite, or -1."""
    rec, state, normals, local, traces, rows = records
    kernel = _boundary_faces(N.shape[1], normals.shape[1], bool(traces), only_law(laws))
    return parallel.Pass(len(N), kernel, "lh" + "w" * 17,
                         (T, U, Q, rho, N, cell, cell_material, laws, params, ghosts, ctu, topo,
                          (rec, state, local, rows), flux, t_s, v_s, parts), "first", max(1, parallel.MIN_ROWS // 8))


@kernel_factory
def _boundary_faces(d, slots, traces, only):   # without traces the trace path is not compiled
    width, every = record_width(d, slots), not traces       # every: every cell recorded

    def boundary_faces(lo, hi, T, U, Q, rho, N, cell, cell_material, laws, params, ghosts, ctu, topo, records, flux,
                       t_s, v_s, parts):
        nc = d * d + d
        q, F, Zi, w = scratch((nc,)), scratch((3, 3)), scratch((d, d)), scratch((nc,))
        t_L, v_L, Z, C = scratch((d,)), scratch((d,)), scratch((d, d)), scratch((d, d, d, d))
        r, n, t_f, v_f, o = scratch((width,)), scratch((d,)), scratch((d,)), scratch((d,)), scratch((nc,))
        rec, state, local, rows = records
        for f in range(lo, hi):         # rows copied into stack scratch, not viewed (views are reference counted)
            c = cell[f]
            for i in range(d):
                n[i] = N[f, i]
            recorded = state[c] != 0
            if every or recorded:           # the cell's record: its state, the impedance along this face
                if not _copy_side(rec, state, c, local[f] % slots, Q, rows[c], q, Z, d):
                    return f - lo
                if ctu:                     # and its split part, for the corrections
                    _copy_record(rec, c, r, d, slots, True)
                rho_f = 1.0
            else:
                rho_f = _gather(T, f, U, Q, rho, q, F, d)
                m = cell_material[c]
                if d == 1:
                    tangent_call(laws, params, m, only, F, C, d)
                else:
                    tangent_point(laws, params, m, only, F, C, d)
                if not impedance(C, n, rho_f, Z, Zi, d):
                    return f - lo
            ghost_face(ghosts, f, q, n, Z, t_L, v_L, t_f, v_f, d)
            for k in range(nc):
                o[k] = 0.0
            add_normal_flux(t_f, v_f, n, 1.0, o, d)
            for i in range(d):
                t_s[f, i], v_s[f, i] = t_f[i], v_f[i]
            for k in range(nc):
                flux[f, k] = o[k]
            if d == 2 and ctu:              # the fluctuation F_N(t*, v*) - F_N(t_L, v_L) entering the cell
                for k in range(6):
                    w[k] = o[k]
                add_normal_flux(t_L, v_L, n, -1.0, w, d)
                h, edges = topo[0], topo[1]
                scale = -1.0 / (2.0 * h[f])
                if every or recorded:       # the record's impedances along the edges: the same numbers
                    _record_tangent(r, C, d, slots)
                    G_0, G_1 = _record_parts(w, C, r, scale, edges[0, f, 0], edges[0, f, 1], edges[1, f, 0],
                                             edges[1, f, 1], local[f], slots)
                else:
                    ok, G_0, G_1 = ctu_split(w, C, rho_f, scale, edges[0, f, 0], edges[0, f, 1], edges[1, f, 0],
                                             edges[1, f, 1])
                    if not ok:
                        return f - lo
                for k in range(6):
                    parts[f, 0, k], parts[f, 1, k] = G_0[k], G_1[k]
        return -1
    return boundary_faces


@njit(cache=True, nogil=True)
def boundary_corrections(topo, parts, corr, corr_bnd):
    """The boundary faces' CTU parts (nf, 2, nc) (`boundary_faces`) added where they go, face by
    face: an interior edge's to the interior faces' corrections ``corr`` (nf, sides, nc) as
    `interface_flux` keeps them (sides 2: into the row of the side whose cell sends it, sides 1:
    with the edge's sign; `face_corrections`), a boundary edge's to corr_bnd. Serial: boundary
    faces next to one edge write the same rows."""
    _, _, edge_int, edge_bnd, sign = topo
    sides = corr.shape[1]
    for f in range(len(parts)):
        for e in range(2):
            j = edge_int[e, f]
            if j >= 0:
                s = sign[e, f]
                for k in range(6):
                    if sides == 2:              # the part the cell sends: its side's row
                        corr[j, 0 if s > 0 else 1, k] += parts[f, e, k]
                    else:
                        corr[j, 0, k] += s * parts[f, e, k]
        _add_boundary_edges(edge_bnd, f, parts[f, 0], parts[f, 1], corr_bnd)


def boundary_terms(T, measure, N, flux, t_s, v_s, ctu, corr_bnd, dt, weight, R):
    """R += w (-int Phi F over the boundary faces), F their flux (nf, nc) plus, where CTU's filters
    are given as ``ctu`` = (the distinct filters (k, nc, nc), each face's (nf,)), its filtered
    corrections filter (dt corr_bnd) (`DGMPM.transverse_flux`; a few distinct filters are read
    from the caches where one per face came from memory), weighted per node by w = (step, inv_M)
    as in `_integrate`. Returns the power through the boundary, the sum over the faces in order
    of measure t . v (t = P N, v its velocity: (t*, v*) without CTU, read off F with it), summed
    here: numpy's sum of an array of the faces' powers after the pass took 48-65 µs of a 256²
    step (line_profiler; numpy's reduce out of the caches after the passes), more than the pass.
    ``weight`` None: each face's term -m_f F (nf, nc) written into R instead, row f (one particle
    per cell: `CellRows` adds them where each particle's row is formed). One pass on one thread:
    a few thousand faces."""
    return _boundary_terms(N.shape[1], ctu is not None, weight is not None)(
        T, measure, N, flux, t_s, v_s, _NO_FILTER if ctu is None else ctu, corr_bnd, dt,
        _NO_WEIGHT if weight is None else weight, R)


_NO_FILTER = (np.zeros((0, 0, 0)), np.zeros(0, np.int64))
_NO_WEIGHT = (0.0, np.zeros(0))


@kernel_factory
def _boundary_terms(d, ctu, integrate):
    def boundary_terms(T, measure, N, flux, t_s, v_s, filters, corr_bnd, dt, weight, R):
        dd, nc = d * d, d * d + d
        filt, which = filters
        g, c, t_f, v_f = scratch((nc,)), scratch((nc,)), scratch((d,)), scratch((d,))
        total = 0.0
        for f in range(len(measure)):
            if ctu:
                for j in range(nc):
                    c[j] = dt * corr_bnd[f, j]
                x = which[f]
                for k in range(nc):
                    a = 0.0
                    for j in range(nc):
                        a += filt[x, k, j] * c[j]
                    g[k] = flux[f, k] + a
                for i in range(d):          # t = -p, v = -F N of the corrected flux
                    v = 0.0
                    for b in range(d):
                        v += g[i * d + b] * N[f, b]
                    t_f[i], v_f[i] = -g[dd + i], -v
            else:
                for k in range(nc):
                    g[k] = flux[f, k]
                for i in range(d):
                    t_f[i], v_f[i] = t_s[f, i], v_s[f, i]
            total += measure[f] * power(t_f, v_f, d)
            m = -1.0 * measure[f]
            if integrate:
                _integrate(T, f, m, g, weight, R)
            else:                           # the product `_integrate` forms before its weights
                for k in range(nc):
                    R[f, k] = m * g[k]
        return total
    return boundary_terms


def euler_update(gather, flux, corr, dt, Q, stiffness, base, weight, out):
    """out = base + w (volume + G (flux + dt corr)) node by node: a forward Euler stage but its
    boundary terms in one pass over the nodes, the volume term sum_alpha K^alpha F_alpha(Q) of the
    nodal Q computed row by row in the same pass (`system.volume_row`: never stored), given the
    interior faces' fluxes (nf, nc) and corrections per unit Delta t as `interface_flux` gives
    them (nf, sides, nc), `face_corrections`, and w = step M^-1 given as ``weight`` = (step,
    inv_M (n_dofs,)). ``base``: an array, or an integrator's `Combination` (RK2's mean), formed
    here entry by entry.
    G (n_dofs, nf) is the interior surface integral as a gather (`DGMPM.gather_interior`): row i
    holds measure_f (T_R - T_L)[f, i] over the faces f of node i. In parallel chunks of the
    nodes."""
    kind, bases = base_parts(base)
    parallel.chunked(len(out), _euler_update(flux.shape[1], corr.shape[1]), "cwwwwcw(rrrr)(wr)r",
                     (tuple(gather), flux, corr, dt, Q, tuple(stiffness), kind, bases, weight, out))


@kernel_factory
def _euler_update(nc, sides):           # literals: the loops unrolled, the corrections read as they are kept
    d = DIMENSION[nc]

    def euler_update(gather, flux, corr, dt, Q, stiffness, kind, bases, weight, out):
        indptr, indices, data = gather
        step, inv_M = weight
        r = scratch((nc,))
        for i in range(len(indptr) - 1):
            for c in range(nc):
                r[c] = 0.0
            volume_row(Q, stiffness, i, r, d)
            for k in range(indptr[i], indptr[i + 1]):
                f, g = indices[k], data[k]
                for c in range(nc):
                    if sides == 2:
                        r[c] += g * (flux[f, c] + dt * (corr[f, 0, c] - corr[f, 1, c]))
                    elif sides == 1:
                        r[c] += g * (flux[f, c] + dt * corr[f, 0, c])
                    else:
                        r[c] += g * flux[f, c]
            for c in range(nc):
                out[i, c] = base_entry(kind, bases, i, c) + (step * inv_M[i]) * r[c]
    return euler_update


# ---------------------------------------------------------------- one particle per cell
class CellRows(NamedTuple):
    """A forward Euler stage with one particle per cell (`DGMPM` with ``cellwise``), each particle's
    row formed where it is read (`cell_row`): by `cell_update`, or by the law's pass of the step
    that reads it (`skdgmpm.constitutive`: the state written and read in one pass, not two).
    cell (n,) each particle's cell; faces (n_cells, faces per cell) int32: 2 f + side of each
    local face, -1 - b at boundary face b (`DGMPM._cell_faces`); measure (nf,) of the interior
    faces; flux (nf, nc) and corr (nf, sides, nc) as `DGMPM.interface_flux` keeps them; dt;
    step; inv_volume (n,) 1 / V_p; base (n, nc); boundary (nb, nc) the boundary faces' terms
    -m_b F_b (`boundary_terms` without weights)."""
    cell: np.ndarray
    faces: np.ndarray
    measure: np.ndarray
    flux: np.ndarray
    corr: np.ndarray
    dt: float
    step: float
    inv_volume: np.ndarray
    base: np.ndarray
    boundary: np.ndarray

    @property
    def sizes(self):
        """The literal sizes of the compiled row: (nc, sides, faces per cell)."""
        return self.flux.shape[1], self.corr.shape[1], self.faces.shape[1]

    SPEC = "(rwwwwwwrrw)"               # `parallel.chunked`: the particles' arrays cut by rows


@njit(cache=True, inline="always")
def cell_row(rows, p, r, u, nc, sides, n_faces):
    """u = base[p] + step / V_p (sum_k s_k m_f (F*_f + dt corr_f) over the interior faces f of
    the cell of particle p, then + the boundary faces' terms -m_b F_b in the order of b): the
    forward Euler stage and the back map of R18 §5 (f)-(g) as they reduce with one particle
    strictly inside each cell (the projection is that particle's state, the volume term sums to
    zero over the cell's nodes, a face's trace weights to one). s_k = -1 where the cell is side L
    of face f, +1 side R. The boundary terms are added as `boundary_terms` added them face by
    face into the nodal arrays (the same bits). ``rows``: `CellRows`; r: scratch (nc,)."""
    cell, faces, measure, flux, corr, dt, step, inv_volume, base, boundary = rows
    c = cell[p]
    for k in range(nc):
        r[k] = 0.0
    for j in range(n_faces):
        s = faces[c, j]
        if s < 0:
            continue
        f = s >> 1
        g = measure[f] if s & 1 else -measure[f]
        for k in range(nc):
            if sides == 2:
                r[k] += g * (flux[f, k] + dt * (corr[f, 0, k] - corr[f, 1, k]))
            elif sides == 1:
                r[k] += g * (flux[f, k] + dt * corr[f, 0, k])
            else:
                r[k] += g * flux[f, k]
    w = step * inv_volume[p]
    for k in range(nc):
        u[k] = base[p, k] + w * r[k]
    last = -1
    for _ in range(n_faces):            # the cell's boundary faces, lowest first
        b = -1
        for j in range(n_faces):
            s = -1 - faces[c, j]
            if s > last and (b < 0 or s < b):
                b = s
        if b < 0:
            break
        for k in range(nc):
            u[k] += w * boundary[b, k]
        last = b


def cell_update(rows, out):
    """out[p] = `cell_row` of each particle p of ``rows`` (`CellRows`), in parallel chunks of the
    particles."""
    parallel.chunked(len(rows.cell), _cell_update(*rows.sizes), CellRows.SPEC + "r", (tuple(rows), out))


@kernel_factory
def _cell_update(nc, sides, n_faces):
    def cell_update(rows, out):
        r, u = scratch((nc,)), scratch((nc,))
        for p in range(len(out)):
            cell_row(rows, p, r, u, nc, sides, n_faces)
            for k in range(nc):
                out[p, k] = u[k]
    return cell_update
