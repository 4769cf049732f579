"""One form, two quadratures: particle quadrature against hand formulas [R18 eq 38, 48-50] and
against scikit-fem's own Gauss quadrature; trace operators against the assembled surface form."""
import numpy as np
import pytest
from skfem import CellBasis, FacetBasis, InteriorFacetBasis, asm
from skfem.quadrature import get_quadrature

from skdgmpm import forms
from skdgmpm.faces import boundary_faces, interior_faces
from skdgmpm.grid import Grid, line, rectangle
from skdgmpm.particles import Particles, fill_cells, tensor_layout
from skdgmpm.quadrature import ParticleMap, VolumeOperators, interpolation_matrix, particle_basis


def particles_in(grid, layout, rho=7800.0):
    X, xi, cell, vol = fill_cells(grid.submesh, np.arange(grid.submesh.nelements), layout,
                                  grid.cell_volumes())
    return Particles(X, xi, cell, vol, np.full(len(X), rho), np.zeros(len(X), int))


def test_1d_lumped_mass_and_pseudo_stiffness_match_R18():
    dx = 0.1
    grid = Grid(line(1.0, 10), np.arange(10))
    layout = np.array([[0.2], [0.7]])
    p = particles_in(grid, layout)
    basis, slot = particle_basis(grid, p)
    ops = VolumeOperators.assemble(basis)
    S = interpolation_matrix(basis, slot).toarray()
    V = p.volume
    # R18 eq 48: M_i = sum_p S_ip V_p ; eq 49-50: K_{left,j} = -sum V S_j / dx, K_{right,j} = +...
    assert np.allclose(ops.lumped, S.T @ V)
    K = ops.stiffness[0].toarray()
    e = basis.element_dofs[:, 3]
    sums = S[:, e].T @ V                              # sum_p V_p S_jp for the cell's dofs
    assert np.allclose(K[e[0], e], -sums / dx) and np.allclose(K[e[1], e], sums / dx)
    assert np.isclose(ops.lumped.sum(), 1.0)


def test_particles_at_gauss_points_reproduce_gauss_quadrature():
    """Particle quadrature with particles at Gauss points weighted by w |det J| is DGFEM."""
    mesh = rectangle(2.0, 1.0, 4, 3)
    mesh = mesh.morphed(lambda x: x[0] + 0.1 * np.sin(3 * x[1]), lambda x: x[1] + 0.05 * x[0] ** 2)
    grid = Grid(mesh, np.arange(mesh.nelements))
    gauss = CellBasis(grid.submesh, grid.element, intorder=3)
    Xg, Wg = get_quadrature(grid.submesh.refdom, 3)
    nel, nq = grid.submesh.nelements, Wg.size
    cell = np.repeat(np.arange(nel), nq)
    xi = np.tile(Xg.T, (nel, 1))
    p = Particles(np.zeros((nel * nq, 2)), xi, cell, gauss.dx.ravel(), np.ones(nel * nq),
                  np.zeros(nel * nq, int))
    basis, _ = particle_basis(grid, p)
    for form in (forms.mass, forms.pseudo_stiffness(0), forms.pseudo_stiffness(1)):
        A, B = form.assemble(basis).toarray(), form.assemble(gauss).toarray()
        assert np.allclose(A, B, rtol=1e-12, atol=1e-14 * np.abs(B).max())


def test_projection_conserves_and_preserves_constants():
    grid = Grid(rectangle(1.0, 1.0, 5, 4), np.arange(20))
    p = particles_in(grid, tensor_layout([0.2, 0.6, 0.9], 2))
    basis, slot = particle_basis(grid, p)
    ops = VolumeOperators.assemble(basis)
    pm = ParticleMap.build(interpolation_matrix(basis, slot), p.volume, p.rho0, ops.lumped)
    U = np.random.default_rng(0).standard_normal((len(p), 6))
    assert np.allclose(ops.lumped @ pm.project(U), p.volume @ U)              # conservation
    assert np.allclose(pm.project(np.ones((len(p), 1))), 1.0)                 # constants
    assert np.allclose(pm.interpolate(np.ones((basis.N, 1))), 1.0)
    assert np.allclose(pm.rho, 7800.0)


@pytest.mark.parametrize("d", [1, 2])
def test_trace_operators_equal_assembled_surface_form(d):
    mesh = line(1.0, 6) if d == 1 else rectangle(1.0, 2.0, 3, 4)
    grid = Grid(mesh, np.arange(mesh.nelements))
    m, e = grid.submesh, grid.element
    n_dofs = CellBasis(m, e).N
    rng = np.random.default_rng(d)
    inner = interior_faces(m, e)
    flux = rng.standard_normal(len(inner))
    fb = [InteriorFacetBasis(m, e, side=i) for i in (0, 1)]
    for side, k in (("L", 0), ("R", 1)):
        ref = asm(forms.surface_flux, fb[k], flux=np.repeat(flux[:, None], fb[k].dx.shape[1], axis=1))
        assert np.allclose(inner.integrate(flux[:, None], side)[:, 0], ref, atol=1e-14)
    bnd = boundary_faces(m, e, m.boundary_facets(), n_dofs)
    flux = rng.standard_normal(len(bnd))
    fbb = FacetBasis(m, e, facets=bnd.facets)
    ref = asm(forms.surface_flux, fbb, flux=np.repeat(flux[:, None], fbb.dx.shape[1], axis=1))
    assert np.allclose(bnd.integrate(flux[:, None])[:, 0], ref, atol=1e-14)


