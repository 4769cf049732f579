"""The compiled kernels' disk cache (`skdgmpm.kernel_cache`): keyed on every source file of the
package that compiles code, so that an edit of a file whose functions a kernel inlines
(materials/*.py, riemann.py) compiles afresh while an edit of a Python-only file (cli.py) does not, and the same for every environment that installs the same sources; importing
the package changes no global setting (numba's SLP vectoriser is on while the package's own kernels
compile, for them only); the first run says when it compiles."""
import json
import os
import re
import shutil
import subprocess
import sys
from pathlib import Path

import numba
import numpy as np
import pytest

import skdgmpm
from skdgmpm import first_run, kernel_cache


def python(code, cwd, pythonpath=None, cache=None):
    """stdout (JSON) and stderr of ``code`` run by a fresh interpreter."""
    env = {k: v for k, v in os.environ.items() if k != "PYTHONPATH"}
    env.update({"PYTHONPATH": str(pythonpath)} if pythonpath else {})
    env.update({"NUMBA_CACHE_DIR": str(cache)} if cache else {})
    out = subprocess.run([sys.executable, "-c", code], cwd=cwd, env=env, capture_output=True, text=True)
    assert out.returncode == 0, out.stderr
    return json.loads(out.stdout.strip().splitlines()[-1]), out.stderr


def installed_copy(root):
    """The package laid out as ``pip install .`` lays it out (subpackages inside), under ``root``."""
    site = root / "site"
    for folder, name in kernel_cache.package_folders().items():
        target = site.joinpath(*name.split("."))
        shutil.copytree(folder, target, ignore=shutil.ignore_patterns("__pycache__"))
    return site


DIGEST = ("import json, skdgmpm.kernel_cache as k; "
          "print(json.dumps([k.source_digest(), k.cache_dir(), sorted(k.package_folders().values())]))")


def test_import_sets_nothing_global_and_keeps_the_repository_off_the_package_path(tmp_path):
    code = ("import importlib.util, json, numba, sys; before = numba.config.CACHE_DIR; import skdgmpm; "
            "materials = importlib.util.find_spec('skdgmpm.materials').submodule_search_locations; "
            "print(json.dumps([numba.config.CACHE_DIR == before, skdgmpm.__path__, list(materials), "
            "sorted(m for m in sys.modules if m.startswith('skdgmpm'))]))")
    (same, path, materials, modules), _ = python(code, cwd=tmp_path)
    assert same and path == [str(Path(skdgmpm.__file__).parent)]
    assert len(materials) == 1 and Path(materials[0]).name == "materials"
    # no kernel module imported, nothing compiled; `_uids` only moves the start of numba's function
    # numbering (symbol names: any numba code of the process, which it changes nothing else in);
    # `cache_folders` locks numba's saves into this package's kernel folders only
    assert modules == ["skdgmpm", "skdgmpm._uids", "skdgmpm.cache_folders", "skdgmpm.kernel_cache"]


def _axpy4():
    def axpy4(a, x, y, out):            # one point's four components: straight-line code
        for p in range(x.shape[0]):
            x0, x1, x2, x3 = x[p, 0], x[p, 1], x[p, 2], x[p, 3]
            y0, y1, y2, y3 = y[p, 0], y[p, 1], y[p, 2], y[p, 3]
            out[p, 0] = a * x0 + y0
            out[p, 1] = a * x1 + y1
            out[p, 2] = a * x2 + y2
            out[p, 3] = a * x3 + y3
    return axpy4


def _packed(fn):
    """Packed (SIMD) and scalar double multiplications and additions in fn compiled, counted in
    its optimised LLVM IR (``fmul <2 x double>`` against ``fmul double``): the same on every
    processor, where the assembly's names differ (AVX, SSE, NEON)."""
    k = numba.njit(fn)
    x = np.arange(12.0).reshape(3, 4)
    out = np.empty((3, 4))
    k(2.0, x, x, out)
    assert np.array_equal(out, 3 * x)
    ir = next(iter(k.inspect_llvm().values()))
    return (len(re.findall(r"= f(?:mul|add) (?:[a-z]+ )*<\d+ x double>", ir)),
            len(re.findall(r"= f(?:mul|add) (?:[a-z]+ )*double ", ir)))


