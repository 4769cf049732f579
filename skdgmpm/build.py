"""From a `Scene` to a ready stepper: grid, particles, materials, boundary conditions."""
from dataclasses import dataclass

import warnings

import numpy as np

from .bcs import _numbers, make_bc
from .ader_dgmpm import BACKMAPS
from .limiter import KINDS as LIMITERS
from .constitutive import MaterialSet
from .ader import ADERDGFEM
from .ader_dgmpm import ADERDGMPM
from .dgfem import DGFEM, INTEGRATORS
from .dgmpm import DGMPM
from .gimp import SHAPES
from .mpm import MPM, UPDATES
from .exact import INITIAL
from .scene import exact_solution
from .scene_keys import ignored_keys
from .scheme import cell_values
from . import guards
from .errors import InputError, InstabilityError
from .grid import Grid, facets_in_box, line, load_mesh, rectangle
from .heap import release_free_pages, retain_freed_memory
from .particles import Particles, fill_cells, locate, tensor_layout
from skdgmpm.materials import make_material


@dataclass
class Discretisation:
    scene: object
    grid: Grid
    particles: Particles
    layout: np.ndarray           # parent coordinates of the per-cell layout (None for a file)
    stepper: object
    initial: object
    cfl_default: str = None      # why the CFL is what it is, where the scene gives none and 1 is above the limit


def build_mesh(scene):
    g = scene.data["grid"]
    d = scene.dim
    if "mesh" in g:
        path = scene.resolve(g["mesh"])
        if not path.is_file():
            raise InputError(f"{scene.where('grid.mesh')} = {g['mesh']!r}: mesh file {path} not found")
        ignored = [k for k in ("length", "cells", "size", "origin") if k in g]
        if ignored:
            warnings.warn(f"{', '.join(scene.where(f'grid.{k}') for k in ignored)}: no effect, the mesh file "
                          f"grid.mesh = {g['mesh']!r} sets the grid", stacklevel=3)
        mesh = load_mesh(path)
        if mesh.dim() != d:
            raise InputError(f"{scene.where('grid.mesh')} = {g['mesh']!r} is {mesh.dim()}D but dim = {d}")
    elif d == 1:
        length, cells = _positive(scene, "grid.length"), _count(scene, "grid.cells", 1)[0]
        mesh = line(length, cells, _origin(scene, 1)[0])
    else:
        size = g.get("size")
        if not (isinstance(size, list) and len(size) == 2 and all(_number(s) and s > 0 for s in size)):
            raise InputError(f"{scene.where('grid.size')} = {size!r} must be two lengths > 0 (m)")
        nx, ny = _count(scene, "grid.cells", 2)
        mesh = rectangle(size[0], size[1], nx, ny, _origin(scene, 2))
    extra = {}
    for name, spec in (scene.get("boundaries") or {}).items():
        if not isinstance(spec, dict) or not isinstance(spec.get("box"), dict):
            raise InputError(f"{scene.where(f'boundaries.{name}')} needs box = {{x = [lo, hi], ...}}")
        _check_box(scene, f"boundaries.{name}.box", spec["box"], mesh.dim())
        extra[name] = facets_in_box(mesh, spec["box"])
        if len(extra[name]) == 0:
            raise InputError(f"{scene.where(f'boundaries.{name}.box')} = {spec['box']!r} holds no boundary facet")
    if extra:
        mesh = mesh.with_boundaries({**(mesh.boundaries or {}), **extra})
    return mesh


