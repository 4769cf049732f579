"""Linear stability of first-order 1D DGMPM for scalar advection [R18 §6].

Model problem: ``q_t + a q_X = 0`` (``a > 0``) on a periodic grid of cells of size ``dx``,
every cell holding the same particle layout (parent coordinates in (0, 1)). One step of
DGMPM [R18 §5] is the product of three matrices, built here from their definitions:

* ``P`` (nodes x particles): lumped mass-weighted projection ``M_i q_i = sum_p S_ip m_p Q_p``;
* ``G`` (nodes x nodes): grid update ``I + dt L`` (forward Euler) or
  ``I + dt L + (dt L)^2 / 2`` (RK2 Heun, both stages on the grid), where
  ``M_i dq_i/dt = a (sum_j K_ij q_j - q*_i N_i)`` with the upwind value ``q*``;
* ``B`` (particles x nodes): interpolation back ``Q_p = sum_i S_ip q_i``.

so ``Q^{n+1} = D Q^n`` with ``D = B G P`` [R18 eq 59]. Units are chosen so that ``a = dx = 1``
and cell mass ``rho dx = 1``; then ``dt`` is the Courant number. Since the scheme only couples
a cell with upwind cells, the Bloch reduction gives the amplification matrix
``G(theta) = sum_m D_m exp(-i m theta)`` (``npc x npc``), ``D_m`` coupling a cell with the
cell ``m`` places upwind; the blocks are read off a small periodic grid.
"""

from __future__ import annotations

from dataclasses import dataclass
from fractions import Fraction

import numpy as np

from skdgmpm.errors import InputError

__all__ = [
    "StabilityReport",
    "amplification_matrices",
    "analyse",
    "critical_cfl",
    "grid_operators",
    "parse_layout",
    "scheme_blocks",
    "scheme_matrix",
    "spectral_radius",
    "sufficient_bound",
]

#: Taylor coefficients of the stability polynomial of each grid integrator.
_INTEGRATORS = {"euler": (1.0, 1.0), "rk2": (1.0, 1.0, 0.5)}
_TOL = 1e-12


def _layout(layout, weights=None):
    xi = np.asarray(layout, dtype=float).ravel()
    if xi.size == 0 or np.any((xi <= 0.0) | (xi >= 1.0)):
        raise ValueError(f"layout must be non-empty with entries in (0, 1), got {layout!r}")
    w = np.ones_like(xi) if weights is None else np.asarray(weights, dtype=float).ravel()
    if w.shape != xi.shape or np.any(w <= 0.0):
        raise ValueError(f"weights must be positive, one per particle, got {weights!r}")
    return xi, w / w.sum()


def grid_operators(layout, cfl, integrator="euler", weights=None, n_cells=5):
    """Projection, grid step and back-map of one DGMPM step on a periodic grid.

    Parameters
    ----------
    layout : sequence of float
        Parent coordinates in (0, 1) of the particles of every cell.
    cfl : float
        Courant number ``a dt / dx``.
    integrator : {"euler", "rk2"}
        Time integrator of the grid equations.
    weights : sequence of float, optional
        Relative particle masses within a cell (default equal).
    n_cells : int
        Number of cells of the periodic grid.

    Returns
    -------
    P, G, B : ndarray
        ``P`` (2 n_cells x n_particles), ``G`` (2 n_cells x 2 n_cells) and
        ``B`` (n_particles x 2 n_cells); nodes ``2k`` / ``2k+1`` are the left / right
        nodes of cell ``k``, particle ``k npc + j`` is particle ``j`` of cell ``k``.
    """
    xi, w = _layout(layout, weights)
    if integrator not in _INTEGRATORS:
        raise ValueError(f"integrator must be one of {sorted(_INTEGRATORS)}, got {integrator!r}")
    npc, nn = xi.size, 2 * n_cells
    cell = np.repeat(np.arange(n_cells), npc)
    x = np.tile(xi, n_cells)
    m = np.tile(w, n_cells)  # particle masses, cell mass rho dx = 1
    S = np.zeros((nn, cell.size))  # S[i, p] = S_i(X_p)
    dS = np.zeros_like(S)  # dS_i/dX(X_p), dx = 1
    p = np.arange(cell.size)
    S[2 * cell, p], S[2 * cell + 1, p] = 1.0 - x, x
    dS[2 * cell, p], dS[2 * cell + 1, p] = -1.0, 1.0
    M = S @ m  # lumped mass
    K = (dS * m) @ S.T  # K_ij = sum_p dS_i(X_p) m_p S_j(X_p)
    # flux term q*_i N_i (rho = 1): upwind value = right node of the upwind cell
    F = np.zeros((nn, nn))
    k = np.arange(n_cells)
    F[2 * k, (2 * k - 1) % nn] = -1.0  # left node, N = -1
    F[2 * k + 1, 2 * k + 1] = 1.0  # right node, N = +1
    L = (K - F) / M[:, None]
    G = np.zeros((nn, nn))
    power = np.eye(nn)
    for c in _INTEGRATORS[integrator]:
        G += c * power
        power = cfl * L @ power
    P = S * m / M[:, None]
    return P, G, S.T.copy()


