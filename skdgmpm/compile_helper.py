"""A first run's kernels compiled on two cores: while this process compiles the step's law pass
(for its initial state: `GodunovScheme.at_rest`, MPM's stress pass), a second process
compiles the rest of the step (DGMPM's face passes, ADER's predictor and fluxes, MPM's transfers),
which this one then loads from the cache instead of compiling it (numba compiles under one lock a
process: two processes are the only way to use a second core).

The second process (``python -m skdgmpm.compile_helper SCENE.json``) builds the same scene and
steps it once on a placeholder state (no law evaluated, nothing checked), stopping where the
step's law pass would begin (`compile_step`): every kernel the step calls before it is compiled,
with the argument types the real step gives them. It files them in a cache folder of its own (a
temporary $NUMBA_CACHE_DIR: two processes never write one index file), and this one copies the
functions its own cache lacks into it before its first step (`CompileHelper.join`); a function
both compiled keeps this process's files. The helper's folder starts as links to this process's
cache (`mirror`): it loads what that holds and compiles only what it lacks. A helper that fails,
or is not done within `CompileHelper.TIMEOUT_S`, costs nothing but its time: this process
compiles what it lacks.

A DGMPM step on the grid's nodes (any layout but one particle per cell with forward Euler) takes
its face passes' trace path, whose kernels are the longest to compile (13-19 s each in 2D): two
helpers share that step (`shares`), one compiling the cell records' and the boundary faces'
kernels, the other the rest, each stepping past the other's kernels on placeholders.

Started on this process's first compilation of one of the package's kernels in a run
(`skdgmpm.first_run.compile_notice`), where `wanted`. On a cache that holds the rest of the
step already (another scene of the same kind ran, with a new law), the helper loads it and is
done in its start-up, while this process compiles its law's pass. No compiled code here: this
module is not part of the kernels' cache key.
"""
import itertools
import json
import os
import shutil
import subprocess
import sys
import tempfile
import time

import numpy as np

from .cache_folders import locked

ENV = "SKDGMPM_COMPILE_HELPER"  # "0": no helper; "1": one; unset (or any other value): as `shares` says
MAX_POINTS = 2 ** 20            # a larger scene compiles alone: the helper's set-up would double its memory
MAX_MESH_BYTES = 64 * 2 ** 20   # the same for a mesh file, by its size (its cells unknown before it is read)
# a DG cell of order P holds about 8 ((P + 1) / 2)^d times a particle's bytes (the bench at 256²:
# ADER-DGFEM P1 10.5 kB a cell, DGMPM 1.3 kB a particle): its limits that much lower
DG_METHODS = ("ader-dgmpm", "ader-dgfem", "rk-dgfem")


def wanted(scene):
    """Whether a run of ``scene`` should start a helper on its first compilation: every method's
    run compiles the step's law pass itself (for its initial state); where the scene has
    `MAX_POINTS` particles or fewer (a mesh or particle file of `MAX_MESH_BYTES` or less; DG cells
    counted by their bytes, `DG_METHODS`), two cores are free to this process and
    $SKDGMPM_COMPILE_HELPER is not 0."""
    if os.environ.get(ENV, "1") == "0":
        return False
    try:
        cores = len(os.sched_getaffinity(0))
    except AttributeError:
        cores = os.cpu_count() or 1
    return cores >= 2 and _small(scene)


def shares(scene):
    """What each helper of a run of ``scene`` compiles (`compile_step`): ("step",), the whole
    step up to its law's pass; or, for a DGMPM step on the grid's nodes as the scene asks it (its
    face passes' trace path: `DGMPM.trace_path`), ("interior", "boundary"): the cell records' and
    the boundary faces' kernels in the second, the rest in the first, which the two helpers then
    compile side by side ($SKDGMPM_COMPILE_HELPER=1: one helper always; nor above half the
    limits of `wanted`: each helper builds the whole scene). A scene read wrong here (a particle
    file of one particle per cell) costs only the balance: each helper builds the scene and
    compiles what its step calls."""
    if os.environ.get(ENV) == "1" or not nodal(scene) or not _small(scene, 2):
        return ("step",)
    return ("interior", "boundary")


