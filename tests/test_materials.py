"""Constitutive laws: analytic tangents and stresses against finite differences and closed forms."""

import dataclasses

import numpy as np
import pytest

from skdgmpm.errors import InputError
import functools

from skdgmpm.materials import (LAWS, Gavrilyuk, HenckyJ2, J2Plasticity, LinearElastic, Material, MooneyRivlin,
                               NeoHookean, SaintVenantKirchhoff, make_material)

PARAMS = dict(E=2.0, nu=0.3, rho=1.5)
GAVRILYUK = [functools.partial(Gavrilyuk, a=a) for a in (-1.0, 0.0, 0.5)]   # the whole range of a
MOONEY_RIVLIN = [functools.partial(MooneyRivlin, beta=b) for b in (0.0, 0.5)]
ALL = [LinearElastic, SaintVenantKirchhoff, NeoHookean, *GAVRILYUK, *MOONEY_RIVLIN]
HYPERELASTIC = [SaintVenantKirchhoff, NeoHookean, *GAVRILYUK, *MOONEY_RIVLIN]
I3 = np.eye(3)


def random_F(scale, n=6, seed=0):
    """``n`` deformation gradients I + scale * noise with det F > 0.2, shape (n, 3, 3)."""
    rng = np.random.default_rng(seed)
    F = I3 + scale * rng.standard_normal((8 * n, 3, 3))
    return F[np.linalg.det(F) > 0.2][:n]


def rotation(seed=1):
    q, r = np.linalg.qr(np.random.default_rng(seed).standard_normal((3, 3)))
    q = q * np.sign(np.diag(r))
    return q * np.linalg.det(q)  # proper rotation


def central_difference(f, F, h=1e-6):
    """d f / dF[j, b] by central differences, stacked as the last two axes."""
    columns = []
    for j in range(3):
        for b in range(3):
            dF = np.zeros((3, 3))
            dF[j, b] = h
            columns.append((f(F + dF) - f(F - dF)) / (2 * h))
    D = np.stack(columns, axis=-1)
    return D.reshape(D.shape[:-1] + (3, 3))


def isotropic_tensor(lam, mu):
    d = I3
    return (lam * np.einsum("ia,jb->iajb", d, d)
            + mu * (np.einsum("ij,ab->iajb", d, d) + np.einsum("ib,aj->iajb", d, d)))


@pytest.mark.parametrize("law", ALL)
@pytest.mark.parametrize("scale", [0.01, 0.35], ids=["small", "large"])
def test_tangent_matches_finite_differences(law, scale):
    mat, F = law(**PARAMS), random_F(scale)
    C, C_fd = mat.tangent(F), central_difference(mat.first_piola, F)
    assert np.max(np.abs(C - C_fd)) <= 1e-6 * np.max(np.abs(C))


@pytest.mark.parametrize("law", ALL)
@pytest.mark.parametrize("scale", [0.01, 0.35], ids=["small", "large"])
def test_piola_is_energy_gradient(law, scale):
    mat, F = law(**PARAMS), random_F(scale, seed=2)
    P, P_fd = mat.first_piola(F), central_difference(mat.energy, F)
    assert np.max(np.abs(P - P_fd)) <= 1e-6 * np.max(np.abs(P))


@pytest.mark.parametrize("law", ALL)
def test_reference_state_is_stress_free_with_isotropic_tangent(law):
    mat = law(**PARAMS)
    np.testing.assert_allclose(mat.first_piola(I3), 0.0, atol=1e-14)
    np.testing.assert_allclose(mat.energy(I3), 0.0, atol=1e-14)
    np.testing.assert_allclose(mat.tangent(I3), isotropic_tensor(mat.lam, mat.mu), atol=1e-14)


def test_elastic_constants():
    mat = LinearElastic(E=210e9, nu=0.25, rho=7800.0)
    assert mat.lam == pytest.approx(84e9) and mat.mu == pytest.approx(84e9)
    assert mat.bulk == pytest.approx(mat.lam + 2 * mat.mu / 3)


def test_svk_uniaxial_strain_stress():
    """[R18 eq A.5]: P11 = (lam + 2 mu)/2 F (F^2 - 1), P22 = P33 = lam/2 (F^2 - 1)."""
    mat, f = SaintVenantKirchhoff(**PARAMS), np.linspace(0.6, 1.5, 7)
    F = np.zeros((f.size, 3, 3))
    F[:, 0, 0], F[:, 1, 1], F[:, 2, 2] = f, 1.0, 1.0
    P = mat.first_piola(F)
    np.testing.assert_allclose(P[:, 0, 0], (mat.lam + 2 * mat.mu) / 2 * f * (f**2 - 1))
    np.testing.assert_allclose(P[:, 1, 1], mat.lam / 2 * (f**2 - 1))
    np.testing.assert_allclose(P[:, 2, 2], mat.lam / 2 * (f**2 - 1))
    np.testing.assert_allclose(P[:, 0, 1:], 0.0, atol=1e-15)


