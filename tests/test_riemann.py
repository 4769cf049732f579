"""Linearised Godunov solver: closed form against the eigen-decomposition path and wave structure.

References: exact properties of the linear Riemann problem [R18 §4.3, eq 32-33]; the eigen path
is an independent computation from the full quasi-linear Jacobian [L23 eq 11-12].
"""
import numpy as np
import pytest
from scipy.linalg import null_space

from skdgmpm.constitutive import MaterialSet
from skdgmpm.materials import make_material
from skdgmpm.riemann import godunov_state, impedance, transverse_positive

STEEL = dict(E=2e11, nu=0.3, rho=7800.0)
ALU = dict(E=7e10, nu=0.33, rho=2700.0)


def real_span(R):
    """A real basis of the span of eigenvectors R (nq, k) of real eigenvalues: LAPACK may return
    a repeated eigenvalue's eigenvectors with complex phases, whose real parts alone can be
    dependent; their real and imaginary parts span the same real invariant subspace."""
    U, sigma, _ = np.linalg.svd(np.concatenate([R.real, R.imag], axis=1), full_matrices=False)
    return U[:, : R.shape[1]]


def godunov_state_eigen(P_L, v_L, P_R, v_R, C_L, C_R, rho_L, rho_R, N):
    """Reference path: Q* = Q_L + sum over left-going waves, from a full eigen-decomposition.

    Builds the quasi-linear Jacobian A_N(Q) of [L23 eq 11-12] on each side, takes the left-going
    eigenvectors of side L, the right-going of side R and the (material-independent) stationary
    ones, and solves Q_R - Q_L = sum_m delta_m r_m [R18 eq 32-33]. Slow; independent of `skdgmpm.equations`.
    Returns the full Q* = (P* (nf, d, d), v* (nf, d)).
    """
    nf, d = v_L.shape
    nq = d * d + d

    def jacobian(C, rho):
        A = np.zeros((nf, nq, nq))
        A[:, : d * d, d * d:] = -np.einsum("fiajb,fb->fiaj", C, N).reshape(nf, d * d, d)
        A[:, d * d:, : d * d] = -(np.eye(d)[None, :, :, None] * N[:, None, None, :]
                                  ).reshape(nf, d, d * d) / rho[:, None, None]
        return A

    J_L, J_R = jacobian(C_L, rho_L), jacobian(C_R, rho_R)
    lam_L, R_L = np.linalg.eig(J_L)
    lam_R, R_R = np.linalg.eig(J_R)
    scale = np.abs(np.concatenate([lam_L, lam_R], axis=1)).max(axis=1, keepdims=True)
    left = lam_L.real < -1e-8 * scale          # wave speeds are real (hyperbolicity)
    right = lam_R.real > 1e-8 * scale
    Q_L = np.concatenate([P_L.reshape(nf, -1), v_L], axis=1)
    Q_R = np.concatenate([P_R.reshape(nf, -1), v_R], axis=1)
    out = np.empty_like(Q_L)
    for f in range(nf):                       # reference path only: clarity over speed
        # stationary waves: v = 0, P N = 0, i.e. P = e_i (x) m with m . N = 0 (built
        # explicitly: eig may return this kernel as a complex pair)
        tangents = null_space(N[f][None, :])                            # (d, d - 1)
        kernel = np.zeros((nq, d * (d - 1)))
        kernel[: d * d] = np.einsum("ij,am->iajm", np.eye(d), tangents).reshape(d * d, -1)
        basis = np.concatenate([real_span(R_L[f][:, left[f]]), kernel, real_span(R_R[f][:, right[f]])], axis=1)
        delta = np.linalg.solve(basis, Q_R[f] - Q_L[f])
        n_left = left[f].sum()
        out[f] = Q_L[f] + basis[:, :n_left] @ delta[:n_left]
    return out[:, : d * d].reshape(nf, d, d), out[:, d * d:]


