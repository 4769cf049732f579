"""The most a compiled step driver could gain: a step's threaded passes replayed back to back.

    python bench/step_replay.py [--method dgmpm-ctu] [--size 256] [--threads 2] [--rounds 40]

A compiled driver would run a step's passes (the compiled chunk loops of `parallel.chunked`) one
after the other, with no Python between them. This measures what that could gain before anyone
builds it. Each round, on 1 and ``--threads`` threads in turn (ABBA), the bench plate's step is
timed while its passes are captured (each one's chunk loop and arguments, in order), then those
passes are replayed at once, back to back, on the state the step left: the arrays they write are
saved before and put back after (untimed), so the simulation goes on from its own step, and the
replay does one more step's arithmetic on the state of the step beside it. On several threads a
replayed pass runs its compiled chunk loop on the chunks `chunked` would use; on one, its kernel
on the whole range, as `chunked` calls it (a one-chunk compiled loop ran the law's pass 2-7 %
faster than that, which biased a first version). The replay leaves out the step's Python and
its serial compiled code (the boundary's corrections and terms, a few thousand faces): its
speed-up bounds what a driver could reach on this machine in these minutes. Printed: medians
and per-round speed-ups of each, and their difference round by round. Timings are measurements
on the machine at hand, not test results.
"""
import importlib.util
import time
from pathlib import Path

import numpy as np

from skdgmpm import bench, parallel
from skdgmpm.build import build

_spec = importlib.util.spec_from_file_location("pass_scaling", Path(__file__).with_name("pass_scaling.py"))
pass_scaling = importlib.util.module_from_spec(_spec)
_spec.loader.exec_module(pass_scaling)


class Replay:
    """The threaded passes of one step of ``stepping`` (a `bench.Stepping`), captured as the step
    runs (`seconds`: its wall time, the capture's few appends within), to replay on the state the
    step left."""

    def __init__(self, stepping):
        calls, chunked, together, depth = [], parallel.chunked, parallel.together, [0]

        def capture(n, kernel, spec, args, returns=0, min_rows=None):
            if depth[0] == 0:
                calls.append((n, min_rows, kernel, spec, args, returns))
            return chunked(n, kernel, spec, args, returns, min_rows)

        def capture_together(first, second):    # replayed as it ran: two passes in one loop
            calls.append((first, second))
            depth[0] += 1
            try:
                return together(first, second)
            finally:
                depth[0] -= 1
        parallel.chunked, parallel.together = capture, capture_together
        try:
            t0 = time.perf_counter()
            stepping()
            self.seconds = time.perf_counter() - t0
        finally:
            parallel.chunked, parallel.together = chunked, together
        self.names = ["+".join(p.kernel.__name__ for p in call) if len(call) == 2 else
                      getattr(call[2], "__name__", "chunked") for call in calls]
        self.passes, written = [], {}
        for call in calls:
            if len(call) == 2:
                self.passes.append(call)
                for p in call:
                    flat = []
                    parallel._shape(p.args, flat)
                    written.update((id(a), a) for a in flat
                                   if isinstance(a, np.ndarray) and a.size and a.flags.writeable)
                continue
            n, min_rows, kernel, spec, args, returns = call
            plan = parallel._PLANS.get((kernel, spec, returns))     # made where a step ran a chunk loop
            if plan is None:                # never on several threads: replayed through `chunked`
                self.passes.append((n, min_rows, None, 0, (kernel, spec, args, returns), False))
                flat = []
                parallel._shape(args, flat)
            else:
                flat = plan[1](args)
                whole = kernel, parallel._sliced(parallel._parsed(spec), args, 0, n, 0)
                width = 1 if returns == "first" else max(returns, 1)
                self.passes.append((n, min_rows, plan[0], width, (flat, whole), returns == "first"))
            for a in flat:
                if isinstance(a, np.ndarray) and a.size and a.flags.writeable:
                    written[id(a)] = a
        self.written = list(written.values())
        self.saved = None
        self.stopped = 0                    # replayed passes that returned a failing row

    def save(self):
        """Copy the arrays the passes write (the simulation's state among them)."""
        self.saved = [a.copy() for a in self.written]

    def restore(self):
        """The arrays the passes write as `save` found them: the simulation goes on as if never
        replayed."""
        for a, saved in zip(self.written, self.saved):
            np.copyto(a, saved)

    def __call__(self):
        """The passes once, back to back, on the current thread count."""
        for entry in self.passes:
            if len(entry) == 2:             # `parallel.together`'s two passes
                self.stopped += sum(r >= 0 for r in parallel.together(*entry))
                continue
            n, min_rows, loop, width, arguments, first = entry
            if loop is None:
                kernel, spec, args, returns = arguments
                result = parallel.chunked(n, kernel, spec, args, returns, min_rows)
                self.stopped += returns == "first" and result >= 0
                continue
            flat, (kernel, whole) = arguments
            bounds = parallel.compiled_chunks(n, min_rows)
            if bounds is None:              # one chunk: the kernel on the whole range, as `chunked` calls it
                result = kernel(*whole)
                self.stopped += first and result >= 0
                continue
            out = np.full((len(bounds) - 1, width), -1.0)
            loop(bounds, out, *flat)
            self.stopped += first and bool((out[:, 0] >= 0).any())


def measure(method, n, threads, rounds, warmup=3):
    """{(kind, count): [seconds]}: kind "step", the bench plate's step, captured (`Replay`), and
    "replay", its passes replayed at once on the state it left (saved before, put back after,
    both untimed: the simulation goes on from its own step), on 1 and ``threads`` threads in turn
    (ABBA), ``rounds`` timed rounds after ``warmup``; and the replayed passes that stopped early."""
    stepping = bench.Stepping(build(bench.scene_for(method, n)))
    previous = parallel.set_threads(1)
    times = {(kind, t): [] for kind in ("step", "replay") for t in (1, threads)}
    stopped, names = 0, None
    try:
        for t in (1, threads):              # every chunk loop made
            bench._use_threads(t)
            stepping()
        for k in range(warmup + rounds):
            for t in ((1, threads) if k % 2 == 0 else (threads, 1)):
                bench._use_threads(t)
                replay = Replay(stepping)
                replay.save()
                t0 = time.perf_counter()
                replay()
                seconds = time.perf_counter() - t0
                replay.restore()
                stopped, names = stopped + replay.stopped, replay.names
                if k >= warmup:
                    times["step", t].append(replay.seconds)
                    times["replay", t].append(seconds)
    finally:
        parallel.set_threads(previous)
    return times, names, stopped


def main():
    args = pass_scaling.rounds_parser().parse_args()
    t = args.threads
    times, names, stopped = measure(args.method, args.size, t, args.rounds)
    print(f"{args.method} {args.size}^2, the step and its passes back to back ({', '.join(names)}), "
          f"1 and {t} threads in turn, {args.rounds} rounds (ABBA); median per step, per-round speed-up (quartiles)")
    for kind in ("step", "replay"):
        one, many = np.array(times[kind, 1]), np.array(times[kind, t])
        q25, median, q75 = np.percentile(one / many, [25, 50, 75])
        print(f"  {kind:7s} {1e3 * np.median(one):8.2f} / {1e3 * np.median(many):8.2f} ms  x{median:.2f} ({q25:.2f}-{q75:.2f})")
    gain = np.array(times["replay", 1]) / np.array(times["replay", t]) - (
        np.array(times["step", 1]) / np.array(times["step", t]))
    print(f"  the replay's speed-up less the step's, round by round: median {np.median(gain):+.2f}; "
          f"replayed passes stopped early: {stopped}")


if __name__ == "__main__":
    main()