@pytest.mark.parametrize("law", ALL)
def test_wave_speeds_at_rest(law):
    mat = law(**PARAMS)
    cp, cs = np.sqrt((mat.lam + 2 * mat.mu) / mat.rho), np.sqrt(mat.mu / mat.rho)
    N = np.array([0.48, 0.6, 0.64])  # unit
    np.testing.assert_allclose(mat.wave_speeds(I3, N), [cp, cs, cs])
    np.testing.assert_allclose(mat.wave_speeds(I3, N[:2] / np.linalg.norm(N[:2])), [cp, cs])
    np.testing.assert_allclose(mat.wave_speeds(I3, [1.0]), [cp])
    assert mat.max_wave_speed(I3, N) == pytest.approx(cp)
    assert mat.is_hyperbolic(I3, N)


def uniaxial(f):
    F = np.broadcast_to(I3, np.shape(f) + (3, 3)).copy()
    F[..., 0, 0] = f
    return F


def test_svk_longitudinal_speed():
    """c(F) = sqrt((lam + 2 mu)(3 F^2 - 1) / (2 rho)) for F = diag(F, 1, 1) [R18 App. A]."""
    mat, f = SaintVenantKirchhoff(**PARAMS), np.linspace(0.7, 1.5, 9)
    c = np.sqrt((mat.lam + 2 * mat.mu) * (3 * f**2 - 1) / (2 * mat.rho))
    np.testing.assert_allclose(mat.wave_speeds(uniaxial(f), [1.0])[:, 0], c)
    np.testing.assert_allclose(mat.max_wave_speed(uniaxial(f), [1.0, 0.0, 0.0]), c)


def test_svk_hyperbolicity_lost_in_compression():
    """1D: hyperbolic iff F > 1/sqrt(3) [R18 eq A.10]; the 3D shear waves go first."""
    mat, f = SaintVenantKirchhoff(**PARAMS), np.array([0.3, 0.5, 0.57, 0.58, 0.7, 1.0, 2.0])
    np.testing.assert_array_equal(mat.is_hyperbolic(uniaxial(f), [1.0]), f > 1 / np.sqrt(3))
    np.testing.assert_array_equal(mat.wave_speeds(uniaxial(f), [1.0])[:, 0] == 0.0,
                                  f < 1 / np.sqrt(3))
    f_shear = np.sqrt(mat.lam / (mat.lam + 2 * mat.mu))  # transverse speed vanishes
    e1 = [1.0, 0.0, 0.0]
    assert mat.is_hyperbolic(uniaxial(f_shear + 1e-3), e1)
    assert not mat.is_hyperbolic(uniaxial(f_shear - 1e-3), e1)


@pytest.mark.parametrize("law", HYPERELASTIC)
def test_frame_invariance(law):
    mat, F, R = law(**PARAMS), random_F(0.35, seed=3), rotation()
    np.testing.assert_allclose(mat.first_piola(R @ F), R @ mat.first_piola(F), atol=1e-12)
    np.testing.assert_allclose(mat.energy(R @ F), mat.energy(F), atol=1e-12)
    sigma = mat.cauchy(F)
    np.testing.assert_allclose(sigma, np.swapaxes(sigma, -1, -2), atol=1e-12)


@pytest.mark.filterwarnings("error")
def test_neo_hookean_inverted_is_flagged_without_nan():
    mat = NeoHookean(**PARAMS)
    F = np.stack([np.diag([-0.5, 1.0, 1.0]), np.diag([0.0, 1.0, 1.0]), np.diag([0.5, 1.0, 1.0])])
    N = [1.0, 0.0, 0.0]
    assert np.isfinite(mat.first_piola(F)).all() and np.isfinite(mat.tangent(F)).all()
    np.testing.assert_array_equal(mat.energy(F)[:2], np.inf)
    np.testing.assert_array_equal(mat.is_hyperbolic(F, N), [False, False, True])
    assert np.isfinite(mat.wave_speeds(F, N)).all()


