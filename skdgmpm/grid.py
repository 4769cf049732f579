"""Background grids in the reference configuration: generation, mesh files, named boundaries.

A `Grid` is the full scikit-fem mesh plus the *active* sub-mesh made of the cells that hold
particles. Only the active sub-mesh carries degrees of freedom: inactive cells cost nothing, and
the boundary of the active sub-mesh is the body's boundary [R18 Fig. 1].
"""
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
from skfem import ElementDG, ElementLineP1, ElementQuad1, ElementQuadDG, MeshLine, MeshQuad

from .errors import InputError

#: name given to boundary facets of the body that lie on no named grid boundary
SURFACE = "surface"


def line(length, cells, origin=0.0):
    """Uniform 1D grid on [origin, origin + length] with boundaries ``left`` and ``right``."""
    x = np.linspace(origin, origin + length, int(cells) + 1)
    return MeshLine(x).with_boundaries({
        "left": lambda p: np.isclose(p[0], x[0]),
        "right": lambda p: np.isclose(p[0], x[-1]),
    })


def rectangle(lx, ly, nx, ny, origin=(0.0, 0.0)):
    """Uniform quad grid, counter-clockwise cells numbered x fastest.

    Boundaries ``left``, ``right``, ``bottom``, ``top``. (``MeshQuad.init_tensor`` numbers
    cells y fastest with clockwise orientation; we want the reference axes of a cell to follow
    the global axes so that particle layouts read naturally.)
    """
    x = np.linspace(origin[0], origin[0] + lx, int(nx) + 1)
    y = np.linspace(origin[1], origin[1] + ly, int(ny) + 1)
    X, Y = np.meshgrid(x, y)                     # (ny+1, nx+1), x fastest
    p = np.vstack([X.ravel(), Y.ravel()])
    n = np.arange((nx + 1) * (ny + 1)).reshape(ny + 1, nx + 1)
    t = np.vstack([n[:-1, :-1].ravel(), n[:-1, 1:].ravel(), n[1:, 1:].ravel(), n[1:, :-1].ravel()])
    return MeshQuad(p, t).with_boundaries({
        "left": lambda q: np.isclose(q[0], x[0]),
        "right": lambda q: np.isclose(q[0], x[-1]),
        "bottom": lambda q: np.isclose(q[1], y[0]),
        "top": lambda q: np.isclose(q[1], y[-1]),
    })


def load_mesh(path):
    """Read a quad mesh through meshio; gmsh physical groups become named boundaries/subdomains."""
    import meshio
    from skfem.io.meshio import from_meshio

    import contextlib
    import io

    path = Path(path)
    if not path.is_file():
        raise InputError(f"{path}: mesh file not found")
    said = io.StringIO()                  # meshio prints its own warnings and errors: ours says it all
    try:
        with contextlib.redirect_stderr(said), contextlib.redirect_stdout(said):
            raw = meshio.read(path)
            points = np.asarray(raw.points, dtype=float)
            bad = np.flatnonzero(~np.all(np.isfinite(points), axis=1))
            if len(bad):
                raise InputError(f"{path}: node {bad[0]} has non-finite coordinates {points[bad[0]].tolist()} "
                                 f"({len(bad)} such node(s))")
            mesh = from_meshio(raw)
    except InputError:
        raise
    except (Exception, SystemExit) as exc:  # meshio raises many types, or exits; the user needs the file name
        detail = str(exc).strip() or said.getvalue().strip().splitlines()[-1:] or [type(exc).__name__]
        detail = detail if isinstance(detail, str) else detail[0]
        raise InputError(f"{path}: cannot read mesh ({type(exc).__name__}: {detail})") from None
    if not isinstance(mesh, (MeshQuad, MeshLine)):
        raise InputError(f"{path}: grid must be made of quads (or lines in 1D), got {type(mesh).__name__}")
    if isinstance(mesh, MeshQuad):
        mesh = _counter_clockwise(mesh)
        _check_quads(path, mesh)
    _check_connected(path, mesh)
    return mesh


