"""The most a compiled step driver could gain: a step's threaded passes replayed back to back.

    python bench/step_replay.py [--method dgmpm-ctu] [--size 256] [--threads 2] [--rounds 40]

A compiled driver would run a step's passes (the compiled chunk loops of `parallel.chunked`) one
after the other, with no Python between them. This measures what that could gain before anyone
builds it: one step of a second simulation of the bench's plate is captured (each pass's chunk
loop and flattened arguments, in order), then replayed as captured, each pass's loop called
directly on the chunks of the thread count at hand. Before each replay the arrays the passes
write are copied back as they were after the captured step (untimed), so every replay does the
same arithmetic on the same valid state (without it, each replay fed on the last one's output
and its passes stopped early at a failed health check). The real step and the replay run in turn
on 1 and ``--threads`` threads (ABBA); printed: medians and per-round speed-ups of each. The
replay leaves out the step's Python and its serial compiled code (the boundary's corrections
and terms, a few thousand faces): its speed-up bounds what any driver could reach on this
machine in these minutes. Timings are measurements on the machine at hand, not test results.
"""
import argparse
import time

import numpy as np

from skdgmpm import bench, parallel
from skdgmpm.build import build


class Replay:
    """A step's passes, captured from ``stepping`` (a `bench.Stepping`) in one step, to replay."""

    def __init__(self, stepping):
        calls, chunked = [], parallel.chunked

        def capture(n, kernel, spec, args, returns=0, min_rows=None):
            result = chunked(n, kernel, spec, args, returns, min_rows)
            calls.append((n, min_rows, kernel, spec, args, returns))
            return result
        parallel.chunked = capture
        try:
            stepping()
        finally:
            parallel.chunked = chunked
        self.names = [getattr(kernel, "__name__", "chunked") for _, _, kernel, *_ in calls]
        self.passes, written = [], {}
        for n, min_rows, kernel, spec, args, returns in calls:
            plan = parallel._PLANS.get((kernel, spec, returns))     # made where the step ran a chunk loop
            if plan is None:                # a pass of one chunk: replayed through `chunked`
                self.passes.append((n, min_rows, None, (kernel, spec, args, returns), None, False))
                flat = []
                parallel._shape(args, flat)
            else:
                flat = plan[1](args)
                width = 1 if returns == "first" else max(returns, 1)
                self.passes.append((n, min_rows, plan[0], width, flat, returns == "first"))
            for a in flat:
                if isinstance(a, np.ndarray) and a.size and a.flags.writeable:
                    written[id(a)] = a
        self.saved = [(a, a.copy()) for a in written.values()]
        self.stopped = 0                    # replayed passes that returned a failing row

    def restore(self):
        """The passes' arrays as they were after the captured step."""
        for a, saved in self.saved:
            np.copyto(a, saved)

    def __call__(self):
        """The passes once, back to back, on the current thread count."""
        for n, min_rows, loop, width, flat, first in self.passes:
            if loop is None:
                kernel, spec, args, returns = width
                result = parallel.chunked(n, kernel, spec, args, returns, min_rows)
                if returns == "first" and result >= 0:
                    self.stopped += 1
                continue
            bounds = parallel.compiled_chunks(n, min_rows)
            if bounds is None:              # one chunk (`chunked` would call the kernel once): one chunk here
                parallel._numba_threads(1)
                bounds = np.array([0, n], np.int64)
            out = np.full((len(bounds) - 1, width), -1.0)
            loop(bounds, out, *flat)
            if first and (out[:, 0] >= 0).any():
                self.stopped += 1


def measure(method, n, threads, rounds, warmup=3):
    """{(kind, count): [seconds]} for kind "step" (the plate's step) and "replay" (the `Replay`
    of another simulation of it), on 1 and ``threads`` threads in turn (ABBA), ``rounds`` timed
    rounds after ``warmup``; and the replay."""
    step, other = (bench.Stepping(build(bench.scene_for(method, n))) for _ in range(2))
    previous = parallel.set_threads(1)
    try:
        for t in (1, threads):              # every chunk loop made, on both counts
            bench._use_threads(t)
            step()
            other()
        replay = Replay(other)
        times = {(kind, t): [] for kind in ("step", "replay") for t in (1, threads)}
        for k in range(warmup + rounds):
            for t in ((1, threads) if k % 2 == 0 else (threads, 1)):
                bench._use_threads(t)
                for kind, run in (("step", step), ("replay", replay)):
                    if kind == "replay":
                        replay.restore()
                    t0 = time.perf_counter()
                    run()
                    seconds = time.perf_counter() - t0
                    if k >= warmup:
                        times[kind, t].append(seconds)
    finally:
        parallel.set_threads(previous)
    return times, replay


def main():
    parser = argparse.ArgumentParser()
    parser.add_argument("--method", default="dgmpm-ctu")
    parser.add_argument("--size", type=int, default=256)
    parser.add_argument("--threads", type=int, default=2)
    parser.add_argument("--rounds", type=int, default=40)
    args = parser.parse_args()
    t = args.threads
    times, replay = measure(args.method, args.size, t, args.rounds)
    print(f"{args.method} {args.size}^2, the step and its passes back to back ({', '.join(replay.names)}), "
          f"1 and {t} threads in turn, {args.rounds} rounds (ABBA); median per step, per-round speed-up (quartiles)")
    for kind in ("step", "replay"):
        one, many = np.array(times[kind, 1]), np.array(times[kind, t])
        q25, median, q75 = np.percentile(one / many, [25, 50, 75])
        print(f"  {kind:7s} {1e3 * np.median(one):8.2f} / {1e3 * np.median(many):8.2f} ms  x{median:.2f} ({q25:.2f}-{q75:.2f})")
    gain = np.array(times["replay", 1]) / np.array(times["replay", t]) - (
        np.array(times["step", 1]) / np.array(times["step", t]))
    print(f"  the replay's speed-up less the step's, round by round: median {np.median(gain):+.2f}; "
          f"replayed passes stopped early: {replay.stopped}")


if __name__ == "__main__":
    main()
