"""First-order DGMPM on the particles' own arrays (``method.layout = "auto"`` with one particle
strictly inside every cell and forward Euler) against R18's nodal stages (``"nodes"``: projection,
nodal Euler update with the volume term, back map). With one particle per cell and the lumped mass
the two are the same map in exact arithmetic (`DGMPM._cellwise`); the reference here is the nodal
path itself, an independent computation through the assembled operators, and the two must agree
to round-off over many steps, for each ingredient the reduction touches: CTU and DCU faces,
imposed and free boundaries, a body force (manufactured ring), inactive cells, an unstructured
gmsh mesh, two materials and a law with internal variables."""
import dataclasses

import numpy as np
import pytest

from skdgmpm.build import build
from skdgmpm.dgmpm import DGMPM
from skdgmpm.errors import InputError
from skdgmpm.scene import load_scene
from skdgmpm.scheme import GridState

CASES = {
    "impact-ctu": ("plate_impact_neohookean_2d", ["grid.cells=[12, 9]", 'method.transverse="ctu"']),
    "impact-dcu": ("plate_impact_neohookean_2d", ["grid.cells=[12, 9]", 'method.transverse="dcu"', "method.cfl=0.7",
                                                 "method.cfl_above_limit=true"]),      # R18's 0.7 (2D limit 0.651)
    "bar-1d": ("bar_elastic_1d", ["grid.cells=[40]"]),
    "elastoplastic-1d": ("bar_elastoplastic_1d", ["grid.cells=[40]"]),
    "ring-body-force": ("mms_ring_2d", ["particles.per_cell=1", 'method.name="dgmpm"', 'method.transverse="ctu"']),
    "j2-ctu": ("plate_impact_j2_2d", ["grid.cells=[12, 9]"]),
    "gmsh-j2": ("multiholed_cell_j2_2d", ["particles.per_cell=1", 'method.name="dgmpm"', 'method.transverse="ctu"',
                                          "method.cfl=0.5"]),
}


def _run(name, overrides, layout, steps):
    disc = build(load_scene(name, [*overrides, f'method.layout="{layout}"']))
    state = disc.initial
    for _ in range(steps):
        state = disc.stepper.step(state)
    return disc.stepper, state


@pytest.mark.parametrize("case", CASES)
def test_cells_equal_nodes_to_round_off(case):
    name, overrides = CASES[case]
    cells, a = _run(name, overrides, "auto", 25)
    nodes, b = _run(name, overrides, "nodes", 25)
    assert cells.cellwise and not nodes.cellwise
    assert a.t == pytest.approx(b.t, rel=1e-12)
    for key in ("U", "Q", "x", "history"):
        x, y = getattr(a, key), getattr(b, key)
        if y.size:
            scale = np.abs(y).max() or 1.0
            assert np.abs(x - y).max() <= 1e-11 * scale, key
    assert b.U[:, -1].any() or b.U[:, -2].any()          # something moved
    energy = sum(nodes.energy(b))          # the work through the boundary, to round-off of the energy
    assert cells.external_work == pytest.approx(nodes.external_work, rel=1e-10, abs=1e-12 * energy)


@pytest.mark.parametrize("overrides", [["particles.per_cell=2"], ['method.integrator="rk2"'],
                                       ['method.layout="nodes"']])
def test_nodal_stages_where_the_reduction_does_not_hold(overrides):
    """Two particles in a cell, RK2 (its second stage evaluates the law at the nodes), or asked."""
    disc = build(load_scene("plate_impact_neohookean_2d", ["grid.cells=[6, 5]", *overrides]))
    assert not disc.stepper.cellwise


def test_a_particle_on_a_cell_edge_is_not_cellwise_and_one_clear_error():
    """A particle where a node's shape function vanishes: the lumped projection does not hold
    there, so the layout is not taken as cellwise; alone in its cell it leaves that node with no
    mass, which the nodal stages refuse with one clear error (not a division by zero)."""
    st = build(load_scene("bar_elastic_1d", ["grid.cells=[10]"])).stepper
    assert st.cellwise
    xi = st.particles.xi.copy()
    xi[3] = 0.0                             # on the cell's left node: the right node's Phi is 0
    moved = dataclasses.replace(st.particles, xi=xi)
    with pytest.raises(InputError, match=r"cell 3 holds only particles on its edges \(#3 at"):
        DGMPM(st.grid, moved, st.materials, st.bcs, cfl=st.cfl, transverse=st.transverse)


