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

from . import parallel, system
from .ader_kernels import interior_flux_sum, traces
from .dgfem import DGFEM
from .equations import add_flux
from .kernel_cache import kernel_factory, scratch
from .riemann import _not_hyperbolic
from .scheme import stage


def _divergence_cells(Q, D, out):
    """out[r, c] = sum_alpha D[alpha, c] F_alpha(Q[r, c]) for per-cell point values Q (R, nel, n, nc)
    and derivative matrices D (d, nel, n, n)."""
    d, n = D.shape[0], Q.shape[2]
    # literal sizes, the loops unrolled: d always, n for Q1 and Q2 cells in 2D (2 x 2, 3 x 3 points)
    kernel = _divergence_cells_kernel(d, n if d == 2 and n in (4, 9) else None)
    parallel.rows(Q.shape[1], lambda lo, hi: kernel(Q, D, out, lo, hi))      # cells lo:hi


@kernel_factory
def _divergence_cells_kernel(d, n):
    if n is None:                       # n read at run time
        def divergence_cells(Q, D, out, lo, hi):
            _divergence_cells_dn(Q, D, out, d, Q.shape[2], lo, hi)
    else:
        def divergence_cells(Q, D, out, lo, hi):
            _divergence_cells_dn(Q, D, out, d, n, lo, hi)
    return divergence_cells


@njit(cache=True, inline="always")
def _divergence_cells_dn(Q, D, out, d, n, lo, hi):
    nc = d * d + d
    s, o = scratch((nc,)), scratch((nc,))
    for b in range(Q.shape[0]):
        for c in range(lo, hi):
            for k in range(n):
                for v in range(nc):
                    o[v] = 0.0
                for a in range(d):          # F_alpha is linear: applied to the weighted sum
                    for v in range(nc):
                        s[v] = 0.0
                    for m in range(n):
                        w = D[a, c, k, m]
                        for v in range(nc):
                            s[v] += w * Q[b, c, m, v]
                    add_flux(s, a, 1.0, o, d)
                for v in range(nc):
                    out[b, c, k, v] = o[v]


def _picard_update(U0, T, div, dt, scale, u_hat, new):
    """One Picard update new[s] = U0[s] - dt sum_r T[s, r] div[r] and the change
    max |new - u_hat| / scale (nan if any is nan). Flat arrays: div (R, M), new (S, M), U0 and
    u_hat (S or 1, M) (one row: the same at every node), M = n_points nc; scale (nc,)."""
    # 2D, S1T1 / S2T2: literal sizes, so the sum over the nodes unrolls and the loop over the points vectorises
    sizes = (6, len(div)) if len(scale) == 6 and len(div) in (2, 3) else (None, None)
    kernel = _picard_update_kernel(*sizes)
    # points lo:hi in parallel; the largest change is the largest of the chunks' (nan if one is)
    changes = parallel.rows(new.shape[1] // len(scale),
                            lambda lo, hi: kernel(U0, T, div, dt, scale, u_hat, new, lo, hi))
    return np.nan if any(c != c for c in changes) else max(changes)


@kernel_factory
def _picard_update_kernel(nc, n_r):
    if nc is None:                      # sizes read at run time
        def picard_update(U0, T, div, dt, scale, u_hat, new, lo, hi):
            return _picard_update_nc(U0, T, div, dt, scale, u_hat, new, len(scale), len(div), lo, hi)
    else:
        def picard_update(U0, T, div, dt, scale, u_hat, new, lo, hi):
            return _picard_update_nc(U0, T, div, dt, scale, u_hat, new, nc, n_r, lo, hi)
    return picard_update


@njit(cache=True, inline="always")
def _picard_update_nc(U0, T, div, dt, scale, u_hat, new, nc, n_r, lo, hi):
    big, t = scratch((nc,)), scratch((n_r,))    # max |new - u_hat| per component, nan once one is nan
    for v in range(nc):
        big[v] = 0.0
    for s in range(len(new)):           # indices into the 2D arrays, no row views (reference counted)
        s_0, s_u = (s if len(U0) > 1 else 0), (s if len(u_hat) > 1 else 0)
        for r in range(n_r):
            t[r] = T[s, r]
        for p in range(lo, hi):         # one pass: the update and its change, no branch
            for v in range(nc):
                j = p * nc + v
                acc = 0.0
                for r in range(n_r):
                    acc += t[r] * div[r, j]
                y = U0[s_0, j] - dt * acc
                new[s, j] = y
                x = abs(y - u_hat[s_u, j])
                big[v] = x if (x > big[v] or x != x) else big[v]
    change = 0.0
    for v in range(nc):
        x = big[v] / scale[v]
        if x != x:
            return np.nan
        change = max(change, x)
    return change


