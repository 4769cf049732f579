"""The fused DGMPM face passes against the batched reference path (traces as sparse products,
batched tangents, `riemann.godunov_fluxes` and `riemann.transverse_fluxes`), with two laws in one
grid, so the per-cell law dispatch and both CTU sides are checked face by face."""
import numpy as np
import pytest

from skdgmpm import parallel, system
from skdgmpm.build import build
from skdgmpm.dgmpm import distinct_rows
from skdgmpm.dgmpm_kernels import boundary_corrections, face_corrections
from skdgmpm.riemann import godunov_fluxes, transverse_fluxes
from skdgmpm.scene import load_scene
from skdgmpm.scheme import GridState
from skdgmpm.constitutive import MaterialSet
from skdgmpm.materials import NeoHookean, SaintVenantKirchhoff
from skdgmpm.materials.points import law_table


def _stepper(transverse):
    scene = load_scene("plate_impact_neohookean_2d", ["grid.cells=[6, 5]", f'method.transverse="{transverse}"',
                                                      'method.layout="nodes"'])     # random nodal states
    st = build(scene).stepper
    # two laws: the right half of the cells Saint-Venant-Kirchhoff
    st.materials = MaterialSet((NeoHookean(E=200e9, nu=0.3, rho=7800.0),
                                SaintVenantKirchhoff(E=100e9, nu=0.25, rho=2700.0)))
    centre = st.grid.submesh.p[:, st.grid.submesh.t].mean(axis=1)[0]
    st.cell_material = (centre > np.median(centre)).astype(np.int64)
    st.laws = law_table(st.materials.materials)
    return st


def _random_state(st, seed=0, uniform=None):
    """A random state at the nodes; the cells where ``uniform`` is True hold one state at all their
    nodes (as one particle per cell gives), which the face pass reads from the cell's record."""
    rng = np.random.default_rng(seed)
    n, d = st.n_dofs, st.d
    F = np.eye(d)[None] + 0.05 * rng.standard_normal((n, d, d))
    v = 10.0 * rng.standard_normal((n, d))
    if uniform is not None:
        first = st.cell_dofs[:, 0][st.dof_cell]              # each node's cell's first node
        same = uniform[st.dof_cell]
        F[same], v[same] = F[first[same]], v[first[same]]
        st.map.rho[same] = st.map.rho[first[same]]
    P = st.materials.stress(F, st.cell_material[st.dof_cell])
    U = system.join(F, st.map.rho[:, None] * v)
    return GridState(U, system.join(P, v))


UNIFORM = {"none": lambda n: None, "all": lambda n: np.ones(n, bool), "half": lambda n: np.arange(n) % 2 == 0}
# every cell recorded, read by the kernel with the trace path (a nodal layout's) and by the one
# without it (one particle per cell's: `DGMPM.trace_path` False)
CASES = [*UNIFORM, "all, no trace path"]


def _case(st, case):
    """The grid state of a test case (`CASES`), the stepper set as the case says."""
    uniform = case.split(",")[0]
    st.trace_path = not case.endswith("no trace path")
    return _random_state(st, uniform=UNIFORM[uniform](len(st.cell_dofs)))


@pytest.mark.parametrize("case", CASES)
@pytest.mark.parametrize("transverse", ["dcu", "ctu"])
def test_interior_pass_matches_batched_path(transverse, case, monkeypatch):
    """Both paths of a face side (the cell's record, the trace's record), alone and mixed, and a
    grid of recorded cells through the kernel compiled without the trace path. The boundary
    faces' parts are not added to the corrections here (the interior faces' own against the
    reference; the boundary faces' in the next test)."""
    from skdgmpm import dgmpm
    monkeypatch.setattr(dgmpm, "boundary_corrections", lambda *args: None)
    st = _stepper(transverse)
    g = _case(st, case)
    f, d, dt = st.interior, st.d, 1e-7
    flux, corr, corr_bnd = st.interface_flux(g, 0.0)[:3]
    flux, corr_bnd = flux + dt * face_corrections(corr), dt * corr_bnd

    sides = {}
    for side, T, cells in (("L", f.T_L, f.cell_L), ("R", f.T_R, f.cell_R)):
        F = (T @ g.U)[:, : d * d].reshape(-1, d, d)
        sides[side] = (T @ g.Q, st.materials.tangent(F, st.cell_material[cells]), T @ st.map.rho)
    ref, fluct_L, fluct_R = godunov_fluxes(*sides["L"], *sides["R"], f.normal)
    ref_bnd = np.zeros_like(corr_bnd)
    if transverse == "ctu":
        corr = np.zeros_like(ref)
        for side, w in (("L", fluct_L), ("R", fluct_R)):
            h, n, j_int, j_bnd, sign = st.side_topology(side)
            _, C, rho = sides[side]
            transverse_fluxes(w, C, rho, -dt / (2.0 * h), n, j_int, j_bnd, sign, corr, ref_bnd)
        ref = ref + corr
    scale = np.abs(ref).max(axis=0)
    assert np.all(np.abs(flux - ref) <= 1e-12 * scale)
    assert np.all(np.abs(corr_bnd - ref_bnd) <= 1e-12 * np.abs(ref).max())


