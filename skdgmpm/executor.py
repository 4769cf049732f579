"""The study executor: independent runs in parallel on local processes, or on a Dask cluster.

>>> from skdgmpm.executor import make_executor
>>> with make_executor(workers=2) as pool:
...     results = list(pool.map(abs, [-1, -2]))

``make_executor(workers)`` returns a `concurrent.futures` executor: a `ProcessPoolExecutor` with
``workers`` processes (default: the machine's cores), or, for ``workers=1``, a serial stand-in with
the same interface that runs each task in the calling process when it is submitted (no pickling,
exceptions and breakpoints where you expect them). Tasks must be picklable top-level functions
for the process pool. ``make_executor(dask="tcp://host:8786")`` submits to an existing Dask
distributed scheduler instead (its workers need skdgmpm installed), so studies scale past one
machine; the returned executor is Dask's `concurrent.futures` adapter.
"""
import os
from concurrent.futures import Executor, Future, ProcessPoolExecutor, as_completed

from .errors import InputError
from .parallel import set_threads


class SerialExecutor(Executor):
    """`concurrent.futures.Executor` that runs each task at ``submit`` in this process."""

    def submit(self, fn, /, *args, **kwargs):
        future = Future()
        try:
            future.set_result(fn(*args, **kwargs))
        except BaseException as exc:           # noqa: BLE001 - handed to the caller via the future
            if isinstance(exc, KeyboardInterrupt):
                raise
            future.set_exception(exc)
        return future


def map_ordered(pool, fn, tasks, bar, labels=None):
    """``fn(*task)`` for every task on ``pool``; the results in task order, ``bar`` advanced as
    each run finishes (at submission on a serial executor, which runs it then). ``labels`` (one
    per task) become the bar's description as the tasks are submitted."""
    results, pending = [None] * len(tasks), {}
    for k, task in enumerate(tasks):
        if labels is not None:
            bar.set_description(labels[k])
        future = pool.submit(fn, *task)
        if future.done():
            results[k] = future.result()
            bar.update(1)
        else:
            pending[future] = k
    for future in as_completed(pending):
        results[pending[future]] = future.result()
        bar.update(1)
    return results


def make_executor(workers=None, dask=None, timeout="10s"):
    """A process pool of ``workers`` processes (None: ``os.cpu_count()``), a serial executor for
    ``workers=1``, or, with ``dask`` = a scheduler address, an executor on that Dask cluster."""
    if dask is not None:
        return _dask_executor(dask, timeout)
    if workers is None:
        workers = os.cpu_count() or 1
    if not (isinstance(workers, int) and not isinstance(workers, bool) and workers >= 1):
        raise InputError(f"--workers {workers!r}: expected a positive integer")
    if workers == 1:
        return SerialExecutor()
    # the workers share the cores: one thread each (`skdgmpm.parallel`)
    return ProcessPoolExecutor(max_workers=workers, initializer=set_threads, initargs=(1,))


def _dask_executor(address, timeout):
    try:
        from distributed import Client
    except ImportError:
        raise InputError(f"--dask {address}: the 'distributed' package is not installed "
                         f"(pip install 'skdgmpm[dask]')") from None
    try:
        client = Client(address, timeout=timeout)
    except (OSError, TimeoutError) as exc:
        raise InputError(f"--dask {address}: cannot reach the scheduler ({exc})") from None
    executor = client.get_executor()
    shutdown = executor.shutdown

    def close(wait=True, **kwargs):             # the client belongs to the executor
        shutdown(wait=wait)
        client.close()

    executor.shutdown = close
    return executor