def scheme_matrix(layout, cfl, integrator="euler", weights=None, n_cells=5):
    """Particle-to-particle matrix ``D = B G P`` of one step [R18 eq 59].

    Parameters are those of :func:`grid_operators`.

    Returns
    -------
    ndarray
        ``D`` (n_particles x n_particles), ``Q^{n+1} = D Q^n``.
    """
    P, G, B = grid_operators(layout, cfl, integrator, weights, n_cells)
    return B @ G @ P


def scheme_blocks(layout, cfl, integrator="euler", weights=None, n_cells=5):
    """Cell blocks ``D_m`` of ``D``: block ``m`` couples a cell with the cell ``m`` upwind.

    The blocks are read off :func:`scheme_matrix` on a periodic grid of ``n_cells`` cells;
    the grid must be wide enough that the stencil does not wrap around (checked), and the
    block-circulant matrix assembled from the blocks is checked to equal ``D``.

    Returns
    -------
    ndarray
        Shape ``(n_blocks, npc, npc)``; ``D_m[alpha, mu]`` is the weight of particle ``mu``
        of cell ``k - m`` in the new value of particle ``alpha`` of cell ``k``.
    """
    npc = len(layout)
    D = scheme_matrix(layout, cfl, integrator, weights, n_cells)
    col = [(-m % n_cells) * npc for m in range(n_cells)]  # first particle of cell -m
    blocks = np.array([D[:npc, c:c + npc] for c in col])
    scale = np.abs(D).max()
    nonzero = np.flatnonzero(np.abs(blocks).max(axis=(1, 2)) > 1e-14 * scale)
    if nonzero[-1] >= n_cells - 1:
        raise ValueError(f"stencil wraps around the periodic grid; use more than {n_cells} cells")
    blocks = blocks[: nonzero[-1] + 1]
    shift = np.eye(n_cells, k=-1) + np.eye(n_cells, k=n_cells - 1)  # cell k <- cell k-1
    assembled = sum(
        np.kron(np.linalg.matrix_power(shift, m), b) for m, b in enumerate(blocks)
    )
    if not np.allclose(assembled, D, rtol=0.0, atol=1e-12 * max(scale, 1.0)):
        raise RuntimeError("scheme matrix is not block-circulant with the extracted blocks")
    return blocks


def amplification_matrices(layout, cfl, integrator="euler", weights=None, n_theta=256):
    """Bloch amplification matrices ``G(theta) = sum_m D_m exp(-i m theta)``.

    Returns
    -------
    theta : ndarray, shape (n_theta,)
        Wavenumbers ``2 pi k / n_theta``.
    G : ndarray, shape (n_theta, npc, npc)
    """
    blocks = scheme_blocks(layout, cfl, integrator, weights)
    theta = 2.0 * np.pi * np.arange(n_theta) / n_theta
    phase = np.exp(-1j * np.outer(theta, np.arange(len(blocks))))
    return theta, np.einsum("tm,mab->tab", phase, blocks)


def sufficient_bound(layout, cfl, integrator="euler", weights=None):
    """Sufficient stability indicator ``max_alpha sum_mu |D_alpha mu|`` [R18 eq 64].

    Returns
    -------
    float
        The scheme is stable (in the max norm) when this is <= 1.
    """
    blocks = scheme_blocks(layout, cfl, integrator, weights)
    return float(np.abs(blocks).sum(axis=(0, 2)).max())


def spectral_radius(layout, cfl, integrator="euler", weights=None, n_theta=256):
    """Maximum over ``theta`` of the spectral radius of ``G(theta)`` (von Neumann).

    Returns
    -------
    float
        Necessary stability indicator: the scheme is unstable when this exceeds 1.
    """
    _, G = amplification_matrices(layout, cfl, integrator, weights, n_theta)
    return float(np.abs(np.linalg.eigvals(G)).max())