def test_unknown_layout_is_one_clear_error():
    with pytest.raises(InputError, match="method.layout"):
        build(load_scene("bar_elastic_1d", ["grid.cells=[10]", 'method.layout="cells"']))


@pytest.mark.parametrize("case", ["impact-ctu", "impact-dcu", "bar-1d", "j2-ctu"])
def test_records_of_the_constitutive_update_are_those_of_the_record_pass(case):
    """With one particle per cell the step's constitutive update writes the new state's cell
    records (the law's tangent at hand) and the next step reads them instead of its own record
    pass: they must be that pass's bits (`dgmpm_kernels.cell_records`, the independent path a
    state without kept records takes), and a state stepped from elsewhere (not the last result)
    must not read them."""
    name, overrides = CASES[case]
    disc = build(load_scene(name, overrides))
    st, state = disc.stepper, disc.initial
    for _ in range(6):
        state = st.step(state)
    assert st._records_of[0] is state.U and st._records_of[1] is state.Q
    (face, split), rec_state = st._records()
    kept = (face.copy(), split.copy(), rec_state.copy())
    st._records_of = None                   # what a state without kept records gets
    st.interface_flux(GridState(state.U, state.Q), state.t)
    (face, split), rec_state = st._records()
    for a, b in zip(kept, (face, split, rec_state)):
        np.testing.assert_array_equal(a, b)
    fresh = build(load_scene(name, overrides)).stepper     # the same guard state: the same Delta t
    fresh.dt_growth, fresh.dt_recent = st.dt_growth, st.dt_recent
    again = st.step(disc.initial)           # stepped from the initial state: its own records
    other = fresh.step(disc.initial)
    assert again.t == other.t and np.array_equal(again.Q, other.Q)


AT_REST = {**{k: CASES[k] for k in ("impact-ctu", "impact-dcu", "bar-1d", "elastoplastic-1d", "ring-body-force",
                                    "gmsh-j2")},
           "linear-ctu": ("plate_impact_neohookean_2d", ["grid.cells=[12, 9]", 'material.law="linear_elastic"'])}


def _bits(a):
    return np.ascontiguousarray(a, dtype=float).view(np.uint64)      # -0.0 and +0.0 told apart


