"""J2 plasticity laws (small strain and Hencky finite strain) at single points: return mapping against
closed forms, the uniaxial-strain Hugoniot elastic limit and plastic modulus, objectivity, the
small-strain limit, consistent tangents against finite differences, d-blocks, bad parameters."""

import numpy as np
import pytest

from skdgmpm.errors import InputError
from skdgmpm.materials import HenckyJ2, J2Plasticity, LinearElastic, NeoHookean, make_material
from skdgmpm.materials import hencky_j2, j2_plasticity

I3 = np.eye(3)
# nondimensional: strains beyond yield are a few sigma_y / E
PLASTIC = dict(E=1.0, nu=0.3, rho=1.0, sigma_y=1e-3, H=0.1)
LAWS = [J2Plasticity, HenckyJ2]


def random_F(scale, seed=0):
    """One F = I + scale * noise (3, 3), det F > 0 for the scales used here."""
    return I3 + scale * np.random.default_rng(seed).standard_normal((3, 3))


def rotation(seed=1):
    q, r = np.linalg.qr(np.random.default_rng(seed).standard_normal((3, 3)))
    q = q * np.sign(np.diag(r))
    return q * np.linalg.det(q)


def von_mises(S):
    """sqrt(3/2) |dev S| of a symmetric (..., 3, 3) stress."""
    s = S - np.trace(S, axis1=-2, axis2=-1)[..., None, None] / 3.0 * I3
    return np.sqrt(1.5 * np.einsum("...ij,...ij->...", s, s))


def central_difference(f, F, h):
    """d f / dF[j, b] (f (3, 3) of F (3, 3)) by central differences, as the last two axes."""
    D = np.empty((3, 3, 3, 3))
    for j in range(3):
        for b in range(3):
            dF = np.zeros((3, 3))
            dF[j, b] = h
            D[..., j, b] = (f(F + dF) - f(F - dF)) / (2 * h)
    return D


def plastic_metric(h):
    """Cp^-1 (3, 3) of a HenckyJ2 history (7,)."""
    return np.array([[h[1], h[4], h[5]], [h[4], h[2], h[6]], [h[5], h[6], h[3]]])


def hencky_reference(mat, F, Cpi=I3):
    """Independent Hencky stress (numpy eigh): tau = lam tr(eps) I + 2 mu eps, eps = 1/2 log(F Cp^-1
    F^T); returns (P = tau F^-T, tau, eps eigenvalues)."""
    w, N = np.linalg.eigh(F @ Cpi @ F.T)
    e = 0.5 * np.log(w)
    tau = (N * (mat.lam * e.sum() + 2 * mat.mu * e)) @ N.T
    return tau @ np.linalg.inv(F).T, tau, e


def prior_history(mat, seed=7, scale=5e-3):
    """A non-virgin history: one plastic step from the virgin state."""
    h = mat.stress_update(random_F(scale, seed), mat.initial_history(1)[0])[1]
    assert h[0] > 0.0
    return h


# -- elastic inside the yield surface ------------------------------------------------------------

def test_j2_inside_yield_surface_is_linear_elastic_on_eps_minus_eps_p():
    mat = J2Plasticity(**PLASTIC)
    h0 = prior_history(mat)
    ep = plastic_metric(np.r_[0.0, h0[1:]])           # same packing (11, 22, 33, 12, 13, 23)
    # strain near the plastic strain: elastic strain 2e-4, so q ~ 0.3 sigma_y
    F = I3 + ep + 2e-4 * np.random.default_rng(2).standard_normal((3, 3))
    P, h = mat.stress_update(F, h0)
    P_ref = LinearElastic(E=1.0, nu=0.3, rho=1.0).first_piola(F - ep)   # closed form on eps - eps_p
    assert von_mises(P_ref) < mat.sigma_y + mat.H * h0[0]
    np.testing.assert_allclose(P, P_ref, rtol=1e-12, atol=1e-12 * np.abs(P_ref).max())
    np.testing.assert_array_equal(h, h0)
    # virgin state: exactly the linear elastic law
    F = random_F(2e-4, seed=3)
    np.testing.assert_allclose(mat.first_piola(F), LinearElastic(E=1.0, nu=0.3, rho=1.0).first_piola(F),
                               rtol=1e-12, atol=1e-18)