def test_the_package_kernels_alone_compile_with_the_slp_vectoriser():
    """`kernel_cache.Vectorise`: a function of this package compiles with SLP vectorisation (its
    four components in SIMD registers), a function of another module as numba would compile it
    (SLP off by default), and the setting is numba's own again after each compilation."""
    before = numba.config.SLP_VECTORIZE
    other, ours = _axpy4(), _axpy4()
    ours.__module__ = "skdgmpm.probe"
    packed_other, scalar_other = _packed(other)
    packed_ours, scalar_ours = _packed(ours)
    assert numba.config.SLP_VECTORIZE == before
    if not before:
        assert packed_other == 0 and scalar_other > 0
    assert packed_ours > 0 and scalar_ours == 0


def test_kernels_are_filed_under_the_source_digest():
    from skdgmpm import system

    locator = system._embed(1)._cache._impl.locator
    assert isinstance(locator, kernel_cache.Locator)
    assert locator.get_cache_path() == os.path.join(kernel_cache.cache_dir(), "skdgmpm")
    assert Path(kernel_cache.cache_dir()).name == f"kernels-{kernel_cache.source_digest()}"
    assert locator.get_source_stamp() == kernel_cache.source_digest()
    assert kernel_cache.Locator.from_function(python, __file__) is None              # others: numba's own


def test_a_kernel_that_cannot_be_cached_gets_numbas_warning_naming_its_file():
    """numba warns, naming the kernel's file, when a compiled kernel cannot be cached (e.g. it
    calls numba.get_num_threads()); with this package's locator that warning had failed on the
    locator's missing file name. Here numba's own check is handed a result marked uncachable."""
    import types
    import warnings

    from skdgmpm import system

    impl = system._embed(1)._cache._impl
    lifted = types.SimpleNamespace(can_cache=False)
    result = types.SimpleNamespace(lifted=[lifted], fndesc=types.SimpleNamespace(qualname="embed"))
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        assert impl.check_cachable(result) is False
    assert [Path(w.filename).name for w in caught] == ["system.py"]
    assert "Cannot cache compiled function" in str(caught[0].message)


NOTICE_RUN = ("import json, sys, numpy as np; from skdgmpm import first_run, kernel_cache, system; "
              "notice = first_run.compile_notice('dgmpm', 1)\n"
              "with notice: system.embed(np.ones((3, 1, 1)))\n"
              "print(json.dumps([notice.seconds, kernel_cache.cache_dir()]))")


def test_the_first_run_says_it_compiles_and_a_cached_one_does_not(tmp_path):
    (seconds, where), first = python(NOTICE_RUN, cwd=tmp_path, cache=tmp_path / "cache")
    assert where.startswith(str(tmp_path / "cache" / "kernels-")) and seconds > 0
    assert first.count(first_run.NOTICE + "dgmpm, 1D (first run, about ") == 1 and where in first
    (seconds, _), again = python(NOTICE_RUN, cwd=tmp_path, cache=tmp_path / "cache")
    assert seconds == 0 and "compiling" not in again


def test_every_environment_with_the_same_sources_shares_the_cache_and_an_edit_changes_it(tmp_path):
    here, _ = python(DIGEST, cwd=tmp_path)
    site = installed_copy(tmp_path)
    installed, _ = python(DIGEST, cwd=tmp_path, pythonpath=site)
    assert installed[2] == here[2] == ["skdgmpm", "skdgmpm.forms", "skdgmpm.materials"]
    assert installed[0] == here[0] == kernel_cache.source_digest()        # wherever it is installed
    law = site / "skdgmpm" / "materials" / "neo_hookean.py"
    law.write_text(law.read_text() + "\n# edited\n")
    edited, _ = python(DIGEST, cwd=tmp_path, pythonpath=site)
    assert edited[0] != here[0] and edited[1] != here[1]
    cli = site / "skdgmpm" / "cli.py"                                    # no compiled code in it
    cli.write_text(cli.read_text() + "\n# edited\n")
    assert python(DIGEST, cwd=tmp_path, pythonpath=site)[0][0] == edited[0]


PER_D = ("import json, numpy as np; from skdgmpm import system, riemann\n"
         "system.embed(np.ones((4, 1, 1)))\n"
         "riemann.impedances(np.ones((3, 1, 1, 1, 1)), np.ones((3, 1)), np.ones(3))\n"
         "print(json.dumps([sorted(system._embed.kernels), sorted(riemann._impedances.kernels),"
         " sorted(system._volume_flux.kernels)]))")


