"""The bad-input table of issue 17: 167 bad or extreme inputs through `skdgmpm run` (and a few
other commands), each classified as a one-line error with exit 2, a traceback, accepted (exit 0),
or a health stop (exit 3). Run from anywhere: python tests/bad_input_table.py (a few minutes)."""
import contextlib, io, os, sys, tempfile, warnings
from pathlib import Path
import numpy as np, meshio
ROOT = Path(__file__).resolve().parent.parent
os.chdir(ROOT); sys.path.insert(0, str(ROOT))
from skdgmpm.cli import main
base = Path(tempfile.mkdtemp(prefix="table"))
T = ["--set", "grid.cells=20", "--set", "run.t_end=1e-5", "--quiet"]
SET = lambda *o: [a for x in o for a in ("--set", x)]
cases = []
def add(label, argv): cases.append((label, argv))
bad_sets = ["grid.cellz=3", 'grid.cells="many"', "grid.cells=0", "grid.cells=-5", "grid.cells=1.5", "grid.cells=[3,4]",
 "grid.length=0", "grid.length=-1", "grid.length=nan", "grid.length=inf", 'grid.length="6"', 'grid.origin="x"', "grid.origin=true",
 "grid.origin=[1,2]", "grid.origin=[nan]", 'grid.mesh="nope.msh"', "material.E=0", "material.E=-1", "material.E=nan", "material.E=inf",
 "material.E=1e300", "material.rho=1e-300", "material.rho=0", "material.rho=-7800", "material.nu=0.5", "material.nu=-1.2", "material.nu=2",
 'material.law="rubber"', "material.law=3", "material.G=1", 'material.E="steel"', "material.sigma_y=1e8", 'material.law="j2_plasticity"',
 'bc.left.kind="blah"', "bc.left=3", 'bc.left.value=["1e9"]', "bc.left.value=[true]", 'bc.left.value="1e9"', "bc.left.value=[1,2]",
 "bc.left.value=[nan]", "bc.left.value=[inf]", "bc.left.value=[]", 'bc.left.release="x"', "bc.left.release=-1", "bc.left.ramp=-1",
 "bc.nowhere.kind=free", 'bc.left.kind="normal_velocity"', 'bc.left={kind="velocity"}',
 "run.t_end=0", "run.t_end=-1", "run.t_end=inf", "run.t_end=nan", 'run.t_end="1e-3"', "run.frames=0", "run.frames=-3", "run.frames=2.5",
 "run.checkpoint_every=0", 'run.checkpoint_every="soon"', "run.step_limit=0", "run.step_limit=5", "run.nope=1",
 "method.cfl=0", "method.cfl=-1", "method.cfl=3", "method.cfl=nan", 'method.cfl="1"', 'method.integrator="rk4"', 'method.name="fem"',
 'method.transverse="abc"', "method.order=2", 'method.limiter="bogus"', "method.cfl_above_limit=1",
 "dim=3", "dim=0", 'dim="2"', "particles.per_cell=0", 'particles.per_cell=["a"]', "particles.per_cell=[0.5, 1.5]", "particles.per_cell=[-0.1]",
 'particles.file="nope.txt"', 'initial.velocity=["a"]', "initial.velocity=[1.0, 2.0]", "initial.velocity=[nan]", 'initial.velocity=["1"]',
 "initial.F=[[-1.0]]", "initial.F=[[1e300]]", "initial.F=[[0.0]]", "initial.velocity=[1e300]", "initial.exact=3",
 "exact.load=nowhere", "exact.load=right", 'exact.name="nope"', "grid", "grid.cells.x=3", "=3", "title=3", "description=[1]",
 "method.cfl=1.5", 'method.name="mpm"', "boundaries.b.box=3", "body.box={x=[10,20]}", "regions=[3]",
 # outputs a user chooses: run.fields and [probes]
 'run.fields=["stress"]', 'run.fields="P"', "run.fields=[1]", 'run.fields=["v1"]', "run.fields=[[]]", "run.energy_every=0",
 "probes=3", "probes.points={a=[7.0]}", "probes.points={a=[-0.1]}", "probes.points={a=[1.0,2.0]}", 'probes.points={a=["x"]}',
 "probes.points={a=[nan]}", "probes.points={a=[inf]}", "probes.points={a=true}", "probes.points={}", "probes.points=[1.0]",
 'probes.points={a="mid"}', 'probes.fields=["v9"]', "probes.fields=[]", 'probes.fields="v1"', "probes.every=0", "probes.every=-2",
 "probes.every=1.5", "probes.where=1"]
for s in bad_sets:
    gauge = ["--set", "probes.points={a=[1.0]}"] if s.startswith(("probes.fields", "probes.every", "probes.where")) else []
    add(f"--set {s}", ["run", "bar_elastic_1d", "--out", base / "o", *T, *gauge, "--set", s])
two_d = ["grid.cells=[0,3]", "grid.size=[1]", "grid.size=[-1,1]", 'method.transverse="abc"', "method.cfl=1.9",
         'method.name="ader-dgmpm"', 'method.backmap="bogus"', "probes.points={a=[4.5,1.0]}", "probes.points={a=[1.0]}",
         'probes.points={a=[1.0,1.0]} && probes.fields=["P33"]']
for s in two_d:
    extra = ['--set', 'method.name="ader-dgmpm"'] if "backmap" in s else []
    add(f"2D --set {s}", ["run", "partial_impact_2d", "--out", base / "o2", "--set", "grid.cells=[4,4]", "--set", "run.t_end=1e-6",
                          "--quiet", *extra, *SET(*s.split(" && "))])
