"""What the thread pool costs per pass, and what a compiled chunk loop does (docs/bench/session20.md).

    python bench/pool_vs_prange.py [--threads 2,4,8,16] [--json FILE]

On the bench's plate (DGMPM CTU, 256^2), prints:
- the throughput of independent multiply-adds on t threads (whether the threads get cores of
  their own);
- per chunked pass of a step on the pool (`parallel.rows`; the step's compiled chunk loops turned
  off), its time and how much longer it takes than its longest chunk, on each thread count (the
  pool's hand-over: wake-up, GIL, dispatch);
- the particles' rows (`dgmpm_kernels.cell_update`) run per chunk through the pool and from the
  compiled chunk loop (`parallel.compiled_chunks`) over the same chunk bounds, alternating, with
  a check that both give the same bits.

OpenMP's workers wait passively here (``OMP_WAIT_POLICY``), unless it is set: spinning workers
would hold the cores that the pool's workers need. Timings are measurements on the machine at
hand, not test results.
"""
import argparse
import collections
import json
import os
import sys
import threading
import time

os.environ.setdefault("OMP_WAIT_POLICY", "PASSIVE")

import numba  # noqa: E402
import numpy as np  # noqa: E402
from numba import njit  # noqa: E402

from skdgmpm import bench, parallel  # noqa: E402
from skdgmpm import dgmpm_kernels  # noqa: E402
from skdgmpm.build import build  # noqa: E402


@njit(nogil=True, fastmath=True)
def _burn(n):
    a = np.empty(16)
    for k in range(16):
        a[k] = 1.0 + 1e-9 * k
    for _ in range(n):
        for k in range(16):
            a[k] = a[k] * 0.9999999 + 1e-7
    return a.sum()


def compute_throughput(counts, n=150_000_000):
    """{t: throughput of t threads each running the same register-bound loop, over one's}."""
    def run(t):
        workers = [threading.Thread(target=_burn, args=(n,)) for _ in range(t)]
        t0 = time.perf_counter()
        for w in workers:
            w.start()
        for w in workers:
            w.join()
        return time.perf_counter() - t0
    _burn(10)
    one = run(1)
    return {t: t * one / run(t) for t in counts}


def pass_costs(stepper, state, counts, steps=8):
    """Per thread count: the step's time and, per chunked pass (named by the function that asks
    for it), its time and its time beyond the longest chunk (medians, ms). Also returns the
    state."""
    plain, log = parallel.rows, collections.defaultdict(list)

    def timed_rows(n, call, min_rows=None):
        caller = sys._getframe(1)
        while caller.f_globals.get("__name__") == parallel.__name__:      # past `chunked`
            caller = caller.f_back
        chunk = []

        def timed(lo, hi):
            t0 = time.perf_counter()
            result = call(lo, hi)
            chunk.append(time.perf_counter() - t0)
            return result
        t0 = time.perf_counter()
        results = plain(n, timed, min_rows)
        log[caller.f_code.co_name].append((time.perf_counter() - t0, max(chunk)))
        return results

    out, compiled = {}, parallel.compiled_chunks
    for t in counts:
        parallel.set_threads(t)
        bench._use_threads(t)
        parallel.rows = timed_rows
        parallel.compiled_chunks = lambda n, min_rows=None: None      # the pool's passes, not numba's loops
        try:
            state = stepper.step(state)
            log.clear()
            t0 = time.perf_counter()
            for _ in range(steps):
                state = stepper.step(state)
            step = (time.perf_counter() - t0) / steps
        finally:
            parallel.rows, parallel.compiled_chunks = plain, compiled
        out[t] = {"step_ms": 1e3 * step,
                  "passes": {k: 1e3 * float(np.median([a for a, _ in v])) for k, v in log.items()},
                  "overhead_ms_per_pass": {k: 1e3 * float(np.median([a - b for a, b in v])) for k, v in log.items()}}
    return out, state


def update_drivers(stepper, state, counts, rounds=80):
    """The particles' rows of a forward Euler step from ``state`` (`dgmpm_kernels.cell_update`)
    through the pool and from numba's compiled chunk loop over the same chunks, per thread count
    (median ms, same bits); and in one call on one thread."""
    grid_state = stepper.project(state)
    dt = stepper.time_step(state)
    rows, _ = stepper.euler_stage(grid_state, state.U, state.t, dt, dt, rows=True)
    kernel = dgmpm_kernels._cell_update(*rows.sizes)
    pooled, compiled = np.empty_like(state.U), np.empty_like(state.U)
    times = []
    for _ in range(60):
        t0 = time.perf_counter()
        kernel(tuple(rows), pooled)
        times.append(time.perf_counter() - t0)
    out = {"one_thread_ms": 1e3 * float(np.median(times))}
    loop = parallel.compiled_chunks

    def through_pool():
        parallel.compiled_chunks = lambda n, min_rows=None: None
        try:
            dgmpm_kernels.cell_update(rows, pooled)
        finally:
            parallel.compiled_chunks = loop

    for t in counts:
        parallel.set_threads(t)
        bench._use_threads(t)
        sides = [through_pool, lambda: dgmpm_kernels.cell_update(rows, compiled)]
        _, wall = bench.alternate(sides, rounds, warmup=2)
        out[t] = {"pool_ms": 1e3 * float(np.median(wall[0])), "prange_ms": 1e3 * float(np.median(wall[1])),
                  "same_bits": bool(np.array_equal(pooled, compiled)), "layer": numba.threading_layer()}
    return out


def main():
    parser = argparse.ArgumentParser()
    parser.add_argument("--threads", default="2,4,8,16")
    parser.add_argument("--json")
    args = parser.parse_args()
    counts = [int(t) for t in args.threads.split(",")]
    result = {"cpus": os.cpu_count(), "numba": numba.__version__}
    result["compute_throughput"] = compute_throughput([1] + counts)
    print("independent multiply-adds, throughput over one thread:",
          ", ".join(f"{t}: x{v:.2f}" for t, v in result["compute_throughput"].items()))
    disc = build(bench.scene_for("dgmpm-ctu", 256))
    state = disc.initial
    parallel.set_threads(1)
    for _ in range(3):
        state = disc.stepper.step(state)
    result["pool"], state = pass_costs(disc.stepper, state, [1] + counts)
    for t, r in result["pool"].items():
        parts = ", ".join(f"{k} {v:.3f} (+{r['overhead_ms_per_pass'][k]:.3f})" for k, v in r["passes"].items())
        print(f"{t} thread(s): step {r['step_ms']:.2f} ms; passes, ms (beyond the longest chunk): {parts}")
    result["cell_update"] = update_drivers(disc.stepper, state, counts)
    print(f"cell update, one thread: {result['cell_update']['one_thread_ms']:.3f} ms")
    for t in counts:
        r = result["cell_update"][t]
        print(f"{t} threads: pool {r['pool_ms']:.3f} ms, prange ({r['layer']}) {r['prange_ms']:.3f} ms, "
              f"same bits: {r['same_bits']}")
    if args.json:
        with open(args.json, "w") as f:
            json.dump(result, f, indent=1)


if __name__ == "__main__":
    main()