@pytest.mark.parametrize("case", CASES[1:])
@pytest.mark.parametrize("transverse", ["dcu", "ctu"])
def test_boundary_pass_reads_a_recorded_cell_as_its_trace(transverse, case):
    """A boundary face whose cell is recorded takes its side (state, impedance, and for CTU the
    tangent and the edges' impedances) from the cell's record; the same face computed from its
    trace and the law's tangent (the record states set to 0: no cell recorded) gives the same
    stationary states, fluxes and CTU corrections (an independent path through the law). With
    every cell recorded, the kernel with the trace path and the one without it (one particle per
    cell's) both."""
    st = _stepper(transverse)
    g = _case(st, case)
    _, corr, corr_bnd = st.interface_flux(g, 1e-6)[:3]     # the records of g
    _, state = st._records()
    assert np.any(state[st.boundary.cell_L] == 1)          # some boundary faces read a record
    assert st._every_cell_recorded(state) == case.startswith("all")
    made = {}
    for path in ("records", "traces"):
        if path == "traces":
            state[:] = 0
            st.trace_path = True
        c, c_bnd = corr.copy(), corr_bnd.copy()
        run, (flux, t_s, v_s, parts) = st.boundary_pass(g, 1e-6)
        assert parallel.chunked(*run) == -1
        if transverse == "ctu":
            boundary_corrections(st.topology["boundary"], parts, c, c_bnd)
        made[path] = (flux, t_s, v_s, c, c_bnd)
    for mine, ref in zip(made["records"], made["traces"]):
        assert mine.shape == ref.shape
        if ref.size:                    # DCU: no interior corrections
            assert np.all(np.abs(mine - ref) <= 1e-12 * np.abs(ref).max())


def test_a_nodal_run_steps_on_one_kernel_of_each_face_pass(monkeypatch):
    """Two particles per cell: the first step's cells are all recorded (a uniform initial state),
    later ones' are not. Both face passes take the kernel with the trace path from the first step
    on (one kernel each, compiled within the start-up that the run reports apart), not one kernel
    for the first steps and another, compiled inside the timed loop, once a cell is not recorded."""
    from skdgmpm import dgmpm_kernels
    asked = {"_interior_pass": set(), "_boundary_faces": set()}
    for name in asked:
        def recording(*sizes, factory=getattr(dgmpm_kernels, name), name=name):
            asked[name].add(sizes[2])               # the literal: the trace path compiled
            return factory(*sizes)
        monkeypatch.setattr(dgmpm_kernels, name, recording)
    built = build(load_scene("bar_elastic_1d", ["particles.per_cell=2", "method.cfl=0.5"]))
    stepper, state, recorded = built.stepper, built.initial, []
    for _ in range(30):
        state = stepper.step(state)
        recorded.append(stepper._every_cell_recorded(stepper._records()[1]))
    assert recorded[0] and not all(recorded)
    assert asked == {"_interior_pass": {True}, "_boundary_faces": {True}}


def test_a_recorded_cell_that_is_not_hyperbolic_stops_the_pass_at_its_first_face():
    """A cell whose nodes hold one state with a negative density (rho A_n negative definite): its
    record says so and the face pass stops at the first face of that cell, naming it."""
    from skdgmpm.errors import InstabilityError
    st = _stepper("ctu")
    n_cells = len(st.cell_dofs)
    g = _random_state(st, uniform=np.ones(n_cells, bool))
    c = n_cells // 2
    st.map.rho[st.dof_cell == c] *= -1.0
    with pytest.raises(InstabilityError, match="not positive definite"):
        try:
            st.interface_flux(g, 0.0)
        except InstabilityError as exc:
            faces = np.flatnonzero((st.interior.cell_L == c) | (st.interior.cell_R == c))
            assert str(exc).endswith(f"at face {faces[0]}")
            raise


