"""Where and how the compiled kernels are made and kept: a disk cache keyed on the package's
sources, one compiled kernel per dimension (or other literal size). The first run's notice is
`skdgmpm.first_run` (no compiled code: its estimates change without changing the cache's key).

The cache
---------
numba checks a cached kernel only against its own file (a hash of it) and files it under the
file's directory path: a kernel that inlines functions of other files (riemann.py,
materials/*.py, equations.py) would keep running old code after they are edited, and a second
environment installing the same sources (another venv, another checkout, ``pip install .``)
would compile everything again. `Locator`, which numba consults first for this package's files
only (`install`; every other file keeps numba's own locators), files every kernel under

    <base>/kernels-<digest>/<package>/        (<package>: skdgmpm, skdgmpm.materials, ...)

where <digest> hashes every source file of the package that compiles code (by its name within
the package), and the numba version; the digest is also each kernel's source stamp. An edit
anywhere in the package thus compiles afresh, and every environment with the same sources and
numba version shares one cache, wherever it is installed. Where numba's settings make other code
of the same kernels (debug information, bounds checks, another optimisation level), the folder
takes a suffix (kernels-<digest>-debug, ...: `build_tag`): numba's index keys a kernel on its
signature and target, not on those flags, and would hand such a build to every later run.
<base>: $NUMBA_CACHE_DIR if set, else $XDG_CACHE_HOME/skdgmpm or ~/.cache/skdgmpm; where it
cannot be written, numba's own locators take over. Nothing global is set: numba's configuration
is read, and written only for the time this package's own kernels compile (`Vectorise`).

Straight-line SIMD
------------------
A kernel's work per point or face is straight-line code over a few components (a state's 6, a
tangent's 16) with control flow between points, which LLVM's loop vectoriser cannot take over
several points. Its SLP vectoriser packs the isomorphic operations of one point into SIMD
registers; numba leaves it off by default since 0.57 (miscompilations in the LLVM of the time;
clang runs it at -O2). `Vectorise` turns it on while this package's kernels compile (and what
they compile on their behalf), never for other code: it keeps every operation an IEEE operation
lane by lane (no reassociation, no contraction), so the answers are the same bits (the stored
answers of tests/test_regression.py and the state hashes check that); the face, cells' and law's
passes of a 2D DGMPM step take 5-12 % less time (docs/bench/session19.md).

One kernel per dimension
------------------------
A compiled function that branches on the dimension (``if d == 2: f(..., 2) else: f(..., d)``)
compiles every branch: a 1D scene would pay for the 2D code and the other way round. Instead the
dimension (or any small size the compiler should see as a constant: a state width, a node count)
is chosen in Python, and each value gets its own compiled kernel, made by a factory:

    @kernel_factory
    def _embed(d):                              # d: a literal int (or None: read at run time)
        def embed(F, F3):                       # the kernel's body, d a constant in it
            for p in range(len(F)):
                for i in range(3):
                    for j in range(3):
                        F3[p, i, j] = F[p, i, j] if i < d and j < d else (1.0 if i == j else 0.0)
        return embed

    def embed(F):                               # the Python entry point picks the kernel
        F3 = np.empty((len(F), 3, 3))
        _embed(F.shape[1])(F, F3)
        return F3

``_embed(2)`` compiles (once per process, memoised) the inner function, a closure over d = 2,
with ``njit(cache=True)``: its ``range(d)`` loops see a constant (unrolled), and its ``if d ==
2:`` branches, with those of the ``inline="always"`` helpers it calls (given d), are pruned before
typing: a kernel holds the code of its own dimension only. numba keys a closure's cache entry on
its cells' contents (here d), so each d is cached on disk apart. Rules:

- the body lives in the inner function itself, not in an ``inline="always"`` helper it calls:
  numba copies an inlined function's IR at a cost that grows as its size squared (the ~500
  blocks of a face pass took 44 s);
- the closure's free variables are plain ints (or None), never functions or arrays (a dispatcher
  does not pickle the same in every process: the cache would never hit); the functions it calls
  are module globals;
- call the factory from Python (entry points keep their names and signatures), never from
  compiled code;
- sizes not worth a kernel of their own map to None, e.g. ``(nb, nc) if nb in (4, 9) else (None,
  None)``, and the factory then returns a body that reads them from the arrays.
"""
import functools
import hashlib
import importlib.util
import os
import re
from pathlib import Path

import llvmlite.ir as ir
import numba
from numba import njit, types
from numba.core import cgutils, config, event
from numba.core.caching import CacheImpl, _CacheLocator
from numba.extending import intrinsic
from numba.np.arrayobj import np_cfarray

