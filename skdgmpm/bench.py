"""Benchmarks: set-up time, wall time per step, per cell, per degree of freedom, particles per
second and peak memory of every method on a 2D plane-strain neo-Hookean impact. Step times are
given as wall time and as the process's CPU time (the same on an idle machine; on a shared one the
CPU time is the one that measures the code).

    skdgmpm bench --sizes 64,128 --methods dgmpm-ctu,ader-dgmpm-1 --steps 5 --json bench.json

Each (method, size) runs in a fresh process, so its peak memory is its own. Set-up is the time to
build the discretisation of the grid (bases, faces, operators, particles, the initial state); the
once-per-process start-up (imports, loading the compiled kernels from numba's disk cache) is
measured apart, on a 4 x 4 run of the same method before it. Step times are the
median over ``steps`` timed steps after ``warmup`` steps. A degree of freedom is one state vector
at a grid node (DG) or at a particle (MPM); per-stage times divide by the right-hand sides one
step evaluates (Euler 1, RK2 2, RK4 4, ADER 1 predictor + corrector). Each row runs on a given
number of threads (``--threads 1,2``; `skdgmpm.parallel`): a one-thread row's CPU time per cell
is the cost per core, and the rows of several thread counts give the speed-up (same bits for
any count). Timings are measurements on the machine at hand, never test results.

A peer row (Clawpack/PyClaw, `skdgmpm.peer`) asked for beside its counterpart (``--methods
dgmpm-ctu,pyclaw-ctu``) also gets a paired measurement at each size (`measure_pair`): one more
fresh process runs both schemes on the same plate, alternating one step of each (ABBA, after
``warmup`` pairs; ours on one thread), so the ratio is taken between steps milliseconds apart
instead of rows seconds apart. It times `pairs_for` (``steps``, at least 30) pairs. The JSON
keeps the rows as they are and adds a top-level ``paired`` list, one dict per (peer, size):
``method`` ("dgmpm-ctu/pyclaw-ctu"), ``pair`` ([ours, peer]), ``cells``, ``pairs``, ``order``;
for each clock (``cpu``, ``wall``) the quartiles of the per-pair ratios ours / peer
(``cpu_ratio_q25``, ``cpu_ratio_median``, ``cpu_ratio_q75``), the ratio of the two medians
(``cpu_medians_ratio``), the median step of each side (``cpu_step_s``: {"ours", "peer"}) and every
timed step (``cpu_s``: {"ours": [...], "peer": [...]}, pair k at index k).

The speed-up of two rows on different thread counts swings as much on a shared host (1.07-1.93
over rounds for the same code), so with several thread counts, one thread among them, every
method but the peer's also gets a paired scaling measurement at each size (`measure_threads`):
one more fresh process builds the plate once and steps one simulation, switching the thread
count between steps (the same bits for any count), one timed step per count a round, the
rounds in the order of the counts and reversed in turn (ABBA for 1, 2), `pairs_for` timed rounds
after ``warmup``. Its speed-up on t threads is taken between steps milliseconds apart: each
round's step on one thread over its step on t. Each timed step follows `SETTLE` untimed steps on
its own count, as every step of a run does: the first step after a switch starts with the caches
the other count left and, on several threads, with numba's workers asleep (on 6 ms steps that
cost the two-thread step 3-8 %). It costs len(threads) x (1 + SETTLE) x (pairs + warmup) steps
per method and size, ~20 s for ADER at 256^2. The JSON adds
a top-level ``threads_paired`` list, one dict per (method, size): ``method``, ``cells``,
``threads`` (the counts, [1, 2]), ``pairs``, ``warmup``, ``order``, ``settle``; for each clock
(``wall``, ``cpu``, and ``switch_wall``: the wall time of the first step after each switch) and
each count t > 1 (keys are strings, "2"), the quartiles of the per-round speed-ups
(``wall_speedup``: {"2": {"q25", "median", "q75", "medians_ratio"}}, the last the median step on
one thread over the median step on t; on the ``cpu`` clock below 1 by the core time the threads
add), the median step of each count (``wall_step_s``: {"1", "2"}) and every timed step
(``wall_s``: {"1": [...], "2": [...]}, round k at index k).
"""
import json
import multiprocessing
import os
import platform
import resource
import statistics
import threading
import time
from typing import NamedTuple

import numpy as np

from . import peer
from .bench_kernels import arithmetic_rows
from .errors import InputError
from .integrators import EVALUATIONS
from .study import L23_LAYOUT

# the plate impact of R18 §7.4 on a square plate: lower quarter of the left face driven at
# 1000 m/s, neo-Hookean steel; long enough that no run reaches its end time
SCENE = "plate_impact_neohookean_2d"
BASE = ["grid.size=[4.0, 4.0]", "run.t_end=1.0"]