def random_faces(rng, nf, d, law_L="neo_hookean", law_R="neo_hookean", right=ALU, amp=0.1):
    mats = MaterialSet((make_material(law_L, **STEEL), make_material(law_R, **right)))
    F_L = np.eye(d) + amp * rng.standard_normal((nf, d, d))
    F_R = np.eye(d) + amp * rng.standard_normal((nf, d, d))
    N = rng.standard_normal((nf, d))
    N /= np.linalg.norm(N, axis=1, keepdims=True)
    side = dict(
        P_L=mats.stress(F_L, np.zeros(nf, int)), P_R=mats.stress(F_R, np.ones(nf, int)),
        C_L=mats.tangent(F_L, np.zeros(nf, int)), C_R=mats.tangent(F_R, np.ones(nf, int)),
        v_L=100 * rng.standard_normal((nf, d)), v_R=100 * rng.standard_normal((nf, d)),
        rho_L=np.full(nf, STEEL["rho"]), rho_R=np.full(nf, right["rho"]), N=N)
    return side


def closed_form(s):
    t_L = np.einsum("fia,fa->fi", s["P_L"], s["N"])
    t_R = np.einsum("fia,fa->fi", s["P_R"], s["N"])
    Z_L = impedance(s["C_L"], s["N"], s["rho_L"])
    Z_R = impedance(s["C_R"], s["N"], s["rho_R"])
    return godunov_state(t_L, s["v_L"], t_R, s["v_R"], Z_L, Z_R), (t_L, t_R, Z_L, Z_R)


@pytest.mark.parametrize("d", [1, 2, 3])
def test_closed_form_equals_eigen_path_different_materials(d):
    s = random_faces(np.random.default_rng(d), 25, d)
    (t_star, v_star), _ = closed_form(s)
    P_star, v_eig = godunov_state_eigen(s["P_L"], s["v_L"], s["P_R"], s["v_R"], s["C_L"], s["C_R"],
                                        s["rho_L"], s["rho_R"], s["N"])
    t_eig = np.einsum("fia,fa->fi", P_star, s["N"])
    scale_t = np.abs(s["P_L"]).max()
    assert np.allclose(v_star, v_eig, rtol=1e-9, atol=1e-9 * np.abs(s["v_L"]).max())
    assert np.allclose(t_star, t_eig, rtol=1e-9, atol=1e-9 * scale_t)


@pytest.mark.parametrize("d", [1, 2])
def test_consistency_equal_states_give_that_state(d):
    s = random_faces(np.random.default_rng(10 + d), 10, d, right=STEEL)
    s.update(P_R=s["P_L"], v_R=s["v_L"], C_R=s["C_L"])
    (t_star, v_star), (t_L, _, _, _) = closed_form(s)
    assert np.allclose(v_star, s["v_L"], rtol=0, atol=1e-10 * np.abs(s["v_L"]).max())
    assert np.allclose(t_star, t_L, rtol=0, atol=1e-10 * np.abs(t_L).max())


@pytest.mark.parametrize("d", [1, 2])
def test_interface_conditions_traction_and_velocity_continuous(d):
    """The star state lies on side L's left-going and side R's right-going characteristics:
    one traction and one velocity shared by both sides (continuity at the interface)."""
    s = random_faces(np.random.default_rng(20 + d), 30, d, law_R="saint_venant_kirchhoff")
    (t_s, v_s), (t_L, t_R, Z_L, Z_R) = closed_form(s)
    res_L = t_s - t_L - np.einsum("fij,fj->fi", Z_L, v_s - s["v_L"])
    res_R = t_s - t_R + np.einsum("fij,fj->fi", Z_R, v_s - s["v_R"])
    assert np.abs(res_L).max() < 1e-6 * np.abs(t_L).max()
    assert np.abs(res_R).max() < 1e-6 * np.abs(t_L).max()


