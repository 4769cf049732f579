"""Threads for the compiled passes: a loop over independent rows (faces, nodes, points) split into
contiguous chunks, `PIECES` per thread, that the threads take in turn, each the next chunk left
as soon as it is free (`rows`): a thread that wakes late, or that the host slows, takes fewer
chunks, and no pass waits for a worker that finds none left.

Every pass that is chunked computes each row from its inputs alone and writes that row only (no
scatter into another row, no running sum over rows): a row's value does not depend on which
chunk, or which thread, computes it, so the results are bit-identical for any thread count. A
sum over rows (e.g. the transverse corrections an edge receives from its neighbours) is made a
gather of its own, each row summing its terms in a fixed order. A pass names its kernel, how
each argument is cut per chunk and what the chunks return (`chunked`):

    out = np.empty(...)
    parallel.chunked(n, kernel, "rcw", (a, T, out))     # kernel(a[lo:hi], csr_rows(T, lo, hi), out) per chunk

Sparse products: `matmul` (CSR times dense, each output row its own sum, in CSR order, as
scipy's product sums it) is the one product every step uses; a transposed product A^T X is a
`matmul` with A^T stored as CSR at set-up (scipy's ``A.T.tocsr()``: each row's entries in the
order of A's rows, as scipy's A.T @ X visits them), so a scatter into rows becomes a gather with
the same bits; where A changes every step (MPM's shape functions), `matmul_T` applies A^T
without storing it, each chunk of output rows scattering into its own rows only.

Compiled chunk loops: every method's chunked passes run over their chunks from a numba ``prange``
(`compiled_chunks`: one loop for every pass, `_chunk_loop`, which writes each kernel's call out
once from its spec) where numba's threading layer is OpenMP or TBB: its threads take their chunks
without the GIL and without waking from the OS, where each worker of the pool below wakes and
takes the GIL (docs/bench/session20.md). numba deals a ``prange`` out in equal shares, so each of
its threads takes the next chunk left from a counter (`take_chunk`, an atomic add), as the pool's
threads do: a core the host slows takes fewer chunks (docs/bench/session25.md). The same chunks
and kernels: the same bits. Every pass of a step goes one way, so that numba's waiting threads,
which spin a while, never hold a core that a worker of the pool needs; the pool runs them where
numba's layer is another (`rows`), and the bench's probes.

Two passes that do not read what the other writes may share one compiled loop (`together`, each
described as a `Pass`): their chunks taken from one counter, the first pass's first, so that the
second (a few hundred boundary faces beside the interior faces) waits for no start of its own.

The thread count: `set_threads` (the scene key ``run.threads``, ``skdgmpm run --threads``), else
$SKDGMPM_THREADS, else every core this process may use. A loop shorter than `MIN_ROWS` per thread
runs in the calling thread (small scenes pay nothing); study workers run one thread each.
"""
import functools
import hashlib
import inspect
import itertools
import os
import threading
from concurrent.futures import ThreadPoolExecutor
from typing import NamedTuple

import numba
import numpy as np
from numba import njit, prange, types
from numba.core import cgutils
from numba.extending import intrinsic, overload

from .kernel_cache import kernel_factory, scratch

MIN_ROWS = 2048         # rows per thread below which a loop stays in one thread
PIECES = 8              # chunks per thread, taken in turn as each thread is free (`rows`)

_threads = None
_pool = None


def available():
    """The cores this process may use."""
    try:
        return len(os.sched_getaffinity(0))
    except AttributeError:              # not Linux
        return os.cpu_count() or 1


def threads():
    """The number of threads the chunked passes use."""
    if _threads is not None:
        return _threads
    value = os.environ.get("SKDGMPM_THREADS")
    if value:
        try:
            n = int(value)
        except ValueError:
            n = 0
        if n < 1:
            raise ValueError(f"SKDGMPM_THREADS = {value!r}: expected a whole number >= 1")
        return n
    return available()


def set_threads(n):
    """Use ``n`` threads from now on (None: back to $SKDGMPM_THREADS or every core); returns the
    setting it replaces."""
    global _threads
    if n is not None and (not isinstance(n, int) or isinstance(n, bool) or n < 1):
        raise ValueError(f"threads = {n!r}: expected a whole number >= 1")
    previous, _threads = _threads, n
    # a pool with more workers than needed is kept (a pass submits to as many as it uses): a
    # paired bench that alternates 1 and 2 threads then steps on the same worker each round,
    # as a run does, not on a thread new every round (RK2 at 256^2 read x1.72 so, x1.81 kept)
    if _pool is not None and _pool._max_workers < threads() - 1:
        restart()
    return previous


def restart():
    """Shut the pool down: the next pass starts its workers anew. For the bench's arithmetic
    probe: a worker that sat idle through steps of numba's threads was woken on a busy core (the
    probe read x1.0 on two threads of the VM, x1.2-1.9 on new workers, in the same minutes)."""
    global _pool
    if _pool is not None:
        _pool.shutdown()
        _pool = None