METHODS = {
    # R18's 0.7, kept since the first bench (2D limit 0.651: a few steps cannot grow its modes)
    "dgmpm-dcu": ['method.name="dgmpm"', 'method.transverse="dcu"', "method.cfl=0.7", "method.cfl_above_limit=true"],
    "dgmpm-ctu": ['method.name="dgmpm"', 'method.transverse="ctu"', "method.cfl=1.0"],
    "mpm-cd-cpgimp": ['method.name="mpm"', 'method.update="cd"', 'method.shape="cpgimp"', "method.cfl=0.4",
                      "particles.per_cell=2"],
}
for _p in (1, 2, 3):
    METHODS[f"ader-dgmpm-{_p}"] = ['method.name="ader-dgmpm"', f"method.order={_p}", "method.cfl=0.4",
                                   f"particles.per_cell={L23_LAYOUT[_p]}"]
    METHODS[f"ader-dgfem-{_p}"] = ['method.name="ader-dgfem"', f"method.order={_p}", "method.cfl=0.4"]
    METHODS[f"rk-dgfem-{_p}"] = ['method.name="rk-dgfem"', f"method.order={_p}", "method.cfl=0.4",
                                 f'method.integrator="{"rk2" if _p == 1 else "rk4"}"']
# unlimited, S3T3 inverts the edge of the driven zone (where 1000 m/s meets the free face) at step 49
# on any grid, before a paired measurement ends: its row runs with L23's Barth-Jespersen limiter
METHODS["ader-dgmpm-3"] = [*METHODS["ader-dgmpm-3"], 'method.limiter="barth-jespersen"']
# elastoplastic rows: the impact of plate_impact_j2_2d, a small-strain J2 steel driven at 50 m/s
# (history at the points); compare with the neo-Hookean rows of the same method for the cost of
# the history. At the neo-Hookean plate's 1000 m/s the small-strain law inverts the shear band at
# the edge of the driven zone after 51-69 steps on any grid, before a paired measurement ends.
J2 = ['material.law="j2_plasticity"', "material.sigma_y=4e8", "material.H=1e10", "bc.impact.velocity.x=50.0"]
METHODS["dgmpm-ctu-j2"] = [*METHODS["dgmpm-ctu"], *J2]
METHODS["ader-dgmpm-1-j2"] = [*METHODS["ader-dgmpm-1"], *J2]


def scene_for(method, n):
    """The bench's plate on n x n cells, set for ``method`` (a name of `METHODS`)."""
    from .scene import load_scene

    return load_scene(SCENE, [*BASE, f"grid.cells=[{n}, {n}]", *METHODS[method]])


def _measure(method, n, steps, warmup, threads=1):
    """One benchmark in this process, its passes on ``threads`` threads: returns a row (dict)."""
    if method in peer.METHODS:          # Clawpack/PyClaw on the same plate (serial): skdgmpm.peer
        return peer.measure_here(method, n, steps, warmup)
    from . import parallel
    from .build import build

    parallel.set_threads(threads)
    # once per process, not per grid: imports and loading the compiled kernels from numba's
    # cache, paid by a tiny run of the same method (a study building many grids pays it once)
    t0 = time.perf_counter()
    tiny = build(scene_for(method, 4))
    tiny.stepper.step(tiny.initial)
    startup = time.perf_counter() - t0
    base_rss = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss
    scene = scene_for(method, n)
    t0 = time.perf_counter()
    disc = build(scene)
    setup = time.perf_counter() - t0
    stepper, state = disc.stepper, disc.initial
    times, cpu = [], []
    for k in range(warmup + steps):
        if k == warmup:
            stepper.stage_times(reset=True)     # the timed steps' stages only
        t0, c0 = time.perf_counter(), time.process_time()
        state = stepper.step(state)
        if k >= warmup:
            times.append(time.perf_counter() - t0)
            cpu.append(time.process_time() - c0)
    step = statistics.median(times)
    clock = stepper.stage_times()
    per_stage = {name: seconds / steps for name, (seconds, _) in clock.items()}
    # the CFL guard's repeated attempts: the median step hides them, the mean step includes them
    attempts = clock["check"][1] / steps if "check" in clock else None
    cells = int(stepper.grid.submesh.nelements)
    dofs = len(disc.particles) if method.startswith("mpm") else int(stepper.n_dofs)
    stages = EVALUATIONS.get(stepper.integrator, 1)
    peak = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss      # KiB on Linux
    return {"method": method, "cells": cells, "threads": threads, "particles": len(disc.particles), "dofs": dofs,
            "startup_s": startup, "setup_s": setup, "step_s": step, "setup_in_steps": setup / step,
            "us_per_cell_step": 1e6 * step / cells,
            "cpu_us_per_cell_step": 1e6 * statistics.median(cpu) / cells, "s_per_dof_step": step / dofs,
            "s_per_dof_stage": step / dofs / stages, "particles_per_s": len(disc.particles) / step,
            "peak_MiB": peak / 1024, "peak_over_base_MiB": (peak - base_rss) / 1024,
            "bytes_per_cell": 1024 * (peak - base_rss) / cells,
            "step_mean_s": statistics.mean(times), "attempts_per_step": attempts,
            "stage_s": per_stage}                   # mean wall time per step of each stage (its own)