def nodal(scene):
    """Whether ``scene`` asks for a DGMPM step on the grid's nodes (`DGMPM.trace_path`: any
    layout but one particle a cell with forward Euler), read from its keys before it is built: a
    `particles.per_cell` other than one a direction, a particle file, `method.integrator` other
    than euler, or `method.layout = "nodes"`."""
    if scene.get("method.name", "dgmpm") != "dgmpm":
        return False
    return (per_axis(scene) != 1 or scene.get("particles.file") is not None
            or scene.get("method.integrator", "euler") != "euler" or scene.get("method.layout", "auto") == "nodes")


def per_axis(scene):
    """Particles per cell and direction as `particles.per_cell` gives them (a count, or a list of
    positions), unchecked: the build says what is wrong."""
    per_cell = scene.get("particles.per_cell", 1)
    return len(per_cell) if isinstance(per_cell, list) else per_cell


def _small(scene, helpers=1):
    """Whether ``helpers`` set-ups of ``scene`` beside the run's stay within `MAX_POINTS` and
    `MAX_MESH_BYTES` (each counted once per helper)."""
    try:
        d, order = scene.dim, int(scene.get("method.order", 1))
        dg = scene.get("method.name", "dgmpm") in DG_METHODS
        scale = 8 * ((order + 1) / 2) ** d if dg else 1.0
        files = [scene.get(key) for key in ("grid.mesh", "particles.file") if scene.get(key) is not None]
        if files:
            return all(os.path.getsize(scene.resolve(f)) * scale * helpers <= MAX_MESH_BYTES for f in files)
        # a DG scene: its cells' bytes (ADER-DGMPM's particles are fewer), else its particles'
        points = 1 if dg else int(per_axis(scene)) ** d
        return float(np.prod(np.asarray(scene.get("grid.cells"), dtype=float))) * points * scale * helpers <= MAX_POINTS
    except (OSError, TypeError, ValueError):    # the build says what is wrong
        return False


class CompileHelper:
    """The second process of one run: `start` (idempotent), `join` before the first step, `close`
    in every case (kills it if still running, removes its folder; a `start` after it starts
    nothing: a compilation later in the run, in its steps, has no first step left to help)."""

    TIMEOUT_S = 300

    def __init__(self, scene, resumed=False, share="step"):
        self.scene, self.resumed, self.share = scene, resumed, share
        self.process, self.folder, self.closed = None, None, False
        self.code = None                # its exit status: 0 where its step reached the law's pass
        self.waited = 0.0               # seconds `join` waited for it
        self.compiled = []              # the index files it wrote (the functions it compiled)
        self.merged = []                # those copied into this process's cache

    @property
    def running(self):
        """Whether it was started and not yet joined or closed."""
        return self.process is not None

    def start(self):
        """Start the helper (once, and not after `close`); whether it runs."""
        if self.process is not None or self.closed:
            return self.process is not None
        from .kernel_cache import cache_dir
        try:
            os.makedirs(cache_dir(), exist_ok=True)
            self.folder = tempfile.mkdtemp(prefix="skdgmpm-helper-")
            mirror(cache_dir(), os.path.join(self.folder, "cache", os.path.basename(cache_dir())))
            spec = os.path.join(self.folder, "scene.json")
            with open(spec, "w") as f:
                json.dump({"name": self.scene.name, "data": self.scene.data, "resumed": self.resumed,
                           "share": self.share, "path": None if self.scene.path is None else str(self.scene.path)},
                          f)
            env = {**os.environ, "NUMBA_CACHE_DIR": os.path.join(self.folder, "cache"), ENV: "0"}
            self.process = subprocess.Popen([sys.executable, "-m", __name__, spec], env=env,
                                            stdin=subprocess.DEVNULL, stdout=subprocess.DEVNULL,
                                            stderr=subprocess.DEVNULL)
        except (OSError, TypeError, ValueError):       # no helper: this process compiles all
            self.close()
        return self.process is not None

    def join(self):
        """Wait for the helper (up to `TIMEOUT_S`), then copy its kernels that this process's
        cache lacks into it; the helper's folder is removed. Returns the index files copied."""
        if self.process is None:
            return []
        from .kernel_cache import cache_dir
        t0 = time.perf_counter()
        try:
            code = self.code = self.process.wait(timeout=self.TIMEOUT_S)
        except subprocess.TimeoutExpired:
            code = None
        self.waited = time.perf_counter() - t0
        if code is not None:            # ended on its own (whatever it reached): its files are whole
            target = cache_dir()
            source = os.path.join(self.folder, "cache", os.path.basename(target))
            self.compiled = sorted(os.path.relpath(os.path.join(folder, n), source)
                                   for folder, _, names in os.walk(source) for n in names
                                   if n.endswith(".nbi") and not os.path.islink(os.path.join(folder, n)))
            self.merged = merge(source, target)
        self.close()
        return self.merged

    def close(self):
        self.closed = True
        if self.process is not None and self.process.poll() is None:
            self.process.kill()
            self.process.wait()
        self.process = None
        if self.folder is not None:
            shutil.rmtree(self.folder, ignore_errors=True)
            self.folder = None