@pytest.mark.parametrize("d", [1, 2])
def test_mirror_symmetry(d):
    """Swapping the sides and flipping the normal gives the same interface state."""
    s = random_faces(np.random.default_rng(30 + d), 20, d)
    (t1, v1), _ = closed_form(s)
    m = dict(P_L=s["P_R"], P_R=s["P_L"], v_L=s["v_R"], v_R=s["v_L"], C_L=s["C_R"], C_R=s["C_L"],
             rho_L=s["rho_R"], rho_R=s["rho_L"], N=-s["N"])
    (t2, v2), _ = closed_form(m)
    assert np.allclose(v1, v2, rtol=1e-12, atol=1e-9)
    assert np.allclose(t1, -t2, rtol=1e-12, atol=1e-9 * np.abs(t1).max())   # t = P N flips with N


@pytest.mark.parametrize("d", [1, 2])
def test_single_wave_jump_is_resolved_exactly(d):
    """Q_R = Q_L + a right-going wave of the (common) linearisation: the star state is Q_L;
    a left-going wave: the star state is Q_R (linear elasticity, same material)."""
    rng = np.random.default_rng(40 + d)
    nf = 8
    mat = make_material("linear_elastic", **STEEL)
    C = np.broadcast_to(MaterialSet((mat,)).tangent(np.eye(d)[None], np.zeros(1, int)),
                        (nf,) + (d,) * 4).copy()
    N = rng.standard_normal((nf, d))
    N /= np.linalg.norm(N, axis=1, keepdims=True)
    rho = np.full(nf, STEEL["rho"])
    Z = impedance(C, N, rho)
    t_L, v_L = 1e8 * rng.standard_normal((nf, d)), 10 * rng.standard_normal((nf, d))
    dv = rng.standard_normal((nf, d))
    # right-going wave: t_R - t_L = -Z (v_R - v_L)
    t_s, v_s = godunov_state(t_L, v_L, t_L - np.einsum("fij,fj->fi", Z, dv), v_L + dv, Z, Z)
    assert np.allclose(v_s, v_L, rtol=1e-12, atol=1e-12) and np.allclose(t_s, t_L, rtol=1e-12, atol=1e-3)
    # left-going wave: t_R - t_L = +Z (v_R - v_L)
    t_R, v_R = t_L + np.einsum("fij,fj->fi", Z, dv), v_L + dv
    t_s, v_s = godunov_state(t_L, v_L, t_R, v_R, Z, Z)
    assert np.allclose(v_s, v_R, rtol=1e-12, atol=1e-12) and np.allclose(t_s, t_R, rtol=1e-12, atol=1e-3)


def test_impedance_closed_form_matches_eigen_sqrt():
    s = random_faces(np.random.default_rng(50), 40, 2)
    Z = impedance(s["C_L"], s["N"], s["rho_L"])
    Zi = impedance(s["C_L"], s["N"], s["rho_L"], inverse=True)
    A = s["rho_L"][:, None, None] * np.einsum("fiajb,fa,fb->fij", s["C_L"], s["N"], s["N"])
    assert np.allclose(Z @ Z, A, rtol=1e-10, atol=1e-10 * np.abs(A).max())
    assert np.allclose(Z @ Zi, np.eye(2), atol=1e-10)


def test_transverse_operator_keeps_positive_waves_times_speed():
    """B+ r+_k = c_k r+_k and B+ r-_k = 0 for the eigenvectors r = [Y (x) n; -+rho c Y]."""
    rng = np.random.default_rng(60)
    nf, d = 6, 2
    s = random_faces(rng, nf, d)
    C, rho, n = s["C_L"], s["rho_L"], s["N"]
    A = np.einsum("fiajb,fa,fb->fij", C, n, n)
    omega, Y = np.linalg.eigh(A)
    for k in range(d):
        c = np.sqrt(omega[:, k] / rho)
        y = Y[:, :, k]
        for sign, expected in ((+1, c), (-1, 0 * c)):
            w_F = y[:, :, None] * n[:, None, :]
            w_p = -sign * (rho * c)[:, None] * y
            B_F, B_p = transverse_positive(w_F, w_p, C, n, rho)
            assert np.allclose(B_F, expected[:, None, None] * w_F, atol=1e-12)
            assert np.allclose(B_p, expected[:, None] * w_p, rtol=1e-10, atol=1e-12 * np.abs(w_p).max())