def test_hencky_inside_yield_surface_is_the_hencky_hyperelastic_stress():
    mat = HenckyJ2(**{**PLASTIC, "sigma_y": 1.0})         # finite strain, still elastic
    F = random_F(0.2, seed=4)
    P, h = mat.stress_update(F, mat.initial_history(1)[0])
    P_ref, tau, _ = hencky_reference(mat, F)
    assert von_mises(tau) < mat.sigma_y
    np.testing.assert_allclose(P, P_ref, rtol=1e-11, atol=1e-13)
    np.testing.assert_array_equal(h, mat.initial_history(1)[0])
    # a non-virgin plastic metric: the Hencky stress of be = F Cp^-1 F^T, history unchanged
    h0 = prior_history(HenckyJ2(**{**PLASTIC, "sigma_y": 0.01}), scale=0.2)
    P, h = mat.stress_update(F, h0)
    np.testing.assert_allclose(P, hencky_reference(mat, F, plastic_metric(h0))[0], rtol=1e-11, atol=1e-13)
    np.testing.assert_array_equal(h, h0)


# -- a plastic step ------------------------------------------------------------------------------

@pytest.mark.parametrize("H", [0.1, 0.0], ids=["hardening", "perfect"])
def test_j2_plastic_step_returns_to_the_yield_surface(H):
    mat = J2Plasticity(**{**PLASTIC, "H": H})
    h0 = prior_history(mat)
    P, h = mat.stress_update(random_F(5e-3, seed=8), h0)
    d_eqp, d_ep = h[0] - h0[0], plastic_metric(np.r_[0.0, h[1:] - h0[1:]])
    assert d_eqp > 1e-4
    # on the yield surface of the hardened state (closed form sigma_y + H eqp)
    assert von_mises(P) == pytest.approx(mat.sigma_y + H * h[0], rel=1e-10)
    # consistency: d(eqp) = sqrt(2/3) |d eps_p|; flow along the normal 3/2 dev(sigma)/q
    assert d_eqp == pytest.approx(np.sqrt(2 / 3) * np.linalg.norm(d_ep), rel=1e-12)
    s = P - np.trace(P) / 3 * I3
    np.testing.assert_allclose(d_ep, 1.5 * d_eqp * s / von_mises(P), rtol=1e-10, atol=1e-14)
    # plastic incompressibility
    assert abs(np.trace(plastic_metric(np.r_[0.0, h[1:]]))) < 1e-15


@pytest.mark.parametrize("H", [0.1, 0.0], ids=["hardening", "perfect"])
def test_hencky_plastic_step_returns_to_the_yield_surface(H):
    mat = HenckyJ2(**{**PLASTIC, "sigma_y": 0.01, "H": H})
    h0 = prior_history(mat, scale=0.2)
    F = random_F(0.2, seed=9)
    P, h = mat.stress_update(F, h0)
    d_eqp = h[0] - h0[0]
    assert d_eqp > 1e-2
    tau = P @ F.T
    # Kirchhoff stress on the yield surface of the hardened state
    assert von_mises(tau) == pytest.approx(mat.sigma_y + H * h[0], rel=1e-10)
    # plastically incompressible: det Cp^-1 stays 1 (the exponential map)
    assert np.linalg.det(plastic_metric(h0)) == pytest.approx(1.0, abs=1e-12)
    assert np.linalg.det(plastic_metric(h)) == pytest.approx(1.0, abs=1e-12)
    # consistency: d(eqp) = sqrt(2/3) |d eps_p|, d eps_p = trial minus final principal log strains
    # (numpy eigvalsh of be_trial and of be = F Cp^-1 F^T; the return keeps their order)
    e_trial = 0.5 * np.log(np.linalg.eigvalsh(F @ plastic_metric(h0) @ F.T))
    e_new = 0.5 * np.log(np.linalg.eigvalsh(F @ plastic_metric(h) @ F.T))
    assert d_eqp == pytest.approx(np.sqrt(2 / 3) * np.linalg.norm(e_trial - e_new), rel=1e-10)
    # the returned tau is the Hencky stress of the new elastic state, coaxial with it
    P_ref, tau_ref, _ = hencky_reference(mat, F, plastic_metric(h))
    np.testing.assert_allclose(P, P_ref, rtol=1e-10, atol=1e-12)