def _picard_step(Q, D, U0, T, dt, scale, u_hat, new):
    """`_divergence_cells` of Q (R, nel, n, nc) with D (d, nel, n, n), then `_picard_update` from
    it, in one pass over the cells: each point's divergence at every time node kept in registers,
    never stored (the same operations, in the same order, for every entry; the change the same
    max). U0, u_hat, new flat as in `_picard_update`."""
    d, n, n_r, nc = D.shape[0], Q.shape[2], Q.shape[0], Q.shape[3]
    literal = d == 2 and n in (4, 9) and n_r in (2, 3)      # 2D S1T1 / S2T2: the loops unrolled
    kernel = _picard_step_kernel(d, n if literal else None, n_r if literal else None)
    changes = parallel.rows(Q.shape[1], lambda lo, hi: kernel(Q, D, U0, T, dt, u_hat, new, lo, hi))   # cells lo:hi
    big = np.array(changes)                                                                           # (chunks, nc)
    big = np.where(np.isnan(big).any(axis=0), np.nan, big.max(axis=0)) / scale
    return np.nan if np.isnan(big).any() else float(big.max())


@kernel_factory
def _picard_step_kernel(d, n, n_r):
    if n is None:                       # sizes read at run time
        def picard_step(Q, D, U0, T, dt, u_hat, new, lo, hi):
            return _picard_step_n(Q, D, U0, T, dt, u_hat, new, lo, hi, d, Q.shape[2], Q.shape[0])
    else:
        def picard_step(Q, D, U0, T, dt, u_hat, new, lo, hi):
            return _picard_step_n(Q, D, U0, T, dt, u_hat, new, lo, hi, d, n, n_r)
    return picard_step


@njit(cache=True, inline="always")
def _picard_step_n(Q, D, U0, T, dt, u_hat, new, lo, hi, d, n, n_r):
    nc = d * d + d
    s, o, dv = scratch((nc,)), scratch((nc,)), scratch((n_r, nc))
    big = np.zeros(nc)                  # max |new - u_hat| per component, nan once one is nan
    for c in range(lo, hi):
        for k in range(n):
            for b in range(n_r):        # `_divergence_cells_dn` at (b, c, k)
                for v in range(nc):
                    o[v] = 0.0
                for a in range(d):
                    for v in range(nc):
                        s[v] = 0.0
                    for m in range(n):
                        w = D[a, c, k, m]
                        for v in range(nc):
                            s[v] += w * Q[b, c, m, v]
                    add_flux(s, a, 1.0, o, d)
                for v in range(nc):
                    dv[b, v] = o[v]
            p = c * n + k
            for t in range(len(new)):   # `_picard_update_nc` at point p
                t_0, t_u = (t if len(U0) > 1 else 0), (t if len(u_hat) > 1 else 0)
                for v in range(nc):
                    j = p * nc + v
                    acc = 0.0
                    for r in range(n_r):
                        acc += T[t, r] * dv[r, v]
                    y = U0[t_0, j] - dt * acc
                    new[t, j] = y
                    x = abs(y - u_hat[t_u, j])
                    big[v] = x if (x > big[v] or x != x) else big[v]
    return big


def _block_scale(U, dd):
    """Per component of the state (n, nc): the largest |U| of its block (F: the first dd
    components, p: the others), 1 where that is 0, nan if any is nan; the largest of the row
    chunks' (exact, in any order)."""
    big = np.array(parallel.rows(len(U), lambda lo, hi: _block_max(U[lo:hi], dd)))       # (chunks, 2)
    big = np.where(np.isnan(big).any(axis=0), np.nan, big.max(axis=0))
    big = np.where(big != 0.0, big, 1.0)
    return np.where(np.arange(U.shape[1]) < dd, big[0], big[1])


@njit(cache=True, nogil=True)
def _block_max(U, dd):
    """The largest |U| of the F block and of the p block of rows U, nan once one is nan."""
    big = np.zeros(2)
    for p in range(len(U)):
        for c in range(U.shape[1]):
            x = abs(U[p, c])
            k = 0 if c < dd else 1
            if x > big[k] or x != x:
                big[k] = x
    return big


def _time_sum(w, a):
    """sum_s w[s] a[s] over the time nodes (the leading axis): w[0] a[0] + w[1] a[1] + ..., in
    that order, entry by entry (one compiled pass on the threads)."""
    out = np.empty(a.shape[1:])
    flat, o, w = a.reshape(len(a), -1), out.reshape(-1), np.asarray(w, dtype=float)
    parallel.rows(len(o), lambda lo, hi: _time_sum_kernel(w, flat[:, lo:hi], o[lo:hi]))
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
    total: int = 0
    max: int = 0
    not_converged: int = 0

    def add(self, n, converged):
        self.steps += 1
        self.total += n
        self.max = max(self.max, n)
        self.not_converged += not converged

    @property
    def mean(self):
        return self.total / max(self.steps, 1)


