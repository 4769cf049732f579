"""Material laws evaluated on d-dimensional states, one law per particle (or node) group."""
import functools
from dataclasses import dataclass
from functools import cached_property

import numpy as np
from numba import njit

from skdgmpm.materials.points import (energy_densities, law_table, only_law, stress_tangent_point, stress_update_point,
                                      tangent_call)

from .dgmpm_kernels import CellRows, cell_row, record_width, write_record
from .equations import embed as _embed_point, flux_state
from .health import Health, health_point, identity_if_not, summarise, tally
from .parallel import row_product
from . import parallel
from .kernel_cache import kernel_factory, scratch
from .system import DIMENSION, embed


@njit(cache=True, inline="always")
def law_point(laws, params, m, only, u, h_n, h, rho, F, P, q, d):
    """q = [P, v] at the state row u = [F, p] of a point of material m and density rho: its law's
    stress at F embedded in 3D (`points.stress_update_point`, the history h_n of t_n updated into
    h), v = p / rho (F, P: scratch (3, 3), (d, d))."""
    _embed_point(u, F, d)
    stress_update_point(laws, params, m, only, F, h_n, h, P, d)
    flux_state(P, u, rho, q, d)


@kernel_factory
def _states(d, assess, gathered, slots, split, only, sides, n_faces):   # literals: the loops unrolled, the health
    dd, nc = d * d, d * d + d           # computed or not, U read ("") or formed ("csr", "cells": sides and faces
                                        # of the cell rows), the face records (slots > 0) or not, one law
    width = record_width(d, slots, split) if slots else 1

    def states(laws, params, index, U, rho, h_n, h, Q, health, motion, gather, records):
        """Each point's row copied into stack scratch: a row view (U[k], h[k]) handed to the
        inlined law would be reference counted at every point (half the time of the pass). With
        ``assess``, also the point's health (`skdgmpm.health.health_point`) at the law's tangent,
        tallied into the chunk's summary and, where its arrays are not empty, into ``health`` =
        (finite, J, lowest, speed, densities of the materials), and its position
        moved with the material, x + dt (v_old + v) / 2 (trapezoidal), ``motion`` = (x, v_old,
        dt / 2, new x). With ``gathered``, each point's U is first formed and written into U: "csr",
        its row of a sparse product, ``gather`` = (CSR rows of the points, nodal values)
        (`parallel.row_product`); "cells", its row of a forward Euler stage with one particle per
        cell, ``gather`` a `dgmpm_kernels.CellRows` (`cell_row`).
        With ``slots`` (and ``assess``), also each point's face record at the law's tangent
        (`skdgmpm.dgmpm_kernels.write_record`, its ``slots`` face directions, the split part with
        ``split``) into row row[k] of ``records`` = (rec, row, normals, record states): DGMPM with
        one particle per cell reads its cells' records from the pass that made their states."""
        F, P, u, C = scratch((3, 3)), scratch((d, d)), scratch((nc,)), scratch((d, d, d, d))
        n_c, r, q, s = scratch((max(slots, 1), d)), scratch((width,)), scratch((nc,)), scratch((nc,))
        first, J_min, omega_min, fastest = -1, np.inf, np.inf, -np.inf
        n_h = h_n.shape[1]
        h_k_n, h_k = scratch((n_h,)), scratch((n_h,))
        finite, J, lowest, speed, rho_m = health
        keep = len(finite) > 0
        for k in range(len(U)):
            if gathered == "csr":
                indptr, indices, data, nodal = gather
                row_product(indptr, indices, data, nodal, k, u, nc)
            elif gathered == "cells":
                cell_row(gather, k, s, u, nc, sides, n_faces)
            if gathered:
                for c in range(nc):
                    U[k, c] = u[c]
            else:
                for c in range(nc):
                    u[c] = U[k, c]
            for c in range(n_h):
                h_k_n[c] = h_n[k, c]
            m = index[k]
            if assess and d > 1:            # the tangent beside the stress (1D: called apart, below)
                _embed_point(u, F, d)
                stress_tangent_point(laws, params, m, only, F, h_k_n, h_k, P, C, d)
                flux_state(P, u, rho[k], q, d)
            else:
                law_point(laws, params, m, only, u, h_k_n, h_k, rho[k], F, P, q, d)
            for c in range(n_h):
                h[k, c] = h_k[c]
            ok = True
            for c in range(nc):
                Q[k, c] = q[c]
                ok = ok and np.isfinite(q[c])
            if assess:
                for c in range(nc):
                    ok = ok and np.isfinite(u[c])
                if not ok or d == 1:        # not finite: the health of F = I; 1D: the tangent called apart
                    identity_if_not(ok, F)
                    tangent_call(laws, params, m, only, F, C, d)
                J_k, lo, speed_k = health_point(F, C, rho_m[m], d)
                lo = lo if ok else np.nan
                if keep:
                    finite[k], J[k], lowest[k], speed[k] = ok, J_k, lo, speed_k
                first, J_min, omega_min, fastest = tally(k, ok, J_k, lo, speed_k, first, J_min, omega_min, fastest)
                x, v_old, half_dt, x_new = motion
                for i in range(x.shape[1]):
                    x_new[k, i] = x[k, i] + half_dt * (v_old[k, i] + Q[k, dd + i])
                if slots:
                    rec, row, normals, rec_state = records
                    write_record(q, rho[k], C, normals, row[k], rec, rec_state, n_c, r, d, slots, split)
        return first, J_min, omega_min, fastest
    return states


