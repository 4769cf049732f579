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
    "impact-dcu": ("plate_impact_neohookean_2d", ["grid.cells=[12, 9]", 'method.transverse="dcu"', "method.cfl=0.7"]),
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
    st.interface_flux(GridState(state.U, state.Q))
    (face, split), rec_state = st._records()
    for a, b in zip(kept, (face, split, rec_state)):
        np.testing.assert_array_equal(a, b)
    fresh = build(load_scene(name, overrides)).stepper     # the same guard state: the same Delta t
    fresh.dt_growth, fresh.dt_recent = st.dt_growth, st.dt_recent
    again = st.step(disc.initial)           # stepped from the initial state: its own records
    other = fresh.step(disc.initial)
    assert again.t == other.t and np.array_equal(again.Q, other.Q)