@pytest.mark.parametrize("scene, keys", [
    ("plate_impact_neohookean_2d", ['method.transverse="ctu"']),
    ("plate_impact_neohookean_2d", ['method.transverse="dcu"']),
    ("plate_impact_j2_2d", []),                        # internal variables at the points
    ("bar_elastoplastic_1d", []),
])
def test_the_law_pass_forms_each_particles_row_as_the_nodal_path_did(scene, keys, monkeypatch):
    """With one particle per cell and forward Euler, the law's pass forms each particle's new state
    where it reads it (`CellRows`: the interior faces' sum, then the boundary faces' terms; one pass
    over the particles, not two). The reference: the rows formed first without the boundary faces
    (`cell_update`), then the boundary faces' terms integrated face by face through the boundary
    trace with the nodal weights (`boundary_terms`, as the nodal layout does), then the law's pass:
    the same bits after 12 steps of an impact."""
    def run(fused):
        st = build(load_scene(scene, ["grid.cells=[12, 10]"] * scene.endswith("_2d") + keys))
        stepper, state = st.stepper, st.initial
        assert stepper.cellwise and stepper.rows_in_law_pass
        if not fused:
            _boundary_faces_after_the_rows(monkeypatch)
        for _ in range(12):
            state = stepper.step(state)
        monkeypatch.undo()
        return state

    fused, reference = run(True), run(False)
    for name in ("U", "Q", "x", "history"):
        assert np.array_equal(getattr(fused, name), getattr(reference, name)), name
    assert fused.t == reference.t and fused.step == reference.step == 12


def _boundary_faces_after_the_rows(monkeypatch):
    """Patch `DGMPM` so that the particles' rows are formed apart from the law's pass, with zero
    boundary terms, and the boundary faces' terms then added into them by `boundary_terms` with
    the weights (step, 1 / V) through the boundary trace (the faces in order, as a scatter)."""
    from skdgmpm.dgmpm import DGMPM
    original, kept = DGMPM.add_boundary_terms, {}

    def add_boundary_terms(self, terms, time, dt, weight, out):
        if weight is not None:
            return original(self, terms, time, dt, weight, out)
        power = original(self, terms, time, dt, None, out)      # the power as the step has it
        out[:] = 0.0
        kept.update(terms=terms, dt=dt)
        return power

    def add_source(self, time, weight, out):        # called just after the rows are formed (no body force here)
        self._boundary_terms(kept["terms"], kept["dt"], weight, out)

    monkeypatch.setattr(DGMPM, "rows_in_law_pass", property(lambda self: False))
    monkeypatch.setattr(DGMPM, "add_boundary_terms", add_boundary_terms)
    monkeypatch.setattr(DGMPM, "add_source", add_source)


def test_distinct_rows_give_every_row_back_bit_for_bit():
    """`distinct_rows`: each row once, and every row read back through its index with its bits,
    -0.0 kept apart from 0.0 and nan kept (a product by one can tell them)."""
    rows = np.array([[1.0, 0.0], [1.0, -0.0], [np.nan, 2.0], [1.0, 0.0], [np.nan, 2.0], [0.5, 3.0]])
    a = rows.reshape(6, 1, 2)
    distinct, which = distinct_rows(a)
    assert distinct.shape == (4, 1, 2) and which.dtype == np.int64
    assert np.array_equal(distinct[which].view(np.int64), a.view(np.int64))


def test_ctu_boundary_filters_are_kept_once_per_condition_and_direction():
    """CTU's boundary filter (`DGMPM.transverse_flux`) is kept as its distinct matrices and each
    face's: no more than the boundary's (condition, normal) pairs; each face's is a projection
    onto the components its condition leaves free (rank: the free velocity and traction
    components, `BoundaryCondition.constraints`)."""
    s = build(load_scene("plate_impact_neohookean_2d", ['method.transverse="ctu"'])).stepper
    filters, which = s.ctu
    group = np.empty(len(s.boundary), int)
    for k, (sel, _) in enumerate(s.bc_groups):
        group[sel] = k
    pairs = {(g, *n) for g, n in zip(group, np.round(s.boundary.normal, 12))}
    assert len(which) == len(s.boundary) and 2 <= len(filters) <= len(pairs) < len(which)
    for sel, bc in s.bc_groups:
        _, imposed_v, imposed_t = bc.constraints(s.boundary.normal[sel])
        P = filters[which[sel]]
        assert np.allclose(P @ P, P, atol=1e-12)
        assert np.all(np.linalg.matrix_rank(P) == np.sum(~imposed_v) + np.sum(~imposed_t))