@kernel_factory
def _stresses(d, assess, only):         # literals: the loops unrolled, the health computed or not, one law
    def stresses(laws, params, index, F_n, h_n, h, P_n, health):
        """P (n, d, d) at F (n, d, d) with the history of t_n and its update: each point copied
        into stack scratch, embedded, and its law's `stress_update_point`. With ``assess``, also
        the point's health at the law's tangent into ``health`` = (finite, J, lowest, speed,
        densities of the materials), as `skdgmpm.health.assess` computes it where the rest of the
        state (momentum, velocity) is finite: ``finite`` covers F and P."""
        F, P, u, C = scratch((3, 3)), scratch((d, d)), scratch((d * d,)), scratch((d, d, d, d))
        n_h = h_n.shape[1]
        h_k_n, h_k = scratch((n_h,)), scratch((n_h,))
        first, J_min, omega_min, fastest = -1, np.inf, np.inf, -np.inf
        finite, J, lowest, speed, rho_m = health
        for k in range(len(F_n)):
            for i in range(d):
                for a in range(d):
                    u[i * d + a] = F_n[k, i, a]
            for c in range(n_h):
                h_k_n[c] = h_n[k, c]
            _embed_point(u, F, d)
            m = index[k]
            if assess and d > 1:            # the tangent beside the stress (1D: called apart, below)
                stress_tangent_point(laws, params, m, only, F, h_k_n, h_k, P, C, d)
            else:
                stress_update_point(laws, params, m, only, F, h_k_n, h_k, P, d)
            for c in range(n_h):
                h[k, c] = h_k[c]
            ok = True
            for i in range(d):
                for a in range(d):
                    P_n[k, i, a] = P[i, a]
                    ok = ok and np.isfinite(P[i, a]) and np.isfinite(u[i * d + a])
            if assess:
                finite[k] = ok
                if not ok or d == 1:        # not finite: the health of F = I; 1D: the tangent called apart
                    identity_if_not(ok, F)
                    tangent_call(laws, params, m, only, F, C, d)
                J[k], lo, speed[k] = health_point(F, C, rho_m[m], d)
                lowest[k] = lo if ok else np.nan
                first, J_min, omega_min, fastest = tally(k, ok, J[k], lowest[k], speed[k], first, J_min, omega_min,
                                                         fastest)
        return first, J_min, omega_min, fastest
    return stresses


@functools.lru_cache(maxsize=8)
def _no_gather(n, width):
    """The empty gather of `MaterialSet.update` (a CSR of n empty rows, no nodal values): read,
    never written, so made once per size (its indptr is n + 1 zeros, 256 kB at 256^2, zeroed
    afresh at every step before). Left writable: numba types a read-only array apart, and would
    compile the law's pass twice."""
    return (np.zeros(n + 1, np.int32), np.zeros(0, np.int32), np.zeros(0)), np.zeros((0, width))