def critical_cfl(layout, integrator="euler", criterion="bound", tol=1e-4, weights=None,
                 cfl_max=2.0, n_scan=400, n_theta=256):
    """Largest Courant number up to which the criterion stays <= 1.

    The criterion is evaluated on a uniform scan of ``(0, cfl_max]``; the first failing
    scan point is then located by bisection to ``tol``. The criterion need not be monotone
    in the Courant number: the first failure is reported.

    Parameters
    ----------
    layout : sequence of float
        Parent coordinates of the particles of a cell.
    integrator : {"euler", "rk2"}
    criterion : {"bound", "spectral"}
        :func:`sufficient_bound` or :func:`spectral_radius`.
    tol : float
        Bisection tolerance on the Courant number.
    weights : sequence of float, optional
    cfl_max : float
        Returned when no failure is found in ``(0, cfl_max]``.
    n_scan : int
        Number of scan points.
    n_theta : int
        Number of wavenumbers for the spectral criterion.

    Returns
    -------
    float
    """
    funcs = {
        "bound": lambda c: sufficient_bound(layout, c, integrator, weights),
        "spectral": lambda c: spectral_radius(layout, c, integrator, weights, n_theta),
    }
    if criterion not in funcs:
        raise ValueError(f"criterion must be one of {sorted(funcs)}, got {criterion!r}")

    def ok(c):
        return funcs[criterion](c) <= 1.0 + _TOL

    lo = 0.0
    for c in np.linspace(cfl_max / n_scan, cfl_max, n_scan):
        if not ok(c):
            hi = c
            break
        lo = c
    else:
        return float(cfl_max)
    while hi - lo > tol:
        mid = 0.5 * (lo + hi)
        lo, hi = (mid, hi) if ok(mid) else (lo, mid)
    return float(lo)


@dataclass
class StabilityReport:
    """Critical Courant numbers of a layout for both integrators and both criteria."""

    layout: tuple
    euler_bound: float
    euler_spectral: float
    rk2_bound: float
    rk2_spectral: float

    def format(self):
        """Aligned text table (integrator rows; the CFL limit, then the max-norm bound, to 2
        decimals) followed by what each number means."""
        lay = ", ".join(f"{x:.4g}" for x in self.layout)
        rows = [f"layout: {lay} (parent coordinates of the particles in a cell); first-order DGMPM, "
                f"1D advection [R18 §6]",
                f"{'method':<8}{'CFL limit':>11}{'max-norm bound':>16}"]
        for name in ("euler", "rk2"):
            b, s = getattr(self, f"{name}_bound"), getattr(self, f"{name}_spectral")
            rows.append(f"{name:<8}{s:>11.2f}{b:>16.2f}")
        rows += [
            "CFL limit: the von Neumann limit, the largest CFL at which no Fourier mode grows (spectral",
            "  radius <= 1); above it a run blows up, and skdgmpm run refuses a DGMPM CFL above it",
            "  (method.cfl_above_limit = true runs it anyway).",
            "max-norm bound: the sufficient condition of R18 eq 64; below it the largest value of the",
            "  solution cannot grow from one step to the next. Between the two the scheme is stable",
            "  in the von Neumann (L2) sense, but the largest value may grow from one step to the next.",
        ]
        return "\n".join(rows)


def analyse(layout, weights=None):
    """Critical Courant numbers of ``layout`` (sequence or text, see :func:`parse_layout`).

    Returns
    -------
    StabilityReport
    """
    if isinstance(layout, str):
        layout = parse_layout(layout)
    layout = tuple(float(x) for x in layout)
    values = {
        f"{i}_{c}": critical_cfl(layout, i, c, weights=weights)
        for i in ("euler", "rk2")
        for c in ("bound", "spectral")
    }
    return StabilityReport(layout, **values)


def parse_layout(text):
    """Parse a particle layout such as ``"0.25,0.75"`` or ``"1/6,1/2,5/6"``.

    Raises
    ------
    InputError
        If a value is not a number, not strictly inside (0, 1), or the values are not
        strictly increasing.
    """
    values = []
    for item in str(text).split(","):
        try:
            x = Fraction(item.strip())
        except (ValueError, ZeroDivisionError):
            raise InputError(f"--layout: {item.strip()!r} is not a number") from None
        if not 0 < x < 1:
            raise InputError(f"--layout: {item.strip()!r} is not strictly inside (0, 1)")
        if values and x <= values[-1]:
            raise InputError(
                f"--layout: {item.strip()!r} is not greater than the previous value"
                " (values must be sorted and unique)"
            )
        values.append(x)
    return [float(x) for x in values]