def active_cells(scene, mesh):
    body = scene.get("body") or {}
    if "subdomain" in body:
        subs = mesh.subdomains or {}
        if body["subdomain"] not in subs:
            raise InputError(f"{scene.where('body.subdomain')} = {body['subdomain']!r} is not in the mesh "
                             f"(known: {', '.join(subs) or 'none'})")
        return np.asarray(subs[body["subdomain"]])
    cells = np.arange(mesh.nelements)
    if "box" in body:
        _check_box(scene, "body.box", body["box"], mesh.dim())
        centre = mesh.p[:, mesh.t].mean(axis=1)
        keep = np.ones(mesh.nelements, dtype=bool)
        for axis, key in enumerate("xy"[: mesh.dim()]):
            if key in body["box"]:
                lo, hi = body["box"][key]
                keep &= (centre[axis] >= lo) & (centre[axis] <= hi)
        cells = cells[keep]
        if len(cells) == 0:
            raise InputError(f"{scene.where('body.box')} = {body['box']!r} holds no cell")
    if "ring" in body:                      # stair-stepped annulus [WG08 §5.2]: cells centred in it
        ring = body["ring"]
        ok = (mesh.dim() == 2 and set(ring) == {"centre", "radii"}
              and all(isinstance(ring[k], list) and len(ring[k]) == 2 and all(_number(x) for x in ring[k])
                      for k in ring) and 0 <= ring["radii"][0] < ring["radii"][1])
        if not ok:
            raise InputError(f"{scene.where('body.ring')} = {ring!r} must be {{centre = [x, y], "
                             f"radii = [R_I, R_O]}} (m, 0 <= R_I < R_O) in 2D")
        centre = mesh.p[:, mesh.t].mean(axis=1)[:, cells]
        r = np.hypot(centre[0] - ring["centre"][0], centre[1] - ring["centre"][1])
        cells = cells[(r >= ring["radii"][0]) & (r <= ring["radii"][1])]
        if len(cells) == 0:
            raise InputError(f"{scene.where('body.ring')} = {ring!r} holds no cell")
    return cells


def _material(scene, table, where):
    spec = dict(table)
    law = spec.pop("law", "linear_elastic")
    try:
        return make_material(law, **spec)
    except InputError as exc:            # the message starts with "material: "
        message = str(exc).removeprefix("material: ")
        raise InputError(f"{scene.where(where)}: {message}") from None