PACKAGE = __name__.rpartition(".")[0]           # "skdgmpm"
SUBPACKAGES = ("materials", "forms")            # with kernels or inlined code (cases/: scenes, meshes)


@functools.lru_cache(maxsize=None)
def package_folders():
    """{absolute folder: package name} of the package and its subpackages, wherever installed."""
    folders = {str(Path(__file__).resolve().parent): PACKAGE}
    for sub in SUBPACKAGES:
        try:
            spec = importlib.util.find_spec(f"{PACKAGE}.{sub}")
        except ImportError:
            spec = None
        for path in (spec.submodule_search_locations or []) if spec else []:
            folders.setdefault(str(Path(path).resolve()), f"{PACKAGE}.{sub}")
    return folders


# A source that compiles something: only these can put code into a kernel (a compiled function
# reads the globals of its own module and calls compiled functions of other such modules).
_COMPILES = re.compile(rb"@njit|njit\(|@kernel_factory|@intrinsic")


@functools.lru_cache(maxsize=None)
def source_digest():
    """Hash of the package's source files that compile code (`_COMPILES`; by their names within
    the package) and of the numba version: the same for every environment that installs the same
    sources; an edit of the Python-only files (command line, scenes, outputs) keeps the kernels."""
    digest = hashlib.sha256(f"numba {numba.__version__}\n".encode())
    for folder, name in sorted(package_folders().items(), key=lambda item: item[1]):
        for path in sorted(Path(folder).glob("*.py")):
            text = path.read_bytes()
            if _COMPILES.search(text):
                digest.update(f"{name}/{path.name}\n".encode())
                digest.update(text)
    return digest.hexdigest()[:16]


def cache_base():
    """$NUMBA_CACHE_DIR if set, else $XDG_CACHE_HOME/skdgmpm or ~/.cache/skdgmpm."""
    if config.CACHE_DIR:
        return config.CACHE_DIR
    return os.path.join(os.environ.get("XDG_CACHE_HOME") or os.path.join(os.path.expanduser("~"), ".cache"),
                        "skdgmpm")


def build_tag():
    """The numba settings in force that change the code it compiles but not its cache's index
    (which keys a kernel on its signature and target only), as a folder suffix: "" where none is;
    "debug" (NUMBA_DEBUGINFO, NUMBA_ENABLE_PROFILING), "boundscheck" (NUMBA_BOUNDSCHECK), "opt<n>"
    (NUMBA_OPT other than 3). Kernels compiled under one are filed apart from the others: a
    profiling run's debug builds, filed with them, made every later run's CTU passes two to four
    times slower (docs/bench/session37.md)."""
    tags = []
    if config.DEBUGINFO_DEFAULT or config.ENABLE_PROFILING:
        tags.append("debug")
    if config.BOUNDSCHECK:
        tags.append("boundscheck")
    if int(config.OPT) != 3:
        tags.append(f"opt{int(config.OPT)}")
    return "-".join(tags)


def cache_dir():
    """The directory of this package's kernels: <base>/kernels-<source digest>, with
    -<`build_tag`> where numba compiles otherwise than by default."""
    tag = build_tag()
    return os.path.join(cache_base(), f"kernels-{source_digest()}" + (f"-{tag}" if tag else ""))


class Locator(_CacheLocator):
    """numba's cache locator for this package's own files (see the module's docstring)."""

    def __init__(self, py_func, py_file, package):
        self._lineno = py_func.__code__.co_firstlineno
        self._py_file = py_file                 # named in numba's warning when a kernel cannot be cached
        self._cache_path = os.path.join(cache_dir(), package)

    def get_cache_path(self):
        return self._cache_path

    def get_source_stamp(self):
        return source_digest()

    def get_disambiguator(self):
        return str(self._lineno)

    @classmethod
    def from_function(cls, py_func, py_file):
        package = package_folders().get(os.path.dirname(os.path.realpath(py_file)))
        if package is None:                     # not this package's file: numba's own locators
            return None
        self = cls(py_func, py_file, package)
        try:
            self.ensure_cache_path()
        except OSError:                         # not writable: numba's own locators
            return None
        return self


def install():
    """Make numba consult `Locator` first (idempotent); it claims this package's files only. And
    compile this package's kernels with the SLP vectoriser (`Vectorise`)."""
    if Locator not in CacheImpl._locator_classes:
        CacheImpl._locator_classes = [Locator] + list(CacheImpl._locator_classes)
    if not Vectorise.installed:
        event.register("numba:compile", Vectorise())
        Vectorise.installed = True


