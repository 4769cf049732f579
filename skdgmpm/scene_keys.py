"""Every key a scene file can hold: type, unit, default, example, the methods that use it, meaning.

One table (`KEYS`) for docs/scenes.md (`markdown`, written by ``skdgmpm scenes schema --markdown``),
for ``skdgmpm scenes schema`` (`text`) and for the warning about keys a method ignores
(`ignored_keys`). The types of the keys that `skdgmpm.scene.SCHEMA` checks are read from it, so
they cannot drift; tests/test_scene_keys.py fails when a key of the schema, of a law, of an exact
solution or of a shipped scene is missing here, or when docs/scenes.md is not the generated text.

Names: ``bc.NAME.kind`` stands for any boundary name, ``regions[].box`` for a key of each
``[[regions]]`` table.
"""
from dataclasses import dataclass

ALL = ("dgmpm", "rk-dgfem", "ader-dgfem", "ader-dgmpm", "mpm")
HIGH_ORDER = ("rk-dgfem", "ader-dgfem", "ader-dgmpm")


@dataclass(frozen=True)
class Key:
    """One row: dotted ``name``, ``unit`` ("" for none), ``default`` ("required", "none" or a
    value, as text), ``example`` (TOML), the ``methods`` that read it, what it ``means``; ``type``
    is taken from the schema where it checks the key (else given here); ``dims`` where it is read."""

    name: str
    unit: str
    default: str
    example: str
    means: str
    methods: tuple = ALL
    type: str = ""
    dims: tuple = (1, 2)


SECTIONS = {
    "": "Top level",
    "grid": "[grid]: the background grid, generated or read from a mesh file",
    "body": "[body]: which cells hold particles (default: every cell)",
    "particles": "[particles]",
    "material": "[material]: the constitutive law and its parameters",
    "regions": "[[regions]]: other materials in parts of the body (the last region holding a cell wins)",
    "initial": "[initial]: the state at t = 0 (default: at rest, F = I)",
    "boundaries": "[boundaries.NAME]: extra named boundaries",
    "bc": "[bc.NAME]: boundary conditions by boundary name (later tables override earlier ones on shared faces)",
    "method": "[method]",
    "run": "[run]",
    "probes": "[probes]: gauges, time histories of fields at named points (optional; probes.csv, probes.png)",
    "exact": "[exact]: the exact solution the errors are measured against (optional)",
    "figures": "[figures]: what `skdgmpm compare-figures` draws (optional)",
}

BOX = "{x = [lo, hi], y = [lo, hi]}"