def test_a_scene_compiles_the_kernels_of_its_own_dimension_only(tmp_path):
    (embed, impedances, volume_flux), _ = python(PER_D, cwd=tmp_path)
    assert embed == impedances == [[1]] and volume_flux == []


ONE_LAW = ("import json, numpy as np; from types import SimpleNamespace\n"
           "from skdgmpm import health, system; from skdgmpm.constitutive import MaterialSet\n"
           "from skdgmpm.materials import LinearElastic; from skdgmpm.materials.points import _tangent_of\n"
           "law = LinearElastic(E=200e9, nu=0.3, rho=7800.0); materials = MaterialSet((law,))\n"
           "U = system.join(np.ones((5, 1, 1)), np.zeros((5, 1)))\n"
           "h = health.assess(materials, SimpleNamespace(material=np.zeros(5, np.int64)), U, U.copy())\n"
           "print(json.dumps([law.law_id, sorted(_tangent_of.kernels), bool(h.finite.all())]))")


def test_a_1d_kernel_of_one_law_compiles_that_laws_tangent_alone(tmp_path):
    """1D kernels call the law's tangent as a function of its own (`points.tangent_call`); on a
    cold cache, a scene of one law compiles that law's tangent only (it compiled every registered
    law's: 9 s of a 1D bar's first run)."""
    (law_id, made, finite), _ = python(ONE_LAW, cwd=tmp_path, cache=tmp_path / "cache")
    assert made == [[law_id]] and finite


VARIANTS = '''
from skdgmpm.kernel_cache import kernel_factory


@kernel_factory
def _scaled(k):
    def scaled(x):
        return k * x
    return scaled
'''

# compile (or load) the variants asked for, numba's function numbering from 1 as in every process
# before `skdgmpm._uids` (only the variants' own names keep their symbols apart then)
COMPILE = ("import itertools, json, sys; import skdgmpm; from numba.core import bytecode\n"
           "bytecode.FunctionIdentity._unique_ids = itertools.count(1)\n"
           "import variants\n"
           "ks = [variants._scaled(int(a)) for a in sys.argv[1:]]\n"
           "values = [k(1.0) for k in ks]\n"
           "print(json.dumps([values, [sum(k.stats.cache_hits.values()) for k in ks], "
           "[k.py_func.__qualname__ for k in ks]]))")


def test_each_variant_of_a_factory_has_its_own_name_whichever_process_compiled_it(tmp_path):
    """Two variants of one factory with the same argument types, each compiled first thing in a
    process of its own with numba's numbering from 1: their qualified names, hence their symbols
    and cache indexes, differ (docs/bench/session29.md §5: two variants under one symbol, and one
    ran the other's code), and loaded together each runs its own code."""
    (tmp_path / "variants.py").write_text(VARIANTS)
    cache = tmp_path / "cache"

    def run(*sizes):
        env = {**os.environ, "NUMBA_CACHE_DIR": str(cache), "PYTHONPATH": str(tmp_path)}
        out = subprocess.run([sys.executable, "-c", COMPILE, *map(str, sizes)], cwd=tmp_path, env=env,
                             capture_output=True, text=True)
        assert out.returncode == 0, out.stderr
        return json.loads(out.stdout.strip().splitlines()[-1])

    assert run(2)[0] == [2.0] and run(3)[0] == [3.0]            # each compiled in its own process
    values, hits, names = run(2, 3)
    assert hits == [1, 1]                                       # both loaded from the cache
    assert values == [2.0, 3.0]
    assert len(list(cache.rglob("*scaled_2_*.nbi"))) == len(list(cache.rglob("*scaled_3_*.nbi"))) == 1
    assert len(set(names)) == 2 and all(re.fullmatch(r"_scaled\.<locals>\.scaled_\d_[0-9a-f]{12}", n) for n in names)
    assert kernel_cache.variant_qualname("f", ()) == "f"
    assert kernel_cache.variant_qualname("f", (1,)) != kernel_cache.variant_qualname("f", (-1,))