# -- uniaxial strain: Hugoniot elastic limit and plastic modulus ---------------------------------

@pytest.mark.parametrize("law", LAWS)
def test_uniaxial_strain_compression_hel_and_plastic_modulus(law):
    """Compression F = diag(f, 1, 1) in small steps (Hencky: e = ln f, Kirchhoff tau_11; the
    principal axes stay fixed, so it is the small-strain law in log strain exactly). Closed forms:
    yield at |e| = e_Y = sigma_y / (2 mu), sigma_HEL = (lam + 2 mu) e_Y, then slope
    M_p = K + 4 mu H / (3 (3 mu + H)) and eqp = (2 mu |e| - sigma_y) / (3 mu + H); the path is
    proportional, so the return is exact and the trapezoidal work equals W + D."""
    mat = law(**PLASTIC)
    lam, mu, K, H, sy = mat.lam, mat.mu, mat.bulk, mat.H, mat.sigma_y
    e_Y = sy / (2 * mu)
    e = -np.linspace(0.0, 6 * e_Y, 61)                  # yield at step 10
    h, s11, eqp, W = mat.initial_history(1)[0], [], [], []
    for ek in e:
        F = np.diag([np.exp(ek) if law is HenckyJ2 else 1.0 + ek, 1.0, 1.0])
        P, h = mat.stress_update(F, h)
        s11.append(P[0, 0] * F[0, 0] if law is HenckyJ2 else P[0, 0])    # tau_11, or sigma_11
        eqp.append(h[0])
        W.append(mat.energy(F, h) + mat.dissipation(h))
    s11, eqp = np.array(s11), np.array(eqp)
    elastic, plastic = np.abs(e) <= e_Y * (1 - 1e-9), np.abs(e) > e_Y * (1 + 1e-9)
    np.testing.assert_allclose(s11[elastic], (lam + 2 * mu) * e[elastic], rtol=1e-9)
    np.testing.assert_array_equal(eqp[elastic], 0.0)
    slope, intercept = np.polyfit(e[plastic], s11[plastic], 1)
    M_p = K + 4 * mu * H / (3 * (3 * mu + H))
    assert slope == pytest.approx(M_p, rel=1e-8)
    sigma_HEL = (lam + 2 * mu) * sy / (2 * mu)
    assert slope * (-e_Y) + intercept == pytest.approx(-sigma_HEL, rel=1e-8)
    np.testing.assert_allclose(eqp[plastic], (2 * mu * np.abs(e[plastic]) - sy) / (3 * mu + H), rtol=1e-8)
    work = np.concatenate([[0.0], np.cumsum(0.5 * (s11[1:] + s11[:-1]) * np.diff(e))])
    np.testing.assert_allclose(np.ravel(W), work, rtol=1e-8, atol=1e-12 * work[-1])


# -- finite strain ---------------------------------------------------------------------------------

def test_hencky_is_objective():
    mat = HenckyJ2(**{**PLASTIC, "sigma_y": 0.01})
    h0 = prior_history(mat, scale=0.2)
    F, R = random_F(0.2, seed=10), rotation()
    P, h = mat.stress_update(F, h0)
    P_R, h_R = mat.stress_update(R @ F, h0)
    assert h[0] > h0[0]                                   # a plastic step
    np.testing.assert_allclose(P_R, R @ P, rtol=1e-11, atol=1e-13)
    np.testing.assert_allclose(h_R, h, rtol=1e-11, atol=1e-13)
    assert mat.energy(R @ F, h) == pytest.approx(mat.energy(F, h), rel=1e-11)