def _check_connected(path, mesh):
    """Warn (a crack or two bodies may be meant, so not an error) when nodes are duplicated (two
    nodes at one position: the cells on either side share no facet and are decoupled, a crack
    along that line) or when the mesh falls into pieces that no facet connects."""
    import warnings

    p = mesh.p
    size = float(np.max(np.ptp(p, axis=1))) or 1.0
    keys = np.round(p.T / (1e-9 * size)).astype(np.int64)
    _, first, counts = np.unique(keys, axis=0, return_index=True, return_counts=True)
    if (counts > 1).any():
        k = int(first[np.flatnonzero(counts > 1)[0]])
        warnings.warn(f"{path}: {int(np.sum(counts[counts > 1] - 1))} node(s) duplicate another node's position "
                      f"(first at ({', '.join(f'{x:.6g}' for x in p[:, k])})): the cells on either side share no "
                      "facet and are decoupled, a crack; merge the nodes in the mesher unless it is meant",
                      stacklevel=4)
    f2t = mesh.f2t
    inner = f2t[1] >= 0
    parent = np.arange(mesh.nelements)

    def find(i):
        while parent[i] != i:
            parent[i] = parent[parent[i]]
            i = parent[i]
        return i

    for a, b in zip(f2t[0, inner], f2t[1, inner]):
        ra, rb = find(a), find(b)
        if ra != rb:
            parent[ra] = rb
    roots = np.array([find(i) for i in range(mesh.nelements)])
    _, sizes = np.unique(roots, return_counts=True)
    if len(sizes) > 1:
        warnings.warn(f"{path}: the mesh is in {len(sizes)} pieces that share no facet "
                      f"({', '.join(str(s) for s in sorted(sizes, reverse=True)[:5])} cells): they only interact "
                      "through the boundary conditions", stacklevel=4)


def _check_quads(path, mesh):
    """Every quad convex with a positive Jacobian at its four corners (after `_counter_clockwise`):
    a degenerate (zero area, repeated node), bow-tie (self-intersecting) or non-convex quad has a
    Jacobian <= 0 somewhere, where the bilinear map folds; such a mesh is refused, naming the cell."""
    p, t = mesh.p, mesh.t
    for c in range(4):
        corner, after, before = p[:, t[c]], p[:, t[(c + 1) % 4]], p[:, t[(c + 3) % 4]]
        a, b = after - corner, before - corner
        cross = a[0] * b[1] - a[1] * b[0]
        scale = np.linalg.norm(a, axis=0) * np.linalg.norm(b, axis=0)
        bad = np.flatnonzero(~(cross > 1e-10 * scale))
        if len(bad):
            k = int(bad[0])
            kind = "degenerate (zero area or a repeated node)" if abs(cross[k]) <= 1e-10 * scale[k] else \
                "self-intersecting (bow-tie) or not convex"
            raise InputError(f"{path}: cell {k} (nodes {t[:, k].tolist()}) is {kind}: at node {int(t[c, k])} "
                             f"({', '.join(f'{x:.6g}' for x in p[:, t[c, k]])}) its Jacobian is {cross[k]:.3g} "
                             f"({len(bad)} such cell(s)); fix the mesh")


def _counter_clockwise(mesh):
    """Reorder clockwise quads so that detJ > 0 everywhere (keeps boundary names)."""
    p, t = mesh.p, mesh.t
    a = p[:, t[1]] - p[:, t[0]]
    b = p[:, t[3]] - p[:, t[0]]
    cw = a[0] * b[1] - a[1] * b[0] < 0
    if not cw.any():
        return mesh
    t = t.copy()
    t[1, cw], t[3, cw] = mesh.t[3, cw], mesh.t[1, cw]
    return _with_facet_names(type(mesh)(p, t), mesh, mesh.boundaries or {}, np.arange(p.shape[1]))


def _facet_keys(mesh, facets, node_map, n_nodes):
    """One int64 key per facet: its original node indices (``node_map``, < ``n_nodes``), sorted,
    as one number in base ``n_nodes`` (a line's or a quad's facets: 1 or 2 nodes)."""
    nodes = np.sort(node_map[mesh.facets[:, facets]], axis=0)
    return np.ravel_multi_index(tuple(nodes), (n_nodes,) * len(nodes))


def _with_facet_names(new, old, boundaries, new_to_old):
    """Carry named facet sets of ``old`` over to ``new`` by matching facet vertices: each named
    facet's key looked up among the sorted keys of ``new``'s facets (no Python object per facet:
    a dict of tuples took 13 % of a 512^2 grid's set-up)."""
    n_nodes = old.p.shape[1]
    keys = _facet_keys(new, np.arange(new.nfacets), new_to_old, n_nodes)
    order = np.argsort(keys, kind="stable")
    ranked = keys[order]
    named = {}
    for name, facets in boundaries.items():
        wanted = _facet_keys(old, np.asarray(facets, dtype=np.int64), np.arange(n_nodes), n_nodes)
        at = np.minimum(np.searchsorted(ranked, wanted), len(ranked) - 1)
        found = ranked[at] == wanted if len(ranked) else np.zeros(len(wanted), bool)
        named[name] = np.sort(order[at[found]]).astype(np.int64)
    return new.with_boundaries(named) if named else new