@pytest.mark.parametrize("case", AT_REST)
def test_the_initial_state_takes_the_steps_law_pass_and_its_records(case, monkeypatch):
    """With one particle per cell the initial state comes from the step's own law pass
    (`DGMPM.at_rest`), which also writes the cell records that the first step's faces read: t = 0
    compiles neither the stand-alone stress pass and health check nor the record pass (each
    patched to fail here); it calls the step's law-pass kernel with the step's argument types (one
    compiled signature). The reference is those stand-alone passes (`MaterialSet.stress_update`,
    `skdgmpm.health.assess`, `dgmpm_kernels.cell_records`), bit for bit: Q, the history, the wave
    speeds, the health, the records, and the first step against one whose records the record pass
    made. F and v hold -0.0 (and F != I, v != 0 elsewhere): the rows of the stage that adds
    nothing (`DGMPM._rows_at_rest`) are U's, bit for bit (with a step of +0.0, -0.0 came back +0.0).
    The case "linear-ctu": a law whose tangent does not depend on F."""
    import numba
    from skdgmpm import constitutive, parallel, system
    from skdgmpm.dgmpm_kernels import cell_update
    from skdgmpm.health import assess

    name, overrides = AT_REST[case]
    twin = build(load_scene(name, overrides)).stepper
    st = build(load_scene(name, overrides)).stepper
    assert st.cellwise and st.initial_pass == "law"
    n, d = len(st.particles), st.d
    rng = np.random.default_rng(3)
    F = np.broadcast_to(np.eye(d), (n, d, d)) + 1e-3 * rng.standard_normal((n, d, d))
    v = 10.0 * rng.standard_normal((n, d))
    F[::3] = np.eye(d) * np.where(np.eye(d) > 0, 1.0, -1.0)       # off-diagonal -0.0
    v[::2, 0] = -0.0
    for target in ("skdgmpm.scheme.assess", "skdgmpm.dgmpm.cell_records"):
        monkeypatch.setattr(target, lambda *args, target=target: pytest.fail(target))
    monkeypatch.setattr(constitutive.MaterialSet, "stress_update", lambda *args, **kw: pytest.fail("stress pass"))
    passes, chunked = [], parallel.chunked

    def law_passes(n, kernel, spec, args, *rest):         # the law's passes: kernel and argument types
        if kernel in constitutive._states.kernels.values():
            passes.append((kernel, numba.typeof(args)))
        return chunked(n, kernel, spec, args, *rest)
    monkeypatch.setattr(parallel, "chunked", law_passes)
    state = st.initial_state(F, v)
    first = st.step(state)
    monkeypatch.undo()
    assert len(passes) >= 2 and all(p == passes[0] for p in passes), passes   # one kernel, one signature

    virgin = st.materials.initial_history(st.particles.material)
    P, history = st.materials.stress_update(F, st.particles.material, virgin)
    np.testing.assert_array_equal(_bits(state.Q), _bits(system.join(P, v)))
    np.testing.assert_array_equal(_bits(state.U), _bits(system.join(F, st.particles.rho0[:, None] * v)))
    if st.materials.n_history:
        np.testing.assert_array_equal(_bits(state.history), _bits(history))
    alone = assess(st.materials, st.particles, state.U, state.Q)
    np.testing.assert_array_equal(state.speed, alone.speed)
    assert state.health == alone.record() and state.fastest == alone.fastest
    if st.rows_in_law_pass:
        rows = np.empty(state.U.shape)
        cell_update(st._rows_at_rest(state.U), rows)
        np.testing.assert_array_equal(_bits(rows), _bits(state.U))

    reference = twin.initial_state(F, v)
    twin._records_of = None                 # the first step's records from the record pass
    (face, split), rec_state = twin._records()
    twin.interface_flux(GridState(reference.U, reference.Q), reference.t)
    made = (face.copy(), split.copy(), rec_state.copy())
    twin._records_of = None
    other = twin.step(reference)
    assert first.t == other.t
    for key in ("U", "Q", "x", "history"):
        np.testing.assert_array_equal(_bits(getattr(first, key)), _bits(getattr(other, key)))
    ours = st.initial_state(F, v)           # the records this state's pass wrote
    assert st._records_of[0] is ours.U and st._records_of[1] is ours.Q
    (face, split), rec_state = st._records()
    for a, b in zip(made, (face, split, rec_state)):
        np.testing.assert_array_equal(_bits(a) if a.dtype.kind == "f" else a, _bits(b) if b.dtype.kind == "f" else b)


@pytest.mark.parametrize("case", ["impact-ctu", "impact-dcu", "j2-ctu", "gmsh-j2"])
def test_particles_in_any_order_step_to_the_same_bits(case):
    """One particle per cell, the particles listed in a shuffled order (a particle file need not
    follow the cells): each particle's state after 10 steps equals, bit for bit, that of the same
    particle listed in the cells' order. The face passes read a recorded cell's state from Q at its
    particle's row (`DGMPM.state_rows`), the records by cell: an identity taken for that map, or
    a record written by point row, would mix the cells up here."""
    name, overrides = CASES[case]
    disc = build(load_scene(name, overrides))
    st, p = disc.stepper, disc.stepper.particles
    order = np.random.default_rng(7).permutation(len(p))
    shuffled = dataclasses.replace(p, **{f.name: getattr(p, f.name)[order] for f in dataclasses.fields(p)})
    twin = DGMPM(st.grid, shuffled, st.materials, st.bcs, cfl=st.cfl, integrator=st.integrator,
                 transverse=st.transverse, layout=st.layout)
    assert st.cellwise and twin.cellwise and not np.array_equal(twin.state_rows, np.arange(len(p)))
    d = st.d
    F, v = disc.initial.U[:, :d * d].reshape(-1, d, d), disc.initial.Q[:, d * d:]
    a, b = disc.initial, twin.initial_state(F[order], v[order])
    for _ in range(10):
        a, b = st.step(a), twin.step(b)
    assert a.t == b.t and a.U[:, -1].any()
    for key in ("U", "Q", "x", "history"):
        assert np.array_equal(getattr(a, key)[order], getattr(b, key)), key
    assert st.external_work == twin.external_work
