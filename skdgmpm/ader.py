"""ADER-DGFEM [L23 §3-4]: local space-time predictor, then a one-step corrector.

Predictor (L23 eq 56-64, element-local, no neighbours): the space-time field of order P in space
and time is represented by its values at the (P+1)^d Gauss points of each cell times the P+1
Gauss-Legendre time nodes tau_s (a nodal basis: the DG space restricted to a cell is spanned by
the Lagrange polynomials of its Gauss points). With the time basis phi_k(tau) the weak form in
time gives

    u_hat[s] = U^n - dt sum_s' T[s, s'] sum_alpha D_alpha F_alpha(q_hat[s']),
    T = K_tau^-1 M_tau,  K_tau = phi(1) phi(1)^T - int phi' phi^T,  M_tau = int phi phi^T,

solved by Picard iteration from the Taylor guess u_hat[s] = U^n - dt tau_s DIV F(Q^n) (eq 64);
the law is evaluated at every point and time node at every iteration. For a linear law the
iteration error is multiplied each time by dt T (x) L, L = sum_alpha A_alpha D_alpha, and L is
nilpotent on a cell's polynomials: L^(P+1) = 0 in 1D, L^(2P+1) = 0 on 2D tensor spaces Q_P (mixed
derivatives). From the constant guess the predictor is therefore exact after P + 1 (1D) or
2P + 1 (2D) iterations; the Taylor guess saves two (tested).

Corrector (eq 28-33): u^{n+1} = u^n + dt sum_s w_s M^-1 R(q_hat[s]) with the volume term at the
Gauss points and Godunov fluxes at every facet Gauss point, q traced from the predictor.

Source S = [0, rho0 b(X, t)] (a body force, e.g. of a manufactured solution): the standard ADER
predictor with a source, u_hat[s] = U^n + dt sum_s' T[s, s'] (S[s'] - sum_alpha D_alpha F_alpha),
S at the predictor's points and time nodes t_n + tau_s dt (known, so T S is computed once per
step); the corrector adds int Phi S at the Gauss points at the same time nodes.
"""
from dataclasses import dataclass, field

import numpy as np
import scipy.sparse as sp
from numba import njit
from numpy.polynomial import legendre

from skdgmpm.materials.points import only_law

from . import parallel, system
from .ader_kernels import interior_flux_sum
from .constitutive import law_point
from .dgfem import DGFEM
from .equations import add_flux
from .kernel_cache import kernel_factory, scratch
from .scheme import stage


def _picard_cells(guess, U0, D, T, dt, scale, tol, n_max, law, points, out):
    """The predictor of every cell, each iterated to its own convergence, in one compiled pass: a
    cell's iterates stay in cache from the guess to the last. ``guess`` = (U, Q, D_taylor, g, S):
    with g (R,) = dt tau_s the Taylor guess u_hat[s] = U - g[s] DIV F(Q) (+ g[s] S[s] where S
    (R, nel, n, nc) is not empty) from U and Q = law(U) (nel, n, nc) and the derivative matrices
    D_taylor (d, nel, n, n); with g empty the constant guess u_hat = U. Then: q = law(u_hat) at
    every point and node, new = U0 - dt T DIV F(q) (`_divergence_point`), until max |new -
    u_hat| / scale <= tol over the cell's points, or ``n_max`` iterations; q_hat (R, nel, n, nc)
    gets the law of the last iterate (`constitutive.law_point`), and q_sum (nel, n, nc) its sum
    over the nodes with the weights w (R,), for the corrector's volume term: ``out`` = (u_hat,
    q_hat, w, q_sum). U0 flat (R or 1, nel n nc).
    ``law`` = (laws, params), the law table; ``points`` = (material (nel n,), rho0 (nel n,),
    history of t_n (nel n, n_history), padding (nel n,) bool: q = 0 there). Cells are taken in
    chunks by each thread as it is free (`parallel.chunked`), so that a region that iterates more
    (an impact's front) does not keep the other threads waiting. Returns (most iterations of a
    cell, mean iterations per cell, cells not converged)."""
    laws, params = law
    n_r, nel, n, nc = out[0].shape
    d = D.shape[0]
    literal = d == 2 and n in (4, 9) and n_r in (2, 3)      # 2D S1T1 / S2T2: the loops unrolled
    kernel = _picard_cells_kernel(d, n if literal else None, n_r if literal else None, only_law(laws))
    args = (*guess, U0, D, T, dt, scale, tol, n_max, laws, params, *points, *out)
    results = parallel.chunked(nel, kernel, "w" * len(args) + "lh", args, 3).astype(np.int64)
    return int(results[:, 0].max()), int(results[:, 1].sum()) / max(nel, 1), int(results[:, 2].sum())


