"""Each core alone: how fast one step, and three kinds of arithmetic, run on each core of this
machine, the cores in turn (docs/bench/session25.md).

    python bench/cores_alone.py [--method dgmpm-dcu] [--size 256] [--turns 12] [--json FILE]

A thread pinned to one core at a time runs, on each core in turn, every turn:
- two steps of ``--method`` on one thread (the bench's plate, one simulation stepped on);
- multiply-adds over 1024 numbers in cache (vectorised: bound by the cores' vector units);
- square roots (bound by the divider) and a chain of multiply-adds each waiting for the last
  (bound by latency, not by any unit).

On a VM whose virtual cores share their host's cores with other guests, a kind of work that fills
a unit the other guest uses too runs slower on that core, for as long as the guest runs: two
threads on two such cores gain less than 2 over one, whatever the code. Timings are measurements
on the machine at hand, not test results.
"""
import argparse
import json
import os

import numpy as np
from numba import njit

from skdgmpm import bench
from skdgmpm.build import build


@njit(nogil=True, fastmath=True)
def multiply_adds(y, rounds):
    for _ in range(rounds):
        for i in range(y.size):
            y[i] = y[i] * 0.9999999 + 1e-9
    return y[0]


@njit(nogil=True)
def square_roots(y, rounds):
    s = 0.0
    for r in range(rounds):
        for i in range(y.size):
            s += np.sqrt(y[i] + r)
    return s


@njit(nogil=True, fastmath=True)
def chain(n):
    x = 1.0
    for _ in range(n):
        x = x * 0.9999999 + 1e-9
    return x


def main():
    parser = argparse.ArgumentParser()
    parser.add_argument("--method", default="dgmpm-dcu")
    parser.add_argument("--size", type=int, default=256)
    parser.add_argument("--turns", type=int, default=12)
    parser.add_argument("--json")
    args = parser.parse_args()
    step = bench.Stepping(build(bench.scene_for(args.method, args.size)))
    bench._use_threads(1)
    step()
    multiply_adds(np.ones(1024), 1), square_roots(np.ones(1024), 1), chain(1)
    work = {f"{args.method} x2": lambda: (step(), step()),
            "multiply-adds": lambda: multiply_adds(np.ones(1024), 60_000),
            "square roots": lambda: square_roots(np.ones(1024), 4_000),
            "chain": lambda: chain(20_000_000)}
    cores = sorted(os.sched_getaffinity(0))
    times = {name: {core: [] for core in cores} for name in work}
    for turn in range(args.turns):
        line = []
        for name, call in work.items():
            for core in cores:
                times[name][core].append(bench.on_core(core, call))
            line.append(f"{name} " + " ".join(f"{1e3 * times[name][c][-1]:6.1f}" for c in cores))
        print(" | ".join(line) + " ms")
    for name in work:
        per_turn = np.array([times[name][c] for c in cores])
        spread = per_turn.max(axis=0) / per_turn.min(axis=0)
        print(f"{name}: the slowest core x{np.median(spread):.2f} the fastest's time (median turn), "
              f"x{spread.min():.2f}-{spread.max():.2f}; each core's range "
              + ", ".join(f"{1e3 * min(times[name][c]):.1f}-{1e3 * max(times[name][c]):.1f} ms" for c in cores))
    if args.json:
        with open(args.json, "w") as fh:
            json.dump({"method": args.method, "size": args.size, "cores": cores,
                       "seconds": {name: {str(c): v for c, v in t.items()} for name, t in times.items()}}, fh, indent=1)


if __name__ == "__main__":
    main()