@dataclass(frozen=True)
class MaterialSet:
    """The scene's materials and, for a batch of points, which one applies (``index`` (n,))."""

    materials: tuple

    def _apply(self, method, F, index, shape, d, *args):
        F3 = embed(F)
        if len(self.materials) == 1:                 # no masks, no copies
            return getattr(self.materials[0], method)(F3, *args)[(slice(None),) + (slice(0, d),) * len(shape)]
        out = np.empty((len(F),) + shape)
        for k, mat in enumerate(self.materials):
            sel = index == k
            if sel.any():
                out[sel] = getattr(mat, method)(F3[sel], *args)[(slice(None),) + (slice(0, d),) * len(shape)]
        return out

    @cached_property
    def laws(self):
        """The compiled point laws' table (`skdgmpm.materials.points.law_table`)."""
        return law_table(self.materials)

    @cached_property
    def n_history(self):
        """Width of the points' history array: the most internal variables of any law (0: every
        law is hyperelastic, and the history costs nothing)."""
        return max(m.n_history for m in self.materials)

    @cached_property
    def history_names(self):
        """Column names of the history array (the widest law's; a law with plastic flow puts
        ``"eqp"`` first, so that column is the equivalent plastic strain of every such law)."""
        return max((m.history_names for m in self.materials), key=len)

    def initial_history(self, index):
        """History of points in the virgin state, (n, n_history), each with its material's."""
        out = np.zeros((len(index), self.n_history))
        for k, mat in enumerate(self.materials):
            sel = index == k
            out[sel, : mat.n_history] = mat.initial_history(int(sel.sum()))
        return out

    def field(self, name, history):
        """The history column ``name`` of the points (n,), or None if no law has it."""
        return history[:, self.history_names.index(name)] if name in self.history_names else None

    @cached_property
    def densities(self):
        """Reference density of each material (n_mat,): the wave speeds of the health check."""
        return np.array([m.rho for m in self.materials])

    def update(self, U, index, rho, history):
        """(Q, history_{n+1}): Q = [P(F, history_n), p / rho0] from states U = [F, p] (n, d*d + d),
        densities rho (n,) and the internal variables of t_n (n, n_history), with their update;
        one compiled pass over the points (no embedded copies, masks or per-law batches)."""
        return self._update(U, index, rho, history, None)

    def update_and_assess(self, U, index, rho, history, motion, gather=None, records=None, points=True):
        """`update`, the new state's `skdgmpm.health.Health` and the points' new positions in the
        same pass over the points (the law's tangent at F beside its stress: F embedded once, the
        state read once): (Q, history, Health, x). ``points`` False: the Health's summary only
        (first bad point, extremes), no per-point array written (`Health.kept`). ``motion`` = (x
        (n, dim), v_old (n, dim), dt): the positions moved by the trapezoidal rule, x + dt (v_old +
        v) / 2. ``gather`` = (A CSR,
        nodal values): the points' states are A @ nodal, computed row by row in the pass and
        written into U (the same bits as `parallel.matmul`); or a `dgmpm_kernels.CellRows`: the
        points' states are its rows (the same bits as `dgmpm_kernels.cell_update`). ``records`` = (rec, row, normals,
        record states): each point's face record also written, into row row[k] of rec = (face
        parts, split parts) (rows distinct: `_states`; the split parts' width says whether the
        records hold them)."""
        return self._update(U, index, rho, history, motion, gather, records, points)

    def _update(self, U, index, rho, history, motion, gather=None, records=None, points=True):
        if history is None:
            history = self.initial_history(np.asarray(index)) if self.n_history else np.empty((len(U), 0))
        n, assess = len(U), motion is not None
        Q, h = np.empty(U.shape), np.empty_like(history)
        # the per-point health only where asked: four arrays a step that no step reads (3-7 % of
        # the law's pass of DGMPM at 256^2), the summary being the step's
        m = n if assess and points else 0
        health = (np.empty(m, dtype=np.bool_), np.empty(m), np.empty(m), np.empty(m), self.densities)
        if assess:
            x, v_old, dt = motion
            x_new = np.empty_like(x)
            moved = (x, v_old, 0.5 * dt, x_new)
        else:
            moved = (np.empty((0, 1)), np.empty((0, 1)), 0.0, np.empty((0, 1)))
        d = DIMENSION[U.shape[1]]
        if records is None:
            slots, split = 0, False
            records = ((np.empty((0, 1)), np.empty((0, 0))), np.zeros(0, np.int32), np.empty((0, 1, d)),
                       np.empty(0, np.int8))
        else:
            slots = records[2].shape[1]
            split = records[0][1].shape[1] > 0
        if isinstance(gather, CellRows):
            gathered, (_, sides, n_faces), spec = "cells", gather.sizes, CellRows.SPEC
            gather = tuple(gather)
        else:
            A, nodal = _no_gather(n, U.shape[1]) if gather is None else (parallel.csr(gather[0]), gather[1])
            gathered, sides, n_faces, spec = "" if gather is None else "csr", 0, 0, "(iwww)"
            gather = (*A, nodal)
        (laws, params), kernel = self.laws, _states(d, assess, gathered, slots, split, only_law(self.laws[0]), sides,
                                                    n_faces)
        index, rho = np.asarray(index, dtype=np.int64), np.asarray(rho, dtype=float)
        # health and motion empty without assess, the records' rows without slots: their chunks empty
        results = parallel.chunked(n, kernel, f"wwrrrrrr(rrrrw)(rrwr){spec}(wrww)",
                                   (laws, params, index, U, rho, history, h, Q, health, moved, gather, records), 4)
        if not assess:
            return Q, h
        summary = summarise(parallel.chunk_starts(n), results)
        finite, J, lowest, speed, _ = health if points else (None,) * 5
        return Q, h, Health(finite, J, lowest, speed, summary), x_new

    def state(self, U, index, rho, history=None):
        """Q = [P(F), p / rho0] from states U = [F, p] (n, d*d + d) and densities rho (n,), with
        the internal variables ``history`` (n, n_history) of t_n (None: none, or the virgin
        state), which stay as they are."""
        return self.update(U, index, rho, history)[0]

    def stress(self, F, index):
        """First Piola-Kirchhoff P(F): (n, d, d) -> (n, d, d) (a law with internal variables: in
        its virgin state)."""
        d = F.shape[1]
        return self._apply("first_piola", F, index, (d, d), d)

    def stress_update(self, F, index, history, assess=False):
        """(P, history_{n+1}) at F (n, d, d) from the internal variables of t_n (n, n_history):
        one compiled pass of the point laws over the points, on the threads (a law without
        internal variables returns ``history`` as it is). With ``assess``: (P, history, health),
        the `skdgmpm.health.Health` of the points' F and P at the law's tangent in the same pass
        (`Health.finite` covers F and P only: the caller checks the rest of its state)."""
        n, d = len(F), F.shape[1]
        h_n = history if self.n_history else np.empty((n, 0))
        if h_n is None:
            h_n = self.initial_history(np.asarray(index))
        P, h = np.empty((n, d, d)), np.empty_like(h_n)
        m = n if assess else 0
        health = (np.empty(m, dtype=np.bool_), np.empty(m), np.empty(m), np.empty(m), self.densities)
        F = np.ascontiguousarray(F, dtype=float)
        (laws, params), kernel = self.laws, _stresses(d, assess, only_law(self.laws[0]))
        index = np.asarray(index, dtype=np.int64)
        results = parallel.chunked(n, kernel, "wwrrrrr" + ("(rrrrw)" if assess else "w"),
                                   (laws, params, index, F, h_n, h, P, health), 4)
        h = h if self.n_history else history
        if not assess:
            return P, h
        return P, h, Health(*health[:4], summarise(parallel.chunk_starts(n), results))

    def tangent(self, F, index):
        """C = dP/dF restricted to the d-dimensional system: (n, d, d, d, d); for a law with
        internal variables, the tangent its Riemann solver uses (`tangent_point`)."""
        d = F.shape[1]
        return self._apply("tangent_block", F, index, (d, d, d, d), d, d)

    def energy(self, F, index, history=None):
        """Stored (recoverable) energy density per reference volume (n,) at F (n, d, d), with the
        internal variables ``history`` (n, n_history) in force (None: none, or the virgin state):
        the laws' compiled point energies in one pass over the points, on the threads."""
        if history is None:
            history = self.initial_history(np.asarray(index)) if self.n_history else np.empty((len(F), 0))
        return energy_densities(*self.laws, index, F, history)

    def dissipation(self, index, history):
        """Plastic work density done up to ``history`` (n,) (zero for hyperelastic laws)."""
        out = np.zeros(len(index))
        for k, mat in enumerate(self.materials):
            sel = index == k
            if mat.n_history:
                out[sel] = mat.dissipation(history[sel, : mat.n_history])
        return out

    def cauchy(self, F, index, history=None):
        """Cauchy stress sigma = P F^T / J of the embedded 3x3 state: (n, 3, 3)."""
        F3 = embed(F)
        out = np.empty((len(F), 3, 3))
        for k, mat in enumerate(self.materials):
            sel = index == k
            out[sel] = (mat.cauchy(F3[sel], history[sel, : mat.n_history]) if mat.n_history and history is not None
                        else mat.cauchy(F3[sel]))
        return out