def build(scene):
    """Validate and discretise a scene: raises InputError before anything is computed."""
    retain_freed_memory()           # a solver process from here on: step temporaries reuse warm pages
    d = scene.dim
    mesh = build_mesh(scene)
    materials = [_material(scene, scene.data["material"], "material")]
    regions = scene.get("regions") or []
    if not isinstance(regions, list):
        raise InputError(f"{scene.where('regions')} = {regions!r} must be a list of tables ([[regions]])")
    region_cells = [_region_cells(scene, mesh, k, region) for k, region in enumerate(regions)]
    for k, region in enumerate(regions):
        materials.append(_material(scene, region["material"], f"regions[{k}].material"))

    pspec = scene.get("particles") or {}
    if "file" in pspec:
        X = _read_points(scene, pspec["file"], d)
        cell_full, _ = locate(mesh, X, source=str(scene.resolve(pspec["file"])))
        grid = Grid(mesh, np.unique(cell_full))
        cell, xi = locate(grid.submesh, X, source=str(scene.resolve(pspec["file"])))
        volume = grid.cell_volumes()[cell] / np.bincount(cell)[cell]
        layout = None
    else:
        grid = Grid(mesh, active_cells(scene, mesh))
        layout = _layout(scene, pspec.get("per_cell", 1), d)
        X, xi, cell, volume = fill_cells(grid.submesh, np.arange(grid.submesh.nelements), layout,
                                         grid.cell_volumes())
    n = len(X)
    # material of a particle: the last region holding its cell, else the default
    which = np.zeros(n, dtype=np.int64)
    for k, in_region in enumerate(region_cells):
        which[in_region[grid.active[cell]]] = k + 1
    rho0 = np.array([m.rho for m in materials])[which]
    particles = Particles(X, xi, cell, volume, rho0, which)

    bcs = [(name, _bc(scene, grid, name, spec, d)) for name, spec in (scene.get("bc") or {}).items()]
    method = scene.data["method"]
    cfl = float(method.get("cfl", 1.0))    # without it, set below once the method's limit is known
    if not 0 < cfl <= 2:
        raise InputError(f"{scene.where('method.cfl')} = {cfl!r} must be in (0, 2]")
    name = method.get("name", "dgmpm")
    integrators = {"dgmpm": ("euler", "rk2"), "rk-dgfem": INTEGRATORS}.get(name)
    mpm_options = ((("update", tuple(UPDATES)), ("shape", SHAPES), ("time_step", ("current", "bar")))
                   if name == "mpm" else ())
    # a limiter is checked for every method (DGMPM and MPM have none: a wrong name is still wrong)
    dg_options = (("limiter", LIMITERS),) + ((("backmap", BACKMAPS),) if name == "ader-dgmpm" else ())
    layouts = ("auto", "nodes") if name == "dgmpm" else None
    for key, choices in (("integrator", integrators), ("transverse", ("dcu", "ctu")), ("layout", layouts),
                         *mpm_options, *dg_options):
        # ADER methods are their own time integrator: a scene's integrator key is ignored
        if choices is not None and key in method and method[key] not in choices:
            raise InputError(f"{scene.where(f'method.{key}')} = {method[key]!r}: expected one of "
                             f"{', '.join(choices)}")
    for _, message in ignored_keys(scene):       # e.g. method.integrator in an ADER run: one line each
        warnings.warn(message, stacklevel=2)
    mats = MaterialSet(tuple(materials))
    if name == "dgmpm":
        if method.get("order", 1) != 1:
            raise InputError(f"{scene.where('method.order')} = {method['order']!r}: dgmpm is first order")
        integrator = method.get("integrator", "euler")
        if integrator == "rk2" and mats.n_history:
            laws = ", ".join(sorted({repr(m.law_name) for m in materials if m.n_history}))
            raise InputError(f"{scene.where('method.integrator')} = 'rk2' with material law {laws}: a law with "
                             "internal variables needs integrator = 'euler' in dgmpm (RK2 would evaluate it at "
                             "the grid nodes, where its history does not live)")
        stepper = DGMPM(grid, particles, mats, bcs, cfl=cfl, integrator=integrator,
                        transverse=method.get("transverse", "dcu"), layout=method.get("layout", "auto"),
                        particles_key=scene.where("particles.file" if scene.get("particles.file") else "particles.per_cell"))
    elif name == "mpm":              # the whole background grid; integrator/transverse keys are ignored
        stepper = MPM(grid, particles, mats, bcs, cfl=cfl, update=method.get("update", "usl"),
                      shape=method.get("shape", "cpgimp"), time_step_rule=method.get("time_step", "current"),
                      geometry=method.get("geometry", "updated"))
    else:
        order = method.get("order", 1)
        if not 1 <= order <= 5:
            raise InputError(f"{scene.where('method.order')} = {order!r} must be in 1..5")
        cell_material = cell_values("materials", particles.cell, particles.material, grid.submesh.nelements)
        picard = _picard_options(scene, method) if name.startswith("ader") else {}
        if name == "rk-dgfem":
            stepper = DGFEM(grid, mats, bcs, cell_material, order=order, cfl=cfl,
                            integrator=method.get("integrator", "rk2"), limiter=method.get("limiter", "none"))
        elif name == "ader-dgfem":
            stepper = ADERDGFEM(grid, mats, bcs, cell_material, order=order, cfl=cfl,
                                limiter=method.get("limiter", "none"), **picard)
        else:
            stepper = ADERDGMPM(grid, mats, bcs, cell_material, order=order, cfl=cfl, particles_in=particles,
                                mls_order=method.get("mls_order", -1), backmap=method.get("backmap", "pic"),
                                limiter=method.get("limiter", "none"), **picard)
    grid.release_caches()                   # the operators are assembled: memory back
    guard = method.get("cfl_guard", "predict")
    if guard not in ("predict", "largest"):
        raise InputError(f"{scene.where('method.cfl_guard')} = {guard!r}: expected 'predict' (a step scaled by "
                         "the last step's wave speed-up, rarely repeated) or 'largest' (the largest admissible step)")
    if name != "mpm":
        stepper.cfl_guard = guard
    solution = exact_solution(scene)
    if getattr(solution, "body_force", None) is not None:    # manufactured solution: source rho0 b
        stepper.body_force = solution.body_force
    n = len(stepper.particles)
    init = scene.get("initial") or {}
    v0 = _array(scene, "initial.velocity", init.get("velocity", [0.0] * d), (d,), f"{d} number(s) (m/s)")
    F0 = _array(scene, "initial.F", init.get("F", np.eye(d).tolist()), (d, d), f"{d}x{d} numbers")
    F0, v0 = np.broadcast_to(F0, (n, d, d)).copy(), np.broadcast_to(v0, (n, d)).copy()
    source = None
    if init.get("exact"):
        source = solution
        if source is None:
            raise InputError(f"{scene.where('initial.exact')} = true needs an [exact] table")
    elif "field" in init:
        spec = dict(init["field"])
        field_name = spec.pop("name", None)          # not `name`: that is the method's
        if field_name not in INITIAL:
            raise InputError(f"{scene.where('initial.field.name')} = {field_name!r}: expected one of "
                             f"{', '.join(INITIAL)}")
        try:
            source = INITIAL[field_name](**spec)
        except TypeError as exc:
            raise InputError(f"{scene.where('initial.field')}: {exc}") from None
    if source is not None:
        fields = source.fields(stepper.particles.X, 0.0)
        for i in range(d):
            v0[:, i] = fields[f"v{i + 1}"]
            for a in range(d):
                F0[:, i, a] = fields[f"F{i + 1}{a + 1}"]
    try:
        with np.errstate(over="ignore", invalid="ignore"):
            initial = stepper.initial_state(F0, v0)
        if hasattr(source, "displacement"):             # a deformed start: x = X + u(X, 0)
            initial.x = initial.x + source.displacement(stepper.particles.X, 0.0)
        with np.errstate(over="ignore", invalid="ignore"):
            energy = stepper.energy(initial)
        if not np.all(np.isfinite(energy)):
            raise InstabilityError("non-finite energy")
    except InstabilityError as exc:
        raise InputError(f"{scene.where('initial')}: the initial state is not admissible "
                         f"({str(exc).split(' at step')[0]})") from None
    release_free_pages()                    # the set-up's freed temporaries: not resident under the step's peak
    disc = Discretisation(scene, grid, stepper.particles, layout if name == "dgmpm" else None, stepper, initial)
    if "cfl" not in method:             # 1, or below the method's known limit (`guards.default_cfl`)
        stepper.cfl, disc.cfl_default = guards.default_cfl(disc)
    return disc


