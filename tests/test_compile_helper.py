"""A first run's second process (`skdgmpm.compile_helper`): it compiles a scene's step up to its law's
pass (DGMPM's face passes) while the run compiles that law's pass, and the run loads them from its
cache instead of compiling them; only functions the cache lacks are copied into it, each whole."""
import os
import subprocess
import sys

import meshio
import numpy as np
import pytest

from skdgmpm import compile_helper, first_run
from skdgmpm.run import run
from skdgmpm.scene import load_scene
from test_cache_folders import waits_for_lock


def write(path, text):
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_bytes(text)


def test_merge_copies_the_functions_the_cache_lacks_and_keeps_its_own(tmp_path):
    source, target = tmp_path / "helper" / "kernels-x", tmp_path / "mine" / "kernels-x"
    write(source / "skdgmpm" / "m.f-10.py311.nbi", b"index f")
    write(source / "skdgmpm" / "m.f-10.py311.1.nbc", b"f 1")
    write(source / "skdgmpm" / "m.f-10.py311.2.nbc", b"f 2")
    write(source / "skdgmpm" / "m.f-100.py311.1.nbc", b"another function's")       # not f's data
    write(source / "skdgmpm.materials" / "law.g-5.py311.nbi", b"index g")
    write(source / "skdgmpm.materials" / "law.g-5.py311.1.nbc", b"g 1 (helper)")
    write(target / "skdgmpm.materials" / "law.g-5.py311.nbi", b"my index g")
    write(target / "skdgmpm.materials" / "law.g-5.py311.1.nbc", b"g 1 (mine)")
    write(tmp_path / "elsewhere" / "m.h-7.py311.nbi", b"index h")       # a link of `mirror`'s: not copied
    (source / "skdgmpm" / "m.h-7.py311.nbi").symlink_to(tmp_path / "elsewhere" / "m.h-7.py311.nbi")
    copied = compile_helper.merge(str(source), str(target))
    assert copied == [str(target / "skdgmpm" / "m.f-10.py311.nbi")]
    assert sorted(os.listdir(target / "skdgmpm")) == ["m.f-10.py311.1.nbc", "m.f-10.py311.2.nbc", "m.f-10.py311.nbi"]
    for name in os.listdir(target / "skdgmpm"):
        assert (target / "skdgmpm" / name).read_bytes() == (source / "skdgmpm" / name).read_bytes()
    assert (target / "skdgmpm.materials" / "law.g-5.py311.nbi").read_bytes() == b"my index g"
    assert (target / "skdgmpm.materials" / "law.g-5.py311.1.nbc").read_bytes() == b"g 1 (mine)"
    assert compile_helper.merge(str(source), str(target)) == []               # nothing left to copy


def test_every_method_on_two_cores_takes_a_helper(monkeypatch):
    """Every method's run compiles the step's law pass in its own process (its initial state's,
    or `compile_law_pass` beside the helper for DGMPM with several particles in a cell) and the
    rest in the helper's; not on one core, nor with $SKDGMPM_COMPILE_HELPER=0."""
    monkeypatch.setenv(compile_helper.ENV, "1")
    monkeypatch.setattr(os, "sched_getaffinity", lambda pid: {0, 1})
    bar = load_scene("bar_elastic_1d")
    for taken in ([], ["particles.per_cell=2"], ["method.integrator=rk2"], ["method.name=ader-dgmpm", "particles.per_cell=2"],
                  ["method.name=ader-dgfem"], ["method.name=rk-dgfem", "method.integrator=rk2"], ["method.name=mpm"]):
        assert compile_helper.wanted(bar.with_overrides(taken) if taken else bar), taken
    assert compile_helper.wanted(load_scene("standing_wave_2d"))
    monkeypatch.setattr(os, "sched_getaffinity", lambda pid: {0})
    assert not compile_helper.wanted(bar)
    monkeypatch.setattr(os, "sched_getaffinity", lambda pid: {0, 1})
    monkeypatch.setenv(compile_helper.ENV, "0")
    assert not compile_helper.wanted(bar)