def facets_in_box(mesh, box, facets=None):
    """Boundary facets whose midpoint lies in ``box`` = {"x": [lo, hi], "y": [lo, hi]}."""
    facets = mesh.boundary_facets() if facets is None else facets
    mid = mesh.p[:, mesh.facets[:, facets]].mean(axis=1)
    span = np.ptp(mesh.p, axis=1).max()
    keep = np.ones(len(facets), dtype=bool)
    for axis, key in enumerate("xyz"[: mesh.dim()]):
        if key in box:
            lo, hi = box[key]
            keep &= (mid[axis] >= lo - 1e-9 * span) & (mid[axis] <= hi + 1e-9 * span)
    return facets[keep]


@dataclass
class Grid:
    """Full grid, its active sub-mesh and the DG element.

    Attributes
    ----------
    mesh : skfem.Mesh
        Full background grid (reference configuration).
    active : (n_active,) int
        Indices of active cells in ``mesh``.
    submesh : skfem.Mesh
        Mesh of the active cells; boundary facets carry the grid's names, or ``SURFACE``.
    """

    mesh: object
    active: np.ndarray
    submesh: object = field(init=False)
    element: object = field(init=False)

    def __post_init__(self):
        self.active = np.asarray(self.active, dtype=np.int64)
        sub, node_map = self.mesh.restrict(self.active, return_mapping=True, skip_boundaries=True)
        names = dict(self.mesh.boundaries or {})
        sub = _with_facet_names(sub, self.mesh, names, node_map)
        named = np.concatenate([np.zeros(0, np.int64), *sub.boundaries.values()]) if names else []
        surface = np.setdiff1d(sub.boundary_facets(), named)
        self.submesh = sub.with_boundaries({**(sub.boundaries or {}), SURFACE: surface})
        m, sub = self.mesh, self.submesh
        if m.t.shape == sub.t.shape and np.array_equal(m.t, sub.t) and np.array_equal(m.p, sub.p):
            sub.doflocs, sub.t = m.doflocs, m.t         # every cell active: one copy (16 + 16 B per cell)
        for cache in ("_facets", "_t2f", "_f2t"):     # the full mesh's facets, computed again if asked
            self.mesh.__dict__.pop(cache, None)        # for (48 B per cell: the sub-mesh has its own)
        self.element = (ElementDG(ElementLineP1()) if self.dim == 1
                        else ElementQuadDG(ElementQuad1()))

    @property
    def dim(self):
        return self.mesh.dim()

    def release_caches(self):
        """Drop what scikit-fem memoises on the meshes once the operators are assembled: the
        Jacobians of its isoparametric mapping for every basis built (about 0.8 kB per cell on a
        DGMPM grid) and the sub-mesh's facets, cell-to-facet and facet-to-cell maps and nodal
        dofs (84 B per cell; no step reads them). Whatever asks for them later computes them again."""
        for m in (self.mesh, self.submesh):
            mapping = getattr(m, "_cached_mapping", None)
            if isinstance(getattr(mapping, "_cache", None), dict):
                mapping._cache.clear()
            for cache in ("_facets", "_t2f", "_f2t", "_dofs"):
                m.__dict__.pop(cache, None)

    @property
    def boundary_names(self):
        return tuple(self.submesh.boundaries)

    def cell_sizes(self):
        """(n_active,) smallest height of each active cell (area / longest edge in 2D)."""
        m = self.submesh
        if self.dim == 1:
            return np.abs(np.diff(m.p[0, m.t], axis=0))[0]
        edges = np.linalg.norm(m.p[:, m.facets[0, m.t2f]] - m.p[:, m.facets[1, m.t2f]], axis=0)
        return self.cell_volumes() / edges.max(axis=0)

    def cell_volumes(self):
        """(n_active,) cell length (1D) or area (2D)."""
        m = self.submesh
        if self.dim == 1:
            return np.abs(np.diff(m.p[0, m.t], axis=0))[0]
        x, y = m.p[0, m.t], m.p[1, m.t]
        return 0.5 * np.abs(np.sum(x * np.roll(y, -1, axis=0) - np.roll(x, -1, axis=0) * y, axis=0))