def _picard_options(scene, method):
    """ADER's Picard controls from the scene (`method.picard_max`, `method.picard_tol`), checked;
    the stepper's defaults where absent (`ader.default_picard_max` iterations, 1e-12)."""
    options = {}
    if "picard_max" in method:
        if method["picard_max"] < 1:
            raise InputError(f"{scene.where('method.picard_max')} = {method['picard_max']!r} must be >= 1 "
                             "(Picard iterations of the ADER predictor per step)")
        options["picard_max"] = int(method["picard_max"])
    if "picard_tol" in method:
        tol = float(method["picard_tol"])
        if not tol >= 0:
            raise InputError(f"{scene.where('method.picard_tol')} = {method['picard_tol']!r} must be >= 0 (a "
                             "relative change of the predictor)")
        options["picard_tol"] = tol
    return options


def _region_cells(scene, mesh, k, region):
    """Mask over the cells of ``mesh`` of ``[[regions]]`` number k: the cells whose centre lies in
    its ``box``, or those of its ``subdomain`` (a gmsh physical surface, as ``body.subdomain``)."""
    where = f"regions[{k}]"
    if not (isinstance(region, dict) and isinstance(region.get("material"), dict)
            and set(region) <= {"box", "subdomain", "material"} and ("box" in region) != ("subdomain" in region)):
        raise InputError(f"{scene.where(where)} = {region!r} must be a table with material and one of "
                         f"box = {{x = [lo, hi], ...}} or subdomain = \"NAME\" (a physical surface of the mesh)")
    if "subdomain" in region:
        name, subs = region["subdomain"], mesh.subdomains or {}
        if not isinstance(name, str) or name not in subs:
            known = ", ".join(subs) if subs else "none: a generated grid has none, a gmsh file's physical surfaces"
            raise InputError(f"{scene.where(f'{where}.subdomain')} = {name!r} is not a physical surface of the "
                             f"mesh (known: {known})")
        inside = np.zeros(mesh.nelements, dtype=bool)
        inside[np.asarray(subs[name])] = True
        return inside
    if not isinstance(region["box"], dict):
        raise InputError(f"{scene.where(f'{where}.box')} = {region['box']!r} must be a table {{x = [lo, hi], ...}}")
    _check_box(scene, f"{where}.box", region["box"], mesh.dim())
    centre = mesh.p[:, mesh.t].mean(axis=1)
    inside = np.ones(mesh.nelements, dtype=bool)
    for axis, key in enumerate("xy"[: mesh.dim()]):
        if key in region["box"]:
            lo, hi = region["box"][key]
            inside &= (centre[axis] >= lo) & (centre[axis] <= hi)
    return inside


