"""Whether a pass runs slower called from Python than inside numba's compiled chunk loop, on one
thread (docs/bench/session41.md).

    python bench/one_thread_paths.py [--methods rk-dgfem-1,dgmpm-ctu] [--size 256] [--rounds 10]

On one thread `parallel.chunked` calls a pass's kernel from Python over the whole range (`rows`);
on more, the compiled chunk loop (`parallel._chunk_loop`, a numba parallel function) calls it on
each chunk. numba marks a parallel function's arrays as not aliasing one another, and LLVM inlines
the kernel there; called from Python, the kernel cannot tell the array it writes from those it
reads, and a loop that stores between its loads loads them again (RK-DGFEM's mass blocks were
x3-6 slower that way until the thirty-second session). Each round steps the bench plate once each
way on one thread (ABBA), the compiled loop forced over the one chunk; prints per pass the median
time of each way per step and their ratio (above 1: the pass is slower called from Python).
Timings are measurements on the machine at hand, not test results.
"""
import argparse
import functools
import importlib.util
import statistics
from pathlib import Path

import numpy as np

from skdgmpm import bench, parallel
from skdgmpm.build import build

_spec = importlib.util.spec_from_file_location("pass_gaps", Path(__file__).with_name("pass_gaps.py"))
pass_gaps = importlib.util.module_from_spec(_spec)
_spec.loader.exec_module(pass_gaps)


_IN_PYTHON = parallel._compiled_bounds         # the engine's: one chunk runs from Python


def _loop_over_one_chunk(n, min_rows, n_threads, *settings):
    """`parallel._compiled_bounds`, but the compiled loop also for one chunk."""
    bounds, count = _IN_PYTHON(n, min_rows, n_threads, *settings)
    if bounds is None and parallel._compiled_layer():
        return parallel._chunk_bounds(n, min_rows, n_threads, *settings), 1
    return bounds, count


WAYS = {"python": _IN_PYTHON, "loop": functools.lru_cache(maxsize=64)(_loop_over_one_chunk)}


def measure(method, n, rounds, marks, warmup=2):
    """{way: {pass: [seconds per step]}} (and "step"), one simulation on one thread."""
    step = bench.Stepping(build(bench.scene_for(method, n)))
    previous = parallel.set_threads(1)
    bench._use_threads(1)

    def use(way):
        parallel._compiled_bounds = WAYS[way]

    try:
        return pass_gaps.paired_rounds(step, marks, tuple(WAYS), use, rounds, warmup)
    finally:
        parallel._compiled_bounds = WAYS["python"]
        parallel.set_threads(previous)


def main():
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--methods", default="rk-dgfem-1,dgmpm-ctu,dgmpm-dcu,ader-dgfem-1,ader-dgmpm-1")
    parser.add_argument("--size", type=int, default=256)
    parser.add_argument("--rounds", type=int, default=10)
    args = parser.parse_args()
    marks = []
    pass_gaps.timestamped(marks)
    for method in args.methods.split(","):
        times = measure(method, args.size, args.rounds, marks)
        print(f"{method} {args.size}^2, one thread, {args.rounds} rounds (ABBA): median us per step called from "
              "Python / in the compiled loop, ratio")
        for name in times["python"]:
            py, loop = (statistics.median(times[w][name]) for w in WAYS)
            ratio = np.median(np.array(times["python"][name]) / np.array(times["loop"][name]))
            print(f"  {name:22s} {1e6 * py:10.0f} / {1e6 * loop:10.0f} us  x{ratio:.2f}")


if __name__ == "__main__":
    main()