@pytest.mark.parametrize("scale", [3e-5, 3e-4])
def test_hencky_reduces_to_small_strain_j2(scale):
    """Strains a few times sigma_y / E beyond yield: the two laws differ by O(strain)."""
    params = {**PLASTIC, "sigma_y": scale / 3, "H": 0.05}
    small, finite = J2Plasticity(**params), HenckyJ2(**params)
    F = np.stack([random_F(scale, seed=s) for s in range(4)])
    P_s, h_s = small.stress_update(F, small.initial_history(4))
    P_f, h_f = finite.stress_update(F, finite.initial_history(4))
    assert (h_s[:, 0] > 0).all()
    assert np.abs(P_f - P_s).max() <= 5 * scale * np.abs(P_s).max()
    np.testing.assert_allclose(h_f[:, 0], h_s[:, 0], rtol=20 * scale)
    # Cp^-1 = I - 2 eps_p + O(strain^2)
    Cpi = np.stack([plastic_metric(h) for h in h_f])
    ep = np.stack([plastic_metric(np.r_[0.0, h[1:]]) for h in h_s])
    assert np.abs(Cpi - (I3 - 2 * ep)).max() <= 50 * scale**2        # |F - I| up to ~3 scale


def test_energy_gradient_is_the_updated_stress():
    """P_{n+1} = dW/dF (F_{n+1}, history_{n+1}) (central differences), after a plastic step."""
    for mat, F, h0 in ((J2Plasticity(**PLASTIC), random_F(5e-3, seed=11), None),
                       (HenckyJ2(**{**PLASTIC, "sigma_y": 0.01}), random_F(0.2, seed=11), None)):
        P, h = mat.stress_update(F, mat.initial_history(1)[0])
        assert h[0] > 0
        D = np.zeros((3, 3))
        for j in range(3):
            for b in range(3):
                dF = np.zeros((3, 3))
                dF[j, b] = 1e-6
                D[j, b] = (mat.energy(F + dF, h) - mat.energy(F - dF, h)) / 2e-6
        np.testing.assert_allclose(D, P, rtol=0, atol=1e-6 * np.abs(P).max())
        assert mat.dissipation(h) == pytest.approx(mat.sigma_y * h[0] + 0.5 * mat.H * h[0] ** 2)
        assert mat.energy(I3) == 0.0 and mat.dissipation(mat.initial_history(1)[0]) == 0.0


# -- tangents -----------------------------------------------------------------------------------------

CASES = {  # (law, parameters, F, history from a prior plastic step?)
    "j2-elastic": (J2Plasticity, {**PLASTIC, "sigma_y": 1.0}, random_F(5e-3, seed=12), False),
    "j2-plastic": (J2Plasticity, PLASTIC, random_F(5e-3, seed=12), True),
    "j2-perfect": (J2Plasticity, {**PLASTIC, "H": 0.0}, random_F(5e-3, seed=12), True),
    "hencky-elastic": (HenckyJ2, {**PLASTIC, "sigma_y": 1.0}, random_F(0.2, seed=12), False),
    "hencky-plastic": (HenckyJ2, {**PLASTIC, "sigma_y": 0.01}, random_F(0.2, seed=12), True),
    "hencky-perfect": (HenckyJ2, {**PLASTIC, "sigma_y": 0.01, "H": 0.0}, random_F(0.2, seed=12), True),
    # uniaxial strain: two coincident eigenvalues of be (the limit of the spectral derivative)
    "hencky-uniaxial": (HenckyJ2, {**PLASTIC, "sigma_y": 0.01}, np.diag([0.8, 1.0, 1.0]), False),
}


@pytest.mark.parametrize("case", CASES)
def test_consistent_tangent_matches_finite_differences(case):
    law, params, F, prior = CASES[case]
    mat = law(**params)
    h0 = prior_history(mat, scale=5e-3 if law is J2Plasticity else 0.2) if prior else mat.initial_history(1)[0]
    plastic = mat.stress_update(F, h0)[1][0] > h0[0]
    assert plastic == ("elastic" not in case)
    C = mat.consistent_tangent(F, h0)
    C_fd = central_difference(lambda G: mat.stress_update(G, h0)[0], F, 1e-6)
    assert np.abs(C - C_fd).max() <= 1e-8 * np.abs(C).max()          # measured: <= 3e-10
    if not plastic and law is J2Plasticity:               # the elastic tangent of `tangent`
        np.testing.assert_allclose(C, mat.tangent(F), rtol=1e-12, atol=1e-14)


