"""Where a step's Python lies between its threaded passes (docs/bench/session32.md).

    python bench/pass_gaps.py [--method dgmpm-ctu] [--size 256] [--threads 2] [--steps 100]

The bench's plate is stepped on ``--threads`` threads; every threaded pass (`parallel.chunked`,
`parallel.together`, the pool's `parallel.rows`; a pass inside another counted once) is timestamped as it starts and
ends. Prints the median wall time of each gap (from the step's start to its first pass, between
two passes, from its last pass to its end), named by the passes around it, and each pass's own
time. `serial_share.py` gives the sum; this says where it is. Timings are measurements on the
machine at hand, not test results.
"""
import argparse
import collections
import statistics
import time

from skdgmpm import bench, parallel
from skdgmpm.build import build


def pass_name(call, args):
    """The name of a threaded pass: its kernel's (`parallel.chunked`, `parallel.rows`), or its
    passes' joined by "+" (`parallel.together`)."""
    if call.__name__ == "together":
        return "+".join(getattr(p.kernel, "__name__", "chunked") for p in args)
    return getattr(args[1], "__name__", call.__name__)


def timestamped(marks, patch=setattr):
    """Wrap `parallel.chunked`, `parallel.together` and `parallel.rows` to append ("in", pass name,
    t) and ("out", "", t) to ``marks`` around each outermost pass (`pass_name`). ``patch(module,
    name, value)`` replaces each (a test passes pytest's monkeypatch.setattr, which undoes it)."""
    depth = [0]

    def wrap(call):
        def timed(*args, **kwargs):
            depth[0] += 1
            if depth[0] == 1:
                marks.append(("in", pass_name(call, args), time.perf_counter()))
            try:
                return call(*args, **kwargs)
            finally:
                depth[0] -= 1
                if depth[0] == 0:
                    marks.append(("out", "", time.perf_counter()))
        timed.__name__ = call.__name__
        return timed
    for name in ("chunked", "together", "rows"):
        patch(parallel, name, wrap(getattr(parallel, name)))


def split(marks, t0, t1):
    """One step's wall time t0 -> t1 cut at its passes' ``marks``: (gaps, passes), lists of
    (name, seconds) in step order; a gap is named by the passes around it ("start -> a",
    "a -> b", "b -> end"). Together they add up to the step."""
    gaps, passes = [], []
    last, label = t0, "start"
    for kind, name, t in marks:
        if kind == "in":
            gaps.append((f"{label} -> {name}", t - last))
            label, began = name, t
        else:
            passes.append((label, t - began))
            last = t
    gaps.append((f"{label} -> end", t1 - last))
    return gaps, passes


def step_passes(step, marks):
    """One ``step()`` timed: (its wall seconds, {pass: its seconds in the step, summed where it
    runs several times}). The passes must be `timestamped` into ``marks``."""
    marks.clear()
    t0 = time.perf_counter()
    step()
    t1 = time.perf_counter()
    total = collections.Counter()
    for name, seconds in split(marks, t0, t1)[1]:
        total[name] += seconds
    return t1 - t0, total


def paired_rounds(step, marks, ways, use, rounds, warmup):
    """{way: {pass: [seconds per step], "step": [...]}} of ``rounds`` timed rounds after
    ``warmup``: each round steps once each way of the pair ``ways``, in ABBA order (a, b, then b,
    a), ``use(way)`` called before each step (`step_passes`)."""
    a, b = ways
    times = {way: collections.defaultdict(list) for way in ways}
    for k in range(warmup + rounds):
        for way in ((a, b) if k % 2 == 0 else (b, a)):
            use(way)
            wall, passes = step_passes(step, marks)
            if k < warmup:
                continue
            for name, seconds in passes.items():
                times[way][name].append(seconds)
            times[way]["step"].append(wall)
    return times


def measure(method, n, steps, threads, marks):
    """(gaps, passes, walls) over ``steps`` steps of the bench's plate after 5 warm-up steps:
    {name: [seconds per step]} for the gaps and the passes, and the steps' wall times. The
    passes must be `timestamped` into ``marks``."""
    disc = build(bench.scene_for(method, n))
    step = bench.Stepping(disc)
    bench._use_threads(threads)
    for _ in range(5):
        step()
    gaps, passes, walls = collections.defaultdict(list), collections.defaultdict(list), []
    for _ in range(steps):
        marks.clear()
        t0 = time.perf_counter()
        step()
        t1 = time.perf_counter()
        for into, parts in zip((gaps, passes), split(marks, t0, t1)):
            for name, seconds in parts:
                into[name].append(seconds)
        walls.append(t1 - t0)
    return gaps, passes, walls


def main():
    parser = argparse.ArgumentParser()
    parser.add_argument("--method", default="dgmpm-ctu")
    parser.add_argument("--size", type=int, default=256)
    parser.add_argument("--threads", type=int, default=2)
    parser.add_argument("--steps", type=int, default=100)
    args = parser.parse_args()
    marks = []
    timestamped(marks)
    gaps, passes, walls = measure(args.method, args.size, args.steps, args.threads, marks)
    print(f"{args.method} {args.size}^2, {args.threads} thread(s), medians of {args.steps} steps")
    for name, values in gaps.items():
        print(f"  gap  {name:48s} {1e6 * statistics.median(values):8.1f} us")
    for name, values in passes.items():
        print(f"  pass {name:48s} {1e6 * statistics.median(values):8.1f} us")
    total = sum(statistics.median(v) for v in gaps.values())
    print(f"  step {1e6 * statistics.median(walls):.0f} us; the gaps' medians add up to {1e6 * total:.0f} us")


if __name__ == "__main__":
    main()