@pytest.mark.parametrize("scene, overrides", [("standing_wave_2d", ["grid.cells=[4, 4]"]),
                                              ("bar_elastic_1d", ["particles.per_cell=2", "grid.cells=8"]),
                                              ("bar_elastic_1d", ["grid.cells=8"])],
                         ids=["nodal-2d", "nodal-1d", "one-per-cell"])
def test_the_initial_state_takes_the_steps_law_kernel_as_the_step_does(scene, overrides, monkeypatch):
    """The initial state's law pass is the step's (`DGMPM.at_rest`): the same kernel, its
    arguments of the same numba types as the step's, so that the run compiles it for t = 0 while
    its helper compiles the rest of the step, and t = 0 compiles nothing else. With several
    particles in a cell the pass forms each point's U from nodal values: given U, through the
    identity's rows, into a scratch U; the state's U is the one given, bit for bit."""
    import numba

    from skdgmpm import parallel
    from skdgmpm.build import build

    calls, chunked = [], parallel.chunked

    def spy(n, kernel, spec, args, *rest, **kwargs):
        if kernel.__name__ in ("states", "stresses", "assess"):         # the law passes
            calls.append((kernel, numba.typeof(args), args))
        return chunked(n, kernel, spec, args, *rest, **kwargs)

    monkeypatch.setattr(parallel, "chunked", spy)
    disc = build(load_scene(scene).with_overrides(overrides))
    state = disc.initial
    assert [kernel.__name__ for kernel, *_ in calls] == ["states"]      # no stand-alone pass at t = 0
    written, gather = calls[0][2][3], calls[0][2][10]
    if not disc.stepper.cellwise:           # U formed from "nodal" values: the given U, into a scratch
        assert written is not state.U and gather[-1] is state.U and np.array_equal(written, state.U)
    disc.stepper.step(state)
    assert len(calls) == 2 and calls[1][:2] == calls[0][:2]


def face_passes(lines, verb):
    """The face passes' kernels named in numba's cache log lines ``[cache] data <verb> ...``."""
    return {kernel for line in lines if line.startswith(f"[cache] data {verb}")
            for kernel in ("interior_pass", "boundary_faces", "boundary_terms") if f"_{kernel}." in line}


@pytest.mark.skipif(len(getattr(os, "sched_getaffinity", lambda pid: {0})(0)) < 2, reason="one core")
@pytest.mark.parametrize("overrides", [[], ["particles.per_cell=2", "method.cfl=0.5"]], ids=["one-helper", "two-helpers-nodes"])
def test_a_cold_first_run_loads_the_face_passes_its_helper_compiled(overrides, tmp_path):
    """A first run on an empty cache: its own process saves the law's pass and loads the face
    passes (numba's cache log, which the helpers' processes do not write here), and its answers
    are those of this process's kernels, compiled alone, bit for bit (the same code compiled).
    With two particles a cell two helpers share the face passes (`shares`)."""
    (tmp_path / "tmp").mkdir()
    env = {k: v for k, v in os.environ.items() if k != compile_helper.ENV}      # as a user's run: `shares`
    env.update({"NUMBA_CACHE_DIR": str(tmp_path / "cache"), "NUMBA_DEBUG_CACHE": "1", "TMPDIR": str(tmp_path / "tmp")})
    scene = load_scene("bar_elastic_1d").with_overrides(overrides) if overrides else load_scene("bar_elastic_1d")
    assert len(compile_helper.shares(scene)) == (2 if overrides else 1)
    sets = [a for o in overrides for a in ("--set", o)]
    done = subprocess.run([sys.executable, "-m", "skdgmpm.cli", "run", "bar_elastic_1d", "--out", str(tmp_path / "out"),
                           "--quiet", *sets], env=env, cwd=tmp_path, capture_output=True, text=True, timeout=600)
    assert done.returncode == 0, done.stderr[-3000:]
    lines = done.stdout.splitlines() + done.stderr.splitlines()
    assert face_passes(lines, "loaded") == {"interior_pass", "boundary_faces", "boundary_terms"}
    assert face_passes(lines, "saved") == set()
    assert any(line.startswith("[cache] data saved") and "_states." in line for line in lines)
    kind = "dgmpm on the nodes" if overrides else "dgmpm"          # its own estimate, and its own measured time
    about = first_run.EXPECTED_S[kind][1]
    assert done.stderr.count(f"{first_run.NOTICE}{kind}, 1D (first run, about {about} s, on two cores; cached") == 1
    assert os.listdir(tmp_path / "tmp") == []                  # the helper's folder removed

    alone = run(scene, out=tmp_path / "alone", progress=False)
    assert alone.status == "ok"
    last = sorted((tmp_path / "out").glob("particles_*.vtu"))[-1]
    here, there = meshio.read(tmp_path / "alone" / last.name), meshio.read(last)
    assert set(here.point_data) == set(there.point_data)
    for name, values in here.point_data.items():
        assert np.array_equal(values.view(np.uint8), there.point_data[name].view(np.uint8)), name