def test_consistent_tangent_at_rest_and_inverted():
    # virgin at F = I: the isotropic elastic tensor; J <= 0: that of F = I, finite
    for mat in (J2Plasticity(**PLASTIC), HenckyJ2(**PLASTIC)):
        np.testing.assert_allclose(mat.consistent_tangent(I3, mat.initial_history(1)[0]),
                                   LinearElastic(E=1.0, nu=0.3, rho=1.0).tangent(I3), atol=1e-14)
    mat = HenckyJ2(**PLASTIC)
    F = np.diag([-0.5, 1.0, 1.0])
    np.testing.assert_allclose(mat.consistent_tangent(F, prior_history(mat, scale=0.2)),
                               mat.consistent_tangent(I3, mat.initial_history(1)[0]))


def test_riemann_tangent_is_the_elastic_laws():
    """`tangent` (the compiled tangent_point): LinearElastic's (j2), NeoHookean's (hencky)."""
    F = random_F(0.2, seed=13)
    for law, elastic, module in ((J2Plasticity, LinearElastic, j2_plasticity),
                                 (HenckyJ2, NeoHookean, hencky_j2)):
        mat, ref = law(**PLASTIC), elastic(E=1.0, nu=0.3, rho=1.0)
        np.testing.assert_allclose(mat.tangent(F), ref.tangent(F), rtol=1e-14, atol=1e-14)
        C = np.zeros((3, 3, 3, 3))
        module.tangent_point(F, np.array(mat.law_parameters), C, 3)
        np.testing.assert_allclose(C, ref.tangent(F), rtol=1e-14, atol=1e-14)
        N = np.array([0.48, 0.6, 0.64])
        np.testing.assert_allclose(mat.wave_speeds(I3, N), [np.sqrt((mat.lam + 2 * mat.mu) / mat.rho),
                                                             np.sqrt(mat.mu / mat.rho), np.sqrt(mat.mu / mat.rho)])


# -- the compiled point function on d-dimensional systems -----------------------------------------

@pytest.mark.parametrize("law", LAWS)
@pytest.mark.parametrize("d", [1, 2])
def test_point_update_d_block_is_the_block_of_the_3d_update(law, d):
    mat = law(**{**PLASTIC, "sigma_y": 0.01})
    point = (j2_plasticity if law is J2Plasticity else hencky_j2).stress_update_point
    prm = np.array(mat.law_parameters)

    def embedded(seed):
        F = I3.copy()
        F[:d, :d] = random_F(0.2, seed)[:d, :d]
        return F

    h0 = mat.stress_update(embedded(14), mat.initial_history(1)[0])[1]   # plastic, same embedding
    F = embedded(15)
    P3, h3, P, h = np.zeros((3, 3)), np.zeros(7), np.zeros((d, d)), np.zeros(7)
    point(F, prm, h0, h3, P3, 3)
    point(F, prm, h0, h, P, d)
    assert h3[0] > h0[0]
    np.testing.assert_array_equal(P, P3[:d, :d])
    np.testing.assert_array_equal(h, h3)
    np.testing.assert_allclose(P3, mat.stress_update(F, h0)[0], rtol=1e-14, atol=1e-16)
    # the history keeps the embedding's block structure: off-block components exactly zero
    off = [5, 6] if d == 2 else [4, 5, 6]
    np.testing.assert_array_equal(h3[off], 0.0)
    if law is J2Plasticity:                               # plane/uniaxial strain: eps_p33 != 0, eps33 = 0
        assert h3[3] != 0.0
    # in place: h_n and h the same array
    h_in = h0.copy()
    point(F, prm, h_in, h_in, P, d)
    np.testing.assert_array_equal(h_in, h3)