def _child(queue, task, *args):
    try:
        queue.put(task(*args))
    except BaseException as exc:        # report, never hang the parent
        queue.put({"error": f"{type(exc).__name__}: {exc}"})


def _spawned(task, *args):
    """``task(*args)`` in a fresh process (spawned, so its peak memory is its own): its row, or
    ``{"error": ...}``."""
    ctx = multiprocessing.get_context("spawn")
    queue = ctx.Queue()
    proc = ctx.Process(target=_child, args=(queue, task, *args))
    proc.start()
    row = queue.get()
    proc.join()
    return row


def measure(method, n, steps=5, warmup=2, threads=1):
    """Run one benchmark in a fresh process (spawned, so its peak memory is its own)."""
    if method not in METHODS and method not in peer.METHODS:
        raise InputError(f"--methods: {method!r} is not a benchmark (known: {', '.join([*METHODS, *peer.METHODS])})")
    if method in peer.METHODS and not peer.available():
        return peer.missing_row(method, n)
    row = _spawned(_measure, method, n, steps, warmup, threads)
    if "error" in row:
        return {"method": method, "cells": n * n, "threads": threads, "error": row["error"]}
    return row


PAIRS = 30             # the fewest timed pairs (rounds) of a paired measurement (`pairs_for`)


def pairs_for(steps):
    """Timed pairs of a paired measurement: ``steps``, at least `PAIRS`, rounded up to even (ABBA).
    The median of 30 per-pair ratios has a standard error of about a sixth of their interquartile
    range (1.25 sigma / sqrt(30) for a normal spread; quartiles 0.95-1.10 for the peer at 256^2 on
    a shared host: about 0.02), and 30 pairs at 256^2 cost about a second (DGMPM CTU) to ten
    (ADER)."""
    pairs = max(steps, PAIRS)
    return pairs + pairs % 2


def alternate(steps, rounds, warmup, before=None):
    """Time ``steps`` (callables, one step of each side) in turn, each once a round: in their order
    in even rounds, reversed in odd ones (ABBA for two sides), ``warmup`` rounds, then ``rounds``
    timed ones. ``before(i)``, if given, runs untimed before each call of ``steps[i]``. Returns
    the CPU and wall time of every timed call, two arrays (len(steps), rounds): side i, round k."""
    cpu, wall = np.zeros((2, len(steps), rounds))
    order = list(range(len(steps)))
    for k in range(warmup + rounds):
        # ABBA: each of two sides first in half of the rounds, so an order effect (caches, the
        # other side's leftovers; the second step of a peer pair ran 3-6 % slower at 256^2) falls
        # on both alike
        for i in order if k % 2 == 0 else order[::-1]:
            if before is not None:
                before(i)
            t0, c0 = time.perf_counter(), time.process_time()
            steps[i]()
            if k >= warmup:
                wall[i, k - warmup] = time.perf_counter() - t0
                cpu[i, k - warmup] = time.process_time() - c0
    return cpu, wall


def ratios(num, den):
    """The quartiles of the per-round ratios num / den of two sides' step times (arrays, one entry
    a round) and the ratio of their medians: {"q25", "median", "q75", "medians_ratio"}."""
    q25, median, q75 = np.percentile(num / den, [25, 50, 75])
    return {"q25": float(q25), "median": float(median), "q75": float(q75),
            "medians_ratio": float(np.median(num) / np.median(den))}


def measure_pair(method, n, steps=5, warmup=2):
    """The peer ``method`` and its counterpart stepping in turn in one fresh process
    (`peer.measure_pair_here`): a paired row (dict)."""
    row = _spawned(peer.measure_pair_here, method, n, steps, warmup)
    if "error" in row:
        pair = [peer.COUNTERPART[method], method]
        return {"method": "/".join(pair), "pair": pair, "cells": n * n, "threads": 1, "error": row["error"]}
    return row


def _use_threads(n):
    """Switch the passes to ``n`` threads with their workers running: `parallel.set_threads` drops
    a pool too small for n, whose new workers would otherwise start inside the next timed step
    (each blocks on the barrier, so the pool starts all n - 1 of them); a larger one is kept, its
    workers the same from round to round."""
    from . import parallel

    parallel.set_threads(n)
    barrier = threading.Barrier(n, timeout=60)
    parallel.each_thread(n * parallel.MIN_ROWS, lambda lo, hi: barrier.wait())