@kernel_factory
def _picard_cells_kernel(d, n, n_r, only):
    if n is None:                       # sizes read at run time
        def picard_cells(U, Q, D_g, g, S, U0, D, T, dt, scale, tol, n_max, laws, params, material, rho, h_n, pad,
                         u_hat, q_hat, w, q_sum, lo, hi):
            return _picard_cells_n(U, Q, D_g, g, S, U0, D, T, dt, scale, tol, n_max, laws, params, only, material,
                                   rho, h_n, pad, u_hat, q_hat, w, q_sum, lo, hi, d, u_hat.shape[2],
                                   u_hat.shape[0])
    else:
        def picard_cells(U, Q, D_g, g, S, U0, D, T, dt, scale, tol, n_max, laws, params, material, rho, h_n, pad,
                         u_hat, q_hat, w, q_sum, lo, hi):
            return _picard_cells_n(U, Q, D_g, g, S, U0, D, T, dt, scale, tol, n_max, laws, params, only, material,
                                   rho, h_n, pad, u_hat, q_hat, w, q_sum, lo, hi, d, n, n_r)
    return picard_cells


@njit(cache=True, inline="always")
def _picard_cells_n(U, Q, D_g, g, S, U0, D, T, dt, scale, tol, n_max, laws, params, only, material, rho, h_n, pad,
                    u_hat, q_hat, w, q_sum, lo, hi, d, n, n_r):
    nc = d * d + d
    n_h = h_n.shape[1]
    s, o, x, row, big = scratch((nc,)), scratch((nc,)), scratch((nc,)), scratch((nc,)), scratch((nc,))
    dv, F, P = scratch((n_r, nc)), scratch((3, 3)), scratch((d, d))
    h_k_n, h_k = scratch((n_h,)), scratch((n_h,))
    u, new, q = np.empty((n_r, n, nc)), np.empty((n_r, n, nc)), np.empty((n_r, n, nc))     # one cell's
    most, total, missed = 0, 0, 0
    for c in range(lo, hi):
        for k in range(n):
            if len(g):                          # the Taylor guess (L23 eq 64)
                _divergence_point(Q, c, D_g, c, k, s, o, d, n)
                for t in range(n_r):
                    for v in range(nc):
                        acc = 0.0
                        acc += g[t] * o[v]
                        y = U[c, k, v] - 1.0 * acc
                        u[t, k, v] = y + g[t] * S[t, c, k, v] if len(S) else y
            else:
                for t in range(n_r):
                    for v in range(nc):
                        u[t, k, v] = U[c, k, v]
        change, it = np.nan, 0
        while it < n_max:
            it += 1
            for t in range(n_r):                # the law at every point and node
                for k in range(n):
                    p = c * n + k
                    for v in range(nc):
                        x[v] = u[t, k, v]
                    for v in range(n_h):
                        h_k_n[v] = h_n[p, v]
                    law_point(laws, params, material[p], only, x, h_k_n, h_k, rho[p], F, P, row, d)
                    for v in range(nc):
                        q[t, k, v] = 0.0 if pad[p] else row[v]
            for v in range(nc):
                big[v] = 0.0
            for k in range(n):
                for b in range(n_r):
                    _divergence_point(q, b, D, c, k, s, o, d, n)
                    for v in range(nc):
                        dv[b, v] = o[v]
                p = c * n + k
                for t in range(n_r):            # new = U0 - dt T DIV F(q) at point p
                    t_0 = t if len(U0) > 1 else 0
                    for v in range(nc):
                        acc = 0.0
                        for r in range(n_r):
                            acc += T[t, r] * dv[r, v]
                        y = U0[t_0, p * nc + v] - dt * acc
                        new[t, k, v] = y
                        e = abs(y - u[t, k, v])
                        big[v] = e if (e > big[v] or e != e) else big[v]
            u, new = new, u
            change = 0.0
            for v in range(nc):
                e = big[v] / scale[v]
                change = e if (e > change or e != e) else change
            if change <= tol:
                break
        for t in range(n_r):
            for k in range(n):
                for v in range(nc):
                    u_hat[t, c, k, v] = u[t, k, v]
                    q_hat[t, c, k, v] = q[t, k, v]
        for k in range(n):                      # sum_s w_s q_hat[s], in the order of `_time_sum`
            for v in range(nc):
                acc = w[0] * q[0, k, v]
                for t in range(1, n_r):
                    acc += w[t] * q[t, k, v]
                q_sum[c, k, v] = acc
        most = max(most, it)
        total += it
        missed += 0 if change <= tol else 1
    return most, total, missed


