"""First-order DGMPM [R18 §5]: Q1 broken grid, particles as quadrature, Godunov fluxes.

One step is the list of named stages of R18 §5 (a)-(h):

    project -> time_step -> interface_flux (interior and boundary faces) -> transverse_flux -> source
    -> advance (with the volume term) -> constitutive_update (with the back map)

``advance`` is forward Euler [R18 eq 20] or Heun's RK2 with both stages on the grid [R18 §7.1]
(the second stage evaluates the law at the grid nodes). The CTU corrections of R18 §4.4 (2D,
``transverse="ctu"``) come with the Godunov fluxes (`skdgmpm.dgmpm_kernels`): with one particle
per cell the faces keep their fluctuations and each cell splits the sum of those entering it
through the two faces next to each of its edges (`cell_corrections`: B+ is linear); otherwise
each fluctuation is split at its face as soon as it is known and the edges gather the parts.
``transverse_flux`` filters the boundary faces' corrections (and integrates those faces in the same
pass); DCU leaves them out. ``source`` adds
int Phi rho0 b = sum_p S_ip V_p rho0 b(X_p, t) when a body force is set (particle quadrature, at
the time the boundary values are taken).

The faces' terms depend on Delta t only through the factor of the CTU corrections and the
boundary conditions' values at the step's middle: they are computed once per projected state
(``fixed_terms``), and an attempt that the CFL guard repeats with a smaller Delta t reuses them
while those values stay as they were (everything after the faces is redone). A stage of
``advance`` is one compiled pass over the nodes, U + dt M^-1 (volume term + interior faces),
the volume term (c) sum_alpha K^alpha F_alpha(Q) computed row by row and the interior faces'
integral gathered node by node in that pass (neither is stored), to which the boundary faces'
terms are then added, weighted by dt M^-1 (no residual array). ``volume_flux`` remains as the
stand-alone statement of (c).

With forward Euler and one particle strictly inside every cell (R18's usual layout; ``layout``
"auto", `DGMPM._cellwise`), (a), (c), (f) and (g) reduce exactly: the projection puts the
particle's state at the cell's nodes, the volume term sums to zero over them and the back map of
the Euler stage is U_p + dt / V_p (sum of the cell's face fluxes). The step then runs on the
particles' own arrays (the cell records read the particle; (f)-(g) is each particle's row,
`dgmpm_kernels.cell_row`, formed by the law's pass where it reads the particle's new state: one
pass over the particles, not two) and keeps no nodal array, operator or trace: the same numbers
up to round-off (tests/test_layout.py), a third of the memory and half the passes.
"""
from dataclasses import dataclass, field

import numpy as np
import scipy.sparse as sp

from skdgmpm.materials.points import law_table

from . import parallel, system
from .dgmpm_kernels import (CellRows, boundary_corrections, boundary_edge_corrections, boundary_faces, boundary_terms,
                            cell_corrections, cell_records, cell_update, euler_update, interior_pass,
                            kept_width, split_width)
from .errors import InputError
from .faces import interior_faces
from .integrators import INTEGRATORS
from .quadrature import ParticleMap, particle_operators
from .riemann import face_passes
from .scheme import GodunovScheme, GridState, cell_values, stage