def test_a_dgmpm_step_on_the_nodes_is_shared_by_two_helpers(monkeypatch):
    """DGMPM on the grid's nodes (several particles a cell, RK2, the "nodes" layout) compiles its
    face passes' trace path: two helpers share its step; every other step takes one, as does any
    run with $SKDGMPM_COMPILE_HELPER=1; a run's helpers are one per share."""
    monkeypatch.delenv(compile_helper.ENV, raising=False)
    monkeypatch.setattr(os, "sched_getaffinity", lambda pid: {0, 1})
    bar = load_scene("bar_elastic_1d")
    for taken, shares in (([], ("step",)), (["particles.per_cell=2"], ("interior", "boundary")),
                          (["particles.per_cell=[0.5]"], ("step",)), (["particles.per_cell=[0.25, 0.75]"], ("interior", "boundary")),
                          (["method.integrator=rk2"], ("interior", "boundary")), (["method.layout=nodes"], ("interior", "boundary")),
                          (["method.name=ader-dgmpm", "particles.per_cell=2"], ("step",)), (["method.name=mpm"], ("step",))):
        scene = bar.with_overrides(taken) if taken else bar
        assert compile_helper.shares(scene) == shares, taken
        assert compile_helper.nodal(scene) == (shares == ("interior", "boundary")), taken
    wave = load_scene("standing_wave_2d")
    assert compile_helper.shares(wave) == ("interior", "boundary")
    assert [h.share for h in compile_helper.CompileHelpers(wave).helpers] == ["interior", "boundary"]
    monkeypatch.setenv(compile_helper.ENV, "1")
    assert compile_helper.shares(wave) == ("step",)
    monkeypatch.delenv(compile_helper.ENV)
    nodal = bar.with_overrides(["particles.per_cell=2"])          # two set-ups beside the run's: half the limit
    assert compile_helper.shares(nodal.with_overrides([f"grid.cells={compile_helper.MAX_POINTS // 4}"])) == (
        "interior", "boundary")
    assert compile_helper.shares(nodal.with_overrides([f"grid.cells={compile_helper.MAX_POINTS // 4 + 1}"])) == ("step",)
    assert compile_helper.wanted(nodal.with_overrides([f"grid.cells={compile_helper.MAX_POINTS // 4 + 1}"]))


@pytest.fixture
def put_back(monkeypatch):
    """Every class attribute and module name that `compile_step` may replace, of any share, put
    back after the test: a placeholder left behind runs in every later test (one did: 30 CTU
    tests failed after it)."""
    from skdgmpm import dgmpm, riemann
    from skdgmpm.constitutive import MaterialSet
    from skdgmpm.dgfem import DGFEM
    from skdgmpm.mpm import MPM
    from skdgmpm.scheme import GodunovScheme

    for owner, name in ((GodunovScheme, "at_rest"), (GodunovScheme, "check"), (GodunovScheme, "constitutive_update"),
                        (MaterialSet, "stress_update"), (DGFEM, "evaluate_points"), (MPM, "strain_stress"),
                        (riemann, "_not_hyperbolic"),
                        (dgmpm.DGMPM, "nodal_state"),
                        *((dgmpm, name) for name in ("cell_records", "interior_pass", "cell_corrections",
                                                     "boundary_faces", "boundary_terms"))):
        monkeypatch.setattr(owner, name, getattr(owner, name))