KEYS = (
    # ------------------------------------------------------------------------------ top level
    Key("title", "", "the scene's name", '"Compression impact on a linear elastic bar"',
        "one line shown by `skdgmpm list`, the pictures and the plots"),
    Key("reference", "", "none", '"Renaud et al. 2018 (JCP), §7.1, Fig. 6"',
        "the paper and section the scene reproduces (shown by `skdgmpm list`)"),
    Key("description", "", "none", '"""A bar of length 6 m ..."""', "the problem statement, in words"),
    Key("dim", "", "required", "2", "dimension: 1 (a bar, uniaxial strain) or 2 (plane strain)"),
    # ------------------------------------------------------------------------------ grid
    Key("grid.length", "m", "required in 1D without mesh", "6.0", "length of the bar (1D)", dims=(1,)),
    Key("grid.cells", "", "required without mesh", "[33, 25]",
        "number of cells: an integer in 1D, [nx, ny] in 2D"),
    Key("grid.size", "m", "required in 2D without mesh", "[4.0, 3.0]", "[lx, ly] of the rectangle (2D)",
        dims=(2,)),
    Key("grid.origin", "m", "0 (each axis)", "[-0.7, -0.7]", "position of the lower-left corner (1D: a number)"),
    Key("grid.mesh", "", "none", '"plate_4x3.msh"',
        "a gmsh (or any meshio) file of quads (lines in 1D), relative to the scene file; its physical "
        "lines name boundaries, its physical surfaces subdomains; it sets the grid (length, cells, size "
        "and origin then have no effect and are warned about)"),
    # ------------------------------------------------------------------------------ body
    Key("body.box", "m", "none", "{x = [0.0, 2.0], y = [0.0, 1.0]}",
        "only the cells whose centre lies in the box hold particles (an axis left out is not limited)"),
    Key("body.subdomain", "", "none", '"body"', "only the cells of this physical surface of grid.mesh hold particles",
        dims=(2,)),
    Key("body.ring", "m", "none", "{centre = [0.0, 0.0], radii = [0.4, 0.6]}",
        "only the cells whose centre lies in the annulus R_I <= |X - centre| <= R_O hold particles "
        "(a stair-stepped ring, WG08 §5.2); 0 <= R_I < R_O", dims=(2,)),
    # ------------------------------------------------------------------------------ particles
    Key("particles.per_cell", "", "1", "[0.25, 0.75]",
        "particles per cell and direction (2: 2 x 2 in 2D): n puts them at parent coordinates (k + 1/2) / n, a list gives "
        "the parent coordinates in (0, 1) (the same in each direction); DGFEM methods use them as output "
        "points only; DGMPM's CFL limit depends on them (`skdgmpm stability`)"),
    Key("particles.file", "", "none", '"points.csv"',
        "instead of per_cell: reference positions of the particles, one per line, d comma-separated "
        "columns (m), relative to the scene file; the cells holding a particle are the body, each "
        "particle gets its cell's volume divided by the particles in that cell (no DGMPM CFL limit is "
        "known for such a layout: none is checked)"),
    # ------------------------------------------------------------------------------ material
    Key("material.law", "", '"linear_elastic"', '"neo_hookean"',
        "linear_elastic (small strain), saint_venant_kirchhoff (alias svk), neo_hookean, gavrilyuk "
        "(quadratic volume + rank-one convex isochoric family, L23 eq 16-17), mooney_rivlin, "
        "j2_plasticity (small strain), hencky_j2 (finite strain J2)"),
    Key("material.E", "Pa", "required", "2.0e11", "Young's modulus (every law)"),
    Key("material.nu", "", "required", "0.3", "Poisson's ratio, in (-1, 0.5) (every law)"),
    Key("material.rho", "kg/m^3", "required", "7800.0", "density in the reference configuration (every law)"),
    Key("material.a", "", "-1.0", "-1.0",
        "gavrilyuk only: the isochoric family's parameter, in [-1, 0.5]; a = -1 is the neo-Hookean shear "
        "energy mu/2 (I1b - 3) of L23 eq 19"),
    Key("material.beta", "", "0.5", "0.5",
        "mooney_rivlin only: the share of the small-strain shear modulus carried by the second invariant, "
        "in [0, 1) (0: neo-Hookean)"),
    Key("material.sigma_y", "Pa", "required for j2_plasticity, hencky_j2", "4.0e8",
        "j2_plasticity, hencky_j2: initial yield stress (> 0)"),
    Key("material.H", "Pa", "required for j2_plasticity, hencky_j2", "1.0e10",
        "j2_plasticity, hencky_j2: linear isotropic hardening modulus (>= 0; 0 = perfect plasticity)"),
    # ------------------------------------------------------------------------------ regions
    Key("regions[].box", "m", "none", "{x = [2.0, 4.0]}",
        "the region's cells: those whose centre lies in the box (give box or subdomain)", type="table"),
    Key("regions[].subdomain", "", "none", '"alu"',
        "the region's cells: those of this physical surface of grid.mesh (give box or subdomain)",
        type="string", dims=(2,)),
    Key("regions[].material", "", "required", '{law = "linear_elastic", E = 7.0e10, nu = 0.33, rho = 2700.0}',
        "the region's material: the keys of [material]", type="table"),
    # ------------------------------------------------------------------------------ initial
    Key("initial.velocity", "m/s", "0", "[-200.0, 0.0]", "uniform initial velocity, d numbers"),
    Key("initial.F", "", "identity", "[[1.01, 0.0], [0.0, 1.0]]", "uniform initial deformation gradient, d x d"),
    Key("initial.exact", "", "false", "true", "F and v from the [exact] solution at t = 0 (and its displacement)"),
    Key("initial.field", "", "none", '{name = "square_initial_strain", amplitude = 5.0e-4}',
        "F and v from a named initial field (its parameters beside name)"),
    Key("initial.field.name", "", "required in field", '"square_initial_strain"',
        "square_initial_strain: eps = f (e1 x e1 - e2 x e2), f = U0 pi/2 cos(pi x/2) sin(pi y/2) (L23 eq 68-69)",
        type="string"),
    Key("initial.field.amplitude", "m", "5.0e-4", "5.0e-4", "square_initial_strain: U0", type="number"),
    # ------------------------------------------------------------------------------ boundaries
    Key("boundaries.NAME.box", "m", "required", "{x = [0.0, 0.0], y = [0.0, 1.0]}",
        "a boundary named NAME: the boundary faces whose midpoint lies in the box (over the names of the "
        "grid: left, right, bottom, top for a generated one, the physical lines of a mesh file)", type="table"),
    # ------------------------------------------------------------------------------ bc
    Key("bc.NAME.kind", "", "required", '"traction"',
        "velocity | traction | free | symmetry | normal_velocity | transmissive | mixed, on the boundary "
        "NAME (the body's own boundary, where no cell of the grid is next to it, is named surface and is "
        "free unless a table says otherwise)", type="string"),
    Key("bc.NAME.value", "m/s or Pa", "required for velocity, traction", "[5.0, 0.0]",
        "velocity (m/s, d numbers), traction t = P N on the body (Pa, d numbers), normal_velocity (m/s, "
        "one number, default 0)", type="list or number"),
    Key("bc.NAME.velocity", "m/s", "none", "{x = 1000.0}", "mixed: the imposed velocity components by axis",
        type="table"),
    Key("bc.NAME.traction", "Pa", "none", "{y = 0.0}",
        "mixed: the imposed traction components by axis (with velocity: exactly one per axis)", type="table"),
    Key("bc.NAME.release", "s", "never", "5.106e-4", "the condition's value is switched off at this time",
        type="number"),
    Key("bc.NAME.ramp", "s", "0", "1.0e-5", "the value rises linearly from 0 over this time", type="number"),
    # ------------------------------------------------------------------------------ method
    Key("method.name", "", '"dgmpm"', '"ader-dgmpm"', "dgmpm | rk-dgfem | ader-dgfem | ader-dgmpm | mpm"),
    Key("method.integrator", "", '"euler" (dgmpm), "rk2" (rk-dgfem)', '"rk2"',
        "time integrator: euler | rk2 for dgmpm, rk2 | rk4 for rk-dgfem (the ADER methods are their own "
        "one-step method, MPM its update)", methods=("dgmpm", "rk-dgfem")),
    Key("method.transverse", "", '"dcu"', '"ctu"',
        "2D DGMPM: dcu (donor-cell upwind, no transverse waves) or ctu (corner transport upwind, R18 "
        "§5; a CFL of 1)", methods=("dgmpm",), dims=(2,)),
    Key("method.layout", "", '"auto"', '"nodes"',
        "auto: with forward Euler and one particle strictly inside every cell, the step runs on the "
        "particles' own arrays (R18 §5 as it reduces there: the same numbers up to round-off, without "
        "the nodal arrays); nodes: R18's nodal stages (projection, nodal update, back map) always",
        methods=("dgmpm",)),
    Key("method.cfl", "", "1.0, or 0.9 of the method's known limit where that is below 1", "0.5",
        "Courant number, in (0, 2]: dt = CFL h_min / c_max (DG methods of order P: / (2P + 1)); unset, "
        "the run says which it took where not 1 (e.g. 2D DGMPM with DCU: 0.58, with nu = 0.3)"),
    Key("method.order", "", "1", "2", "polynomial order P, 1..5 (dgmpm: 1 only)",
        methods=("dgmpm", *HIGH_ORDER)),
    Key("method.mls_order", "", "order", "1", "order of the moving-least-squares fit of the particles",
        methods=("ader-dgmpm",)),
    Key("method.backmap", "", '"pic"', '"flip"', "pic | flip: how the grid update reaches the particles",
        methods=("ader-dgmpm",)),
    Key("method.picard_max", "", "dP + 1, >= P + 2", "3",
        "ADER predictor: at most this many Picard iterations per step (>= 1; fewer than the default may "
        "stop the predictor before it converges, docs/choices.md); the run's summary counts them",
        methods=("ader-dgfem", "ader-dgmpm")),
    Key("method.picard_tol", "", "1e-12", "1e-10",
        "ADER predictor: each cell stops its Picard iterations when its change is below this fraction of "
        "the F and p blocks' size (>= 0; 0: only once its iterate no longer changes)",
        methods=("ader-dgfem", "ader-dgmpm")),
    Key("method.limiter", "", '"none"', '"barth-jespersen"',
        "none | barth-jespersen | venkatakrishnan, each also -invariant, -scaled, -invariant-scaled "
        "(L23 eq 41-43; docs/choices.md)", methods=HIGH_ORDER),
    Key("method.update", "", '"usl"', '"cd"', "MPM variant: usf | usl | cd | uvf (WG08)", methods=("mpm",)),
    Key("method.shape", "", '"cpgimp"', '"ugimp"', "MPM shape functions: hat | ugimp | cpgimp", methods=("mpm",)),
    Key("method.time_step", "", '"current"', '"bar"',
        "MPM: current (wave speed of the current state) or bar (WG08's fixed step from the bar speed)",
        methods=("mpm",)),
    Key("method.cfl_above_limit", "", "false", "true",
        "run a CFL above the method's known stability limit (DGMPM: the von Neumann limit of its step, "
        "in 2D `skdgmpm stability --dim 2`, else the layout's; MPM: 1) with a warning instead of refusing it; no effect where no limit is known"),
    Key("method.cfl_guard", "", '"predict"', '"largest"',
        "Godunov schemes: predict (the first attempt of a step divided by the wave speed-up foreseen from "
        "those of the last 16 steps and no longer than their CFL steps: rarely repeated) or largest (always the largest admissible step: CFL 1 exactness in 1D)",
        methods=("dgmpm", "rk-dgfem", "ader-dgfem", "ader-dgmpm")),
    Key("method.geometry", "", '"updated"', '"linearised"',
        "MPM: updated (particles move over the grid) or linearised (they stay at their reference "
        "positions: small displacements, R18 §7.1)", methods=("mpm",)),
    # ------------------------------------------------------------------------------ run
    Key("run.t_end", "s", "required (or run.steps)", "1.0e-3", "end time; given with --set it replaces the file's run.steps"),
    Key("run.steps", "", "none", '"cells"',
        "instead of run.t_end: the end time of that many first time steps; \"cells\": as many as cells along X "
        "(L23 §5.1's N_t = N_e, the step of eq 67)"),
    Key("run.frames", "", "20", "12", "frames written (particles_NNNN.vtu) and kept by run() after t = 0"),
    Key("run.checkpoint_every", "steps or time", '"10 min"', '"30 s"',
        "how often checkpoint.npz is written: a number of steps (500) or a wall time ('30 s', '10 min', '2 h'); "
        "a run can be resumed: `skdgmpm run --resume DIR`"),
    Key("run.step_limit", "", "10000000", "100000", "a run that needs more steps is refused or stopped"),
    Key("run.threads", "", "every core", "2",
        "threads of the compiled passes (also --threads, $SKDGMPM_THREADS); the answers are the same for any count"),
    Key("run.energy_every", "steps", "1 (10 above 20 000 points)", "5",
        "steps between rows of energy.csv and checks of the energy balance (frames and the last step always)"),
    Key("run.fields", "", "all", '["velocity", "P", "cauchy"]',
        "the particle arrays of the frames: F, P, cauchy, velocity, momentum, X, volume, material and the law's "
        "history variables (eqp, ...); positions always; checkpoints keep the whole state"),
    # ------------------------------------------------------------------------------ probes
    Key("probes.points", "m", "required in [probes]", "{rear = [0.01, 0.0], mid = [0.005, 0.0]}",
        "named points in the reference configuration, inside the body; each reads the particle nearest to it "
        "(DGFEM: the Gauss point), a gauge glued to the material"),
    Key("probes.fields", "", "v_i and P_ii", '["v1", "P11"]',
        "the fields recorded, any of `result.fields()` (v1, P11, sigma11, F11, eps11, x1, eqp, ...); columns "
        "field@point of probes.csv"),
    Key("probes.every", "steps", "1", "10", "steps between rows (step 0 and the last step always)"),
    # ------------------------------------------------------------------------------ exact
    Key("exact.name", "", "required in [exact]", '"elastic_bar_step"',
        "elastic_bar_step | svk_bar_riemann | elastoplastic_bar_step | standing_wave_2d | square_shear_mode | "
        "mms_axis_aligned | mms_ring (E, nu, rho and the law are the scene's [material])", type="string"),
    Key("exact.load", "", "none", '"left"',
        "the [bc.NAME] of kind traction or free whose value drives a bar solution", type="string", dims=(1,)),
    Key("exact.traction", "Pa", "from load", "-1.0e9", "bar solutions: P11 at the loaded end (negative: compression), if not given by load",
        type="number", dims=(1,)),
    Key("exact.length", "m", "grid.length", "6.0", "bar solutions: the bar's length (reflections)",
        type="number", dims=(1,)),
    Key("exact.sigma_y", "Pa", "material.sigma_y", "4.0e8", "elastoplastic_bar_step: yield stress",
        type="number", dims=(1,)),
    Key("exact.H", "Pa", "material.H", "1.0e10", "elastoplastic_bar_step: hardening modulus", type="number",
        dims=(1,)),
    Key("exact.amplitude", "m", "per solution", "1.0e-4",
        "standing_wave_2d, square_shear_mode (U0), mms_axis_aligned (0.1), mms_ring (0.1 R_O): displacement "
        "amplitude", type="number",
        dims=(2,)),
    Key("exact.modes", "", "[1, 1]", "[2, 1]", "standing_wave_2d: mode numbers in x and y", type="list",
        dims=(2,)),
    Key("exact.size", "m", "grid.size", "[1.0, 1.0]", "standing_wave_2d: the square's sides", type="list",
        dims=(2,)),
    Key("exact.radii", "m", "body.ring radii", "[0.4, 0.6]", "mms_ring: R_I, R_O", type="list", dims=(2,)),
    Key("exact.centre", "m", "body.ring centre", "[0.0, 0.0]", "mms_ring: the ring's centre", type="list",
        dims=(2,)),
    # ------------------------------------------------------------------------------ figures
    Key("figures.times", "s", "[run.t_end]", "[2.55e-4, 1.14e-3]",
        "`skdgmpm compare-figures`: the times of the maps and line plots (the paper's figures)"),
    Key("figures.fields", "", '["sigma11"]', '["eqp", "sigma11"]', "`skdgmpm compare-figures`: the fields drawn"),
)

