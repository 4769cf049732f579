"""MPM / GIMP shape functions [WG08 eq 5-6]: partition of unity, linear reproduction, gradients
against finite differences, clear errors for particles outside the grid or non-uniform grids."""
import numpy as np
import pytest
from skfem import MeshQuad

from skdgmpm.errors import InputError, InstabilityError
from skdgmpm.gimp import SHAPES, Lattice, half_lengths, shape_functions
from skdgmpm.grid import line, rectangle

H = 0.25


def lattice(d):
    return Lattice.from_mesh(line(2.0, 8, origin=-0.5) if d == 1 else rectangle(2.0, 1.0, 8, 4))


def points(d, n=200, seed=0):
    """Random points, points on and next to cell edges, points on and next to the grid's edge."""
    L = lattice(d)
    rng = np.random.default_rng(seed)
    x = L.origin + rng.uniform(0, 1, (n, d)) * (L.upper - L.origin)
    edges = L.origin + H * rng.integers(0, 5, (40, d)) + rng.choice([0.0, 1e-13, -1e-13, 1e-3, -1e-3], (40, d))
    return L, np.clip(np.concatenate([x, edges, [L.origin, L.upper]]), L.origin, L.upper)


def lengths(kind, x, rng):
    """uGIMP: half of a 2 ppc spacing; cpGIMP: that times a random stretch (clipped at h/2)."""
    l0 = np.full(x.shape, H / 4)
    F = np.eye(x.shape[1]) + 0.6 * rng.uniform(-1, 1, (len(x), x.shape[1], x.shape[1]))
    return half_lengths(kind, l0, F, np.full(x.shape[1], H))


@pytest.mark.parametrize("d", [1, 2])
@pytest.mark.parametrize("kind", SHAPES)
def test_partition_of_unity_and_linear_reproduction(kind, d):
    L, x = points(d)
    mesh_nodes = (line(2.0, 8, origin=-0.5) if d == 1 else rectangle(2.0, 1.0, 8, 4)).p.T
    sf = shape_functions(L, x, kind, lengths(kind, x, np.random.default_rng(1)))
    assert sf.S.shape == (len(x), L.n_nodes)
    assert np.abs(sf.S.sum(axis=1).A1 - 1).max() < 1e-13
    assert np.abs(sf.S @ mesh_nodes - x).max() < 1e-13              # sum_i S_ip x_i = x_p
    assert sf.S.min() >= 0
    for k, G in enumerate(sf.grad):
        assert np.abs(G.sum(axis=1).A1).max() < 1e-10 / H          # sum_i grad S_ip = 0
        assert np.allclose(G @ mesh_nodes, np.eye(d)[k], atol=1e-10)   # grad x = I


@pytest.mark.parametrize("d", [1, 2])
@pytest.mark.parametrize("kind", SHAPES)
def test_gradient_is_the_derivative_at_fixed_half_length(kind, d):
    """Central differences of S in x (l_p fixed) away from kinks: points placed off the
    breakpoints |xi| = l_p, h - l_p, h + l_p by more than the increment."""
    L, x = points(d, seed=2)
    lp = None if kind == "hat" else np.full(x.shape, 0.3 * H)
    x = x[np.all((x > L.origin + 0.01) & (x < L.upper - 0.01), axis=1)]
    lp = None if lp is None else lp[: len(x)]
    s = ((x - L.origin) / H) % 1.0
    breaks = np.array([0.0, 0.3, 0.7, 1.0]) if kind != "hat" else np.array([0.0, 1.0])
    far = np.all(np.abs(s[..., None] - breaks).min(axis=-1) > 1e-4, axis=1)
    x, lp = x[far], None if lp is None else lp[far]
    sf = shape_functions(L, x, kind, lp)
    eps = 1e-7
    for k in range(d):
        step = eps * np.eye(d)[k]
        fd = (shape_functions(L, x + step, kind, lp).S - shape_functions(L, x - step, kind, lp).S) / (2 * eps)
        assert np.abs((fd - sf.grad[k]).toarray()).max() < 1e-5 / H


