"""How much of a step runs on one thread: the wall time a step spends outside its threaded passes
(docs/bench/session26.md).

    python bench/serial_share.py [--methods dgmpm-dcu,dgmpm-ctu] [--size 256] [--steps 100] [--threads 2]

Each method's bench plate is stepped on ``--threads`` threads; every threaded pass is timed from the
calling thread: numba's compiled chunk loops (`parallel.chunked`, `parallel.together`) and the pool's `parallel.rows`
(where numba's layer cannot run them; a pass inside another is counted once). What is left of
the step is the Python between them, the numpy calls on whole arrays and the compiled passes kept
on one thread. A share s of the k-thread step run on one thread caps k threads at k - (k - 1) s over
one (Amdahl's law: the passes k times faster, the rest as it was; 2 - s on two threads). Timings
are measurements on the machine at hand, not test results.
"""
import argparse
import statistics
import time

from skdgmpm import bench, parallel
from skdgmpm.build import build

class Clock:
    """Seconds spent in the threaded passes since the last `reset`, each pass once."""

    def __init__(self):
        self.seconds, self.depth = 0.0, 0

    def reset(self):
        self.seconds = 0.0

    def wrap(self, call):
        def timed(*args, **kwargs):
            self.depth += 1
            t0 = time.perf_counter()
            try:
                return call(*args, **kwargs)
            finally:
                self.depth -= 1
                if self.depth == 0:
                    self.seconds += time.perf_counter() - t0
        return timed


def hook(clock, patch=setattr):
    """Time every threaded pass: `parallel.chunked` and `parallel.together` (every chunked pass
    goes through one of them) and the pool's `parallel.rows`. ``patch(module, name, value)``
    replaces each (a test passes pytest's monkeypatch.setattr, which undoes it)."""
    for name in ("chunked", "together", "rows"):
        patch(parallel, name, clock.wrap(getattr(parallel, name)))


def share(method, n, steps, threads, clock):
    """(median step s, median s in threaded passes, median s outside them) over ``steps`` steps."""
    disc = build(bench.scene_for(method, n))
    step = bench.Stepping(disc)
    bench._use_threads(threads)
    for _ in range(3):
        step()
    walls, inside = [], []
    for _ in range(steps):
        clock.reset()
        t0 = time.perf_counter()
        step()
        walls.append(time.perf_counter() - t0)
        inside.append(clock.seconds)
    outside = [w - i for w, i in zip(walls, inside)]
    return statistics.median(walls), statistics.median(inside), statistics.median(outside)


def main():
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--methods", default="dgmpm-dcu,dgmpm-ctu")
    parser.add_argument("--size", type=int, default=256)
    parser.add_argument("--steps", type=int, default=100)
    parser.add_argument("--threads", type=int, default=2)
    args = parser.parse_args()
    clock = Clock()
    hook(clock)
    print(f"{args.size}^2, {args.threads} threads, median of {args.steps} steps")
    for method in args.methods.split(","):
        wall, inside, outside = share(method, args.size, args.steps, args.threads, clock)
        s = outside / wall
        cap = args.threads - (args.threads - 1) * s
        print(f"{method:14s} step {1e3 * wall:8.2f} ms, threaded passes {1e3 * inside:8.2f} ms, outside "
              f"{1e3 * outside:6.3f} ms ({100 * s:4.1f} %): at most x{cap:.2f} on {args.threads} threads "
              "were the passes perfect")


if __name__ == "__main__":
    main()