BY_NAME = {k.name: k for k in KEYS}
TYPE_NAMES = {str: "string", int: "integer", float: "number", bool: "boolean", list: "list", dict: "table"}


def schema_type(expected):
    """(int, float) -> "number"; (int, list) -> "integer or list"; a sub-table -> "table"."""
    if isinstance(expected, dict) or expected is None:
        return "table"
    from .scene import _flat_types
    names = [TYPE_NAMES[t] for t in _flat_types(expected)]
    if "number" in names and "integer" in names:         # (int, float): any number
        names.remove("integer")
    return " or ".join(dict.fromkeys(names))


def schema_paths(schema=None, prefix=""):
    """Every dotted key of the schema with its expected type(s); a free-form table (None) and a
    list of tables are keys too (their rows here are ``bc.NAME.*``, ``regions[].*``)."""
    if schema is None:
        from .scene import SCHEMA
        schema = SCHEMA
    for key, expected in schema.items():
        path = prefix + key
        if isinstance(expected, dict):
            yield from schema_paths(expected, path + ".")
        else:
            yield path, expected


def rows():
    """The keys with their type filled in from the schema where it checks them."""
    types = dict(schema_paths())
    return [k if k.name not in types else Key(**{**k.__dict__, "type": schema_type(types[k.name])})
            for k in KEYS]