def test_batched_shapes():
    mat, F = NeoHookean(**PARAMS), random_F(0.1, n=20).reshape(4, 5, 3, 3)
    N = np.random.default_rng(4).standard_normal((4, 5, 3))
    assert mat.first_piola(F).shape == (4, 5, 3, 3) and mat.cauchy(F).shape == (4, 5, 3, 3)
    assert mat.tangent(F).shape == (4, 5, 3, 3, 3, 3) and mat.energy(F).shape == (4, 5)
    assert mat.acoustic_tensor(F, N).shape == (4, 5, 3, 3)
    assert mat.acoustic_tensor(F, N[0, 0]).shape == (4, 5, 3, 3)
    assert mat.wave_speeds(F, N).shape == (4, 5, 3) and mat.max_wave_speed(F, N).shape == (4, 5)
    assert mat.is_hyperbolic(F, N).dtype == bool and mat.is_hyperbolic(F, N).shape == (4, 5)
    c = mat.wave_speeds(F, N)
    assert (np.diff(c, axis=-1) <= 0).all()
    # a batch gives the same numbers as one point at a time
    np.testing.assert_allclose(mat.tangent(F)[2, 3], mat.tangent(F[2, 3]))
    assert mat.energy(I3).shape == () and LinearElastic(**PARAMS).tangent(F).shape[:2] == (4, 5)


@pytest.mark.parametrize("law", ALL)
def test_materials_are_immutable_and_keyword_only(law):
    mat = law(**PARAMS)
    with pytest.raises(dataclasses.FrozenInstanceError):
        mat.E = 3.0
    with pytest.raises(TypeError):
        law(2.0, 0.3, 1.5)
    assert isinstance(mat, Material) and mat == law(**PARAMS)


@pytest.mark.parametrize("name, value", [("E", 0.0), ("E", -1.0), ("E", np.nan), ("E", "2"),
                                         ("nu", 0.5), ("nu", -1.0), ("nu", np.inf),
                                         ("rho", 0.0), ("rho", True)])
def test_bad_parameters_raise_input_error(name, value):
    with pytest.raises(InputError, match=rf"^material: {name} = .*must be") as info:
        NeoHookean(**{**PARAMS, name: value})
    assert "\n" not in str(info.value)


def test_make_material_by_name():
    assert set(LAWS) == {"linear_elastic", "saint_venant_kirchhoff", "neo_hookean", "gavrilyuk",
                         "mooney_rivlin", "j2_plasticity", "hencky_j2"}
    for name, cls in LAWS.items():
        params = {**PARAMS, "sigma_y": 1e-3, "H": 0.1} if cls.history_names else PARAMS   # plastic laws
        assert make_material(name, **params) == cls(**params)
    assert isinstance(make_material("svk", **PARAMS), SaintVenantKirchhoff)
    with pytest.raises(InputError, match="known laws: .*linear_elastic.*neo_hookean") as info:
        make_material("mooney", **PARAMS)
    assert "\n" not in str(info.value)
    with pytest.raises(InputError, match="'density'"):
        make_material("neo_hookean", E=2.0, nu=0.3, density=1.0)
    with pytest.raises(InputError, match="rho"):
        make_material("neo_hookean", E=2.0, nu=0.3)


@pytest.mark.parametrize("law", GAVRILYUK, ids=["a=-1", "a=0", "a=0.5"])
def test_gavrilyuk_small_strain_limit_and_hyperbolicity(law):
    # shear modulus mu and bulk modulus kappa at F = I for every a (the reason for reading L23's
    # "I2b - 9" as I1b^2 - 9, see the class docstring); hyperbolic at large random strains
    mat = law(**PARAMS)
    assert np.allclose(mat.tangent(I3), isotropic_tensor(mat.lam, mat.mu), atol=1e-12)
    rng = np.random.default_rng(3)
    F = I3 + 0.6 * rng.standard_normal((4000, 3, 3))
    F = F[np.linalg.det(F) > 0.05]
    N = rng.standard_normal((len(F), 3))
    assert mat.is_hyperbolic(F, N / np.linalg.norm(N, axis=1)[:, None]).all()


def test_gavrilyuk_a_minus_one_is_quadratic_volume_plus_neo_hookean_shear():
    # closed form of L23 eq 16 + 19
    mat, F = Gavrilyuk(**PARAMS), random_F(0.3, seed=4)
    J = np.linalg.det(F)
    W = 0.5 * mat.bulk * (J - 1) ** 2 + 0.5 * mat.mu * (J ** (-2 / 3) * np.einsum("nia,nia->n", F, F) - 3)
    assert np.allclose(mat.energy(F), W, rtol=1e-12)
    assert make_material("gavrilyuk", **PARAMS) == mat
    with pytest.raises(InputError, match="a = 0.7"):
        make_material("gavrilyuk", **PARAMS, a=0.7)