@njit(cache=True, inline="always")
def _divergence_point(Q, i, D, c, k, s, o, d, n):
    """o (nc,) = sum_alpha F_alpha(sum_m D[alpha, c, k, m] Q[i, m]) at point k of cell c, with
    Q[i] (n, nc) the cell's point values (s: scratch (nc,))."""
    nc = d * d + d
    for v in range(nc):
        o[v] = 0.0
    for a in range(d):                  # F_alpha is linear: applied to the weighted sum
        for v in range(nc):
            s[v] = 0.0
        for m in range(n):
            w = D[a, c, k, m]
            for v in range(nc):
                s[v] += w * Q[i, m, v]
        add_flux(s, a, 1.0, o, d)


def _block_scale(U, dd):
    """Per component of the state (n, nc): the largest |U| of its block (F: the first dd
    components, p: the others), 1 where that is 0, nan if any is nan; the largest of the row
    chunks' (exact, in any order)."""
    big = parallel.chunked(len(U), _block_max, "rw", (U, dd), 2)       # (chunks, 2)
    out = np.empty(U.shape[1])
    _block_scale_of(big, dd, out)
    return out


@njit(cache=True, nogil=True)
def _block_scale_of(big, dd, out):
    """`_block_scale` from the chunks' largest |U| per block ``big`` (chunks, 2), into out (nc,):
    each block's largest (nan if a chunk's is), 1 where that is 0. Compiled: numpy's reductions
    and selections on these few numbers took 50-100 µs of a step, out of the caches."""
    scale = np.empty(2)                 # the F block's, the p block's
    for b in range(2):
        m, nan = 0.0, False
        for c in range(big.shape[0]):
            x = big[c, b]
            nan |= x != x
            m = max(m, x)
        scale[b] = np.nan if nan else (m if m != 0.0 else 1.0)
    for k in range(len(out)):
        out[k] = scale[0] if k < dd else scale[1]


@njit(cache=True, nogil=True)
def _block_max(U, dd):
    """The largest |U| of the F block and of the p block of rows U, nan once one is nan (held in
    scalars: stores to a heap array could alias U, which is then reloaded)."""
    big_F = big_p = 0.0
    for p in range(len(U)):
        for c in range(U.shape[1]):
            x = abs(U[p, c])
            if c < dd:
                if x > big_F or x != x:
                    big_F = x
            elif x > big_p or x != x:
                big_p = x
    return big_F, big_p