@dataclass
class DGMPM(GodunovScheme):
    """First-order DGMPM stepper on a `Grid` with `Particles`.

    Parameters
    ----------
    grid, particles : the discretisation (``particles.cell`` indexes ``grid.submesh``)
    materials : MaterialSet
    bcs : list of (boundary name, BoundaryCondition); later entries override earlier ones on
        shared faces; boundary faces with no condition are free (zero traction).
    cfl : Courant number; integrator : "euler" | "rk2"; transverse : "dcu" | "ctu" (2D)
    body_force : callable (X (n, d), t) -> b (n, d) in m/s^2, or None (no source, no cost)
    layout : "auto" (one particle strictly inside every cell and forward Euler: the step on the
        cells, `_cellwise`) | "nodes" (R18's nodal stages always)
    """

    grid: object
    particles: object
    materials: object
    bcs: list
    cfl: float = 1.0
    integrator: str = "euler"
    transverse: str = "dcu"
    body_force: object = None
    layout: str = "auto"
    particles_key: str = "particles"        # what the errors about the particles name (their scene key)
    stages: tuple = ("project", "time_step", "advance", "interface_flux", "transverse_flux", "source", "nodal_state",
                     "constitutive_update", "check")
    external_work: float = field(default=0.0, init=False)
    _kept: tuple = field(default=None, init=False, repr=False)   # (projected state, (ghost values, its faces' terms))
    _work: dict = field(default_factory=dict, init=False, repr=False)    # `_buffer`'s arrays, by name

    def __post_init__(self):
        if self.integrator not in ("euler", "rk2"):
            raise InputError(f"method.integrator = {self.integrator!r}: expected 'euler' or 'rk2'")
        if self.transverse not in ("dcu", "ctu"):
            raise InputError(f"method.transverse = {self.transverse!r}: expected 'dcu' or 'ctu'")
        if self.integrator == "rk2" and self.materials.n_history:
            # RK2's second stage needs the law at the grid nodes, where no history exists [L23 §1]
            laws = ", ".join(sorted({m.law_name for m in self.materials.materials if m.n_history}))
            raise InputError(f"method.integrator = 'rk2' with material law {laws}: a law with internal "
                             "variables needs integrator = 'euler' in DGMPM (RK2 would evaluate it at the "
                             "grid nodes, where the history does not live)")
        g, p = self.grid, self.particles
        self.d = g.dim
        n_cells = g.submesh.nelements
        self.cellwise = self._cellwise()
        # whether a face pass may meet a cell whose nodes differ (not recorded): then its one kernel
        # has the trace path from the first step on, whether that step's cells are all recorded or not
        self.trace_path = not self.cellwise
        self._records_of = None                 # (U, Q) of the state whose cell records are kept: `_records`
        if self.cellwise:       # the particles' own arrays are the grid state: no operators kept
            self.n_dofs = n_cells * len(g.element.doflocs)
            self.point = np.empty(n_cells, dtype=np.int32)
            self.point[p.cell] = np.arange(len(p), dtype=np.int32)
            self.point_cell = np.ascontiguousarray(p.cell, dtype=np.int32)
            self.inv_volume = 1.0 / p.volume
        else:
            # built a chunk of cells at a time: the peak of the set-up is a chunk's basis, not the grid's
            lumped, self.stiffness, S, self.dof_cell = particle_operators(g, p)
            self.map = ParticleMap.build(S, p.volume, p.rho0, lumped)
            del S
            self.n_dofs = len(lumped)
            self._check_covered(lumped)
            self.inv_M = 1.0 / lumped
        self.cell_material = cell_values("materials", p.cell, p.material, n_cells)
        self.cell_volume = g.cell_volumes()
        self.h_min = float(g.cell_sizes().min())
        # X: not read here; the traces: not with one particle per cell
        self.interior = interior_faces(g.submesh, g.element, coordinates=False, traces=not self.cellwise)
        self._setup_boundary(g.element)
        self._setup_cell_faces()
        self._setup_transverse()
        # the cell records (`_records`): work arrays of every step, their shapes the grid's, made once
        slots, ctu = self.cell_normals.shape[1], self.ctu is not None
        self._record_arrays = ((np.empty((n_cells, kept_width(self.d, slots))),
                                np.empty((n_cells, split_width(self.d, slots, ctu)))), np.empty(n_cells, np.int8))
        self.laws = law_table(self.materials.materials)          # the compiled point laws
        f = self.interior
        if self.cellwise:       # a boundary face's side: its cell's particle (weight 1: the same bits)
            b = self.boundary
            T = sp.csr_matrix((np.ones(len(b)), (np.arange(len(b)), self.point[b.cell_L])), shape=(len(b), len(p)))
            self.traces = {"boundary": parallel.csr(T)}
            self.cell_faces = self.cell_sources[0] if self.ctu is not None else self._cell_faces()
        else:
            self.traces = {"L": parallel.csr(f.T_L), "R": parallel.csr(f.T_R),
                           "boundary": parallel.csr(self.boundary.T_L)}
            # -int Phi F* over the interior faces as a gather over each node's faces (`euler_update`)
            self.gather_interior = parallel.csr((sp.diags(f.measure) @ (f.T_R - f.T_L)).T.tocsr())

    def _cellwise(self):
        """Whether the step runs on the particles' own arrays (``layout`` "auto": forward Euler,
        exactly one particle in every cell, strictly inside it). With the lumped mass, one particle
        p in a cell makes the projection of (a) that particle's state at the cell's nodes, and
        the back map (g) of the Euler stage (f) U_p + dt / V_p sum_i R_i (sum_i S_ip = 1, m_i =
        S_ip V_p > 0): the volume term sums to zero over the nodes (sum_i grad Phi_i = 0), a
        face's trace weights to one, a body force to V_p rho0 b. The step is then R18 §5 on the
        cells (`dgmpm_kernels.cell_update`), the same numbers up to round-off, without the nodal
        arrays, the operators or their passes; "nodes" keeps R18's nodal stages."""
        if self.layout not in ("auto", "nodes"):
            raise InputError(f"method.layout = {self.layout!r}: expected 'auto' or 'nodes'")
        p, n_cells = self.particles, self.grid.submesh.nelements
        if self.layout == "nodes" or self.integrator != "euler" or len(p) != n_cells:
            return False
        if not np.array_equal(np.bincount(p.cell, minlength=n_cells), np.ones(n_cells, dtype=np.int64)):
            return False
        e = self.grid.element
        return all(np.all(e.lbasis(np.ascontiguousarray(p.xi.T), i)[0] > 0.0) for i in range(len(e.doflocs)))

    def _check_covered(self, lumped):
        """Every node of a cell with particles needs mass (m_i = sum_p S_ip V_p > 0, R18 eq 38): a
        cell whose particles all lie on the edges opposite one of its nodes leaves it none."""
        empty = np.flatnonzero(lumped <= 0.0)
        if len(empty):
            cell = int(self.dof_cell[empty[0]])
            inside = np.flatnonzero(self.particles.cell == cell)
            where = ", ".join(f"#{k} at {tuple(float(x) for x in self.particles.X[k])}" for k in inside[:3])
            raise InputError(f"{self.particles_key}: cell {cell} holds only particles on its edges ({where}): "
                             f"{len(empty)} node(s) of the grid get no mass (DGMPM lumps S_ip V_p onto a cell's "
                             "nodes): move such particles inside their cells")

    def _buffer(self, name, shape, dtype=float):
        """A work array of the step that no result refers to once the step is done (the nodal
        state, forward Euler's stage, the CTU fluctuations), allocated once and reused: an array
        over glibc's 32 MB mmap threshold allocated every step is mapped afresh and its pages
        faulted in and zeroed each time, which two threads do slower than one (512^2: the Euler
        stage 25 ms on one thread, 69 ms on two)."""
        shape = (shape,) if isinstance(shape, int) else tuple(shape)
        a = self._work.get(name)
        if a is None or a.shape != shape or a.dtype != dtype:
            a = self._work[name] = np.empty(shape, dtype=dtype)
        return a

    def _records(self):
        """The cell records and their states (`cell_records`): work arrays of the step. With one
        particle per cell the step's constitutive update writes those of its new state (the law's
        tangent at hand, no pass of their own), and ``_records_of`` = (U, Q) of the state they
        describe once the step is accepted; `interface_flux` computes them for any other state."""
        return self._record_arrays

    def _every_cell_recorded(self, state):
        """Whether every cell of the records' ``state`` is recorded (always with one particle per
        cell): the face passes then read no trace (CTU: the cells split the fluctuations)."""
        return self.cellwise or bool(np.all(state != 0))

    initial_pass = "law"                # the step's own (`at_rest`): t = 0 compiles no kernel of its own

    def at_rest(self, state, points):
        """The step's law pass called as the step calls it (`step`), so that t = 0 compiles no
        kernel of its own. With one particle per cell it writes the state's cell records, which
        the first step's faces read, and where the step forms the particles' rows in that pass
        (`rows_in_law_pass`) they are those of a stage that adds nothing (`_rows_at_rest`). With
        several particles in a cell the pass forms each point's state from nodal values (the back
        map, a CSR product): here the identity's rows times the state's U, into a scratch U, U
        kept as given (a product sums from +0.0: a -0.0 of U reads as +0.0 in the law)."""
        if not self.cellwise:
            indptr, indices, data = parallel.csr(self.map.S)
            n = len(state.U)
            identity = (np.arange(n + 1, dtype=indptr.dtype), np.arange(n, dtype=indices.dtype),
                        np.ones(n, data.dtype))     # typed as the back map's CSR: the step's kernel
            return super().at_rest(state, points, (identity, state.U), into=np.empty_like(state.U))
        rec, rec_state = self._records()
        gather = self._rows_at_rest(state.U) if self.rows_in_law_pass else None   # rows U's: written onto U
        return super().at_rest(state, points, gather, (rec, self.point_cell, self.cell_normals, rec_state))

    def _rows_at_rest(self, U):
        """The particles' rows (`CellRows`) of a forward Euler stage that adds nothing to U, its
        arrays typed as the step's (the same kernel) and next to none held: each cell's faces all
        boundary face 0, whose term is zero (no interior face, no flux), and a step of -0.0, since
        x + -0.0 is x for every x (-0.0 + +0.0 would be +0.0): each row is U's, bit for bit."""
        nc, sides = U.shape[1], 0 if self.ctu is None else 2       # `interface_flux`'s corrections
        return CellRows(self.particles.cell, np.full(self.cell_faces.shape, -1, self.cell_faces.dtype), np.zeros(0),
                        np.zeros((0, nc)), np.zeros((0, sides, nc)), 0.0, -0.0, self.inv_volume, U, np.zeros((1, nc)))

    def initial_state(self, F, v, t=0.0):
        state = super().initial_state(F, v, t)
        if self.cellwise:       # the first step's faces read them (a record's state: Q's row, v as given)
            self._records_of = (state.U, state.Q)
        return state

    # ---------------------------------------------------------------- set-up
    def _setup_cell_faces(self):
        """What `cell_records` and the face pass read: each cell's nodes (n_cells, nodes), the local
        index of each interior face in its two cells, and each cell's face directions (n_cells,
        slots, d): a cell's local faces k and k + n/2 are opposite; where every cell's opposite faces
        are parallel (bit for bit: a structured grid) they share an impedance (A_n is quadratic in n),
        so the record keeps n/2 directions, otherwise one per face."""
        m, f = self.grid.submesh, self.interior
        n_cells = m.nelements
        if self.cellwise:       # a cell's one "node": its particle (`cell_records` reads its state)
            self.cell_dofs = self.point[:, None]
        else:
            self.cell_dofs = np.argsort(self.dof_cell, kind="stable").astype(np.int32).reshape(n_cells, -1)
        # where a recorded cell's state is (its first node's row; the records keep the rest)
        self.state_rows = np.ascontiguousarray(self.cell_dofs[:, 0])
        self.local_face = tuple(_local_face(m, cells, f.facets).astype(np.int8) for cells in (f.cell_L, f.cell_R))
        self.boundary_local_face = _local_face(m, self.boundary.cell_L, self.boundary.facets).astype(np.int8)
        normal = np.zeros((m.nfacets, self.d))
        normal[f.facets], normal[self.boundary.facets] = f.normal, self.boundary.normal
        normals = normal[m.t2f.T]                                   # (n_cells, faces, d)
        half = normals.shape[1] // 2
        opposite = normals[:, half:]
        parallel_pairs = np.all((opposite == normals[:, :half]) | (opposite == -normals[:, :half]))
        self.cell_normals = np.ascontiguousarray(normals[:, :half] if parallel_pairs else normals)

    def _setup_transverse(self):
        """CTU set-up: the boundary faces' `side_topology` and what the cells read to send their
        parts (`_cell_sources`); the faces' split, for a step where a cell is not recorded, is
        set up when first needed (`_split_topology`). DCU: empty."""
        empty = (np.zeros(0), np.zeros((2, 0, 2)), np.zeros((2, 0), np.int64), np.zeros((2, 0), np.int64),
                 np.zeros((2, 0)))
        self.ctu, self._split = None, None
        self.topology = {"boundary": empty}
        if self.transverse != "ctu" or self.d != 2:
            return
        self.topology["boundary"] = self.side_topology("boundary")
        self.cell_sources = self._cell_sources()
        frame = np.zeros((len(self.boundary), 2, 2))
        free_v = np.zeros((len(self.boundary), 2), bool)
        free_t = np.zeros((len(self.boundary), 2), bool)
        for sel, bc in self.bc_groups:
            frame[sel], imp_v, imp_t = bc.constraints(self.boundary.normal[sel])
            free_v[sel], free_t[sel] = ~imp_v, ~imp_t
        self.ctu = distinct_rows(self._boundary_filter(frame, free_v, free_t))

    def _split_topology(self):
        """What the faces' CTU split reads when a cell is not recorded (more than one particle in
        it): the interior faces' sides (h, normals (nf, 2, 2)) (face-major: a chunk of faces is a
        slice) and the edges' gathers of the parts (`_edge_gathers`): each face writes its own
        parts, each edge sums those it receives, the same for any thread count. Built on first
        need and kept (with one particle per cell it never is: 208 B per cell not held)."""
        if self._split is None:
            sides = {side: self.side_topology(side) for side in ("L", "R")}
            split = {side: (h, np.ascontiguousarray(n.transpose(1, 0, 2))) for side, (h, n, *_) in sides.items()}
            self._split = (split, *self._edge_gathers(sides))
        return self._split

    def _cell_faces(self):
        """Each cell's local faces k (n_cells, faces per cell) int32: 2 f + side for interior face
        f, -1 - b for boundary face b (`cell_update`, `cell_corrections`)."""
        m, f, b = self.grid.submesh, self.interior, self.boundary
        faces = np.empty((m.nelements, m.t2f.shape[0]), np.int32)
        faces[b.cell_L, _local_face(m, b.cell_L, b.facets)] = -1 - np.arange(len(b))
        for s, (cells, k) in enumerate(((f.cell_L, self.local_face[0]), (f.cell_R, self.local_face[1]))):
            faces[cells, k] = 2 * np.arange(len(f)) + s
        return faces

    def _cell_sources(self):
        """What `cell_corrections` reads per cell and local face k (n_cells, 4): the row of the
        face's fluctuation entering the cell, 2 f + side (int32; -1 - b for boundary face b:
        `_cell_faces`), its scale -1 / (2 h) (0 at boundary faces), and the sign that makes the
        cell's face direction ``cell_normals[c, k % slots]`` the outward normal of face k (int8,
        exact)."""
        m, f, b = self.grid.submesh, self.interior, self.boundary
        n_cells, slots = m.nelements, self.cell_normals.shape[1]
        scale = np.zeros((n_cells, 4))
        outward = np.empty((n_cells, 4, 2))
        outward[b.cell_L, _local_face(m, b.cell_L, b.facets)] = b.normal
        for s, (cells, k, sign) in enumerate(((f.cell_L, self.local_face[0], 1.0), (f.cell_R, self.local_face[1], -1.0))):
            scale[cells, k] = -1.0 / (2.0 * (self.cell_volume[cells] / f.measure))     # h as `side_topology`
            outward[cells, k] = sign * f.normal
        direction = self.cell_normals[:, np.arange(4) % slots]
        signs = np.where(np.all(outward == direction, axis=2), 1, -1).astype(np.int8)
        assert np.all(signs[..., None] * direction == outward), "a cell's opposite faces are not parallel"
        return self._cell_faces(), scale, signs

    # ---------------------------------------------------------------- stages
    @stage
    def project(self, state, out=None):
        """(a) M_i U_i = sum_p S_ip V_p U_p; Q likewise (v from the projected momentum); into
        ``out`` = (U, Q) nodal arrays if given. With ``cellwise``, the particles' own arrays."""
        if self.cellwise:
            grid_state = GridState(state.U, state.Q)
        else:
            grid_state = GridState(*self.map.project_state(state.U, state.Q, self.d, out))
        self._kept = (grid_state, None)           # its Delta t-free terms, once computed
        return grid_state

    @stage
    def volume_flux(self, grid_state, out=None):
        """(c) sum_alpha K^alpha F_alpha(Q) (added to ``out`` if given)."""
        return system.volume_flux(grid_state.Q, self.stiffness, out)

    @stage
    def interface_flux(self, grid_state, time):
        """(d)-(e) Godunov fluxes at the interior faces from the linearised Riemann solver, and at
        the boundary faces from the ghost states of their conditions at ``time`` (stationary
        states t*, v*), with (CTU) the transverse corrections of the fluctuations entering the
        cells. Returns the faces' terms (flux, corr, corr_bnd, boundary flux, t*, v*): the
        interior faces' fluxes (nf, nc) and their corrections per unit Delta t as the Euler pass
        reads them, (nf, sides, nc) (`dgmpm_kernels.face_corrections`: the parts both cells send,
        the gathered correction, or none for DCU), the boundary faces' corrections per unit Delta
        t (nb, nc), fluxes (nb, nc) and stationary states (nb, d). Both kinds of faces in one
        pass over the threads (`riemann.face_passes`), but where a cell may be unrecorded (the
        trace path, whose kernels two compile helpers share out: `skdgmpm.compile_helper`)."""
        f, nc = self.interior, grid_state.U.shape[1]
        ctu = self.ctu is not None
        # forward Euler: one projected state's faces a step (the CFL guard's attempts reuse them),
        # so the fluxes are a work array; RK2's second stage keeps the first's while it computes
        flux = self._buffer("interior fluxes", (len(f), nc)) if self.integrator == "euler" else np.empty((len(f), nc))
        corr_bnd = np.zeros((len(self.boundary), nc))
        T_L, T_R = (self.traces.get(side, _NO_TRACE) for side in ("L", "R"))
        rho, laws = self.density, self.laws
        dofs, normals = self.cell_dofs, self.cell_normals
        k_L, k_R = self.local_face
        rec, state = self._records()
        made, self._records_of = self._records_of, None     # the buffer is rewritten from here on
        if made is None or made[0] is not grid_state.U or made[1] is not grid_state.Q:
            cell_records(dofs, grid_state.U, grid_state.Q, rho, self.cell_material, *laws, normals, rec, state)
        recorded = self._every_cell_recorded(state)
        # CTU: with every cell recorded, the faces keep their fluctuations (nf, 2, nc) and each cell
        # sends the parts of those entering it (`cell_corrections`), in place; otherwise the faces
        # split them and keep the parts (nf, 4, nc), which each edge gathers
        G = self._buffer("fluctuations", (len(f) if ctu else 0, 2 if recorded else 4, nc))
        if ctu and not recorded:
            split, to_interior, to_boundary = self._split_topology()
            (h_L, n_L), (h_R, n_R) = split["L"], split["R"]
        else:                                   # not read
            h_L = h_R = np.zeros(0)
            n_L = n_R = np.zeros((0, 2, 2))

        interior = interior_pass(T_L, T_R, grid_state.U, grid_state.Q, rho, f.normal, f.cell_L, f.cell_R,
                                 self.cell_material, *laws,
                                 (rec, state, normals, k_L, k_R, recorded, self.trace_path, self.state_rows),
                                 ctu, (h_L, n_L), (h_R, n_R), flux, G)
        boundary, (flux_b, t_s, v_s, parts) = self.boundary_pass(grid_state, time)
        face_passes(interior, boundary, together=not self.trace_path)
        if ctu and recorded:
            sources, scale, signs = self.cell_sources
            W = G.reshape(-1, nc)
            cell_corrections(sources, scale, signs, rec, normals, W, corr_bnd)
            corr = G
        elif ctu:
            corr = np.empty((len(f), 1, nc))
            parts_int = G.reshape(-1, nc)           # each edge: sum_k sign_k G[part_k], in face order
            parallel.matmul(to_interior, parts_int, corr[:, 0])
            boundary_edge_corrections(to_boundary, parts_int, corr_bnd)
        else:
            corr = np.empty((len(f), 0, nc))
        if ctu:         # the corrections of the fluctuations entering the boundary cells, where they go
            boundary_corrections(self.topology["boundary"], parts, corr, corr_bnd)
        return flux, corr, corr_bnd, flux_b, t_s, v_s

    def boundary_pass(self, grid_state, time):
        """The boundary faces' pass (`dgmpm_kernels.boundary_faces`, a `parallel.Pass`: run, it
        returns the first face that is not hyperbolic, or -1) and the arrays it fills: fluxes (nb,
        nc), stationary states t*, v* (nb, d) under the conditions at ``time`` and (CTU) the parts
        of the fluctuations entering the boundary cells (nb, 2, nc), for `boundary_corrections`. A
        face whose cell is recorded reads its side in the cell records (those of this state)."""
        b, d, g, ctu = self.boundary, self.d, self.ghosts, self.ctu is not None
        nb, nc = len(b), grid_state.U.shape[1]
        flux, t_s, v_s = np.empty((nb, nc)), np.empty((nb, d)), np.empty((nb, d))
        parts = self._buffer("boundary parts", (nb if ctu else 0, 2, nc))
        rec, state = self._records()
        run = boundary_faces(self.traces["boundary"], grid_state.U, grid_state.Q, self.density, b.normal, b.cell_L,
                             self.cell_material, *self.laws, (g.frame, g.velocity, g.values_at(time), g.copy), ctu,
                             self.topology["boundary"],
                             (rec, state, self.cell_normals, self.boundary_local_face, self.trace_path,
                              self.state_rows), flux, t_s, v_s, parts)
        return run, (flux, t_s, v_s, parts)

    @stage
    def transverse_flux(self, terms, dt, weight, out):
        """CTU [R18 eq 34-37] at boundary faces: keep the components of the corrections that the
        condition leaves free, so it still holds exactly. (Each fluctuation entering a cell is split
        on the characteristic basis of the cell's two edges adjacent to the source face; the part
        moving out through an edge becomes the extra flux G = -dt / (2 h) B+ A dU there, h the cell
        size across the source face; at a boundary edge the ghost cell is a copy of the cell and
        sends back the cell's own correction through the opposite edge. The face passes compute
        them with the fluxes.) The filter is linear: its matrix per face is built once
        (``_boundary_filter``). The boundary faces' fluxes so corrected are integrated in the same
        pass (`dgmpm_kernels.boundary_terms`). Returns the power through the boundary (W)."""
        return self._boundary_terms(terms, dt, weight, out)

    def _boundary_terms(self, terms, dt, weight, out):
        """out += weight (-int Phi F over the boundary faces), F their fluxes with (CTU) the
        filtered corrections for ``dt``, or with ``weight`` None each face's term -m_b F into row b
        of ``out`` (nb, nc); returns the power through them (W)."""
        b = self.boundary
        _, _, corr_bnd, flux, t_s, v_s = terms
        return boundary_terms(self.traces["boundary"], b.measure, b.normal, flux, t_s, v_s, self.ctu, corr_bnd, dt,
                              weight, out)

    def side_topology(self, side):
        """CTU topology of one face side ("L", "R" of the interior faces, "boundary"): the
        source cell's size across the face h and its two edges adjacent to the face (axis 0 of
        the (2, nf) arrays), with their outward normals and their index among interior faces
        (with the sign of the interior normal) or boundary faces (-1 where not one)."""
        m = self.grid.submesh
        pos_int = -np.ones(m.nfacets, dtype=np.int64)
        pos_int[self.interior.facets] = np.arange(len(self.interior))
        pos_bnd = -np.ones(m.nfacets, dtype=np.int64)
        pos_bnd[self.boundary.facets] = np.arange(len(self.boundary))
        faces = self.boundary if side == "boundary" else self.interior
        cells = {"L": self.interior.cell_L, "R": self.interior.cell_R, "boundary": self.boundary.cell_L}[side]
        k = _local_face(m, cells, faces.facets)
        j = m.t2f[(k[None, :] + np.array([1, 3])[:, None]) % 4, cells[None, :]]     # (2, nf)
        j_int, j_bnd = pos_int[j], pos_bnd[j]
        sign = np.where(self.interior.cell_L[j_int] == cells, 1.0, -1.0)
        n = np.where((j_int >= 0)[..., None], sign[..., None] * self.interior.normal[j_int],
                     self.boundary.normal[j_bnd])
        h = self.cell_volume[cells] / faces.measure
        return tuple(np.ascontiguousarray(a) for a in (h, n, j_int, j_bnd, sign))

    def _edge_gathers(self, sides):
        """CSR rows, one per interior edge, of the parts (rows of `interior_pass`'s G flattened,
        4 f + 2 side + e) that it receives and their signs (`parallel.matmul`); and per
        boundary edge, the parts and the opposite edge's parts (`boundary_edge_corrections`).
        Within a row the parts are in the order a loop over the faces meets them. The interior
        edges' rows are int32 indices and int8 signs (+-1, exact: the products are the same bits
        as with float64 signs; 72 -> 42 B per cell kept)."""
        nf = len(self.interior)
        part = 4 * np.arange(nf)[None, :] + np.arange(2)[:, None]            # (2 edges, nf)
        rows = {"interior": ([], [], []), "boundary": ([], [], [])}
        for s, side in enumerate(("L", "R")):
            _, _, j_int, j_bnd, sign = sides[side]
            for e in range(2):
                k = j_int[e] >= 0
                rows["interior"][0].append(j_int[e][k])
                rows["interior"][1].append(part[e][k] + 2 * s)
                rows["interior"][2].append(sign[e][k])
                k = j_bnd[e] >= 0
                rows["boundary"][0].append(j_bnd[e][k])
                rows["boundary"][1].append(part[e][k] + 2 * s)
                rows["boundary"][2].append(part[1 - e][k] + 2 * s)
        out = []
        for name, n in (("interior", nf), ("boundary", len(self.boundary))):
            j, parts, third = (np.concatenate(a) for a in rows[name])
            order = np.lexsort((parts, j))
            indptr = np.concatenate([[0], np.cumsum(np.bincount(j, minlength=n))]).astype(np.int64)
            if name == "interior" and 4 * nf < 2 ** 31:      # the signs exact in int8, the indices in int32
                out.append((indptr.astype(np.int32), parts[order].astype(np.int32), third[order].astype(np.int8)))
            else:
                out.append((indptr, parts[order].astype(np.int64), third[order]))
        return out

    def _boundary_filter(self, frame, free_v, free_t):
        """The matrix (nb, nc, nc) of `transverse_flux` (linear in the corrections): the components
        left free by each boundary face's condition, in its frame (nb, 2, 2). (The step keeps its
        distinct matrices and each face's, `distinct_rows`: a few conditions and directions.)"""
        nb, nc = len(self.boundary), system.n_components(self.d)
        filt = np.empty((nb, nc, nc))
        for c in range(nc):             # the filter of each unit correction: a column
            F, p = system.split(np.broadcast_to(np.eye(nc)[c], (nb, nc)), self.d)
            dv = np.einsum("fkj,fja,fa->fk", frame, F, self.boundary.normal) * free_v
            dt_ = np.einsum("fkj,fj->fk", frame, p) * free_t
            filt[:, :, c] = system.join(
                np.einsum("fkj,fk->fj", frame, dv)[:, :, None] * self.boundary.normal[:, None, :],
                np.einsum("fkj,fk->fj", frame, dt_))
        return filt

    def fixed_terms(self, grid_state, time):
        """The faces' terms of a grid state at ``time`` (`interface_flux`'s: flux, corrections,
        boundary corrections, boundary flux, t*, v*). They depend on Delta t only through the
        factor of the CTU corrections and, through the conditions' values at ``time`` (the
        step's middle), through the schedules of time-dependent conditions: the CFL guard's
        repeated attempts on the projected state reuse them while those values stay as they were
        (`BoundaryGhosts.values_at` returns the same array), and compute them anew where a ramp
        or a release makes them differ at the shorter step's middle. (The volume term is
        computed inside the Euler stage's pass over the nodes.)"""
        values = self.ghosts.values_at(time)
        kept = self._kept
        if kept is not None and kept[0] is grid_state and kept[1] is not None and kept[1][0] is values:
            return kept[1][1]
        terms = self.interface_flux(grid_state, time)
        if kept is not None and kept[0] is grid_state:
            self._kept = (grid_state, (values, terms))
        return terms

    def add_boundary_terms(self, terms, time, dt, weight, out):
        """out += weight (-int Phi F_N* over the boundary faces + int Phi S): the Delta
        t-dependent part of M dU/dt (the boundary faces' fluxes with their CTU corrections for
        ``dt``), weighted per node by weight = (step, inv_M): step inv_M[i]; ``terms``:
        `fixed_terms`. Returns the power through the boundary (W). ``weight`` None: the boundary
        faces' terms -m_b F_b (nb, nc) written into ``out`` instead (`dgmpm_kernels.CellRows`), no
        source."""
        if self.ctu is None:
            power = self._boundary_terms(terms, dt, weight, out)
        else:
            power = self.transverse_flux(terms, dt, weight, out)
        if weight is not None:
            self.add_source(time, weight, out)
        return power

    def add_source(self, time, weight, out):
        """out += weight int Phi rho0 b (the particles as quadrature), if the scene has a body force."""
        if self.body_force is not None:
            p = self.particles
            source = self.source(p, time)
            source = p.volume[:, None] * source if self.cellwise else parallel.matmul(self.map.S_T, source,
                                                                                      scale=p.volume)
            out += (weight[0] * weight[1])[:, None] * source

    def euler_stage(self, grid_state, base, time, dt, step, out=None, rows=False):
        """base + step M^-1 R, M dU/dt = R = K^alpha F_alpha - int Phi F_N* + int Phi S at
        ``grid_state`` (boundary values at ``time``, CTU corrections for ``dt``): the volume term
        and the interior faces in one pass over the nodes (`euler_update`), then the boundary
        faces and the source; also returns the boundary power (W). With ``cellwise``, the
        particles' rows (`dgmpm_kernels.CellRows`): the boundary faces' terms first, then each
        particle's row; with ``rows`` (no source), the rows are returned unformed, for the law's
        pass to form each where it reads it (`step`)."""
        terms = self.fixed_terms(grid_state, time)
        flux, corr = terms[:2]
        if self.cellwise:                       # base, out: the particles'
            boundary = self._buffer("boundary terms", (len(self.boundary), flux.shape[1]))
            power = self.add_boundary_terms(terms, time, dt, None, boundary)
            cells = CellRows(self.particles.cell, self.cell_faces, self.interior.measure, flux, corr, dt, step,
                             self.inv_volume, base, boundary)
            if rows:
                return cells, power
            out = np.empty_like(base) if out is None else out
            cell_update(cells, out)
            self.add_source(time, (step, self.inv_volume), out)
            return out, power
        out = np.empty(base.shape) if out is None else out   # base: an array or RK2's `Combination`
        weight = (step, self.inv_M)              # step M^-1, node by node
        euler_update(self.gather_interior, flux, corr, dt, grid_state.Q, self.stiffness, base, weight, out)
        return out, self.add_boundary_terms(terms, time, dt, weight, out)

    @stage
    def advance(self, grid_state, time, dt):
        """(f) forward Euler [R18 eq 20] or Heun's RK2 (`skdgmpm.integrators`), every stage on
        the grid: the first from the projected state, the second's law at the grid nodes."""
        # forward Euler's one stage into a work array of the step (read by the back map, then dead);
        # with ``cellwise``, its rows unformed (`rows_in_law_pass`), or the particles' new U
        out = (self._buffer("nodal stage", grid_state.U.shape) if self.integrator == "euler" and not self.cellwise
               else None)
        rows = self.rows_in_law_pass

        def euler_stage(U, base, t, step):
            at = grid_state if U is grid_state.U else self.nodal_state(U)
            return self.euler_stage(at, base, t, dt, step, out, rows)

        return INTEGRATORS[self.integrator](euler_stage, grid_state.U, time, dt)

    @stage
    def nodal_state(self, U):
        """Q at the nodes from U at the nodes (the law evaluated at nodes, RK2 second stage): the
        law's pass of the particles (`MaterialSet.state`), the history in its virgin state."""
        return GridState(U, self.materials.state(U, self.cell_material[self.dof_cell], self.density))

    @property
    def rows_in_law_pass(self):
        """Whether the step's new particle states are formed in the law's pass that reads them
        (`dgmpm_kernels.CellRows`; one pass over the particles, not two): one particle per cell,
        forward Euler, no body force."""
        return self.cellwise and self.integrator == "euler" and self.body_force is None

    # ---------------------------------------------------------------- driver-facing
    @property
    def density(self):
        """rho0 at the nodes (`ParticleMap`), or the particles' with ``cellwise``."""
        return self.particles.rho0 if self.cellwise else self.map.rho

    def step(self, state, dt_max=np.inf):
        shape = (self.n_dofs, state.U.shape[1])     # the step's nodal arrays: work arrays, reused
        grid_state = self.project(state, None if self.cellwise else (self._buffer("nodal U", shape),
                                                                     self._buffer("nodal Q", shape)))

        def attempt(dt):
            U_nodes, work = self.advance(grid_state, state.t, dt)
            if self.cellwise:                   # the particles' U (or its rows); the new state's records beside it
                rec, rec_state = self._records()
                records = (rec, self.point_cell, self.cell_normals, rec_state)
                if isinstance(U_nodes, CellRows):
                    return self.constitutive_update(state, np.empty(state.U.shape), dt, gather=U_nodes,
                                                    records=records), work
                return self.constitutive_update(state, U_nodes, dt, records=records), work
            # (g) U_p = sum_i S_ip U_i [R18 eq 40] (PIC), each particle's row computed in the
            # law's pass (h): one pass over the particles, not two
            U_p = np.empty(state.U.shape)
            return self.constitutive_update(state, U_p, dt, gather=(self.map.S, U_nodes)), work

        try:
            new = self.step_with_cfl_guard(state, dt_max, attempt)
            if self.cellwise:                   # the last attempt's records: the accepted state's
                self._records_of = (new.U, new.Q)
            return new
        finally:
            self._kept = None       # the projected state and its terms: not held between steps


_NO_TRACE = (np.zeros(1, np.int32), np.zeros(0, np.int32), np.zeros(0))    # an empty CSR triple: not read


def distinct_rows(a):
    """(the distinct rows of ``a`` (k, ...) in bits, the row of each (n,) int64): a[i] ==
    distinct[which[i]] bit for bit (-0.0 and 0.0 kept apart, as a product can tell them)."""
    bits, which = np.unique(a.reshape(len(a), -1).view(np.int64), axis=0, return_inverse=True)
    return np.ascontiguousarray(bits.view(a.dtype).reshape(-1, *a.shape[1:])), which.reshape(-1).astype(np.int64)


def _local_face(mesh, cells, facets):
    """The local index (0 .. faces per cell - 1) of each facet in its cell (both (nf,))."""
    return np.argmax(mesh.t2f[:, cells] == facets[None, :], axis=0)