def _read_points(scene, name, d):
    path = scene.resolve(name)
    if not path.is_file():
        raise InputError(f"{scene.where('particles.file')} = {name!r}: file not found")
    try:
        X = np.loadtxt(path, delimiter=",", ndmin=2)
    except ValueError as exc:
        raise InputError(f"{path}: cannot read particle coordinates ({exc})") from None
    if X.shape[1] != d:
        raise InputError(f"{path}: particle coordinates need {d} column(s), got {X.shape[1]}")
    return X


def _array(scene, key, value, shape, what):
    try:
        arr = np.asarray(value, dtype=float) if _numbers(value) else None
    except (TypeError, ValueError):
        arr = None
    if arr is None or arr.shape != shape or not np.all(np.isfinite(arr)):
        raise InputError(f"{scene.where(key)} = {value!r} must be {what}")
    return arr


def _origin(scene, d):
    value = scene.get("grid.origin", [0.0] * d)
    values = value if isinstance(value, list) else [value]
    if len(values) != d or not all(_number(v) for v in values):
        raise InputError(f"{scene.where('grid.origin')} = {value!r} must be {d} number(s) (m)")
    return tuple(float(v) for v in values)


def _check_box(scene, key, box, d):
    for axis, bounds in box.items():
        if (axis not in "xyz"[:d] or not isinstance(bounds, list) or len(bounds) != 2
                or not all(_number(b) for b in bounds)):
            raise InputError(f"{scene.where(f'{key}.{axis}')} = {bounds!r}: expected an axis in "
                             f"{', '.join('xyz'[:d])} and [lo, hi] (m)")


def _layout(scene, per_cell, d):
    ok = (isinstance(per_cell, int) and not isinstance(per_cell, bool) and per_cell > 0) or (
        isinstance(per_cell, list) and per_cell and all(_number(x) and 0 < x < 1 for x in per_cell))
    if not ok:
        raise InputError(f"{scene.where('particles.per_cell')} = {per_cell!r} must be a positive "
                         f"integer or a list of parent coordinates in (0, 1)")
    return tensor_layout(per_cell, d)


def _bc(scene, grid, name, spec, d):
    where = scene.where(f"bc.{name}")
    if not isinstance(spec, dict):
        raise InputError(f"{where} = {spec!r} must be a table")
    if name not in grid.submesh.boundaries:
        raise InputError(f"{where}: no boundary named {name!r} in the grid "
                         f"(known: {', '.join(sorted(grid.submesh.boundaries))})")
    if len(grid.submesh.boundaries[name]) == 0:
        warnings.warn(f"{where}: boundary {name!r} touches no cell holding particles, the condition "
                      f"is unused (the body's own boundary is named 'surface')", stacklevel=4)
    for key in ("release", "ramp"):
        value = spec.get(key, 0.0)              # release = inf (never) is allowed
        if not (isinstance(value, (int, float)) and not isinstance(value, bool) and value >= 0):
            raise InputError(f"{where}.{key} = {spec[key]!r} must be a time >= 0 (s)")
    if spec.get("kind") == "normal_velocity" and not _number(spec.get("value", 0.0)):
        raise InputError(f"{where}.value = {spec['value']!r} must be a number (m/s)")
    return make_bc(spec, d, where)


def _number(x):
    return isinstance(x, (int, float)) and not isinstance(x, bool) and np.isfinite(x)


def _positive(scene, key):
    value = scene.get(key)
    if not (_number(value) and value > 0):
        raise InputError(f"{scene.where(key)} = {value!r} must be a number > 0")
    return float(value)


def _count(scene, key, d):
    value = scene.get(key)
    values = value if isinstance(value, list) else [value]
    if len(values) != d or not all(isinstance(v, int) and not isinstance(v, bool) and v > 0 for v in values):
        raise InputError(f"{scene.where(key)} = {value!r} must be {d} positive integer(s)")
    return values
