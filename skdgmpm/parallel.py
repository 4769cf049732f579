"""Threads for the compiled passes: a loop over independent rows (faces, nodes, points) split into
contiguous chunks that run at once, one per thread.

Every pass that is chunked computes each row from its inputs alone and writes that row only (no
scatter into another row, no running sum over rows): a row's value does not depend on which
chunk, or which thread, computes it, so the results are bit-identical for any thread count. A
sum over rows (e.g. the transverse corrections an edge receives from its neighbours) is made a
gather of its own, each row summing its terms in a fixed order. The kernels are compiled with
``nogil`` (`kernel_cache.kernel_factory`): Python threads run them in parallel.

    out = np.empty(...)
    parallel.rows(n, lambda lo, hi: kernel(rows(a, lo, hi), csr_rows(T, lo, hi), out[lo:hi]))

The thread count: `set_threads` (the scene key ``run.threads``, ``skdgmpm run --threads``), else
$SKDGMPM_THREADS, else every core this process may use. A loop shorter than `MIN_ROWS` per thread
runs in the calling thread (small scenes pay nothing); study workers run one thread each.
"""
import os
from concurrent.futures import ThreadPoolExecutor

MIN_ROWS = 2048         # rows per chunk below which a loop stays in one thread

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
    global _threads, _pool
    if n is not None and (not isinstance(n, int) or isinstance(n, bool) or n < 1):
        raise ValueError(f"threads = {n!r}: expected a whole number >= 1")
    previous, _threads = _threads, n
    if _pool is not None and _pool._max_workers != threads() - 1:
        _pool.shutdown()
        _pool = None
    return previous


def bounds(n, parts):
    """``parts`` contiguous (lo, hi) chunks of range(n), as equal as can be."""
    return [(n * k // parts, n * (k + 1) // parts) for k in range(parts)]


def rows(n, call):
    """``call(lo, hi)`` over contiguous chunks of range(n), in parallel; returns the results in
    chunk order (the first chunk's first)."""
    parts = min(threads(), max(1, n // MIN_ROWS))
    if parts == 1:
        return [call(0, n)]
    global _pool
    if _pool is None:
        _pool = ThreadPoolExecutor(max_workers=threads() - 1, thread_name_prefix="skdgmpm")
    chunks = bounds(n, parts)
    futures = [_pool.submit(call, lo, hi) for lo, hi in chunks[1:]]
    first = call(*chunks[0])            # the calling thread takes the first chunk itself
    return [first] + [f.result() for f in futures]


def first_bad(n, call):
    """`rows` for a pass that returns the first failing row of its chunk (or -1): the first
    failing row of range(n), or -1 (the same as one serial pass would return)."""
    for (lo, _), bad in zip(bounds(n, min(threads(), max(1, n // MIN_ROWS))), rows(n, call)):
        if bad >= 0:
            return lo + bad
    return -1


def csr_rows(matrix, lo, hi):
    """Rows lo:hi of a CSR triple (indptr, indices, data) (the offsets stay absolute)."""
    indptr, indices, data = matrix
    return indptr[lo:hi + 1], indices, data
