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
from numba import njit
from numpy.polynomial import legendre

from .dgfem import DGFEM
from .scheme import GridState


@njit(cache=True)
def _divergence_cells(Q, D, out):
    """out[b, c] = sum_alpha D[alpha, c] F_alpha(Q[b, c]) for per-cell point values Q (B, nel, n, nc)
    and derivative matrices D (d, nel, n, n): F-rows (i, alpha) get -D_alpha v_i, p-rows
    -sum_alpha D_alpha P_i,alpha (a compiled loop: numpy's batched matmul on (n, n) blocks and
    strided columns cost ~100 ns a block)."""
    if D.shape[0] == 2:                 # a literal d: the (d, d) loops unrolled
        _divergence_cells_d(Q, D, out, 2)
    else:
        _divergence_cells_d(Q, D, out, D.shape[0])


@njit(cache=True, inline="always")
def _divergence_cells_d(Q, D, out, d):
    dd, n = d * d, Q.shape[2]
    for b in range(Q.shape[0]):
        for c in range(Q.shape[1]):
            for k in range(n):
                for i in range(d):
                    out[b, c, k, dd + i] = 0.0
                for a in range(d):
                    for i in range(d):
                        sv, sP = 0.0, 0.0
                        for m in range(n):
                            w = D[a, c, k, m]
                            sv += w * Q[b, c, m, dd + i]
                            sP += w * Q[b, c, m, i * d + a]
                        out[b, c, k, i * d + a] = -sv
                        out[b, c, k, dd + i] -= sP


@njit(cache=True)
def _picard_update(U0, T, div, dt, scale, u_hat, new):
    """One Picard update new[s] = U0[s] - dt sum_s' T[s, s'] div[s'] (U0 (1 or P+1, n, nc)
    broadcast over the time nodes; div, u_hat, new (P+1, n, nc)); returns the change
    max |new - u_hat| / scale (nan if any is nan), all in one pass."""
    if new.shape[2] == 6:               # 2D: a literal number of components, the loop unrolled
        return _picard_update_nc(U0, T, div, dt, scale, u_hat, new, 6)
    return _picard_update_nc(U0, T, div, dt, scale, u_hat, new, new.shape[2])


@njit(cache=True, inline="always")
def _picard_update_nc(U0, T, div, dt, scale, u_hat, new, nc):
    n_t, n = new.shape[0], new.shape[1]
    change, nan = 0.0, False
    for s in range(n_t):
        s0 = s if len(U0) > 1 else 0
        for j in range(n):
            for c in range(nc):
                acc = 0.0
                for r in range(n_t):
                    acc += T[s, r] * div[r, j, c]
                x = U0[s0, j, c] - dt * acc
                new[s, j, c] = x
                ch = abs(x - u_hat[s, j, c]) / scale[c]
                if ch > change:
                    change = ch
                nan = nan or ch != ch
    return np.nan if nan else change


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