class Stepping:
    """The simulation of ``disc`` (a `build.build` result) stepped once per call, its state kept
    (``state``): one side of a paired measurement (`alternate`)."""

    def __init__(self, disc):
        self.stepper, self.state = disc.stepper, disc.initial

    def __call__(self):
        self.state = self.stepper.step(self.state)


# Untimed steps on a thread count after each switch, before its timed step: a run steps on one
# count, while the first step after a switch starts with the other count's caches and, from one
# thread to several, numba's workers asleep (a DGMPM CTU step at 256^2 on two threads: 5.84 ms
# after a step on two, 5.99 after one on one, 6.33 after the probe's pause; docs/bench/session54.md)
SETTLE = 1


class Alternated(NamedTuple):
    """What `alternate_threads` measured: the CPU and wall times of the timed steps (len(threads),
    pairs), the final state, the probe's wall times (len(threads), pairs; None without the probe)
    and the wall times of the untimed first step after each switch (len(threads), pairs)."""
    cpu: np.ndarray
    wall: np.ndarray
    state: object
    probe: object
    switched: np.ndarray


def alternate_threads(disc, threads, pairs, warmup, probe_rounds=0):
    """Step the one simulation of ``disc`` (a `build.build` result) on each of the thread counts
    ``threads`` in turn (`alternate`: one timed step per count a round, any count giving the same
    bits), each after one step of its own count that settles the switch (`SETTLE`), timed apart.
    Returns an `Alternated`; the thread setting is restored. With ``probe_rounds``, each round also
    runs the arithmetic probe's work (`_ArithmeticPass`, that many rounds) on each count, among the
    steps (ABBA): its wall times are what the machine gave the threads in those rounds."""
    from . import parallel

    step, T = Stepping(disc), len(threads)
    sides = [step] * T + ([_ArithmeticPass(t, probe_rounds) for t in threads] if probe_rounds else [])
    switched = [[] for _ in threads]

    def before(i):
        if i >= T:              # where the pool runs the probe, on workers started for it (`parallel.restart`)
            parallel.restart()
        _use_threads(threads[i % T])
        if i >= T:              # numba's threads, spinning after a compiled chunk loop, gone to sleep
            time.sleep(PROBE_PAUSE_S)
        else:
            switched[i].append(_timed(step))
            for _ in range(SETTLE - 1):
                step()

    previous = parallel.set_threads(1)
    try:
        cpu, wall = alternate(sides, pairs, warmup, before=before)
    finally:
        parallel.set_threads(previous)
    switched = np.array([s[warmup:] for s in switched])
    return Alternated(cpu[:T], wall[:T], step.state, wall[T:] if probe_rounds else None, switched)


def measure_threads_here(method, n, threads, steps, warmup):
    """The paired scaling of ``method`` on n x n cells in this process (the bench spawns it): one
    simulation stepping on each count of ``threads`` (1 among them) in turn (`alternate_threads`),
    ``warmup`` rounds, then ``pairs_for(steps)`` timed ones. Returns a paired scaling row (dict):
    per count t > 1, the quartiles of the per-round speed-ups (step on 1 thread / step on t) and
    the ratio of the medians, on each clock."""
    from .build import build

    disc = build(scene_for(method, n))
    pairs = pairs_for(steps)
    cpu, wall, _, probe, switched = alternate_threads(disc, threads, pairs, warmup, probe_rounds=PROBE_ROUNDS)
    one = threads.index(1)
    row = {"method": method, "cells": int(disc.stepper.grid.submesh.nelements), "threads": list(threads),
           "pairs": pairs, "warmup": warmup, "order": "ABBA", "settle": SETTLE}
    for clock, times in (("wall", wall), ("cpu", cpu), ("switch_wall", switched)):
        speedup = {str(t): ratios(times[one], times[i]) for i, t in enumerate(threads) if i != one}
        row.update({f"{clock}_speedup": speedup,
                    f"{clock}_step_s": {str(t): float(np.median(times[i])) for i, t in enumerate(threads)},
                    f"{clock}_s": {str(t): times[i].tolist() for i, t in enumerate(threads)}})
    # the machine in the same rounds: the probe's speed-up (t threads do t times the work), and
    # the step's as a fraction of it
    work = probe / np.asarray(threads, dtype=float)[:, None]            # seconds per thread's share
    row["probe_speedup"] = {str(t): ratios(work[one], work[i]) for i, t in enumerate(threads) if i != one}
    row["probe_s"] = {str(t): probe[i].tolist() for i, t in enumerate(threads)}
    row["share_of_probe"] = {str(t): ratios(wall[one] / wall[i], work[one] / work[i])
                             for i, t in enumerate(threads) if i != one}
    return row