class CompileHelpers:
    """A run's helpers, one per share of its step (`shares`), started, joined and closed together
    (each as `CompileHelper`). ``waited``: the seconds the run waited for them all."""

    def __init__(self, scene, resumed=False):
        self.helpers = [CompileHelper(scene, resumed, share) for share in shares(scene)]

    @property
    def running(self):
        return any(h.running for h in self.helpers)

    @property
    def waited(self):
        return sum(h.waited for h in self.helpers)

    def start(self):
        """Start every helper; whether one runs."""
        return [h.start() for h in self.helpers].count(True) > 0

    def join(self):
        """Join each in turn (`CompileHelper.join`); the index files copied from them all."""
        return [name for h in self.helpers for name in h.join()]

    def close(self):
        for h in self.helpers:
            h.close()


def mirror(source, target):
    """``target``: the cache folder ``source`` as it is now, each of its files a symbolic link,
    for the helper to load what the run's cache holds (it compiles only what that lacks, and
    then is soon done). numba writes an index or data file by renaming a new file onto its
    path, which replaces a link, never the file it points to: ``source`` is only read."""
    for folder, _, names in os.walk(source):
        into = os.path.join(target, os.path.relpath(folder, source))
        os.makedirs(into, exist_ok=True)
        for name in names:
            if name.endswith((".nbi", ".nbc")):
                os.symlink(os.path.join(folder, name), os.path.join(into, name))


def merge(source, target):
    """Copy each compiled function of the cache folder ``source`` (its index file ``*.nbi`` and
    data files ``*.<n>.nbc``, in the package folders below it) into ``target`` where ``target``
    has no index of that function; the data first, each file under a temporary name then renamed,
    so that a reader never sees an index without its data; under ``target``'s lock
    (`cache_folders.locked`, which numba's saves into it hold too), so that a merge never
    interleaves with another run's merge or compilation (a copy of one helper's data under
    another's index would pair a key with another signature's code). Returns the index files
    copied."""
    with locked(target):
        return _merge(source, target)


def _merge(source, target):
    copied = []
    for folder, _, names in os.walk(source):
        into = os.path.join(target, os.path.relpath(folder, source))
        for index in sorted(n for n in names if n.endswith(".nbi")):
            if os.path.islink(os.path.join(folder, index)) or os.path.exists(os.path.join(into, index)):
                continue                # this process's own (`mirror`), or it compiled that function too
            stem = index[:-len(".nbi")]
            data = [n for n in names if n.startswith(stem + ".") and n.endswith(".nbc")]
            try:
                os.makedirs(into, exist_ok=True)
                for name in data + [index]:
                    part = os.path.join(into, f".{name}.{os.getpid()}.part")
                    shutil.copyfile(os.path.join(folder, name), part)
                    os.replace(part, os.path.join(into, name))
            except OSError:
                continue
            copied.append(os.path.join(into, index))
    return copied


class _LawPass(Exception):
    """Raised where the placeholder step reaches the law's pass: the helper's work ends there."""