def _time_sum(w, a):
    """sum_s w[s] a[s] over the time nodes (the leading axis): w[0] a[0] + w[1] a[1] + ..., in
    that order, entry by entry (one compiled pass on the threads)."""
    out = np.empty(a.shape[1:])
    flat, o, w = a.reshape(len(a), -1), out.reshape(-1), np.asarray(w, dtype=float)
    parallel.chunked(len(o), _time_sum_kernel, "wkr", (w, flat, o))
    return out


@njit(cache=True, nogil=True)
def _time_sum_kernel(w, a, out):
    for i in range(a.shape[1]):
        x = w[0] * a[0, i]
        for s in range(1, len(w)):
            x += w[s] * a[s, i]
        out[i] = x


def time_matrices(order):
    """Gauss-Legendre nodes and weights on [0, 1] and the predictor matrix T = K_tau^-1 M_tau."""
    x, w = legendre.leggauss(order + 1)
    tau, w = 0.5 * (x + 1), 0.5 * w
    V = np.vander(tau, order + 1, increasing=True)
    coef = np.linalg.inv(V).T                              # Lagrange polynomials through tau
    P = np.polynomial.polynomial
    at = lambda x_: np.array([P.polyval(x_, c) for c in coef])          # (order+1, len(x_))
    d_at = lambda x_: np.array([P.polyval(x_, P.polyder(c)) for c in coef])
    phi1 = at(np.array([1.0]))[:, 0]
    K = np.outer(phi1, phi1) - (d_at(tau) * w) @ at(tau).T       # int phi_k' phi_l, exact (Gauss)
    M = np.diag(w)
    return tau, w, np.linalg.solve(K, M)


@dataclass
class PicardStats:
    """Predictor iteration counts over a run."""

    steps: int = 0
    total: int = 0              # the most iterations of a cell, summed over the steps
    max: int = 0
    not_converged: int = 0
    cell_total: float = 0.0     # the mean iterations per cell, summed over the steps

    def add(self, n, converged, cell_mean):
        """A step whose cells took at most ``n`` iterations (``cell_mean`` on average), all of
        them converged or not."""
        self.steps += 1
        self.total += n
        self.max = max(self.max, n)
        self.not_converged += not converged
        self.cell_total += cell_mean

    @property
    def mean(self):
        return self.total / max(self.steps, 1)

    @property
    def cell_mean(self):
        """Mean iterations per cell and step (cells stop at their own convergence)."""
        return self.cell_total / max(self.steps, 1)


def default_picard_max(order, d):
    """The predictor's default cap on Picard iterations: dP + 1, at least P + 2. For a linear
    problem the iteration is exact after dP iterations from the constant guess (P in 1D, 2P on 2D
    tensor spaces: tests/test_ader.py) and the next one confirms it (L23's P + 1 in 1D); on a
    nonlinear impact the cap, not the tolerance, ends the iterations, and the errors against the
    manufactured solution do not change beyond it (docs/choices.md)."""
    return max(d * order + 1, order + 2)


def _exact_zeros(T):
    """T (CSR) without the round-off of its exact zeros: a facet Gauss point lies on the cell's
    Gauss lines, so its trace from the Gauss points is a 1D Lagrange interpolation across the
    face, and the (P+1)^2 - (P+1) other entries of the product come out ~1e-17, not 0 (each a
    gather of the face pass). Entries within 64 eps of their row's largest go."""
    T = T.copy()
    big = abs(T).max(axis=1).toarray().ravel()
    rows = np.repeat(np.arange(T.shape[0]), np.diff(T.indptr))
    T.data[np.abs(T.data) <= 64 * np.finfo(float).eps * big[rows]] = 0.0
    T.eliminate_zeros()
    return T