def ours(ev):
    """Whether a numba:compile event compiles a function of this package."""
    module = getattr(getattr(ev.data.get("dispatcher"), "py_func", None), "__module__", "") or ""
    return module == PACKAGE or module.startswith(PACKAGE + ".")


class Vectorise(event.Listener):
    """numba's SLP_VECTORIZE on while a function of this package compiles, with the functions its
    compilation compiles; as it was before for every other compilation (see the module's
    docstring). numba compiles under its global lock, so the setting is not seen by another
    thread's compilation."""

    installed = False

    def __init__(self):
        self.saved = []

    def on_start(self, ev):
        self.saved.append(config.SLP_VECTORIZE)
        if ours(ev):
            config.SLP_VECTORIZE = 1

    def on_end(self, ev):
        config.SLP_VECTORIZE = self.saved.pop()


# ---------------------------------------------------------------- one kernel per literal size
def kernel_factory(factory=None, *, parallel=False):
    """``factory(*sizes)`` returns a Python function closing over the literal ``sizes`` (ints,
    bools, None or strings); the decorated name, called with the sizes, returns it compiled
    (``njit(cache=True, nogil=True)``: threads run it in parallel, `skdgmpm.parallel`), one kernel
    per distinct sizes, memoised. See the module's docstring. ``@kernel_factory(parallel=True)``:
    compiled with numba's ``parallel`` (a chunk loop over ``prange``, `parallel._chunk_loop`)."""
    if factory is None:
        return functools.partial(kernel_factory, parallel=parallel)
    kernels = {}

    @functools.wraps(factory)
    def kernel(*sizes):
        try:
            return kernels[sizes]
        except KeyError:
            body = factory(*sizes)
            body.__qualname__ = variant_qualname(body.__qualname__, sizes)
            k = kernels[sizes] = njit(cache=True, nogil=True, parallel=parallel)(body)
            k.kernel_name = f"{factory.__module__}.{factory.__qualname__}{sizes!r}"
            return k

    kernel.kernels = kernels
    return kernel


def variant_qualname(qualname, sizes):
    """The qualified name of a factory's kernel for ``sizes``: its own, so that its symbol (numba
    names a compiled function by qualified name, a per-process number and argument types) and its
    cache index differ from every other variant's, whichever process compiled them (two variants
    under one symbol ran one another's code: docs/bench/session29.md §5). The sizes as a short
    readable tag and a hash of them (a chunk loop's size is a long key), in [A-Za-z0-9_]: the name
    is part of the index's file name."""
    if not sizes:
        return qualname
    readable = re.sub(r"[^A-Za-z0-9]+", "_", "_".join(map(str, sizes))).strip("_")[:32]
    return f"{qualname}_{readable}_{hashlib.sha256(repr(sizes).encode()).hexdigest()[:12]}"


# ---------------------------------------------------------------- scratch arrays of a kernel
SCRATCH_SIZE = 81       # entries of a `scratch` array: a (3, 3, 3, 3) tangent


@intrinsic
def scratch(typingctx, shape):
    """Uninitialised float array of ``shape`` (a tuple of ints, at most SCRATCH_SIZE entries) on
    the stack of the compiled function that calls it, for the per-point scratch of the compiled
    loops: unlike ``np.empty`` (heap memory the compiler must assume any other array may alias),
    its entries stay in registers once the loops over it are unrolled (a literal d). It lives as
    long as that function's call: never return it or keep it in another object. Written as
    numba's code generation (the stack space, then ``carray``'s array over it), not as an
    inlined function: a kernel calls it dozens of times, and numba's inlining of a function
    translates and copies its body at every call (3.3 s of a 1D first run's 26 s)."""
    if not (isinstance(shape, types.BaseTuple) and all(isinstance(s, types.Integer) for s in shape)):
        raise numba.core.errors.TypingError(f"scratch: a tuple of ints expected, got {shape}")
    array = types.Array(types.float64, len(shape), "C")

    def codegen(context, builder, signature, args):
        data = cgutils.alloca_once(builder, context.get_value_type(types.float64),
                                   size=ir.Constant(ir.IntType(64), SCRATCH_SIZE))
        n = context.get_constant(types.intp, 1)
        for size, kind in zip(cgutils.unpack_tuple(builder, args[0]), shape):
            n = builder.mul(n, context.cast(builder, size, kind, types.intp))
        with builder.if_then(builder.icmp_signed(">", n, context.get_constant(types.intp, SCRATCH_SIZE)),
                             likely=False):
            context.call_conv.return_user_exc(builder, ValueError, ("scratch: more than SCRATCH_SIZE entries",))
        return np_cfarray(context, builder, array(types.CPointer(types.float64), shape), (data, args[0]))
    return array(shape), codegen
