"""Whole runs of the bench's plate on one and on two threads (docs/bench/session54.md §2).

    python bench/whole_runs.py [--method dgmpm-ctu] [--size 256] [--steps 100] [--pairs 6]

Each run is `skdgmpm.run.run` of `bench.scene_for` (``--steps`` steps, no output written), its
own grid built anew, on one or on two threads, the two in turn in one process (ABBA). Prints
each run's time per step of its time loop without its first step (`Result.wall_s`: what a
user's run on that many threads spends, energy rows and guards included) and the per-pair
speed-ups. `skdgmpm bench` pairs single steps of one simulation; this pairs whole runs.
Timings are measurements on the machine at hand, not test results.
"""
import argparse
import warnings

import numpy as np

from skdgmpm import bench
from skdgmpm.run import run


def main():
    parser = argparse.ArgumentParser()
    parser.add_argument("--method", default="dgmpm-ctu")
    parser.add_argument("--size", type=int, default=256)
    parser.add_argument("--steps", type=int, default=100)
    parser.add_argument("--pairs", type=int, default=6)
    args = parser.parse_args()
    warnings.simplefilter("ignore")                 # the DCU plate's CFL above its limit, on purpose
    scene = bench.scene_for(args.method, args.size)
    run(scene, max_steps=3, progress=False)         # kernels loaded, pages touched
    times = {1: [], 2: []}
    for k in range(args.pairs):
        for t in (1, 2) if k % 2 == 0 else (2, 1):
            bench._use_threads(t)
            result = run(scene, max_steps=args.steps, progress=False)
            times[t].append(result.wall_s / (result.state.step - 1))
    one, two = np.array(times[1]), np.array(times[2])
    print(f"{args.method} {args.size}^2, runs of {args.steps} steps, {args.pairs} pairs in one process: one thread "
          f"{1e3 * np.median(one):.2f} ms a step, two threads {1e3 * np.median(two):.2f}; speed-up per pair "
          + " ".join(f"x{s:.2f}" for s in one / two) + f", median x{np.median(one / two):.2f}")


if __name__ == "__main__":
    main()