@dataclass
class ADERDGFEM(DGFEM):
    """ADER-DGFEM of order P in space and time (SPTP). ``integrator`` is "ader"."""

    integrator: str = "ader"
    picard_tol: float = 1e-12
    picard_max: int = 0                     # 0: `default_picard_max`
    picard_guess: str = "taylor"            # or "constant" (u_hat = U^n at every time node)
    stages: tuple = ("time_step", "advance", "predictor", "corrector", "surface_integral", "interface_flux",
                     "source", "cell_update", "limit", "evaluate_points", "check")
    picard: PicardStats = field(default_factory=PicardStats, init=False)

    def __post_init__(self):
        requested, self.integrator = self.integrator, "rk2"      # DGFEM validates its own list
        super().__post_init__()
        self.integrator = requested
        nel, nq = self.basis.dx.shape
        self.B_inv = self.point_to_dofs
        grad = np.transpose(self._grad, (1, 2, 3, 0))                   # (d, nel, nq, nb)
        self.D_points = np.ascontiguousarray(np.einsum("aeqb,ebr->aeqr", grad, self.B_inv))  # d/dX_alpha
        self.tau, self.w_tau, self.T_tau = time_matrices(self.order)
        self.nq = nq
        self._repeated = {}
        if not self.picard_max:
            self.picard_max = default_picard_max(self.order, self.d)
        # the corrector's operators from the predictor's points (here the Gauss points) to the
        # facet rows and to the volume term, built once: point values -> coefficients -> traces
        shape = (nel, self.nb, nq)
        rows = np.broadcast_to(self.cell_dofs[:, :, None], shape)                    # dof k of cell c
        cols = np.broadcast_to(np.arange(nel * nq).reshape(nel, 1, nq), shape)        # point q of cell c
        to_dofs = sp.csr_matrix((self.B_inv.ravel(), (rows.ravel(), cols.ravel())), shape=(self.n_dofs, nel * nq))
        self.set_point_operators([_exact_zeros((T @ to_dofs).tocsr()) for T in self._face_traces()],
                                 sp.identity(nel * nq, format="csr"))

    def _face_traces(self):
        """DG trace operators of the facet rows: interior side L, interior side R, boundary."""
        return self.interior.T_L, self.interior.T_R, self.boundary.T_L

    def set_point_operators(self, traces, gauss):
        """The corrector's operators from the predictor's points: ``traces`` (CSR) to the rows of
        `_face_traces` and ``gauss`` (n_gauss, n_points) to the Gauss points, folded into the volume
        term K_alpha = D_alpha^T gauss (F is linear in Q)."""
        self.traces = tuple((T.indptr, T.indices, T.data) for T in traces)
        self.K = system.Stiffness(tuple((D.T @ gauss).tocsr() for D in self.D))

    # ---------------------------------------------------------------- predictor
    def _law(self, U):
        """Q from U at (..., n_gauss, nc) values at the Gauss points."""
        return self._law_at(U, self.gauss.cell, self.gauss.rho0)

    def _law_at(self, U, cells, rho):
        """The law on (..., n, nc) values at n points of the given cells and densities (n,): one
        evaluation over every batch entry, with the cells' materials and the densities repeated
        once per entry (cached: the batches are 1 or P+1 time nodes), and the internal variables
        of t_n at the points (`history_n`), never committed here [L23 §4.5]."""
        nc = U.shape[-1]
        n_rep = U.size // (len(cells) * nc)
        key = (id(cells), n_rep)
        if key not in self._repeated:
            self._repeated[key] = np.tile(self.cell_material[cells], n_rep), np.tile(rho, n_rep)
        history = None if not self.materials.n_history else np.tile(self.history_n, (n_rep, 1))
        return self.materials.state(U.reshape(-1, nc), *self._repeated[key], history).reshape(U.shape)

    def _points(self, cells, rho, padding=None):
        """The predictor's points for `_picard_cells`: (material, density, history of t_n (zero
        width for hyperelastic laws), padding) at points of the given cells (all but the history
        made once per cells' array)."""
        key = ("points", id(cells))
        if key not in self._repeated:
            pad = np.zeros(len(cells), dtype=np.bool_) if padding is None else np.ascontiguousarray(padding)
            self._repeated[key] = (np.ascontiguousarray(self.cell_material[cells], dtype=np.int64),
                                   np.ascontiguousarray(rho, dtype=float), pad)
        material, rho, pad = self._repeated[key]
        history = self.history_n if self.materials.n_history else np.empty((len(cells), 0))
        return material, rho, np.ascontiguousarray(history, dtype=float), pad

    def space_time_source(self, points, time, dt):
        """Source values at ``points`` and the time nodes t_n + tau_s dt: (P+1, n, nc), or None
        without a body force."""
        if self.body_force is None:
            return None
        return np.stack([self.source(points, time + tau * dt) for tau in self.tau])

    @stage
    def predictor(self, U_points, dt, source=None, Q_points=None):
        """Space-time predictor: (u_hat, q_hat) of shape (P+1, nel, nq, nc) and q_sum (nel, nq, nc),
        the time nodes' weighted sum of q_hat (`_picard`); ``source`` (P+1, n_points, nc) from
        `space_time_source` at the Gauss points; ``Q_points`` the law at U_points when known (the
        state's Q)."""
        nel, nq = self.basis.dx.shape
        S = None if source is None else source.reshape(len(self.tau), nel, nq, -1)
        Q = None if Q_points is None else Q_points.reshape(nel, nq, -1)
        return self._picard(U_points.reshape(nel, nq, -1), dt, self._law, self.D_points, self.D_points,
                            self._points(self.gauss.cell, self.gauss.rho0), S, Q)

    def _picard(self, U, dt, law, D, D_taylor, points, source=None, Q=None):
        """Picard iterations of L23 eq 62 on per-cell values U (nel, n, nc) at t_n, with the law
        ``law`` on (..., nel, n, nc) arrays (the guess's, where Q is not known) and at the points
        ``points`` (`_picard_cells`), the predictor's derivative matrices D and those of the
        Taylor guess D_taylor (d, nel, n, n), the source (P+1, nel, n, nc) or None, and Q = law(U)
        when the caller knows it. Returns (u_hat, q_hat, q_sum): u_hat and q_hat (P+1, nel, n, nc),
        q_hat the law at the last iterate before u_hat, and q_sum (nel, n, nc) = sum_s w_s q_hat[s]."""
        U = np.ascontiguousarray(U)
        d, n_t = self.d, len(self.tau)
        scale = _block_scale(U.reshape(-1, U.shape[-1]), d * d)     # change measured per block (F, p)
        u_hat, q_hat, q_sum = np.empty((n_t,) + U.shape), np.empty((n_t,) + U.shape), np.empty(U.shape)
        no_source = np.empty((0, 0, 0, 0))
        if self.picard_guess == "taylor":           # L23 eq 64: u_hat[s] = U - dt tau_s DIV F(Q(U))
            Q = law(U) if Q is None else np.ascontiguousarray(Q)
            # S at tau_s rather than t_n: only the guess, O(dt^2) apart
            guess = (U, Q, D_taylor, dt * self.tau, no_source if source is None else np.ascontiguousarray(source))
        else:
            guess = (U, U, D_taylor, np.empty(0), no_source)
        U0 = U[None] if source is None else U[None] + dt * np.tensordot(self.T_tau, source, axes=1)
        U0 = np.ascontiguousarray(U0).reshape(len(U0), -1)
        # each cell to its own convergence: a cell whose change is within the tolerance is done
        # (the whole grid iterating on for the cells that are not moved it by about that much)
        most, mean, missed = _picard_cells(guess, U0, D, self.T_tau, dt, scale, self.picard_tol, self.picard_max,
                                           self.laws, points, (u_hat, q_hat, self.w_tau, q_sum))
        self.picard.add(most, missed == 0, mean)
        # q_hat: the law of the last iterate, whose fluxes made u_hat (u_hat = U0 - dt T DIV F(q_hat)
        # exactly; law(u_hat) within the tolerance): the corrector integrates the fluxes of the
        # predictor it was given, and no law is evaluated once more at every point and time node
        return u_hat, q_hat, q_sum

    # ---------------------------------------------------------------- corrector
    @stage
    def corrector(self, dofs, u_hat, q_hat, q_sum, time, dt, source=None):
        """u^{n+1} = u^n + dt M^-1 sum_s w_s (R(q_hat(tau_s)) + int Phi S(tau_s)) (L23 eq 28-33);
        returns it and the boundary work. u_hat, q_hat: (P+1, ..., nc) at the predictor's points,
        q_sum (..., nc) = sum_s w_s q_hat[s] (the predictor's);
        ``source``: (P+1, n_gauss, nc) at the Gauss points, or None. The volume and source terms
        and the surface integral are linear in Q, so the time nodes are summed before them; the
        face states (tangent, Riemann problem) are taken at every node."""
        n_t, nc = len(self.tau), dofs.shape[1]
        u_hat, q_hat = u_hat.reshape(n_t, -1, nc), q_hat.reshape(n_t, -1, nc)
        faces, work = self.surface_integral(u_hat, q_hat, time, dt)
        S = None if source is None else self.source_integral(_time_sum(self.w_tau, source))
        return self.limit(self.cell_update(dofs, dt, faces, q_sum.reshape(-1, nc), S)), work

    volume_first = True         # the corrector's residual: the volume term, then the faces' (`cell_update`)

    @property
    def volume_stiffness(self):
        """The volume term's K^alpha over the predictor's points (`system.Stiffness`)."""
        return self.K

    @stage
    def surface_integral(self, u_hat, q_hat, time, dt):
        """The faces' fluxes of -int Phi sum_s w_s F_N*(tau_s) as `cell_update` reads them
        (`faces_read`), and the boundary work. One compiled pass over the interior faces for every
        time node (`ader_kernels`), one over the boundary faces (`boundary_pass`, each node's
        conditions at its time), both in one loop over the threads (`interface_flux`)."""
        nc = u_hat.shape[-1]
        f, b = self.interior, self.boundary
        T_L, T_R, T_B = self.traces
        flux = np.empty((len(f), nc))
        mat_L, mat_R, rho_L, rho_R = self.interior_sides[:4]          # DGFEM's sides of the interior faces
        interior = interior_flux_sum(T_L, T_R, u_hat, q_hat, rho_L, rho_R, f.normal, mat_L, mat_R, *self.laws,
                                     self.w_tau, flux)
        boundary, (flux_bnd, t_s, v_s) = self.boundary_pass(T_B, u_hat, q_hat, time + self.tau * dt, self.w_tau)
        self.interface_flux(interior, boundary)
        work = 0.0
        if len(b):
            for w, power in zip(self.w_tau, self.boundary_powers(t_s, v_s)):
                work += w * dt * power
        return self.faces_read(flux, flux_bnd), work

    @stage
    def advance(self, U, time, dt, U_points, Q_points):
        """The predictor from the dofs U, their values U_points at the Gauss points and the law
        there Q_points (the state's: its Taylor guess), then the corrector: the new dofs and the
        boundary work."""
        S = self.space_time_source(self.gauss, time, dt)       # predictor and corrector share it
        return self.corrector(U, *self.predictor(U_points, dt, S, Q_points), time, dt, S)

    def step(self, state, dt_max=np.inf):
        self.history_n = state.history          # the predictor's law reads the history of t_n

        def attempt(dt):            # the state's U and Q: B dofs and the law at the Gauss points at t_n
            dofs, work = self.advance(state.dofs, state.t, dt, state.U, state.Q)
            return self.evaluate_points(state, dofs, dt), work

        return self.step_with_cfl_guard(state, dt_max, attempt)