def bounds(n, parts):
    """``parts`` contiguous (lo, hi) chunks of range(n), as equal as can be."""
    return [(n * k // parts, n * (k + 1) // parts) for k in range(parts)]


def team(n, min_rows=None):
    """The threads a loop over range(n) runs on: one per ``min_rows`` rows (default `MIN_ROWS`),
    at most `threads`."""
    return min(threads(), max(1, n // (min_rows or MIN_ROWS)))


def chunks(n, min_rows=None):
    """The (lo, hi) chunks `rows` splits range(n) into: `PIECES` per thread of its `team` (one
    where the loop runs in one thread), of ``min_rows`` / `PIECES` rows at least."""
    t = team(n, min_rows)
    return bounds(n, 1 if t == 1 else min(t * PIECES, n // max(1, (min_rows or MIN_ROWS) // PIECES)))


def chunk_starts(n, min_rows=None):
    """The first rows of the chunks of range(n) (`chunks`), int64, read-only (a step's health
    summary reads them: `health.summarise`): the cached bounds of `compiled_chunks` but the last."""
    return _chunk_bounds(n, min_rows, threads(), MIN_ROWS, PIECES)[:-1]


@functools.lru_cache(maxsize=64)
def _chunk_bounds(n, min_rows, n_threads, *settings):
    """The bounds [lo_0, lo_1, ..., n] (int64) of the chunks of range(n) (`chunks`), made once
    for each set of what they depend on: the loop size, `threads` and the module's ``settings``
    (MIN_ROWS, PIECES), passed as the cache's key; read-only, as the cache shares them."""
    bounds = np.array([lo for lo, _ in chunks(n, min_rows)] + [n], np.int64)
    bounds.flags.writeable = False
    return bounds


def rows(n, call, min_rows=None):
    """``call(lo, hi)`` over contiguous chunks of range(n) (`chunks`), in parallel, each thread
    taking the next chunk not yet taken until none is left; returns the results in chunk order
    (the first chunk's first)."""
    return _run(call, chunks(n, min_rows), team(n, min_rows))


def each_thread(n, call):
    """``call(lo, hi)`` over one contiguous chunk of range(n) per thread of its `team`, each on a
    thread of its own at once (the calling thread the first); returns the results in chunk order.
    For the bench's probes: the same work on every thread, each thread there to take its part."""
    parts = bounds(n, team(n))
    if len(parts) == 1:
        return [call(*parts[0])]
    futures = [_workers().submit(call, *part) for part in parts[1:]]
    first = call(*parts[0])
    return [first] + [f.result() for f in futures]


def _workers():
    global _pool
    if _pool is None:
        _pool = ThreadPoolExecutor(max_workers=threads() - 1, thread_name_prefix="skdgmpm")
    return _pool


def _run(call, parts, n_threads):
    """``call(*part)`` for every part on ``n_threads`` threads, the calling thread among them:
    each takes the next part not yet taken (a counter, advanced under the GIL) until none is
    left, so that a thread that starts late, or that the machine slows, takes fewer parts than
    the others rather than keeping them waiting. Returns once every part is done (not waiting
    for a worker that has found none left to take), the results in part order; an error in a
    part is raised once the parts taken are done, no other part being taken after it."""
    if len(parts) == 1 or n_threads == 1:
        return [call(*part) for part in parts]
    n = len(parts)
    results, errors = [None] * n, []
    taken, done, finished = itertools.count(), itertools.count(1), threading.Event()

    def work():
        for k in iter(taken.__next__, None):
            if k >= n or errors:
                return
            try:
                results[k] = call(*parts[k])
            except BaseException as error:
                errors.append(error)
                finished.set()
                return
            if next(done) == n:
                finished.set()

    futures = [_workers().submit(work) for _ in range(min(n_threads, n) - 1)]
    work()
    if not errors:
        finished.wait()
    else:                               # the parts other threads have taken: done before raising
        for f in futures:
            f.result()
    if errors:
        raise errors[0]
    return results


def compiled_chunks(n, min_rows=None):
    """The bounds [lo_0, lo_1, ..., n] (int64, read-only: `_chunk_bounds`) of the chunks of
    range(n) (`chunks`), for a compiled chunk loop (a ``prange`` over them calling the kernel on
    each: `_chunk_loop`), numba's thread count set to their number; None where the loop is
    better run by `rows`: one chunk, or a threading layer of numba's other than OpenMP and TBB
    (its ``workqueue`` hands chunks over slower than this module's pool, docs/bench/session20.md).
    The same chunks, each computed by the same kernel: the same bits as `rows`. numba's
    threads hand over in microseconds and without the GIL, where the pool's workers each wake
    and take the GIL (0.06-0.2 ms a pass on two threads, 0.8-1.1 ms on sixteen)."""
    bounds, n_threads = _compiled_bounds(n, min_rows, threads(), MIN_ROWS, PIECES)
    if bounds is not None:
        _numba_threads(n_threads)
    return bounds


@functools.lru_cache(maxsize=64)
def _compiled_bounds(n, min_rows, n_threads, *settings):
    """(bounds, numba's thread count) of `compiled_chunks`, made once for each key of
    `_chunk_bounds` (whose bounds they are): a step asks five times; making them and setting
    numba's count anew took 1-2 % of a DGMPM step on two threads, on one thread. (None, 1) where
    `rows` runs the loop."""
    bounds = _chunk_bounds(n, min_rows, n_threads, *settings)
    if len(bounds) == 2 or not _compiled_layer():
        return None, 1
    return bounds, min(team(n, min_rows), numba.config.NUMBA_NUM_THREADS)


_numba_count = threading.local()


def _numba_threads(n):
    """numba's thread count for the calling thread's next compiled loops (numba keeps one per
    thread), set only where it differs from the one this module set last in that thread (numba's
    setter takes a process lock at every call)."""
    if getattr(_numba_count, "n", None) != n:
        numba.set_num_threads(n)
        _numba_count.n = n


_LAYER = None


def _compiled_layer():
    """Whether numba's threading layer runs compiled chunk loops well (OpenMP or TBB): known once
    a parallel function has run (`_start_layer`)."""
    global _LAYER
    if _LAYER is None:
        _start_layer(np.zeros(2))
        _LAYER = numba.threading_layer() in ("omp", "tbb")
    return _LAYER


@intrinsic
def _fetch_add(typingctx, counter, value):
    """counter[0] += value as one atomic add; returns counter[0] before it."""
    def codegen(context, builder, signature, args):
        array = context.make_array(signature.args[0])(context, builder, args[0])
        zero = context.get_constant(types.intp, 0)
        first = cgutils.get_item_pointer(context, builder, signature.args[0], array, [zero])
        return builder.atomic_rmw("add", first, args[1], "monotonic")
    return types.int64(counter, types.int64), codegen


@njit(cache=True, inline="always")
def take_chunk(counter):
    """The next chunk not yet taken in a compiled chunk loop (a count from 0, ``counter`` an int64
    array of one zero made for the loop), for the thread that asks; the chunk count or more once
    none is left. Each of the loop's threads takes chunks until none is left:

        counter = np.zeros(1, np.int64)
        for _ in prange(n):
            c = take_chunk(counter)
            while c < n:
                ...             # chunk c
                c = take_chunk(counter)
    """
    return _fetch_add(counter, np.int64(1))


@njit(cache=True, parallel=True)
def _start_layer(x):
    for i in prange(len(x)):
        x[i] = i


def chunked(n, kernel, spec, args, returns=0, min_rows=None):
    """``kernel`` (compiled) over the chunks of range(n) (`chunks`), in parallel, the same bits
    for any thread count: on each chunk (lo, hi) it is called with ``args`` as ``spec`` says, one
    letter a parameter: ``r`` the argument's rows lo:hi, ``i`` its entries lo:hi + 1 (an
    indptr), ``c`` a CSR triple's rows (`csr_rows`), ``k`` its columns lo:hi, ``n`` its entry of
    the chunk (the chunk's number in `chunks`), ``w`` the argument whole, ``l`` and ``h`` lo and
    hi themselves (no argument taken); letters in brackets, a tuple argument, each of its items
    as its letter says (``(rrw)``). An array left empty where the kernel does not read it (a
    health check not asked for) is cut by ``r`` all the same: its chunks are empty. A compiled
    chunk loop runs the chunks where numba can (`compiled_chunks`), the pool (`rows`) where not.
    ``returns``: 0 (what the kernel returns is dropped; returns None), ``"first"`` (the kernel
    returns its chunk's first failing row or -1; returns the first failing row of range(n), or
    -1, as one serial pass would) or k > 0 (the kernel returns k numbers, a tuple where k > 1;
    returns them, an array (chunks, k) of floats in chunk order). ``min_rows``: as `chunks` has
    it."""
    width = 1 if returns == "first" else returns
    bounds = compiled_chunks(n, min_rows)
    plan = _PLANS.get((kernel, spec, returns))
    if bounds is not None and plan is not None:
        try:
            flat = plan[1](args)
        except _Mismatch:               # the arguments nest otherwise than last time: planned anew
            plan = None
    if bounds is None or plan is None:
        parsed = _checked(spec, args)
    if bounds is None:
        parts = chunks(n, min_rows)
        number = {lo: c for c, (lo, _) in enumerate(parts)}
        results = rows(n, lambda lo, hi: kernel(*_sliced(parsed, args, lo, hi, number[lo])), min_rows)
        if returns == "first":
            return next((lo + b for (lo, _), b in zip(parts, results) if b >= 0), -1)
        return np.array(results, float).reshape(len(results), width) if width else None
    if plan is None:
        plan = _plan(kernel, spec, args, returns)
        flat = plan[1](args)
    out = np.empty((len(bounds) - 1, width))
    plan[0](bounds, out, *flat)
    return _returned(out, returns)


def _checked(spec, args):
    """``spec`` parsed (`_parsed`), refused where it does not take as many arguments as ``args``."""
    parsed = _parsed(spec)
    if sum(letter not in ("l", "h") for letter in parsed) != len(args):
        raise ValueError(f"chunked: spec {spec!r} for {len(args)} arguments")
    return parsed


def _returned(out, returns):
    """What `chunked` returns from its chunks' results ``out`` (chunks, width)."""
    if returns == "first":                 # Python floats: numpy's masking cost 13 µs a call here
        return next((int(b) for b in out[:, 0].tolist() if b >= 0), -1)
    return out if returns else None


_PLANS = {}             # (kernel, spec, returns) -> (its compiled chunk loop, the flattener of its arguments)


class Pass(NamedTuple):
    """A `chunked` pass described, to be run with others (`together`): its arguments as `chunked`
    takes them."""
    n: int
    kernel: object
    spec: str
    args: tuple
    returns: object = 0
    min_rows: object = None


def together(first, second):
    """Two `chunked` passes (`Pass`) that do not read what the other writes, in one compiled loop:
    their chunks (each pass's own, as `chunked` cuts it) taken in turn from one counter, the first
    pass's first, so that a thread done with its share of the first goes on to the second's with
    nothing handed over between them, and a short second pass (a few hundred boundary faces)
    neither waits for a start of its own nor leaves a thread idle at its end. Returns what each
    would return from `chunked`: the same chunks and kernels, the same bits. Where `chunked` would
    run neither on numba's threads (one thread, a layer other than OpenMP and TBB), they run one
    after the other through it."""
    a = _compiled_bounds(first.n, first.min_rows, threads(), MIN_ROWS, PIECES)
    b = _compiled_bounds(second.n, second.min_rows, threads(), MIN_ROWS, PIECES)
    if a[0] is None and b[0] is None:
        return chunked(*first), chunked(*second)
    _numba_threads(max(a[1], b[1]))
    bounds = [_chunk_bounds(p.n, p.min_rows, threads(), MIN_ROWS, PIECES) for p in (first, second)]
    key = (first.kernel, first.spec, first.returns, second.kernel, second.spec, second.returns)
    plan = _PAIR_PLANS.get(key)
    try:
        flat = (plan[1](first.args), plan[2](second.args)) if plan is not None else None
    except _Mismatch:                   # the arguments nest otherwise than last time: planned anew
        plan = None
    if plan is None:
        for p in (first, second):
            _checked(p.spec, p.args)
        names = [_loop_key(p.kernel, p.spec, p.args, p.returns) for p in (first, second)]
        plan = _PAIR_PLANS[key] = (_pair_loop(*names), *(_flattener(_CHUNK_KERNELS[k][2]) for k in names))
        flat = (plan[1](first.args), plan[2](second.args))
    outs = [np.empty((len(bd) - 1, 1 if p.returns == "first" else p.returns)) for bd, p in zip(bounds, (first, second))]
    plan[0](*bounds, *outs, *flat[0], *flat[1])
    return _returned(outs[0], first.returns), _returned(outs[1], second.returns)


_PAIR_PLANS = {}        # both passes' (kernel, spec, returns) -> (their compiled loop, their arguments' flatteners)


class _Mismatch(Exception):
    """Arguments that nest otherwise than the plan's (`_flattener`)."""


def _plan(kernel, spec, args, returns):
    """The compiled chunk loop of a `chunked` pass and a function that flattens its arguments
    into the loop's parameters (`_flattener`), made once per kernel, spec and returns: walking the
    arguments' nesting at every call cost a pass 5-20 µs of Python (the more after a pass that
    has evicted the interpreter from the caches), each step several."""
    key = _loop_key(kernel, spec, args, returns)
    plan = _PLANS[kernel, spec, returns] = _chunk_loop(key), _flattener(_CHUNK_KERNELS[key][2])
    return plan


def _loop_key(kernel, spec, args, returns):
    """The key of a pass's call in a compiled loop (`_chunk_call`), registered with its kernel,
    spec, the nesting of its arguments and what it returns (`_CHUNK_KERNELS`)."""
    leaves = []
    shape = _shape(args, leaves)
    if len(leaves) > LEAVES:
        raise ValueError(f"chunked: {len(leaves)} arrays and numbers, more than {LEAVES}")
    key = f"{kernel_name(kernel)}:{spec}:{shape}:{returns}"
    _CHUNK_KERNELS[key] = kernel, spec, shape, returns
    return key


@functools.lru_cache(maxsize=None)
def _flattener(shape):
    """A function of a `chunked` pass's arguments that nest as ``shape`` (`_shape`'s text):
    their items that are not tuples in order, padded with zeros to `LEAVES` items (the chunk
    loop's parameters); it raises `_Mismatch` where the arguments nest otherwise (tuples as
    `_shape` sees them)."""
    lines, leaves, count = [], [], itertools.count()

    def unpack(name, shape):
        names = [f"x{next(count)}" for _ in shape]
        lines.append(f"if not isinstance({name}, tuple) or len({name}) != {len(shape)}: raise _Mismatch")
        lines.append(f"{''.join(n + ', ' for n in names)}= {name}")
        for n, s in zip(names, shape):
            if isinstance(s, tuple):
                unpack(n, s)
            else:
                lines.append(f"if isinstance({n}, tuple): raise _Mismatch")
                leaves.append(n)

    unpack("args", _parsed(shape, (".",)))
    body = "".join(f"    {line}\n" for line in lines)
    padding = "0, " * (LEAVES - len(leaves))
    namespace = {"_Mismatch": _Mismatch}
    exec(f"def flatten(args):\n{body}    return ({''.join(n + ', ' for n in leaves)}{padding})\n", namespace)
    return namespace["flatten"]


def kernel_name(kernel):
    """A compiled kernel's name, the same in every process: its module and name, and the sizes
    of a `kernel_cache.kernel_factory`'s kernel; outside this package, a hash of its source too
    (the chunk loops are cached under this package's sources only). A closure made otherwise has
    no name of its own: refused."""
    name = getattr(kernel, "kernel_name", None)
    if name is None:
        func = kernel.py_func
        name = f"{func.__module__}.{func.__qualname__}"
        if not name.startswith(__name__.rpartition(".")[0] + "."):
            name += "#" + hashlib.sha256(inspect.getsource(func).encode()).hexdigest()[:16]
    if "<locals>" in name:
        raise ValueError(f"chunked: {name} is not a module's kernel nor a kernel_factory's")
    return name


_SLICES = {"r": "{a}[lo:hi]", "i": "{a}[lo:hi + 1]", "k": "{a}[:, lo:hi]", "n": "{a}[c]", "w": "{a}", "c": None}


@functools.lru_cache(maxsize=None)
def _parsed(spec, letters=tuple(_SLICES) + ("l", "h")):
    """A `chunked` spec (or an arguments' `_shape`, its letters ``.``) as a tuple of letters and
    tuples (the bracketed groups)."""
    stack = [[]]
    for letter in spec:
        if letter == "(":
            stack.append([])
        elif letter == ")" and len(stack) > 1:
            group = tuple(stack.pop())
            stack[-1].append(group)
        elif letter in letters:
            stack[-1].append(letter)
        else:
            raise ValueError(f"chunked: spec {spec!r}: {letter!r} unknown or unmatched")
    if len(stack) != 1:
        raise ValueError(f"chunked: spec {spec!r}: a bracket not closed")
    return tuple(stack[0])


def _shape(args, leaves):
    """The nesting of the tuple ``args`` as text, ``.`` an item that is not a tuple, its tuples in
    brackets; its items that are not tuples appended to ``leaves``, in order. The compiled chunk
    loop takes them as parameters of their own (`_chunk_loop`) and puts the tuples back together
    per chunk."""
    text = []
    for a in args:
        if isinstance(a, tuple):
            text.append(f"({_shape(a, leaves)})")
        else:
            leaves.append(a)
            text.append(".")
    return "".join(text)


def _sliced(spec, args, lo, hi, c):
    """The arguments of chunk c (`chunked`), in Python (``spec`` as `_parsed` gives it)."""
    out, taken = [], iter(args)
    for letter in spec:
        if letter in ("l", "h"):
            out.append(lo if letter == "l" else hi)
            continue
        a = next(taken)
        out.append(tuple(_sliced(letter, a, lo, hi, c)) if isinstance(letter, tuple) else a[lo:hi] if letter == "r"
                   else a[lo:hi + 1] if letter == "i" else csr_rows(a, lo, hi) if letter == "c"
                   else a[:, lo:hi] if letter == "k" else a[c] if letter == "n" else a)
    return out


def _sliced_code(spec, shape, leaves):
    """The arguments of a chunk (`chunked`) as compiled code, from the loop's flat tuple ``args``:
    ``spec`` and the arguments' ``shape`` as `_parsed` gives them, ``leaves`` the numbers of the
    flat items in order (an iterator)."""
    parts, shapes = [], iter(shape)
    for letter in spec:
        if letter in ("l", "h"):
            parts.append("lo" if letter == "l" else "hi")
            continue
        parts.append(_argument_code(letter, next(shapes), leaves))
    return ", ".join(parts)


def _argument_code(letter, shape, leaves):
    """One argument of a chunk as compiled code (`_sliced_code`)."""
    if isinstance(letter, tuple) or (letter in ("w", "c") and shape != "."):
        if isinstance(letter, tuple) and len(letter) != len(shape) or letter == "c" and len(shape) != 3:
            raise ValueError(f"chunked: {letter!r} given a tuple of {len(shape)}")
        if letter == "c":
            indptr, indices, data = (f"args[{next(leaves)}]" for _ in range(3))
            return f"({indptr}[lo:hi + 1], {indices}, {data})"
        items = letter if isinstance(letter, tuple) else ("w",) * len(shape)
        return "(" + "".join(f"{_argument_code(k, s, leaves)}, " for k, s in zip(items, shape)) + ")"
    if shape != ".":
        raise ValueError(f"chunked: {letter!r} given a tuple")
    return _SLICES[letter].format(a=f"args[{next(leaves)}]")


_CHUNK_KERNELS = {}             # key of a `chunked` loop -> (kernel, spec, shape, returns), for its typing


def _chunk_call(key, lo, hi, c, out, args):
    raise TypeError("_chunk_call is for compiled code")


@overload(_chunk_call)
def _chunk_call_typed(key, lo, hi, c, out, args):
    """The call of a `chunked` loop's kernel on chunk c = (lo, hi), its arguments sliced as its
    spec says and what it returns written into out[c], written out as code once per key (a
    string literal: the kernel, its spec and returns, `_CHUNK_KERNELS`)."""
    if not isinstance(key, types.StringLiteral):
        return None                     # not literal: typed again with the literal
    kernel, spec, shape, returns = _CHUNK_KERNELS[key.literal_value]
    call = f"kernel({_sliced_code(_parsed(spec), _parsed(shape, ('.',)), iter(range(len(args))))})"
    if returns == "first":
        body = f"b = {call}\n    out[c, 0] = lo + b if b >= 0 else -1"
    elif returns == 1:
        body = f"out[c, 0] = {call}"
    elif returns:
        body = f"r = {call}\n" + "".join(f"    out[c, {j}] = r[{j}]\n" for j in range(returns))
    else:
        body = call
    namespace = {"kernel": kernel}
    exec(f"def chunk_call(key, lo, hi, c, out, args):\n    {body}\n", namespace)
    return namespace["chunk_call"]


LEAVES = 32             # the arrays and numbers a `chunked` pass may take, its tuples' items counted


@kernel_factory(parallel=True)
def _chunk_loop(key):                   # key: a string literal, `_chunk_call`'s
    def chunk_loop(bounds, out, a0, a1, a2, a3, a4, a5, a6, a7, a8, a9, a10, a11, a12, a13, a14, a15, a16, a17,
                   a18, a19, a20, a21, a22, a23, a24, a25, a26, a27, a28, a29, a30, a31):
        # each array a parameter of its own: a tuple of tuples is refused in a prange, and a tuple
        # of arrays of several kinds handed to numba's threads as one value corrupted the heap
        # (free(): invalid next size, a DCU step after a CTU one; tests/test_threads.py)
        n = len(bounds) - 1
        counter = np.zeros(1, np.int64)
        for _ in prange(n):                 # each thread takes chunks until none is left
            c = take_chunk(counter)
            while c < n:
                _chunk_call(key, bounds[c], bounds[c + 1], c, out,
                            (a0, a1, a2, a3, a4, a5, a6, a7, a8, a9, a10, a11, a12, a13, a14, a15, a16, a17, a18,
                             a19, a20, a21, a22, a23, a24, a25, a26, a27, a28, a29, a30, a31))
                c = take_chunk(counter)
    return chunk_loop


@kernel_factory(parallel=True)
def _pair_loop(key_a, key_b):           # `together`: the keys of the two passes' calls (`_chunk_call`)
    def pair_loop(bounds_a, bounds_b, out_a, out_b, a0, a1, a2, a3, a4, a5, a6, a7, a8, a9, a10, a11, a12, a13,
                  a14, a15, a16, a17, a18, a19, a20, a21, a22, a23, a24, a25, a26, a27, a28, a29, a30, a31, b0, b1,
                  b2, b3, b4, b5, b6, b7, b8, b9, b10, b11, b12, b13, b14, b15, b16, b17, b18, b19, b20, b21, b22,
                  b23, b24, b25, b26, b27, b28, b29, b30, b31):
        n_a = len(bounds_a) - 1
        n = n_a + len(bounds_b) - 1
        counter = np.zeros(1, np.int64)
        for _ in prange(n):                 # each thread takes chunks until none is left, the first pass's first
            c = take_chunk(counter)
            while c < n:
                if c < n_a:
                    _chunk_call(key_a, bounds_a[c], bounds_a[c + 1], c, out_a,
                                (a0, a1, a2, a3, a4, a5, a6, a7, a8, a9, a10, a11, a12, a13, a14, a15, a16, a17, a18,
                                 a19, a20, a21, a22, a23, a24, a25, a26, a27, a28, a29, a30, a31))
                else:
                    k = c - n_a
                    _chunk_call(key_b, bounds_b[k], bounds_b[k + 1], k, out_b,
                                (b0, b1, b2, b3, b4, b5, b6, b7, b8, b9, b10, b11, b12, b13, b14, b15, b16, b17, b18,
                                 b19, b20, b21, b22, b23, b24, b25, b26, b27, b28, b29, b30, b31))
                c = take_chunk(counter)
    return pair_loop


def add_scaled(x, a, y, out=None):
    """x + a * y for arrays of one shape (n, ...) and a scalar a, rows in parallel chunks: entry
    by entry numpy's operations (a * y, then the sum), the same bits; x and y may be strided
    views (a column block of a state array); into ``out`` (contiguous) if given."""
    out = np.empty(x.shape) if out is None else out
    x2, y2, out2 = x.reshape(len(x), -1), y.reshape(len(y), -1), out.reshape(len(out), -1)
    chunked(len(out), _add_scaled, "rwrr", (x2, float(a), y2, out2))
    return out


@njit(cache=True, nogil=True)
def _add_scaled(x, a, y, out):
    for r in range(len(out)):
        for c in range(out.shape[1]):
            out[r, c] = x[r, c] + a * y[r, c]


def take_rows(X, index, out):
    """out[r] = X[index[r]], zero where index[r] < 0, for X (m, ...) and ``out`` holding len(index)
    such rows (C order, any leading shape), in parallel chunks: a gather (e.g. particles into
    padded slots), copies only."""
    X2, out2 = X.reshape(len(X), -1), out.reshape(len(index), -1)
    chunked(len(index), _take_rows, "wrr", (X2, index, out2))
    return out


@njit(cache=True, nogil=True)
def _take_rows(X, index, out):
    for r in range(len(index)):
        j = index[r]
        for c in range(out.shape[1]):
            out[r, c] = X[j, c] if j >= 0 else 0.0


def csr_rows(matrix, lo, hi):
    """Rows lo:hi of a CSR triple (indptr, indices, data) (the offsets stay absolute)."""
    indptr, indices, data = matrix
    return indptr[lo:hi + 1], indices, data


def csr(matrix):
    """The CSR triple (indptr, indices, data) of a scipy CSR matrix (a triple as it is)."""
    return matrix if isinstance(matrix, tuple) else (matrix.indptr, matrix.indices, matrix.data)


_NONE = np.zeros(0)             # no scale


@njit(cache=True, inline="always")
def row_product(indptr, indices, data, X, r, u, nc):
    """u[:nc] = row r of a CSR matrix times X, summed in CSR order from 0 as `matmul` (and
    scipy's product) sums it: for a pass that needs the product's rows one at a time (the law's
    pass at the particles reads their states through DGMPM's back map)."""
    for c in range(nc):
        u[c] = 0.0
    csr_row_add((indptr, indices, data), data, X, r, u, nc, False)     # no scale: ``data`` stands in, unread


def matmul(A, X, out=None, add=False, scale=None):
    """A diag(scale) X for a CSR matrix A (n, m) (a scipy matrix or a tuple, `csr`) and dense X
    (m, k) or (m,): into ``out`` (n, k) or (n,) if given, added to it if ``add``. Each row is one
    compiled sum in CSR order, from 0 (or from out's row if ``add``), of w * X[j] (w * (scale[j] *
    X[j]) with a scale): the bits of scipy's A @ X (of A @ (scale[:, None] * X)); rows in parallel
    chunks. X and out may be strided views (a column of a state array)."""
    indptr, indices, data = csr(A)
    n = len(indptr) - 1
    if out is None:
        if add:
            raise ValueError("matmul: add=True needs out")
        out = np.empty((n,) + X.shape[1:])
    vector = X.ndim == 1
    X2, out2 = (X[:, None], out[:, None]) if vector else (X, out)
    kernel = _matmul(X2.shape[1] if X2.shape[1] <= SCRATCH_WIDTH else None, int(scale is not None))
    s = _NONE if scale is None else np.asarray(scale, dtype=float)
    chunked(n, kernel, "iwwwwwr", (indptr, indices, data, s, X2, add, out2))
    return out


SCRATCH_WIDTH = 81              # widths up to this get a kernel of their own (the loops unrolled)


@kernel_factory
def _matmul(nc, scaled):                # nc: a literal width (None: read at run time); scaled: 0 or 1
    if nc is None:                      # wide X: the sums kept in out's row
        def matmul(indptr, indices, data, scale, X, add, out):
            for r in range(len(indptr) - 1):
                if not add:
                    out[r, :] = 0.0
                for k in range(indptr[r], indptr[r + 1]):
                    j, w = indices[k], data[k]
                    s = scale[j] if scaled else 1.0
                    for c in range(X.shape[1]):
                        out[r, c] += w * (s * X[j, c]) if scaled else w * X[j, c]
        return matmul

    def matmul(indptr, indices, data, scale, X, add, out):
        u = scratch((nc,))                  # the row's sums, in registers
        for r in range(len(indptr) - 1):
            for c in range(nc):
                u[c] = out[r, c] if add else 0.0
            csr_row_add((indptr, indices, data), scale, X, r, u, nc, scaled)
            for c in range(nc):
                out[r, c] = u[c]
    return matmul


@njit(cache=True, inline="always")
def csr_row_add(A, scale, X, r, u, nc, scaled):
    """u[:nc] += row r of A diag(scale) X (A a CSR triple; ``scale`` read only if ``scaled``), in
    CSR order: the sum `matmul` forms for each row, for a pass that uses the row where it is
    formed (`dgfem.cell_update`)."""
    indptr, indices, data = A
    for k in range(indptr[r], indptr[r + 1]):
        j, w = indices[k], data[k]
        if scaled:
            s = scale[j]
            for c in range(nc):
                u[c] += w * (s * X[j, c])
        else:
            for c in range(nc):
                u[c] += w * X[j, c]


class Transposed:
    """A^T for CSR matrices A (n, n_cols) on one pattern (indptr, indices), applied without being
    stored (`matmul_T`): the output rows (A's columns) split into chunks, each with the range of
    A's rows that reach it. Cheap to make (one pass over the pattern, in parallel): for a pattern
    that changes every step (MPM's shape functions). Always right; fast where the rows reaching a
    chunk are a narrow range (particles numbered cell by cell, as they are: at 256^2 the two
    chunks' ranges overlap by ~1 % of the particles)."""

    def __init__(self, indptr, indices, n_cols):
        self.indptr, self.indices, self.n_cols = indptr, indices, n_cols
        self.chunks = chunks(n_cols)
        starts = np.array([lo for lo, _ in self.chunks] + [n_cols], np.int64)
        n = len(indptr) - 1
        parts = chunks(n)
        first = np.full((len(parts), len(self.chunks)), n, np.int64)     # per chunk of A's rows
        last = np.zeros((len(parts), len(self.chunks)), np.int64)
        chunked(n, _row_ranges, "iwlwnn", (indptr, indices, starts, first, last))
        self.first, self.last = first.min(axis=0), last.max(axis=0)


def matmul_T(A, data, X, out=None, add=False, scale=None):
    """A^T diag(scale) X for the `Transposed` pattern A and the data of one matrix on it (nnz,),
    X (n, k) or (n,): into ``out`` (n_cols, k) if given, added to it if ``add``. Each chunk of
    output rows runs over A's rows that reach it, in order, adding w * X[r] (w * (scale[r] *
    X[r])) into its own rows only: every output row is the sum, from 0 (or from out's row), of
    its terms in the order of A's rows, as scipy's A.T @ X sums them (the same bits), for any
    thread count; no transpose is stored."""
    if out is None:
        if add:
            raise ValueError("matmul_T: add=True needs out")
        out = np.empty((A.n_cols,) + X.shape[1:])
    vector = X.ndim == 1
    X2, out2 = (X[:, None], out[:, None]) if vector else (X, out)
    kernel = _scatter(X2.shape[1] if X2.shape[1] <= SCRATCH_WIDTH else None, int(scale is not None))
    s = _NONE if scale is None else np.asarray(scale, dtype=float)
    if len(A.chunks) != len(chunks(A.n_cols)):
        raise ValueError("matmul_T: the thread count changed since the pattern was made")
    chunked(A.n_cols, kernel, "wwwwwnnlhww", (A.indptr, A.indices, data, s, X2, A.first, A.last, add, out2))
    return out


@njit(cache=True, nogil=True)
def _row_ranges(indptr, indices, lo, starts, first, last):
    """For rows lo + r of A: the first and last + 1 row reaching each column chunk (kept in this
    thread's own arrays while it runs: the chunks' outputs share a cache line)."""
    f, l = first.copy(), last.copy()
    for r in range(len(indptr) - 1):
        for k in range(indptr[r], indptr[r + 1]):
            j, c = indices[k], 0
            while j >= starts[c + 1]:
                c += 1
            f[c] = min(f[c], lo + r)
            l[c] = max(l[c], lo + r + 1)
    first[:] = f
    last[:] = l


@kernel_factory
def _scatter(nc, scaled):               # nc: a literal width (None: read at run time); scaled: 0 or 1
    def scatter(indptr, indices, data, scale, X, first, last, lo, hi, add, out):
        width = X.shape[1] if nc is None else nc
        if not add:
            for j in range(lo, hi):
                for c in range(width):
                    out[j, c] = 0.0
        for r in range(first, last):
            s = scale[r] if scaled else 1.0
            for k in range(indptr[r], indptr[r + 1]):
                j = indices[k]
                if j >= lo and j < hi:
                    w = data[k]
                    for c in range(width):
                        out[j, c] += w * (s * X[r, c]) if scaled else w * X[r, c]
    return scatter
