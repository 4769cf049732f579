"""Threads for the compiled passes: a loop over independent rows (faces, nodes, points) split into
contiguous chunks, `PIECES` per thread, that the threads take in turn, each the next chunk left
as soon as it is free (`rows`): a thread that wakes late, or that the host slows, takes fewer
chunks, and no pass waits for a worker that finds none left.

Every pass that is chunked computes each row from its inputs alone and writes that row only (no
scatter into another row, no running sum over rows): a row's value does not depend on which
chunk, or which thread, computes it, so the results are bit-identical for any thread count. A
sum over rows (e.g. the transverse corrections an edge receives from its neighbours) is made a
gather of its own, each row summing its terms in a fixed order. The kernels are compiled with
``nogil`` (`kernel_cache.kernel_factory`): Python threads run them in parallel.

    out = np.empty(...)
    parallel.rows(n, lambda lo, hi: kernel(rows(a, lo, hi), csr_rows(T, lo, hi), out[lo:hi]))

Sparse products: `matmul` (CSR times dense, each output row its own sum, in CSR order, as
scipy's product sums it) is the one product every step uses; a transposed product A^T X is a
`matmul` with A^T stored as CSR at set-up (scipy's ``A.T.tocsr()``: each row's entries in the
order of A's rows, as scipy's A.T @ X visits them), so a scatter into rows becomes a gather with
the same bits; where A changes every step (MPM's shape functions), `matmul_T` applies A^T
without storing it, each chunk of output rows scattering into its own rows only.

Compiled chunk loops: DGMPM with one particle per cell runs its Euler step's chunked passes (faces,
cells' corrections, boundary faces, update, law's pass) over the same chunks from a numba ``prange``
(`compiled_chunks`, the loops in `dgmpm_kernels` and `constitutive`, each reaching its kernel
through `kernel_cache.kernel_call`) where numba's threading layer is OpenMP or TBB: its threads
take their chunks without the GIL and without waking from the OS, where each worker of the pool
below wakes and takes the GIL (docs/bench/session20.md). numba deals a ``prange`` out in equal
shares, so each of its threads takes the next chunk left from a counter (`take_chunk`, an atomic
add), as the pool's threads do: a core the host slows takes fewer chunks
(docs/bench/session25.md). The same chunks and kernels: the same bits. All the passes of that
step go one way, so that numba's waiting threads, which spin a while, never hold a core that a
worker of the pool needs.

The thread count: `set_threads` (the scene key ``run.threads``, ``skdgmpm run --threads``), else
$SKDGMPM_THREADS, else every core this process may use. A loop shorter than `MIN_ROWS` per thread
runs in the calling thread (small scenes pay nothing); study workers run one thread each.
"""
import functools
import itertools
import os
import threading
from concurrent.futures import ThreadPoolExecutor

import numba
import numpy as np
from numba import njit, prange, types
from numba.core import cgutils
from numba.extending import intrinsic

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


def rows(n, call):
    """``call(lo, hi)`` over contiguous chunks of range(n), in parallel, each thread taking the
    next chunk not yet taken until none is left; returns the results in chunk order (the first
    chunk's first)."""
    parts = chunks(n)
    return _run(call, parts, team(n))


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
    """The bounds [lo_0, lo_1, ..., n] (int64) of the chunks of range(n) (`chunks`), for
    a compiled chunk loop (a ``prange`` over them calling the kernel on each: `kernel_cache.
    kernel_call`), numba's thread count set to their number; None where the loop is better run
    by `rows`: one chunk, or a threading layer of numba's other than OpenMP and TBB (its
    ``workqueue`` hands chunks over slower than this module's pool, docs/bench/session20.md).
    The same chunks, each computed by the same kernel: the same bits as `rows`. numba's
    threads hand over in microseconds and without the GIL, where the pool's workers each wake
    and take the GIL (0.06-0.2 ms a pass on two threads, 0.8-1.1 ms on sixteen)."""
    bounds, n_threads = _compiled_bounds(n, min_rows, threads(), MIN_ROWS, PIECES)
    if bounds is not None:
        _numba_threads(n_threads)
    return bounds


@functools.lru_cache(maxsize=64)
def _compiled_bounds(n, min_rows, n_threads, *settings):
    """(bounds, numba's thread count) of `compiled_chunks`, made once for each set of what they
    depend on: the loop size, `threads` and the module's ``settings`` (MIN_ROWS, PIECES), passed
    as the cache's key. A step asks five times; making them and setting numba's count anew took
    1-2 % of a DGMPM step on two threads, on one thread. (None, 1) where `rows` runs the loop."""
    parts = chunks(n, min_rows)
    if len(parts) == 1 or not _compiled_layer():
        return None, 1
    return np.array([lo for lo, _ in parts] + [n], np.int64), min(team(n, min_rows), numba.config.NUMBA_NUM_THREADS)


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


def first_bad(n, call):
    """`rows` for a pass that returns the first failing row of its chunk (or -1): the first
    failing row of range(n), or -1 (the same as one serial pass would return)."""
    for (lo, _), bad in zip(chunks(n), rows(n, call)):
        if bad >= 0:
            return lo + bad
    return -1


def add_scaled(x, a, y, out=None):
    """x + a * y for arrays of one shape (n, ...) and a scalar a, rows in parallel chunks: entry
    by entry numpy's operations (a * y, then the sum), the same bits; x and y may be strided
    views (a column block of a state array); into ``out`` (contiguous) if given."""
    out = np.empty(x.shape) if out is None else out
    x2, y2, out2 = x.reshape(len(x), -1), y.reshape(len(y), -1), out.reshape(len(out), -1)
    rows(len(out), lambda lo, hi: _add_scaled(x2[lo:hi], float(a), y2[lo:hi], out2[lo:hi]))
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
    rows(len(index), lambda lo, hi: _take_rows(X2, index[lo:hi], out2[lo:hi]))
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
    for k in range(indptr[r], indptr[r + 1]):
        j, w = indices[k], data[k]
        for c in range(nc):
            u[c] += w * X[j, c]


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
    rows(n, lambda lo, hi: kernel(indptr[lo:hi + 1], indices, data, s, X2, add, out2[lo:hi]))
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
            for k in range(indptr[r], indptr[r + 1]):
                j, w = indices[k], data[k]
                if scaled:
                    s = scale[j]
                    for c in range(nc):
                        u[c] += w * (s * X[j, c])
                else:
                    for c in range(nc):
                        u[c] += w * X[j, c]
            for c in range(nc):
                out[r, c] = u[c]
    return matmul


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
        index = {lo: k for k, (lo, _) in enumerate(parts)}
        rows(n, lambda lo, hi: _row_ranges(indptr[lo:hi + 1], indices, lo, starts, first[index[lo]], last[index[lo]]))
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
    k_of = {lo: k for k, (lo, _) in enumerate(A.chunks)}
    rows(A.n_cols, lambda lo, hi: kernel(A.indptr, A.indices, data, s, X2, A.first[k_of[lo]], A.last[k_of[lo]],
                                         lo, hi, add, out2))
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