def _section(name):
    """The table a key belongs to: "grid" for grid.cells, "regions" for regions[].box, "" at the top."""
    head = name.split(".")[0].split("[")[0]
    return head if head != name and head in SECTIONS else ""


def _methods(key):
    text = "all" if set(key.methods) == set(ALL) else ", ".join(key.methods)
    return text + ("" if key.dims == (1, 2) else f" ({key.dims[0]}D)")


def markdown():
    """docs/scenes.md."""
    out = [
        "# Scene files: every key",
        "",
        "<!-- generated from skdgmpm/scene_keys.py by `skdgmpm scenes schema --markdown > docs/scenes.md`;",
        "     tests/test_scene_keys.py fails when this file differs from the generated text -->",
        "",
        "A scene is a TOML file (`cases/*.toml`; `skdgmpm scenes show NAME` prints one, `skdgmpm scenes",
        "copy NAME DIR` copies it with its mesh to start from). Every key below can be overridden on the",
        "command line (`--set method.cfl=0.5`) or in Python (`load_scene(name, overrides=[...])`). An",
        "unknown key, a value of the wrong type or out of range is a one-line error naming the file, the",
        "key and the value; a key the scene's method does not read is a one-line warning",
        "(e.g. `method.integrator` in an ADER run, `method.transverse` in 1D).",
        "",
        "Units are SI. *methods*: the methods that read the key (all five unless said; `(2D)`: only in",
        "2D). `NAME` stands for a boundary name, `regions[]` for each `[[regions]]` table.",
    ]
    by_section = {}
    for key in rows():
        by_section.setdefault(_section(key.name), []).append(key)
    for section, title in SECTIONS.items():
        out += ["", f"## {title}", "", "| key | type | unit | default | example | methods | meaning |",
                "|---|---|---|---|---|---|---|"]
        for k in by_section.get(section, []):
            cells = [f"`{k.name}`", k.type, k.unit, k.default, f"`{k.example}`", _methods(k), k.means]
            out.append("| " + " | ".join(c.replace("|", "\\|") for c in cells) + " |")
    return "\n".join(out) + "\n"