@pytest.mark.parametrize("law", ALL)
@pytest.mark.parametrize("d", [1, 2, 3])
def test_tangent_block_is_the_block_of_the_3d_tangent(law, d):
    # the d-dimensional systems use only this block; laws may compute it on d x d arrays
    mat, F = law(**PARAMS), random_F(0.3, seed=5)
    F3 = np.broadcast_to(I3, F.shape).copy()
    F3[:, :d, :d] = F[:, :d, :d]
    F3 = F3[np.linalg.det(F3) > 0.1]
    assert np.allclose(mat.tangent_block(F3, d), mat.tangent(F3)[:, :d, :d, :d, :d], rtol=1e-13, atol=1e-13)


@pytest.mark.parametrize("d", [1, 2, 3])
def test_compiled_state_is_the_block_of_first_piola(d):
    # MaterialSet.state (the compiled point stresses, several materials in one pass) against each
    # law's batched first_piola, inverted points (J <= 0) included
    from skdgmpm.constitutive import MaterialSet
    from skdgmpm.system import embed
    materials = [law(**PARAMS) for law in ALL]
    F = random_F(0.3, n=24, seed=7)[:, :d, :d].copy()
    F[0] = np.diag([-1.0, 1.0, 1.0][:d])             # det F < 0
    index = np.arange(len(F)) % len(materials)
    rho = 1.0 + np.arange(len(F))
    p = np.random.default_rng(3).standard_normal((len(F), d))
    Q = MaterialSet(tuple(materials)).state(np.hstack([F.reshape(-1, d * d), p]), index, rho)
    for k, mat in enumerate(materials):
        sel = index == k
        P = mat.first_piola(embed(F[sel]))[:, :d, :d]
        assert np.allclose(Q[sel, : d * d], P.reshape(-1, d * d), rtol=1e-13, atol=1e-13)
    assert np.array_equal(Q[:, d * d:], p / rho[:, None])


def test_a_law_without_a_compiled_point_law_is_refused():
    """A new law must join the compiled dispatch (materials/points.py), never run as another law."""
    from dataclasses import dataclass

    from skdgmpm.materials.neo_hookean import NeoHookean
    from skdgmpm.materials.points import law_table

    @dataclass(frozen=True, kw_only=True)
    class Unregistered(NeoHookean):
        law_id = 99

    with pytest.raises(TypeError, match="Unregistered: no compiled point law"):
        law_table([Unregistered(E=1e9, nu=0.3, rho=1000.0)])


EVERY_LAW = [LinearElastic, SaintVenantKirchhoff, NeoHookean, GAVRILYUK[2], MOONEY_RIVLIN[1],
             functools.partial(J2Plasticity, sigma_y=0.01, H=0.1), functools.partial(HenckyJ2, sigma_y=0.01, H=0.1)]


@pytest.mark.parametrize("law, d", [(law, 2) for law in EVERY_LAW] + [(NeoHookean, 1)])
def test_a_kernel_made_for_one_law_gives_the_bits_of_the_kernel_for_several(law, d):
    # a set whose materials share a law runs kernels typed for that law alone (points.only_law:
    # its point_law's functions called directly); the same points through a set that also holds
    # another law run the kernel of every law (ANY_LAW: the chain of branches made from
    # points.LAWS). Stresses, history, the tangent-based health and the batched tangent must agree
    # bit for bit: a chain that sends a law to another's branch fails here
    from skdgmpm.constitutive import MaterialSet
    from skdgmpm.materials.points import ANY_LAW, _tangents, law_table, only_law
    from skdgmpm.system import embed
    mat = law(**PARAMS)
    other = LinearElastic(**PARAMS) if mat.law_id != LinearElastic.law_id else NeoHookean(**PARAMS)
    one, mixed = MaterialSet((mat,)), MaterialSet((mat, other))
    assert only_law(one.laws[0]) == mat.law_id and only_law(mixed.laws[0]) == ANY_LAW
    F = random_F(0.3, n=40, seed=11)[:, :d, :d].copy()
    F = F[np.linalg.det(F) > 0.1]
    U = np.hstack([F.reshape(len(F), -1), np.random.default_rng(4).standard_normal((len(F), d))])
    index, rho = np.zeros(len(F), np.int64), np.full(len(F), PARAMS["rho"])
    motion = (np.zeros((len(F), d)), np.zeros((len(F), d)), 1e-6)
    history = one.initial_history(index)
    Q1, h1, health1, _ = one.update_and_assess(U.copy(), index, rho, history, motion)
    Q2, h2, health2, _ = mixed.update_and_assess(U.copy(), index, rho, history, motion)
    assert np.array_equal(Q1, Q2) and np.array_equal(h1, h2[:, : h1.shape[1]])
    for a, b in zip((health1.J, health1.omega, health1.speed), (health2.J, health2.omega, health2.speed)):
        assert np.array_equal(a, b)
    F3 = np.ascontiguousarray(embed(F))
    laws, params = law_table([mat])
    C_any = np.empty((len(F), d, d, d, d))
    _tangents(d, ANY_LAW)(laws, params, F3, C_any)
    assert np.array_equal(mat.tangent_block(F3, d), C_any)