def compile_step(scene, resumed=False, share="step"):
    """Build ``scene`` and step it once on a placeholder initial state, up to the law's pass: the
    kernels of what comes before it compiled (and cached) with the real step's argument types.
    ``share`` (`shares`): "step", all of them; "boundary", DGMPM's cell records, boundary faces
    and the rest of the first stage (the interior faces' passes skipped, their outputs
    placeholders, `_split_faces`); "interior", all but the records and the boundary faces.
    ``resumed``: as a resumed run's first step, whose state is not the initial one (DGMPM's face
    passes then read cell records made for it, `cell_records`, not those of the initial state).
    For the helper process only: it replaces the schemes' law pass at rest (and MPM's stress
    pass), their checks and the step's law pass (`GodunovScheme.constitutive_update`,
    `DGFEM.evaluate_points`, `MPM.strain_stress`). Returns whether the step reached the law's
    pass."""
    from . import dgmpm, riemann
    from .build import build
    from .constitutive import MaterialSet
    from .dgfem import DGFEM
    from .mpm import MPM
    from .scheme import GodunovScheme

    # placeholder numbers: finite, none zero (a compiled division by zero raises and would end
    # the step before its later passes compile); U is the scene's own
    fill = np.random.default_rng(0).uniform

    def at_rest(self, state, points, *args, **kwargs):
        return fill(0.5, 1.5, state.U.shape), state.history, None

    def stress_update(self, F, index, history, assess=False):      # MPM's initial state's
        return (fill(0.5, 1.5, F.shape), history) + ((None,) if assess else ())

    def check(self, state, health=None):
        state.speed, state.fastest, state.health = np.ones(len(state.U)), 1.0, {}

    def law_pass(self, *args, **kwargs):
        raise _LawPass

    GodunovScheme.at_rest, MaterialSet.stress_update, GodunovScheme.check = at_rest, stress_update, check
    GodunovScheme.constitutive_update = DGFEM.evaluate_points = MPM.strain_stress = law_pass
    riemann._not_hyperbolic = lambda face: None      # placeholder states need not be hyperbolic (every face pass)
    if share != "step":
        _split_faces(dgmpm, share, fill)
    disc = build(scene)
    for records in getattr(disc.stepper, "_record_arrays", ((),))[0]:    # DGMPM's cell records
        records[...] = fill(0.5, 1.5, records.shape)
    if resumed and hasattr(disc.stepper, "_records_of"):
        disc.stepper._records_of = None
    try:
        disc.stepper.step(disc.initial)
    except _LawPass:
        return True
    return False


def _split_faces(dgmpm, share, fill):
    """The face passes of DGMPM's step (names in `skdgmpm.dgmpm`) that the helper of ``share``
    leaves to the other (`shares`) replaced by placeholders that fill their outputs (the last of
    their arguments) with ``fill``'s numbers and report no failure. "boundary" goes on after the
    boundary faces to the end of the step's first stage (the law's pass, or RK2's law at the
    nodes, which the other compiles): the Euler stage of the cells' records as they come (for a
    placeholder state, not all recorded: the corrections gathered on the edges) compiled too."""
    from . import parallel

    def placeholder(outputs, returns=None):
        def skipped(*args):
            for a in args[len(args) - outputs:]:
                a[...] = fill(0.5, 1.5, a.shape)
            return returns
        return skipped

    def placeholder_pass(outputs):      # a face pass described (`parallel.Pass`): one chunk, in Python
        return lambda *args: parallel.Pass(1, placeholder(outputs, -1), "w" * len(args), args, "first")

    if share == "boundary":
        def stop(*args, **kwargs):
            raise _LawPass

        # interior_pass(..., flux, G); cell_corrections(..., W, corr_bnd): W is G, in place
        dgmpm.interior_pass, dgmpm.cell_corrections = placeholder_pass(2), placeholder(1)
        dgmpm.DGMPM.nodal_state = stop
    elif share == "interior":
        # cell_records(..., rec, state): the records as the helper filled them (`compile_step`),
        # every cell recorded in the first call (the CTU corrections as the cells send them: the
        # nodes of a cell equal, a body at rest or one particle a cell), none in the others (as
        # the edges gather them: RK2's second stage); boundary_faces(..., flux, t_s, v_s, parts)
        calls = itertools.count()
        dgmpm.cell_records = lambda *args: args[-1].fill(1 if next(calls) == 0 else 0)
        dgmpm.boundary_faces = placeholder_pass(4)
    else:
        raise ValueError(f"compile helper: share {share!r} unknown")


def main(argv=None):
    argv = sys.argv[1:] if argv is None else argv
    with open(argv[0]) as f:
        spec = json.load(f)
    from pathlib import Path

    from .scene import Scene
    scene = Scene.from_dict(spec["data"], spec["name"], None if spec["path"] is None else Path(spec["path"]))
    sys.exit(0 if compile_step(scene, spec.get("resumed", False), spec.get("share", "step")) else 1)


if __name__ == "__main__":
    main()