@pytest.mark.parametrize("scene, overrides", [("standing_wave_2d", ["grid.cells=[4, 4]"]),
                                              ("plate_impact_neohookean_2d", ["grid.cells=[8, 6]", "method.integrator=rk2"])],
                         ids=["nodes", "rk2"])
@pytest.mark.usefixtures("put_back")
def test_each_share_compiles_its_own_face_passes_and_steps_past_the_others(scene, overrides, monkeypatch):
    """`compile_step` of each share in this process (what it patches put back afterwards): the
    "boundary" helper calls the record pass and the boundary faces' pass, then the boundary's
    terms, and ends with the step's first stage (RK2: before its law at the nodes), the interior
    faces' pass a placeholder; the "interior" helper calls the interior faces' pass (in both of
    RK2's stages) and reaches the law's pass, the record and boundary faces' passes
    placeholders."""
    from skdgmpm import dgmpm

    passes = ("cell_records", "interior_pass", "boundary_faces", "boundary_terms")
    stages = 2 if "method.integrator=rk2" in overrides else 1
    nodal_state, corrections = dgmpm.DGMPM.nodal_state, dgmpm.cell_corrections
    reals = {name: getattr(dgmpm, name) for name in passes}
    for share, expected in (("boundary", {"cell_records": 1, "boundary_faces": 1, "boundary_terms": True}),
                            ("interior", {"interior_pass": stages, "boundary_terms": True})):
        calls = []
        monkeypatch.setattr(dgmpm.DGMPM, "nodal_state", nodal_state)        # as the other share's process has them
        monkeypatch.setattr(dgmpm, "cell_corrections", corrections)
        for name, real in reals.items():
            monkeypatch.setattr(dgmpm, name, lambda *a, real=real, name=name: calls.append(name) or real(*a))
        assert compile_helper.compile_step(load_scene(scene).with_overrides(overrides), False, share)
        called = {name: calls.count(name) for name in set(calls)}
        if "boundary_terms" in called:                  # the boundary's terms after it: called, how often aside
            called["boundary_terms"] = True
        assert called == expected, share


def test_a_scene_too_large_for_two_set_ups_compiles_alone(monkeypatch):
    """The helper builds the whole scene too: above `MAX_POINTS` particles (or a mesh file above
    `MAX_MESH_BYTES`) the run compiles in its own process, its memory not doubled."""
    monkeypatch.setenv(compile_helper.ENV, "1")
    monkeypatch.setattr(os, "sched_getaffinity", lambda pid: {0, 1})
    plate = load_scene("plate_impact_neohookean_2d")
    assert compile_helper.wanted(plate.with_overrides(["grid.cells=[1024, 1024]"]))
    assert not compile_helper.wanted(plate.with_overrides(["grid.cells=[1024, 1025]"]))
    ader = plate.with_overrides(["method.name=ader-dgfem"])               # a P1 cell: 8 particles' bytes
    assert compile_helper.wanted(ader.with_overrides(["grid.cells=[256, 512]"]))
    assert not compile_helper.wanted(ader.with_overrides(["grid.cells=[512, 512]"]))
    assert not compile_helper.wanted(ader.with_overrides(["grid.cells=[256, 256]", "method.order=3"]))
    assert compile_helper.wanted(ader.with_overrides(["grid.cells=[128, 128]", "method.order=3"]))
    partial = load_scene("partial_impact_2d")                 # a gmsh file
    assert compile_helper.wanted(partial)
    monkeypatch.setattr(compile_helper, "MAX_MESH_BYTES", 1000)
    assert not compile_helper.wanted(partial)


def test_a_helper_closed_before_it_started_starts_nothing(tmp_path, monkeypatch):
    """A run closes its helper before its steps: a compilation in a step (a first chunk loop on a
    larger grid) must not start a process that nothing would wait for or remove."""
    started = []
    monkeypatch.setattr(compile_helper.subprocess, "Popen", lambda *a, **k: started.append(a))
    helper = compile_helper.CompileHelper(load_scene("bar_elastic_1d"))
    assert helper.join() == [] and helper.waited == 0.0
    helper.close()
    assert not helper.start()
    assert started == [] and helper.process is None and helper.folder is None