def test_hencky_return_mapping_compiles_once_for_every_dimension():
    """The Hencky return mapping is called from the point update, not inlined (compile time,
    `hencky_j2.stress_update_point`); it takes no size, so kernels of every dimension (d a
    literal in them, a signature of its own if passed on) and Python callers share one body."""
    from numba import njit

    def kernel(d):
        @njit
        def update(F, prm, h_n, h, P):
            hencky_j2.stress_update_point(F, prm, h_n, h, P, d)
        return update

    mat = HenckyJ2(**{**PLASTIC, "sigma_y": 0.01})
    prm, h_n, F = np.array(mat.law_parameters), mat.initial_history(1)[0], I3 + 0.1 * random_F(0.2, 3)
    P3 = np.zeros((3, 3))
    hencky_j2.stress_update_point(F, prm, h_n, np.zeros(7), P3, 3)
    for d in (1, 2, 3):
        P = np.zeros((d, d))
        kernel(d)(F, prm, h_n, np.zeros(7), P)
        np.testing.assert_array_equal(P, P3[:d, :d])
    assert len(hencky_j2._return_mapping.signatures) == 1


@pytest.mark.filterwarnings("error")
def test_hencky_inverted_point_is_finite():
    mat = HenckyJ2(**PLASTIC)
    h0 = prior_history(mat, scale=0.2)
    F = np.stack([np.diag([-0.5, 1.0, 1.0]), np.diag([0.0, 1.0, 1.0])])
    P, h = mat.stress_update(F, h0)
    np.testing.assert_array_equal(P, 0.0)
    np.testing.assert_array_equal(h, np.stack([h0, h0]))
    np.testing.assert_array_equal(mat.energy(F, h), np.inf)
    assert not mat.is_hyperbolic(F, [1.0, 0.0, 0.0]).any()


# -- construction ---------------------------------------------------------------------------------

@pytest.mark.parametrize("law", LAWS)
def test_made_by_name_with_history_interface(law):
    name = {J2Plasticity: "j2_plasticity", HenckyJ2: "hencky_j2"}[law]
    mat = make_material(name, **PLASTIC)
    assert mat == law(**PLASTIC) and mat.law_id == {J2Plasticity: 4, HenckyJ2: 5}[law]
    assert mat.history_names[0] == "eqp" and mat.n_history == 7
    assert mat.law_parameters[:2] == (mat.mu, mat.lam) and len(mat.law_parameters) <= 8
    h = mat.initial_history(3)
    assert h.shape == (3, 7) and (h[:, 0] == 0).all()
    assert np.array_equal(h[0, 1:], [1, 1, 1, 0, 0, 0] if law is HenckyJ2 else np.zeros(6))
    # batches broadcast: several F, one history
    F = np.stack([random_F(5e-3, seed=s) for s in range(6)]).reshape(2, 3, 3, 3)
    P, h = mat.stress_update(F, h[0])
    assert P.shape == (2, 3, 3, 3) and h.shape == (2, 3, 7)
    np.testing.assert_allclose(P[1, 2], mat.stress_update(F[1, 2], mat.initial_history(1)[0])[0])
    assert mat.consistent_tangent(F, h).shape == (2, 3, 3, 3, 3, 3)
    with pytest.raises(InputError, match="missing parameter.*sigma_y"):
        make_material(name, E=1.0, nu=0.3, rho=1.0, H=0.0)
    law(**{**PLASTIC, "H": 0.0})                          # perfect plasticity is allowed


@pytest.mark.parametrize("law", LAWS)
@pytest.mark.parametrize("name, value", [("sigma_y", 0.0), ("sigma_y", -1.0), ("sigma_y", np.nan),
                                         ("H", -1.0), ("H", np.inf), ("nu", 0.5), ("nu", -1.0)])
def test_bad_parameters_raise_input_error(law, name, value):
    with pytest.raises(InputError, match=rf"^material: {name} = .*must be a finite number") as info:
        law(**{**PLASTIC, name: value})
    assert "\n" not in str(info.value)
    if name == "H":
        assert ">= 0" in str(info.value)