def test_a_law_with_more_parameters_than_the_table_holds_is_refused():
    from skdgmpm.materials.points import N_PARAMETERS, law_table

    @dataclasses.dataclass(frozen=True, kw_only=True)
    class Wide(NeoHookean):
        @property
        def law_parameters(self):
            return (1.0,) * (N_PARAMETERS + 1)

    with pytest.raises(TypeError, match=f"Wide: {N_PARAMETERS + 1} law_parameters"):
        law_table([Wide(**PARAMS)])


def test_every_registered_law_is_dispatched_and_laws_sharing_a_tangent_share_a_branch():
    # one registration per law (materials.LAWS); the compiled dispatch is made from it
    from skdgmpm.materials.base import PointLaw
    from skdgmpm.materials.points import KNOWN, TANGENT, UPDATE, _branches
    assert sorted(KNOWN) == sorted(cls.law_id for cls in LAWS.values())
    for cls in LAWS.values():
        law = cls.point_law
        assert isinstance(law, PointLaw) and law.tangent is not None
        assert (law.stress is None) != (law.update is None), cls.__name__       # hyperelastic, or with history
    for kind in (TANGENT, UPDATE):
        ids = [i for branch, _ in _branches(kind) for i in branch]
        assert sorted(ids) == sorted(KNOWN)                 # every law in exactly one branch
    shared = {ids for ids, _ in _branches(TANGENT) if len(ids) > 1}
    assert shared == {(LinearElastic.law_id, J2Plasticity.law_id), (NeoHookean.law_id, HenckyJ2.law_id)}


@pytest.mark.parametrize("d", [2, 3])
def test_a_set_of_materials_gives_each_point_its_own_laws_energy(d):
    """`MaterialSet.energy` (what a run sums, one compiled pass over the points of every material)
    against closed forms written here in numpy: a neo-Hookean and a small-strain J2 material in
    turn, the J2 points with a plastic strain in force, F the embedded d-block. The history array
    is as wide as J2's; the neo-Hookean points never read theirs."""
    from skdgmpm.constitutive import MaterialSet
    neo, j2 = NeoHookean(**PARAMS), J2Plasticity(**PARAMS, sigma_y=0.01, H=0.1)
    n, rng = 40, np.random.default_rng(7)
    F = np.tile(I3, (n, 1, 1))
    F[:, :d, :d] += 0.2 * rng.standard_normal((n, d, d))
    F = F[np.linalg.det(F) > 0.1]
    n = len(F)
    index = np.arange(n) % 2
    ep = 0.01 * rng.standard_normal((n, 3, 3))
    ep = 0.5 * (ep + np.swapaxes(ep, 1, 2))
    history = np.zeros((n, 7))
    history[:, 0] = 0.3
    for k, (i, j) in enumerate([(0, 0), (1, 1), (2, 2), (0, 1), (0, 2), (1, 2)]):
        history[:, 1 + k] = ep[:, i, j]
    history[index == 0] = 99.0                                        # never read by the neo-Hookean points
    J, I1 = np.linalg.det(F), np.einsum("nia,nia->n", F, F)
    W_neo = 0.5 * neo.mu * (I1 - 3) - neo.mu * np.log(J) + 0.5 * neo.lam * np.log(J) ** 2
    e = 0.5 * (F + np.swapaxes(F, 1, 2)) - I3 - ep
    W_j2 = 0.5 * j2.lam * np.trace(e, axis1=1, axis2=2) ** 2 + j2.mu * np.einsum("nab,nab->n", e, e)
    W = MaterialSet((neo, j2)).energy(np.ascontiguousarray(F[:, :d, :d]), index, history)
    np.testing.assert_allclose(W, np.where(index == 0, W_neo, W_j2), rtol=1e-12, atol=1e-15)
    assert np.array_equal(W[index == 1], j2.energy(F[index == 1], history[index == 1]))