def test_kernels_compiled_with_debug_information_are_filed_apart(tmp_path, monkeypatch):
    """numba's cache index keys a kernel on its signature and target, not on how it was compiled:
    a run with NUMBA_DEBUGINFO or NUMBA_ENABLE_PROFILING filed debug builds where every later run
    loaded them (two to four times slower, docs/bench/session37.md). `build_tag` files them in
    kernels-<digest>-debug: a plain process after a debug one compiles its own kernel (a cache
    miss), and the next plain one loads it; `skdgmpm cache` lists the debug folder and prunes it."""
    from numba import config
    from skdgmpm import cache_folders

    for name, value, tag in (("DEBUGINFO_DEFAULT", 1, "debug"), ("ENABLE_PROFILING", 1, "debug"),
                             ("BOUNDSCHECK", 1, "boundscheck"), ("OPT", 0, "opt0")):
        with monkeypatch.context() as m:
            m.setattr(config, name, value)
            assert kernel_cache.build_tag() == tag
            assert Path(kernel_cache.cache_dir()).name == f"kernels-{kernel_cache.source_digest()}-{tag}"
    assert kernel_cache.build_tag() == ""
    code = ("import json, numpy as np, skdgmpm.kernel_cache as k; from skdgmpm import system; "
            "e = system._embed(2); e(np.zeros((3, 4)), np.zeros((3, 3, 3))); "
            "print(json.dumps([k.cache_dir(), sum(e.stats.cache_hits.values()), sum(e.stats.cache_misses.values())]))")
    cache = tmp_path / "cache"
    runs = []
    for debug in (True, False, False):
        env = {k: v for k, v in os.environ.items() if k not in ("PYTHONPATH", "NUMBA_DEBUGINFO")}
        env.update({"NUMBA_CACHE_DIR": str(cache)}, **({"NUMBA_DEBUGINFO": "1"} if debug else {}))
        out = subprocess.run([sys.executable, "-c", code], cwd=tmp_path, env=env, capture_output=True, text=True)
        assert out.returncode == 0, out.stderr
        runs.append(json.loads(out.stdout.strip().splitlines()[-1]))
    (debug_dir, _, _), (plain_dir, hits, misses), (_, hits_again, _) = runs
    assert Path(debug_dir).name.endswith("-debug") and Path(plain_dir) == Path(debug_dir[:-len("-debug")])
    assert any(Path(debug_dir, "skdgmpm").glob("system._embed*.nbc"))
    assert hits == 0 and misses == 1                    # compiled: the debug build not taken
    assert hits_again == 1
    rows = cache_folders.folders(cache)
    assert sorted(Path(row[0]).name for row in rows) == sorted([Path(debug_dir).name, Path(plain_dir).name])


def test_scratch_arrays_are_the_shapes_asked_for_and_apart():
    """`scratch` (numba's code generation, not an inlined function): arrays of the shape asked for,
    literal or read at run time, C-ordered, each its own memory (written in turn, each keeps its
    own values); more than SCRATCH_SIZE entries raises; a shape that is not a tuple of ints is
    refused when the caller is typed."""
    from numba import njit
    from numba.core.errors import TypingError
    from skdgmpm.kernel_cache import SCRATCH_SIZE, scratch

    @njit
    def fill(x, n):
        a, b, c = scratch((3, 3)), scratch((n,)), scratch((2, n, 2))
        for i in range(3):
            for j in range(3):
                a[i, j] = x[i] + 10.0 * j
        for i in range(n):
            b[i] = -x[i]
        c[:] = 7.0
        return a.copy(), b.copy(), c.copy(), a.strides, c.strides

    a, b, c, a_strides, c_strides = fill(np.arange(4.0), 4)
    assert np.array_equal(a, np.arange(3.0)[:, None] + 10.0 * np.arange(3.0)[None, :])
    assert np.array_equal(b, -np.arange(4.0)) and np.array_equal(c, np.full((2, 4, 2), 7.0))
    assert a_strides == (24, 8) and c_strides == (64, 16, 8)

    @njit
    def square(n):
        return scratch((n, n)).size

    assert square(9) == SCRATCH_SIZE
    with pytest.raises(ValueError, match="more than SCRATCH_SIZE"):
        square(10)

    @njit
    def flat(n):
        return scratch(n).size

    with pytest.raises(TypingError, match="a tuple of ints"):
        flat(3)