def text(width=100):
    """The key table for a terminal: key, type, unit, default, methods; then the meaning, indented."""
    import textwrap

    out = []
    for k in rows():
        unit = f" ({k.unit})" if k.unit else ""
        out.append(f"{k.name}: {k.type}{unit}, default {k.default}; {_methods(k)}; e.g. {k.example}")
        out += textwrap.wrap(k.means, width, initial_indent="    ", subsequent_indent="    ")
    return "\n".join(out)


def ignored_keys(scene):
    """[(key, message)] for the ``method.*`` keys the scene's method (or dimension) does not read.
    A key the scene file set for its own method is not reported when ``--set method.name=...``
    switched the method (the studies do): only what the user gave for the method that runs."""
    method = scene.data.get("method", {})
    name = method.get("name", "dgmpm")
    switched = "method.name" in scene.overridden
    out = []
    for key, value in method.items():
        row = BY_NAME.get(f"method.{key}")
        if row is None or (switched and f"method.{key}" not in scene.overridden):
            continue
        if (key, value) in (("limiter", "none"), ("integrator", "ader")):      # says nothing is done
            continue
        if name not in row.methods:
            out.append((f"method.{key}", f"{scene.where(f'method.{key}')} = {value!r} is ignored by {name} "
                                         f"(read by {', '.join(row.methods)})"))
        elif scene.dim not in row.dims:
            out.append((f"method.{key}", f"{scene.where(f'method.{key}')} = {value!r} is ignored in "
                                         f"{scene.dim}D (read in {', '.join(f'{d}D' for d in row.dims)})"))
    return out


def main(argv=None):
    import sys
    argv = sys.argv[1:] if argv is None else argv
    sys.stdout.write(markdown() if "--markdown" in argv else text() + "\n")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