def test_gimp_closed_form_in_1d():
    """WG08 eq 5: the three pieces at hand-picked distances, h = 0.25, l_p = 0.05."""
    L = lattice(1)
    lp, x = 0.05, np.array([[0.03], [0.1], [0.22]])         # node 2 at x = 0: xi = 0.03, 0.1, 0.22
    S = shape_functions(L, x, "ugimp", np.full((3, 1), lp)).S.toarray()[:, 2]
    expected = [1 - (0.03 ** 2 + lp ** 2) / (2 * H * lp), 1 - 0.1 / H, (H + lp - 0.22) ** 2 / (4 * H * lp)]
    assert np.allclose(S, expected, rtol=1e-13)


def test_cpgimp_half_length_follows_the_stretch_and_is_clipped():
    F = np.array([[[1.5, 0.2], [0.0, 0.8]], [[3.0, 0.0], [0.0, -1.0]]])
    lp = half_lengths("cpgimp", np.full((2, 2), 0.1), F, np.array([0.25, 0.25]))
    assert np.allclose(lp, [[0.125, 0.08], [0.125, 0.0]])      # 0.15 and -0.1 clipped
    assert half_lengths("hat", None) is None


@pytest.mark.parametrize("kind", SHAPES)
def test_particle_outside_the_grid_is_named(kind):
    L = lattice(2)
    x = np.array([[0.5, 0.5], [2.0 + 1e-6, 0.3]])
    with pytest.raises(InstabilityError, match=r"particle 1 at x = \[2\.000001, 0\.3\] is outside the "
                                               r"background grid .* at step 7, t = 0\.001 s") as info:
        shape_functions(L, x, kind, np.full((2, 2), 0.05), step=7, time=1e-3)
    assert info.value.particle == 1 and info.value.step == 7


def test_non_uniform_or_rotated_grid_is_rejected():
    m = rectangle(1.0, 1.0, 4, 4)
    p = m.p.copy()
    p[0, 6] += 0.01                                          # one interior node moved
    with pytest.raises(InputError, match="mpm needs a uniform axis-aligned grid"):
        Lattice.from_mesh(MeshQuad(p, m.t))
    c, s = np.cos(0.3), np.sin(0.3)
    with pytest.raises(InputError, match="mpm needs a uniform axis-aligned grid"):
        Lattice.from_mesh(MeshQuad(np.array([[c, -s], [s, c]]) @ m.p, m.t))


def test_half_lengths_in_the_pass_match_the_separate_step():
    """The weights pass forms cpGIMP's half-lengths itself (``F``): the same values as
    `half_lengths` before it, on two threads (`parallel.PIECES` chunks of particles and of nodes
    per thread)."""
    from skdgmpm import parallel

    previous = parallel.set_threads(2)
    try:
        L = Lattice.from_mesh(rectangle(2.0, 2.0, 80, 80))
        rng = np.random.default_rng(3)
        x = L.origin + rng.uniform(0, 1, (20000, 2)) * (L.upper - L.origin)
        x = x[np.argsort(np.floor(x[:, 1] / L.h[1]) * 1e3 + x[:, 0], kind="stable")]   # row by row
        l0 = np.full(x.shape, L.h[0] / 4)
        F = np.eye(2) + 0.6 * rng.uniform(-1, 1, (len(x), 2, 2))
        fused = shape_functions(L, x, "cpgimp", l0, F=F)
        apart = shape_functions(L, x, "cpgimp", half_lengths("cpgimp", l0, F, L.h))
        assert np.array_equal(fused.values, apart.values) and np.array_equal(fused.cols, apart.cols)
        T = parallel.Transposed(fused.indptr, fused.cols, L.n_nodes)
        assert len(T.chunks) == 2 * parallel.PIECES
        assert np.array_equal(T.first, fused.pattern_T.first) and np.array_equal(T.last, fused.pattern_T.last)
    finally:
        parallel.set_threads(previous)