def test_inactive_cells_carry_no_dofs_and_body_boundary_is_named_surface():
    mesh = rectangle(3.0, 1.0, 3, 1)
    grid = Grid(mesh, np.array([0, 1]))                # right cell empty
    assert grid.submesh.nelements == 2
    assert CellBasis(grid.submesh, grid.element).N == 8
    surface = grid.submesh.boundaries["surface"]
    mid = grid.submesh.p[:, grid.submesh.facets[:, surface]].mean(axis=1)
    assert np.allclose(mid[0], 2.0) and len(surface) == 1     # the face between active and empty
    assert len(grid.submesh.boundaries["right"]) == 0


@pytest.mark.parametrize("d", [1, 2])
def test_named_facets_follow_their_vertices_to_the_active_mesh(d):
    """Each named facet set of the sub-mesh (active cells renumbered, named facets matched by
    their vertices' keys) is, by coordinates, exactly the named facets of the full mesh that lie
    on an active cell, in increasing order; the same after a mesh's quads are turned clockwise
    and back (`grid._counter_clockwise`), and with the nodes renumbered at random (the new facets
    then in another order than their keys). Reference: facet midpoints, not node numbers."""
    from skdgmpm.grid import _counter_clockwise, _with_facet_names, line

    mesh = line(2.0, 40) if d == 1 else rectangle(3.0, 2.0, 30, 20)
    mid = lambda m, f: np.round(m.p[:, m.facets[:, f]].mean(axis=1).T, 9)       # noqa: E731
    x = mid(mesh, np.arange(mesh.nfacets))
    names = {"low": np.flatnonzero(x[:, -1] < 0.7), "odd": np.arange(1, mesh.nfacets, 7), "none": np.zeros(0, int)}
    mesh = mesh.with_boundaries(names)
    centre = mesh.p[:, mesh.t].mean(axis=1)
    active = np.flatnonzero(np.hypot(*(centre - 1.0)) < 0.8 if d == 2 else centre[0] > 0.55)
    grid = Grid(mesh, active)
    sub = grid.submesh
    on_active = set(np.ravel(mesh.t2f[:, active]).tolist())
    for name, facets in names.items():
        kept = [f for f in facets.tolist() if f in on_active]
        got = sub.boundaries[name]
        assert np.all(np.diff(got) > 0)
        assert sorted(map(tuple, mid(sub, got))) == sorted(map(tuple, mid(mesh, np.array(kept, int))))
    perm = np.random.default_rng(d).permutation(mesh.p.shape[1])      # new node i: old node perm[i]
    renumbered = type(mesh)(mesh.p[:, perm], np.argsort(perm)[mesh.t])  # its facets in another order
    renumbered = _with_facet_names(renumbered, mesh, names, perm)
    for name, facets in names.items():
        got = renumbered.boundaries[name]
        assert np.all(np.diff(got) > 0)
        assert sorted(map(tuple, mid(renumbered, got))) == sorted(map(tuple, mid(mesh, facets)))
    if d == 2:                              # every quad listed clockwise, then turned back
        cw = _with_facet_names(type(mesh)(mesh.p, mesh.t[[0, 3, 2, 1]]), mesh, names, np.arange(mesh.p.shape[1]))
        back = _counter_clockwise(cw)
        for name, facets in names.items():
            got = back.boundaries[name]
            assert np.all(np.diff(got) > 0)
            assert sorted(map(tuple, mid(back, got))) == sorted(map(tuple, mid(mesh, facets)))


@pytest.mark.parametrize("d", [1, 2])
def test_chunked_particle_operators_are_the_whole_grid_ones(monkeypatch, d):
    """`particle_operators` (a chunk of cells at a time, to bound the set-up's memory) gives the
    lumped mass, the K^alpha on their common pattern and S of one particle basis over all the
    cells, bit for bit: a distorted grid, cells holding 1-9 particles (padding), the particles in
    shuffled order."""
    from skdgmpm import quadrature
    from skdgmpm.quadrature import common_pattern, particle_operators

    if d == 1:
        mesh = line(1.0, 23)
    else:
        mesh = rectangle(2.0, 1.0, 9, 7).morphed(lambda x: x[0] + 0.1 * np.sin(3 * x[1]),
                                                 lambda x: x[1] + 0.05 * x[0] ** 2)
    grid = Grid(mesh, np.arange(mesh.nelements))
    full = particles_in(grid, tensor_layout([0.15, 0.5, 0.8], d))
    rng = np.random.default_rng(3)
    keep = rng.random(len(full.X)) < 0.5
    keep[np.unique(full.cell, return_index=True)[1]] = True             # every cell keeps one
    order = rng.permutation(np.flatnonzero(keep))
    p = Particles(full.X[order], full.xi[order], full.cell[order], full.volume[order], full.rho0[order],
                  full.material[order])
    basis, slot = particle_basis(grid, p)
    ops = VolumeOperators.assemble(basis)
    S = interpolation_matrix(basis, slot)
    K = common_pattern(ops.stiffness)
    monkeypatch.setattr(quadrature, "CELL_CHUNK", 5)                      # many chunks of unequal length
    lumped, stiffness, S_c, dof_cell = particle_operators(grid, p)
    assert np.array_equal(lumped, ops.lumped)
    assert np.array_equal(stiffness[0], K[0].indptr) and np.array_equal(stiffness[1], K[0].indices)
    assert np.array_equal(stiffness[2], np.stack([k.data for k in K]))
    assert stiffness[0].dtype == K[0].indptr.dtype and stiffness[1].dtype == K[0].indices.dtype
    for a, b in ((S.indptr, S_c.indptr), (S.indices, S_c.indices), (S.data, S_c.data)):
        assert np.array_equal(a, b) and a.dtype == b.dtype
    assert np.array_equal(dof_cell[basis.element_dofs], np.broadcast_to(np.arange(basis.nelems), basis.element_dofs.shape))
