"""A two-thread step's time by what came before it (docs/bench/session54.md §1).

    python bench/after_switch.py [--method dgmpm-ctu] [--size 256] [--rounds 40]

One simulation of the bench's plate; each round: a step on one thread, then on two threads a
step after that one-thread step, a step after a two-thread step, and a step after a 20 ms pause
(`bench.PROBE_PAUSE_S`, what the paired rounds' probe leaves before a step). Prints each kind's
median time and its speed-up over the round's one-thread step. A run steps on one count, so
its steps are all of the second kind; `skdgmpm bench` times that kind (`bench.SETTLE`). Timings
are measurements on the machine at hand, not test results.
"""
import argparse
import time
import warnings

import numpy as np

from skdgmpm import bench
from skdgmpm.build import build


def main():
    parser = argparse.ArgumentParser()
    parser.add_argument("--method", default="dgmpm-ctu")
    parser.add_argument("--size", type=int, default=256)
    parser.add_argument("--rounds", type=int, default=40)
    args = parser.parse_args()
    warnings.simplefilter("ignore")                 # the DCU plate's CFL above its limit, on purpose
    step = bench.Stepping(build(bench.scene_for(args.method, args.size)))
    for _ in range(5):
        step()

    def timed():
        t0 = time.perf_counter()
        step()
        return time.perf_counter() - t0

    one, kinds = [], {"after a one-thread step": [], "after a two-thread step": [], "after a 20 ms pause": []}
    for _ in range(args.rounds):
        bench._use_threads(1)
        one.append(timed())
        bench._use_threads(2)
        kinds["after a one-thread step"].append(timed())
        kinds["after a two-thread step"].append(timed())
        time.sleep(bench.PROBE_PAUSE_S)
        kinds["after a 20 ms pause"].append(timed())
    one = np.array(one)
    print(f"{args.method} {args.size}^2, {args.rounds} rounds: one thread {1e3 * np.median(one):.2f} ms")
    for name, times in kinds.items():
        times = np.array(times)
        print(f"  two threads {name}: {1e3 * np.median(times):.2f} ms, x{np.median(one / times):.3f} "
              f"(median of the rounds' speed-ups)")


if __name__ == "__main__":
    main()