def default_picard_max(order, d):
    """The predictor's default cap on Picard iterations: dP + 1, at least P + 2. For a linear
    problem the iteration is exact after dP iterations from the constant guess (P in 1D, 2P on 2D
    tensor spaces: tests/test_ader.py) and the next one confirms it (L23's P + 1 in 1D); on a
    nonlinear impact the cap, not the tolerance, ends the iterations, and the errors against the
    manufactured solution do not change beyond it (docs/choices.md)."""
    return max(d * order + 1, order + 2)


@dataclass
class ADERDGFEM(DGFEM):
    """ADER-DGFEM of order P in space and time (SPTP). ``integrator`` is "ader"."""

    integrator: str = "ader"
    picard_tol: float = 1e-12
    picard_max: int = 0                     # 0: `default_picard_max`
    picard_guess: str = "taylor"            # or "constant" (u_hat = U^n at every time node)
    stages: tuple = ("time_step", "advance", "predictor", "corrector", "surface_integral", "boundary_states",
                     "source", "limit", "evaluate_points", "check")
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
        self.set_point_operators([(T @ to_dofs).tocsr() for T in self._face_traces()],
                                 sp.identity(nel * nq, format="csr"))

    def _face_traces(self):
        """DG trace operators of the facet rows: interior side L, interior side R, boundary."""
        return self.interior.T_L, self.interior.T_R, self.boundary.T_L

    def set_point_operators(self, traces, gauss):
        """The corrector's operators from the predictor's points: ``traces`` (CSR) to the rows of
        `_face_traces` and ``gauss`` (n_gauss, n_points) to the Gauss points, folded into the volume
        term K_alpha = D_alpha^T gauss (F is linear in Q)."""
        self.traces = tuple((T.indptr, T.indices, T.data) for T in traces)
        b = self.boundary
        mat_L, mat_R, rho_L, rho_R = self.interior_sides[:4]          # DGFEM's, shared
        self.face_material = (mat_L, mat_R, self.cell_material[b.cell_L])
        self.face_rho = (rho_L, rho_R, self.rho_cell[b.cell_L])
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

    def space_time_source(self, points, time, dt):
        """Source values at ``points`` and the time nodes t_n + tau_s dt: (P+1, n, nc), or None
        without a body force."""
        if self.body_force is None:
            return None
        return np.stack([self.source(points, time + tau * dt) for tau in self.tau])

    @stage
    def predictor(self, U_points, dt, source=None, Q_points=None):
        """Space-time predictor: (u_hat, q_hat) of shape (P+1, nel, nq, nc) and the iterations;
        ``source`` (P+1, n_points, nc) from `space_time_source` at the Gauss points; ``Q_points``
        the law at U_points when known (the state's Q)."""
        nel, nq = self.basis.dx.shape
        S = None if source is None else source.reshape(len(self.tau), nel, nq, -1)
        Q = None if Q_points is None else Q_points.reshape(nel, nq, -1)
        return self._picard(U_points.reshape(nel, nq, -1), dt, self._law, self.D_points, self.D_points, S, Q)

    def _picard(self, U, dt, law, D, D_taylor, source=None, Q=None):
        """Picard iterations of L23 eq 62 on per-cell values U (nel, n, nc) at t_n, with the law
        ``law`` on (..., nel, n, nc) arrays, the predictor's derivative matrices D and those of the
        Taylor guess D_taylor (d, nel, n, n), the source (P+1, nel, n, nc) or None, and Q = law(U)
        when the caller knows it. Returns (u_hat, q_hat), (P+1, nel, n, nc): q_hat the law at the
        last iterate before u_hat."""
        U = np.ascontiguousarray(U)
        d, n_t = self.d, len(self.tau)
        scale = _block_scale(U.reshape(-1, U.shape[-1]), d * d)     # change measured per block (F, p)
        # two buffers, swapped every iteration; two allocations, not one of twice the size: past
        # glibc's mmap threshold (32 MiB, 256^2 P1) each step mapped it afresh and faulted it in
        u_hat, new = np.empty((n_t,) + U.shape), np.empty((n_t,) + U.shape)
        div = np.empty((1,) + U.shape)             # the Taylor guess's (the iterations keep theirs in registers)
        flat = lambda a: a.reshape(len(a), -1)      # noqa: E731 (views: (S, n_points nc))
        if self.picard_guess == "taylor":           # L23 eq 64: u_hat[s] = U - dt tau_s DIV F(Q(U))
            Q = law(U) if Q is None else np.ascontiguousarray(Q)
            _divergence_cells(Q[None], D_taylor, div[:1])
            _picard_update(flat(U[None]), (dt * self.tau)[:, None], flat(div[:1]), 1.0, scale, flat(U[None]),
                           flat(u_hat))
            if source is not None:          # S at tau_s rather than t_n: only the guess, O(dt^2) apart
                u_hat += dt * self.tau[:, None, None, None] * source
        else:
            u_hat[...] = U
        U0 = U[None] if source is None else U[None] + dt * np.tensordot(self.T_tau, source, axes=1)
        U0 = flat(np.ascontiguousarray(U0))
        for it in range(1, self.picard_max + 1):
            q_hat = None                    # the last iterate's law freed before the next is made
            q_hat = law(u_hat)
            change = _picard_step(q_hat, D, U0, self.T_tau, dt, scale, flat(u_hat), flat(new))
            u_hat, new = new, u_hat
            if change <= self.picard_tol:
                break
        self.picard.add(it, change <= self.picard_tol)
        # q_hat: the law of the last iterate, whose fluxes made u_hat (u_hat = U0 - dt T DIV F(q_hat)
        # exactly; law(u_hat) within the tolerance): the corrector integrates the fluxes of the
        # predictor it was given, and no law is evaluated once more at every point and time node
        return u_hat, q_hat

    # ---------------------------------------------------------------- corrector
    @stage
    def corrector(self, dofs, u_hat, q_hat, time, dt, source=None):
        """u^{n+1} = u^n + dt M^-1 sum_s w_s (R(q_hat(tau_s)) + int Phi S(tau_s)) (L23 eq 28-33);
        returns it and the boundary work. u_hat, q_hat: (P+1, ..., nc) at the predictor's points;
        ``source``: (P+1, n_gauss, nc) at the Gauss points, or None. The volume and source terms
        and the surface integral are linear in Q, so the time nodes are summed before them; the
        face states (tangent, Riemann problem) are taken at every node."""
        n_t, nc = len(self.tau), dofs.shape[1]
        u_hat, q_hat = u_hat.reshape(n_t, -1, nc), q_hat.reshape(n_t, -1, nc)
        R = system.volume_flux(_time_sum(self.w_tau, q_hat), self.K, np.zeros_like(dofs))
        work = self.surface_integral(u_hat, q_hat, time, dt, R)
        if source is not None:
            R += self.source_integral(_time_sum(self.w_tau, source))
        return self.limit(self.mass_update(dofs, dt, R)), work

    @stage
    def surface_integral(self, u_hat, q_hat, time, dt, R):
        """-int Phi sum_s w_s F_N*(tau_s) over all faces added to R; returns the boundary work. One
        compiled pass over the interior faces for every time node (`ader_kernels`), then the
        boundary conditions per node (they may depend on time)."""
        d, n_t, nc = self.d, len(self.tau), u_hat.shape[-1]
        f, b = self.interior, self.boundary
        T_L, T_R, T_B = self.traces
        flux = np.empty((len(f), nc))
        bad = interior_flux_sum(T_L, T_R, u_hat, q_hat, self.face_rho[0], self.face_rho[1], f.normal,
                                self.face_material[0], self.face_material[1], *self.laws, self.w_tau, flux)
        if bad >= 0:
            _not_hyperbolic(bad)
        f.integrate_jump(flux, R)
        if not len(b):
            return 0.0
        F, Q = np.empty((n_t, len(b), d * d)), np.empty((n_t, len(b), nc))
        traces(T_B, u_hat, q_hat, F, Q)
        flux, work = 0.0, 0.0
        for s, (tau, w) in enumerate(zip(self.tau, self.w_tau)):
            C = self.materials.tangent(F[s].reshape(-1, d, d), self.face_material[2])
            states, power = self.boundary_states(Q[s], C, self.face_rho[2], time + tau * dt)
            flux = flux + w * states.flux
            work += w * dt * power
        b.integrate(flux, "L", R, sign=-1.0)
        return work

    @stage
    def advance(self, U, time, dt, Q_points=None):
        S = self.space_time_source(self.gauss, time, dt)       # predictor and corrector share it
        u_hat, q_hat = self.predictor(parallel.matmul(self.B, U), dt, S, Q_points)
        return self.corrector(U, u_hat, q_hat, time, dt, S)

    def step(self, state, dt_max=np.inf):
        self.history_n = state.history          # the predictor's law reads the history of t_n

        def attempt(dt):            # the state's Q is the law at the Gauss points at t_n
            dofs, work = self.advance(state.dofs, state.t, dt, state.Q)
            return self.evaluate_points(state, dofs, dt), work

        return self.step_with_cfl_guard(state, dt_max, attempt)