def test_the_mirror_is_read_only_to_numbas_writes(tmp_path):
    """The helper starts from links to the run's cache: numba writes an index or data file by
    renaming a new file onto its path (`numba.core.caching`), which replaces the link alone."""
    mine, theirs = tmp_path / "mine", tmp_path / "theirs"
    write(mine / "skdgmpm" / "m.f-10.py311.nbi", b"my index")
    write(mine / "skdgmpm" / "m.f-10.py311.1.nbc", b"my data")
    write(mine / "skdgmpm" / "notes.txt", b"not numba's")
    compile_helper.mirror(str(mine), str(theirs))
    assert sorted(os.listdir(theirs / "skdgmpm")) == ["m.f-10.py311.1.nbc", "m.f-10.py311.nbi"]
    assert (theirs / "skdgmpm" / "m.f-10.py311.nbi").is_symlink()
    assert (theirs / "skdgmpm" / "m.f-10.py311.nbi").read_bytes() == b"my index"
    write(theirs / "skdgmpm" / "new", b"their index")
    os.replace(theirs / "skdgmpm" / "new", theirs / "skdgmpm" / "m.f-10.py311.nbi")
    assert (mine / "skdgmpm" / "m.f-10.py311.nbi").read_bytes() == b"my index"
    assert compile_helper.merge(str(theirs), str(mine)) == []           # the run has that function


@pytest.mark.parametrize("method", [[], ["method.name=ader-dgmpm", "particles.per_cell=2"], ["method.name=ader-dgfem"],
                                    ["method.name=rk-dgfem", "method.integrator=rk2"], ["method.name=mpm"]],
                         ids=["dgmpm", "ader-dgmpm", "ader-dgfem", "rk-dgfem", "mpm"])
def test_on_a_cache_that_holds_the_step_the_helper_compiles_nothing(method, monkeypatch):
    """Every method's helper steps its placeholder state up to the step's law pass (its exit
    status 0 says it got there), and where the run's cache holds the step (the scene ran) it
    loads every kernel through its mirror: it compiles no function and copies none."""
    monkeypatch.setenv(compile_helper.ENV, "1")
    scene = load_scene("bar_elastic_1d").with_overrides(method) if method else load_scene("bar_elastic_1d")
    assert run(scene, max_steps=1, progress=False).status in ("ok", "stopped")    # the cache holds its step
    helper = compile_helper.CompileHelper(scene)
    try:
        helper.start()
        assert helper.process is not None
        helper.join()
    finally:
        helper.close()
    assert helper.code == 0 and helper.compiled == [] and helper.merged == []


def test_two_merges_into_one_cache_never_interleave(tmp_path):
    """Runs side by side: a merge waits while another holds the cache folder's lock."""
    source, target = tmp_path / "helper" / "kernels-x", tmp_path / "mine" / "kernels-x"
    write(source / "skdgmpm" / "m.f-10.py311.nbi", b"index f")
    write(source / "skdgmpm" / "m.f-10.py311.1.nbc", b"f 1")
    copied = []
    waits_for_lock(target, lambda: copied.extend(compile_helper.merge(str(source), str(target))),
                   target / "skdgmpm")
    assert copied == [str(target / "skdgmpm" / "m.f-10.py311.nbi")]


@pytest.mark.parametrize("resumed", [False, True])
@pytest.mark.usefixtures("put_back")
def test_the_placeholder_step_reaches_the_law_pass_and_a_resumed_one_makes_the_records(resumed, monkeypatch):
    """`compile_step` in this process (the classes it patches put back afterwards): the step
    reaches the law's pass; as a resumed run's first step, whose state is not the initial one,
    it calls the record pass (`cell_records`) that such a step calls, and otherwise not (the
    initial state's law pass wrote the records)."""
    from skdgmpm import dgmpm

    calls, records = [], dgmpm.cell_records
    monkeypatch.setattr(dgmpm, "cell_records", lambda *a: calls.append(1) or records(*a))
    assert compile_helper.compile_step(load_scene("plate_impact_neohookean_2d").with_overrides(["grid.cells=[8, 6]"]),
                                       resumed)
    assert calls == ([1] if resumed else [])