@dataclass
class ADERDGFEM(DGFEM):
    """ADER-DGFEM of order P in space and time (SPTP). ``integrator`` is "ader"."""

    integrator: str = "ader"
    picard_tol: float = 1e-12
    picard_max: int = 0                     # 0: 2P + 2
    picard_guess: str = "taylor"            # or "constant" (u_hat = U^n at every time node)
    stages: tuple = ("time_step", "predictor", "volume_flux", "boundary_flux", "interface_flux",
                     "source", "corrector", "evaluate_points")
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
        if not self.picard_max:
            self.picard_max = 2 * self.order + 2

    # ---------------------------------------------------------------- predictor
    def _divergence(self, Q, D=None):
        """sum_alpha D_alpha F_alpha(Q) at the points; Q (..., nel, nq, nc), D (d, nel, nq, nq)
        C-contiguous."""
        D = self.D_points if D is None else D
        Q4 = np.ascontiguousarray(Q).reshape((-1,) + Q.shape[-3:])
        out = np.empty_like(Q4)
        _divergence_cells(Q4, D, out)
        return out.reshape(Q.shape)

    def _law(self, U, points=None):
        """Q from U at (..., n_points, nc) values at ``points`` (default: the Gauss points)."""
        points = points or self.gauss
        shape = U.shape
        flat = U.reshape(-1, shape[-1])
        n_rep = flat.shape[0] // len(points)
        return self.point_state(flat, np.tile(points.cell, n_rep), np.tile(points.rho0, n_rep)).reshape(shape)

    def space_time_source(self, points, time, dt):
        """Source values at ``points`` and the time nodes t_n + tau_s dt: (P+1, n, nc), or None
        without a body force."""
        if self.body_force is None:
            return None
        return np.stack([self.source(points, time + tau * dt) for tau in self.tau])

    def predictor(self, U_points, dt, source=None):
        """Space-time predictor: (u_hat, q_hat) of shape (P+1, nel, nq, nc) and the iterations;
        ``source`` (P+1, n_points, nc) from `space_time_source` at the Gauss points."""
        nel, nq = self.basis.dx.shape
        S = None if source is None else source.reshape(len(self.tau), nel, nq, -1)
        return self._picard(U_points.reshape(nel, nq, -1), dt, self._law, self.D_points, self.D_points, S)

    def _picard(self, U, dt, law, D, D_taylor, source=None):
        """Picard iterations of L23 eq 62 on per-cell values U (nel, n, nc) at t_n, with the law
        ``law`` on (..., nel, n, nc) arrays, the predictor's derivative matrices D and those of the
        Taylor guess D_taylor (d, nel, n, n), and the source (P+1, nel, n, nc) or None.
        Returns (u_hat, q_hat), (P+1, nel, n, nc)."""
        u_hat = np.broadcast_to(U[None], (len(self.tau),) + U.shape)
        if self.picard_guess == "taylor":                                       # L23 eq 64
            u_hat = u_hat - dt * self.tau[:, None, None, None] * self._divergence(law(U), D_taylor)[None]
            if source is not None:          # S at tau_s rather than t_n: only the guess, O(dt^2) apart
                u_hat = u_hat + dt * self.tau[:, None, None, None] * source
        U0 = U[None] if source is None else U[None] + dt * np.tensordot(self.T_tau, source, axes=1)
        d = self.d                                  # change measured per block (F, p)
        scale = np.ones(U.shape[-1])
        scale[: d * d] = np.abs(U[..., : d * d]).max() or 1.0
        scale[d * d:] = np.abs(U[..., d * d:]).max() or 1.0
        shape = u_hat.shape
        flat = lambda a: a.reshape(len(a), -1, shape[-1])                       # noqa: E731 (views)
        U0, u_hat = flat(np.ascontiguousarray(U0)), np.ascontiguousarray(u_hat)
        for it in range(1, self.picard_max + 1):
            div = self._divergence(law(u_hat), D)
            new = np.empty(shape)
            change = _picard_update(U0, self.T_tau, flat(div), dt, scale, flat(u_hat), flat(new))
            u_hat = new
            if change <= self.picard_tol:
                break
        self.picard.add(it, change <= self.picard_tol)
        return u_hat, law(u_hat)

    # ---------------------------------------------------------------- corrector
    def _coefficients(self, values):
        """Per-cell point values (nel, nq, nc) -> DG coefficients (n_dofs, nc)."""
        out = np.empty((self.n_dofs, values.shape[-1]))
        out[self.cell_dofs] = np.matmul(self.B_inv, values)
        return out

    def corrector(self, dofs, u_hat, q_hat, time, dt, source=None):
        """u^{n+1} = u^n + dt sum_s w_s M^-1 (R(q_hat(tau_s)) + int Phi S(tau_s)); returns it and
        the boundary work. ``source``: (P+1, n_gauss, nc) at the Gauss points, or None."""
        R_total = np.zeros_like(dofs)
        work = 0.0
        nc = dofs.shape[1]
        for s, (tau, w) in enumerate(zip(self.tau, self.w_tau)):
            Q_points = q_hat[s].reshape(-1, nc)
            grid_state = GridState(self._coefficients(u_hat[s]), self._coefficients(q_hat[s]))
            R, power = self.surface_residual(grid_state, time + tau * dt, dt)
            R_total += w * (R + self.volume_flux_points(Q_points))
            if source is not None:
                R_total += w * self.source_integral(source[s])
            work += w * dt * power
        return self.limit(dofs + dt * self.apply_mass_inverse(R_total)), work

    def advance(self, U, time, dt):
        S = self.space_time_source(self.gauss, time, dt)       # predictor and corrector share it
        u_hat, q_hat = self.predictor(self.B @ U, dt, S)
        return self.corrector(U, u_hat, q_hat, time, dt, S)