def measure_threads(method, n, threads, steps=5, warmup=2):
    """The paired scaling of ``method`` over ``threads`` in one fresh process
    (`measure_threads_here`): a paired scaling row (dict)."""
    row = _spawned(measure_threads_here, method, n, list(threads), steps, warmup)
    if "error" in row:
        return {"method": method, "cells": n * n, "threads": list(threads), "error": row["error"]}
    return row


MEMORY_MIB = 64            # each array of the memory probe: far past the caches


def memory_bandwidth(threads, mib=MEMORY_MIB, repeats=5):
    """GB/s of the triad out = x + a y (`parallel.add_scaled`, three arrays of ``mib`` MiB: read
    two, write one) on each thread count, best of ``repeats``: what a pass bound by memory can
    gain from more threads on this machine (bandwidth may not grow with the cores; `arithmetic`
    gives the other bound)."""
    from . import parallel

    n = mib * 2 ** 20 // 8
    x, y, out = (np.full((n // 64, 64), v) for v in (1.0, 1.0, 0.0))       # rows of 64: a vector loop
    previous, speeds = parallel.set_threads(1), {}
    try:
        for t in threads:
            parallel.set_threads(t)
            parallel.add_scaled(x, 2.5, y, out)             # compiled, pages touched
            best = min(_timed(lambda: parallel.add_scaled(x, 2.5, y, out)) for _ in range(repeats))
            speeds[t] = 3 * 8 * n / best / 1e9
    finally:
        parallel.set_threads(previous)
    return speeds


ARITHMETIC_ROWS = 16384     # each thread's share of the arithmetic probe: 128 kB, in its core's cache


def arithmetic(threads, rounds=200, repeats=5):
    """The speed-up of arithmetic on each thread count: a pass of the steps' kind (`parallel.
    chunked`: numba's compiled chunk loop where the steps' passes run on it, the pool where they
    do) over ARITHMETIC_ROWS numbers a thread, ``rounds`` rounds of exp and sqrt over each chunk's
    rows (in cache; `_ArithmeticPass`), best of ``repeats``; t times the work per second of one
    thread. What a pass bound by its arithmetic can gain from more threads now: on a VM whose
    virtual cores share their host's cores with other guests, less than t (x1.27-1.95 on two
    threads of this project's VM within an hour, docs/bench/session21.md)."""
    from . import parallel

    previous, times = parallel.set_threads(1), {}
    try:
        for t in threads:
            parallel.set_threads(t)
            work = _ArithmeticPass(t, rounds)
            work()                                          # the workers started
            times[t] = min(_timed(work) for _ in range(repeats))
    finally:
        parallel.set_threads(previous)
    base = 1 if 1 in times else threads[0]          # the work per second of one thread, if measured
    return {t: t * times[base] / (base * times[t]) for t in threads}


PROBE_ROUNDS = 100          # the arithmetic probe's rounds in each round of a paired scaling (~8 ms)
PROBE_PAUSE_S = 0.02        # untimed, before each: OpenMP's idle threads spin some milliseconds


class _ArithmeticPass:
    """One pass of the arithmetic probe on ``threads`` threads (the count set by the caller):
    ARITHMETIC_ROWS numbers a thread, in the chunks and on the threads of the steps' passes
    (`parallel.chunked`), ``rounds`` rounds of exp and sqrt over each chunk's rows
    (`bench_kernels.arithmetic_rows`), so that a step's speed-up reads against the same machinery's."""

    def __init__(self, threads, rounds):
        self.threads, self.rounds = threads, rounds
        self.x = np.linspace(0.1, 1.0, threads * ARITHMETIC_ROWS)
        self.y = np.empty_like(self.x)

    def _chunk(self, lo, hi):
        arithmetic_rows(self.x[lo:hi], self.y[lo:hi], self.rounds)

    def __call__(self):
        from . import parallel

        parallel.chunked(len(self.x), arithmetic_rows, "rrw", (self.x, self.y, self.rounds))


CORE_TURNS = 9              # turns of the cores-alone probe (each core once a turn)


def cores_alone(turns=CORE_TURNS, rounds=PROBE_ROUNDS):
    """Seconds of one thread's share of the arithmetic probe (`_ArithmeticPass`, ``rounds``
    rounds) on each core this process may use, alone: a thread pinned to one core at a time, the
    cores in turn, ``turns`` times. Returns {core: [seconds per turn]} ({} where a thread cannot
    be pinned). On a VM the host may slow one virtual core and not the other within the same
    second (its other guests): this project's VM's two differed by up to 1.6 times
    (docs/bench/session25.md). Chunks taken as each thread is free (`parallel.rows`,
    `parallel.take_chunk`) make t threads at most (sum of the t cores' speeds) / (one core's)
    faster, not t. Cores that slow each other only when both run (the host running two of them
    on one of its own at times) look equal here: the arithmetic probe run in the same rounds as
    the steps (`alternate_threads`) sees that."""
    if not hasattr(os, "sched_setaffinity"):
        return {}
    cores = sorted(os.sched_getaffinity(0))
    work, times = _ArithmeticPass(1, rounds), {core: [] for core in cores}
    for _ in range(turns):
        for core in cores:
            times[core].append(on_core(core, lambda: work._chunk(0, ARITHMETIC_ROWS)))
    return times


def on_core(core, call):
    """Seconds of ``call()`` on a thread of its own pinned to ``core`` (Linux), the calling
    thread waiting for it (its own affinity unchanged)."""
    seconds = []

    def pinned():
        os.sched_setaffinity(0, {core})             # this thread only
        seconds.append(_timed(call))

    thread = threading.Thread(target=pinned)
    thread.start()
    thread.join()
    return seconds[0]


def format_cores_alone(times):
    """One line: how far apart the cores were, alone, turn by turn (`cores_alone`)."""
    if len(times) < 2:
        return ""
    per_turn = np.array(list(times.values()))                   # (cores, turns)
    spread = per_turn.max(axis=0) / per_turn.min(axis=0)
    gain = (per_turn.min(axis=0) / per_turn).sum(axis=0)         # all cores' speeds over the fastest's
    return (f"cores alone (the arithmetic probe's share pinned to each of {len(times)} cores in turn, "
            f"{per_turn.shape[1]} turns): the slowest took x{np.median(spread):.2f} the fastest's time "
            f"(median; x{spread.min():.2f}-{spread.max():.2f}): {len(times)} threads taking chunks as each is "
            f"free gain at most x{np.median(gain):.2f} (x{gain.min():.2f}-{gain.max():.2f}) over the fastest core")


def format_arithmetic(speedups):
    """One line: the arithmetic probe's speed-up per thread count."""
    if len(speedups) < 2 or 1 not in speedups:
        return ""
    parts = ", ".join(f"{t} thread{'s' if t > 1 else ''} x{x:.2f}" for t, x in sorted(speedups.items()))
    return (f"arithmetic (exp, sqrt on {ARITHMETIC_ROWS} numbers in cache per thread): {parts}: a pass bound by its "
            "arithmetic speeds up at most about that much")


HANDOFF_GAP_S = 5e-4       # the main thread's work between two passes of the probe (a step's glue)


def handoff(threads, calls=200, gap=HANDOFF_GAP_S):
    """Seconds of a pass of next to no work (each row zeroed, `bench_kernels.arithmetic_rows` with
    no rounds) in the chunks and on the threads of the steps' passes (`parallel.chunked`: numba's
    compiled chunk loop, or the pool where the steps' passes run on it), median of ``calls``, the
    main thread busy for ``gap`` s between two (as between a step's passes), on each thread count:
    what handing a pass to every thread costs. numba's threads spin a while after a loop, and find
    the next one at once; the pool's workers sleep, and on a VM waking an idle virtual CPU took
    14-23 µs and 160-420 µs on two threads of the same VM an hour apart (docs/bench/session20.md).
    A step's passes do not wait for a thread that starts late: it takes fewer chunks."""
    from . import parallel

    previous, costs = parallel.set_threads(1), {}
    try:
        for t in threads:
            parallel.set_threads(t)
            x = np.zeros(t * parallel.MIN_ROWS)
            y = np.empty_like(x)
            times = []
            for _ in range(calls):
                t0 = time.perf_counter()
                while time.perf_counter() - t0 < gap:
                    pass
                times.append(_timed(lambda: parallel.chunked(len(x), arithmetic_rows, "rrw", (x, y, 0))))
            costs[t] = float(np.median(times))
    finally:
        parallel.set_threads(previous)
    return costs


def format_handoff(costs):
    """One line: a chunked pass's cost per thread count, its work next to nothing (`handoff`)."""
    if len(costs) < 2:
        return ""
    parts = ", ".join(f"{t} thread{'s' if t > 1 else ''} {1e6 * c:.0f} µs" for t, c in sorted(costs.items()))
    return (f"hand-off (a pass of next to no work on every thread, {1e6 * HANDOFF_GAP_S:.0f} µs after the last): "
            f"{parts}: what handing a pass to the threads takes (a step's passes go on without the threads "
            "not yet awake)")


def _timed(call):
    t0 = time.perf_counter()
    call()
    return time.perf_counter() - t0


def format_memory(speeds, mib=MEMORY_MIB):
    """One line: the triad's GB/s per thread count and its speed-up over one thread."""
    if len(speeds) < 2 or 1 not in speeds:
        return ""
    parts = ", ".join(f"{t} thread{'s' if t > 1 else ''} {g:.1f} GB/s (x{g / speeds[1]:.2f})"
                      for t, g in sorted(speeds.items()))
    return f"memory (x + a y, 3 x {mib} MiB): {parts}: a pass bound by memory speeds up at most about that much"


def machine():
    return {"machine": platform.machine(), "processor": platform.processor() or platform.machine(),
            "cpus": os.cpu_count(), "python": platform.python_version(),
            "threads": os.environ.get("OMP_NUM_THREADS", "unset")}


def format_table(rows):
    head = (f"{'method':<16}{'cells':>8}{'thr':>4}{'setup s':>9}{'ms/step':>10}{'us/cell':>9}{'ns/dof':>8}"
            f"{'cpu us/cell':>12}{'ns/dof/stage':>13}{'particles/s':>12}{'peak MiB':>10}{'setup/step':>11}")
    lines = [head, "-" * len(head)]
    for r in rows:
        if "error" in r:
            lines.append(f"{r['method']:<16}{r['cells']:>8}{r.get('threads', 1):>4}  "
                         f"{'skipped' if r.get('missing') else 'failed'}: {r['error']}")
            continue
        lines.append(f"{r['method']:<16}{r['cells']:>8}{r.get('threads', 1):>4}{r['setup_s']:>9.2f}{1e3 * r['step_s']:>10.2f}"
                     f"{r['us_per_cell_step']:>9.2f}{1e9 * r['s_per_dof_step']:>8.0f}"
                     f"{r['cpu_us_per_cell_step']:>12.2f}{1e9 * r['s_per_dof_stage']:>13.0f}{r['particles_per_s']:>12.3g}"
                     f"{r['peak_MiB']:>10.0f}{r['setup_in_steps']:>11.1f}")
    return "\n".join(lines)


def format_stages(rows):
    """Per row, each stage's share of the step: mean ms per step and percent of the stages' sum."""
    lines = []
    for r in rows:
        stages = r.get("stage_s")
        if not stages:
            continue
        total = sum(stages.values())
        parts = ", ".join(f"{name} {1e3 * s:.2f} ms ({100 * s / total:.0f}%)" for name, s in stages.items())
        if r.get("attempts_per_step"):
            parts += (f"; {r['attempts_per_step']:.2f} attempts per step (CFL guard), mean step "
                      f"{1e3 * r['step_mean_s']:.2f} ms")
        lines.append(f"{r['method']} {r['cells']} cells, {r.get('threads', 1)} thread(s): {parts}")
    return "\n".join(lines)


def format_scaling(rows, threads_paired=()):
    """Per (method, cells) measured on several thread counts: wall time per step and the speed-up
    over one thread; after it, the paired scaling of the same (method, cells) if any
    (`format_threads_pair`)."""
    groups = {}
    for r in rows:
        if "error" not in r:
            groups.setdefault((r["method"], r["cells"]), {})[r["threads"]] = r["step_s"]
    pairs = {}
    for p in threads_paired:
        pairs.setdefault((p["method"], p["cells"]), []).append(p)
    lines = []
    for (method, cells), times in groups.items():
        if len(times) < 2 or 1 not in times:
            continue
        parts = ", ".join(f"{n} thread{'s' if n > 1 else ''} {1e3 * t:.2f} ms (x{times[1] / t:.2f})"
                          for n, t in sorted(times.items()))
        lines.append(f"{method} {cells} cells: {parts}")
        if (method, cells) in pairs:
            lines.extend(format_threads_pairs(pairs.pop((method, cells))))
    return "\n".join([*lines, *(line for p in pairs.values() for line in format_threads_pairs(p))])  # rows failed


def format_threads_pairs(repeats):
    """The lines of the paired scaling rows of one (method, cells): one per repeat, then, with
    several, each count's median speed-up repeat by repeat and the lowest of them."""
    lines = [format_threads_pair(p) for p in repeats]
    done = [p for p in repeats if "error" not in p]
    if len(repeats) > 1 and done:
        counts = ", ".join(f"{t} threads " + " ".join(f"x{p['wall_speedup'][t]['median']:.2f}" for p in done)
                           + f" (lowest x{min(p['wall_speedup'][t]['median'] for p in done):.2f})"
                           for t in done[0]["wall_speedup"])
        lines.append(f"{done[0]['method']} {done[0]['cells']} cells, paired, {len(done)} of {len(repeats)} repeats: "
                     f"{counts}")
    return lines


def format_threads_pair(p):
    """One line of a paired scaling row: per count t > 1, the median per-round wall-time speed-up
    over one thread, its quartiles, the ratio of the medians."""
    head = f"{p['method']} {p['cells']} cells, paired, alternating thread counts in one process"
    if "repeat" in p:
        head += f" (repeat {p['repeat']})"
    if "error" in p:
        return f"{head}: failed: {p['error']}"
    one = p["wall_step_s"]["1"]
    parts = ", ".join(f"{t} threads x{s['median']:.2f} (quartiles {s['q25']:.2f}-{s['q75']:.2f}; ratio of the "
                      f"medians {s['medians_ratio']:.2f}: {1e3 * one:.2f} / {1e3 * p['wall_step_s'][t]:.2f} ms "
                      "per step)" for t, s in p["wall_speedup"].items())
    line = f"{head}: {parts}; medians of {p['pairs']} per-round speed-ups, {p['order']} order"
    if "switch_wall_speedup" in p:      # the untimed steps that settled each switch, timed apart
        first = ", ".join(f"x{s['median']:.2f}" for s in p["switch_wall_speedup"].values())
        line += f", each after a step on its own count (the first after each switch: {first})"
    if "share_of_probe" in p:           # what the machine gave in the same rounds
        gave = ", ".join(f"{t} threads x{p['probe_speedup'][t]['median']:.2f}, the step {s['median']:.2f} of it "
                         f"(quartiles {s['q25']:.2f}-{s['q75']:.2f})" for t, s in p["share_of_probe"].items())
        line += f"; in the same rounds the arithmetic probe gave {gave}"
    return line


def main(methods, sizes, steps=5, warmup=2, json_path=None, progress=True, threads=(1,), repeat=1):
    """Run every (method, size, thread count), then at each size every requested peer method whose
    counterpart is requested too, paired (`measure_pair`; not without the peer), and, with several
    thread counts (1 among them), every method but the peer's on them all in one process
    (`measure_threads`), ``repeat`` times in turn (each paired scaling row then has its ``repeat``,
    1 to ``repeat``: a speed-up is judged by each one, not by their best); write JSON if asked.
    Returns the rows, the paired rows, the paired scaling rows and the machine's probes: with
    several thread counts, the memory bandwidth on each (`memory_bandwidth`), the speed-up of
    arithmetic (`arithmetic`), an empty pass's cost (`handoff`) and each core's speed alone
    (`cores_alone`), {"memory": {t: GB/s}, "arithmetic": {t: x}, "handoff": {t: s},
    "cores_alone": {core: [s]}} (empty dicts with one count). The CPU time per cell
    of a one-thread row is the cost per core."""
    from .run import progress_bar

    pairs = [m for m in methods if m in peer.METHODS and peer.COUNTERPART[m] in methods]
    if pairs and not peer.available():
        pairs = []                      # the peer rows say MISSING; no paired row
    # every method: 2 x pairs steps each, ~10 s for the slowest (ADER) at 256^2; the peer is serial
    scaled = [m for m in methods if m not in peer.METHODS] if len(threads) > 1 and 1 in threads else []
    rows, paired, threads_paired = [], [], []
    bar = progress_bar(progress, len(sizes) * (len(methods) * len(threads) + len(pairs) + repeat * len(scaled)),
                       unit="run")
    for n in sizes:                     # methods interleaved at each size (a peer beside ours)
        for method in methods:
            for t in threads:
                if method in peer.METHODS and t != threads[0]:     # serial: one row
                    bar.update()
                    continue
                bar.set_description(f"{method} {n}x{n} {t} thread{'s' if t > 1 else ''}")
                rows.append(measure(method, n, steps, warmup, t))
                bar.update()
        for method in pairs:
            bar.set_description(f"{peer.COUNTERPART[method]}/{method} {n}x{n} paired")
            paired.append(measure_pair(method, n, steps, warmup))
            bar.update()
        for k in range(1, repeat + 1):      # the methods in turn, then again: each repeat sees the same hour
            for method in scaled:
                bar.set_description(f"{method} {n}x{n} threads {','.join(map(str, threads))} paired"
                                    + (f", {k} of {repeat}" if repeat > 1 else ""))
                row = measure_threads(method, n, threads, steps, warmup)
                threads_paired.append({**row, "repeat": k} if repeat > 1 else row)
                bar.update()
    bar.close()
    probes = {"memory": memory_bandwidth(threads) if len(threads) > 1 else {},
              "arithmetic": arithmetic(threads) if len(threads) > 1 else {},
              "handoff": handoff(threads) if len(threads) > 1 else {},
              "cores_alone": cores_alone() if len(threads) > 1 else {}}
    if json_path is not None:
        info = {**machine(), "memory_GBps": {str(t): g for t, g in probes["memory"].items()}, "memory_MiB": MEMORY_MIB,
                "arithmetic_speedup": {str(t): x for t, x in probes["arithmetic"].items()},
                "handoff_s": {str(t): c for t, c in probes["handoff"].items()}, "handoff_gap_s": HANDOFF_GAP_S,
                "cores_alone_s": {str(c): v for c, v in probes["cores_alone"].items()}}
        with open(json_path, "w") as fh:
            json.dump({"machine": info, "steps": steps, "warmup": warmup, "rows": rows, "paired": paired,
                       "threads_paired": threads_paired}, fh, indent=1)
    return rows, paired, threads_paired, probes