# files
(base / "latin1.toml").write_bytes('title = "à"\n'.encode("latin-1")); add("non-UTF-8 scene", ["run", base / "latin1.toml"])
(base / "bad.toml").write_text("dim = \n"); add("invalid TOML", ["run", base / "bad.toml"])
(base / "empty.toml").write_text(""); add("empty scene", ["run", base / "empty.toml"])
add("missing scene file", ["run", base / "none.toml"]); add("unknown scene", ["run", "no_such_scene"])
(base / "dir.toml").mkdir(); add("scene is a directory", ["run", base / "dir.toml"])
(base / "bin.toml").write_bytes(bytes(range(256))); add("binary scene", ["run", base / "bin.toml"])
SC = 'dim = 2\n[grid]\nmesh = "{m}"\n[material]\nlaw = "linear_elastic"\nE = 2.0e11\nnu = 0.3\nrho = 7800.0\n[method]\nname = "dgmpm"\n[run]\nt_end = 1.0e-5\n'
P = np.array([[0,0,0],[1,0,0],[2,0,0],[0,1,0],[1,1,0],[2,1,0]], float)
def mesh_case(label, points, cells, kind="quad", raw=None):
    d = base / label.replace(" ", "_"); d.mkdir()
    if raw is not None: (d / "m.msh").write_bytes(raw)
    else:
        with contextlib.redirect_stderr(io.StringIO()):
            meshio.write(d / "m.msh", meshio.Mesh(points, [(kind, np.array(cells))]), file_format="gmsh22", binary=False)
    (d / "s.toml").write_text(SC.format(m="m.msh")); add(label, ["run", d / "s.toml", "--out", d / "o", "--quiet"])
Pn = P.copy(); Pn[4, 1] = np.nan
mesh_case("mesh NaN node", Pn, [[0,1,4,3],[1,2,5,4]])
Pi = P.copy(); Pi[4, 1] = np.inf
mesh_case("mesh inf node", Pi, [[0,1,4,3],[1,2,5,4]])
mesh_case("mesh degenerate quad", P, [[0,1,4,3],[1,2,2,4]])
mesh_case("mesh bow-tie quad", P, [[0,1,4,3],[1,2,4,5]])
Pc = P.copy(); Pc[4] = [1.9, 0.9, 0]
mesh_case("mesh non-convex quad", Pc, [[0,1,4,3],[1,2,5,4]])
mesh_case("mesh lines only", P, [[0,1],[1,2]], kind="line")
mesh_case("mesh triangles", P, [[0,1,4],[1,2,5]], kind="triangle")
mesh_case("mesh garbage", None, None, raw=bytes(np.random.default_rng(0).integers(0, 256, 4000, dtype=np.uint8)))
mesh_case("mesh empty file", None, None, raw=b"")
mesh_case("mesh truncated", None, None, raw=(ROOT / "cases" / "plate_4x3.msh").read_bytes()[:3000])
# out and resume
(base / "afile").write_text("x")
add("--out under a file", ["run", "bar_elastic_1d", "--out", base / "afile" / "o", *T])
add("--out is a file", ["run", "bar_elastic_1d", "--out", base / "afile", *T])
add("--out in /proc", ["run", "bar_elastic_1d", "--out", "/proc/skdgmpm_o", *T])
(base / "full").mkdir(); (base / "full" / "x").write_text("x")
add("--out not empty", ["run", "bar_elastic_1d", "--out", base / "full", *T])
add("--resume missing dir", ["run", "--resume", base / "nowhere"])
add("--resume no checkpoint", ["run", "--resume", base / "full"])
(base / "badck").mkdir(); (base / "badck" / "checkpoint.npz").write_bytes(b"garbage")
add("--resume garbage checkpoint", ["run", "--resume", base / "badck"])
add("--resume with scene", ["run", "bar_elastic_1d", "--resume", base / "full"])
add("--resume with --set", ["run", "--resume", base / "full", "--set", "grid.cells=3"])
add("run without scene", ["run"])
add("stability bad layout", ["stability", "--layout", "a,b"]); add("stability layout >1", ["stability", "--layout", "1.5"])
add("converge bad cells", ["converge", "standing_wave_2d", "--cells", "x", "--out", base / "c"])
add("converge bad method", ["converge", "standing_wave_2d", "--methods", "nope", "--out", base / "c2"])
rows = {"one-line exit 2": [], "traceback": [], "accepted (exit 0)": [], "health stop (exit 3)": [], "other": []}
for label, argv in cases:
    err = io.StringIO(); out = io.StringIO()
    try:
        with contextlib.redirect_stderr(err), contextlib.redirect_stdout(out), warnings.catch_warnings():
            warnings.simplefilter("ignore")
            rc = main([str(a) for a in argv])
    except BaseException as exc:
        rows["traceback"].append((label, f"{type(exc).__name__}: {exc}"[:150])); continue
    e = "\n".join(l for l in err.getvalue().splitlines() if not l.startswith("warning:"))
    if rc == 2 and e.count("\n") == 0 and e.startswith("error: ") and "Traceback" not in e:
        rows["one-line exit 2"].append((label, e[:160]))
    elif "Traceback" in e: rows["traceback"].append((label, e[-150:]))
    elif rc == 0: rows["accepted (exit 0)"].append((label, out.getvalue().splitlines()[0][:120] if out.getvalue() else ""))
    elif rc == 3: rows["health stop (exit 3)"].append((label, e[:150]))
    else: rows["other"].append((label, f"rc={rc} {e[:150]!r}"))
    import shutil
    for o in ("o", "o2"): shutil.rmtree(base / o, ignore_errors=True)
print("tried", len(cases))
for k, v in rows.items():
    print(f"== {k}: {len(v)}")
    for label, msg in v: print(f"  {label:<40} {msg}")
