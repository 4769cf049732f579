"""Which threaded pass of a step scales, and the bytes it streams (docs/bench/session34.md).

    python bench/pass_scaling.py [--method dgmpm-ctu] [--size 256] [--threads 2] [--rounds 40]

One simulation of the bench's plate is stepped on one thread and on ``--threads`` in turn, one
step each a round (ABBA, as `skdgmpm bench` pairs its thread counts), every threaded pass
timestamped (`pass_gaps.timestamped`). Prints, per pass, its median time on each count and the
median of its per-round speed-ups (quartiles), and the bytes per cell of the arrays it streams:
those `parallel.chunked` cuts by rows (``r``, ``i``, ``c``, ``k``), each buffer once, and beside
them those it takes whole (``w``: gathered by index, or not read at all). Streamed bytes over
the pass's time give its rate, to read against the triad's on the same counts (the last line,
`bench.memory_bandwidth`): a pass near the triad's rate gains at most what the triad gains. The
bytes are the arrays' sizes, not counted traffic (no write-allocate, no cache reuse), taken in
one more step on each count after the timed ones (taken in the timed steps, the walk over the
arguments doubled the step's time outside its passes, docs/bench/session36.md). Then the
passes' speed-up taken together, and the step's time outside them (`between`): the speed-up the
step would have with nothing between its passes, and what the serial rest costs it. Timings
are measurements on the machine at hand, not test results.
"""
import argparse
import collections
import importlib.util
from pathlib import Path

import numpy as np

from skdgmpm import bench, parallel
from skdgmpm.build import build

_spec = importlib.util.spec_from_file_location("pass_gaps", Path(__file__).with_name("pass_gaps.py"))
pass_gaps = importlib.util.module_from_spec(_spec)
_spec.loader.exec_module(pass_gaps)

STREAMED = ("r", "i", "c", "k")         # `parallel.chunked` letters that cut an argument by rows


def arrays(parsed, args):
    """The arrays of a `chunked` call as (letter, array), each buffer once (by its first byte and
    size), the letters of ``parsed`` (`parallel._parsed`) paired with ``args`` (tuples nested
    alike; a CSR triple's three arrays under its ``c``)."""
    seen, out = set(), []

    def visit(letter, arg):
        if isinstance(letter, tuple):
            for item_letter, item in zip(letter, arg):
                visit(item_letter, item)
        elif isinstance(arg, (tuple, list)):
            for item in arg:
                visit(letter, item)
        elif isinstance(arg, np.ndarray):
            key = (arg.__array_interface__["data"][0], arg.nbytes)
            if key not in seen:
                seen.add(key)
                out.append((letter, arg))

    visit(tuple(letter for letter in parsed if letter not in ("l", "h")), args)
    return out


def counted(sizes, patch=setattr):
    """Wrap `parallel.chunked` and `parallel.together` to add each outermost call's (streamed,
    whole) bytes (both passes' for `together`, each buffer once per pass) to
    ``sizes[kernel name]`` (a list of pairs, one per call) while the switch it returns is on
    (``switch[0] = True``; off as made): the walk over a call's arguments costs a step's Python
    as much again as the step's own between its passes, so the timed steps run with it off
    (`measure`). ``patch(module, name, value)`` replaces it (a test passes pytest's
    monkeypatch.setattr, which undoes it)."""
    depth, switch = [0], [False]

    def wrap(call):
        def sized(*args, **kwargs):
            depth[0] += 1
            try:
                if depth[0] == 1 and switch[0]:
                    passes = args if call.__name__ == "together" else (parallel.Pass(*args, **kwargs),)
                    found = [x for p in passes for x in arrays(parallel._parsed(p.spec), p.args)]
                    streamed = sum(a.nbytes for letter, a in found if letter in STREAMED)
                    sizes[pass_gaps.pass_name(call, args)].append((streamed, sum(a.nbytes for _, a in found) - streamed))
                return call(*args, **kwargs)
            finally:
                depth[0] -= 1
        sized.__name__ = call.__name__
        return sized
    for name in ("chunked", "together"):
        patch(parallel, name, wrap(getattr(parallel, name)))
    return switch


def measure(method, n, threads, rounds, marks, counting=None, warmup=3):
    """Per-pass times {count: {pass: [seconds per step]}} and the step's, one simulation stepped
    on 1 and ``threads`` threads in turn (ABBA), ``rounds`` timed rounds after ``warmup``, and the
    cells. The passes must be `pass_gaps.timestamped` into ``marks``; a pass that runs several
    times in a step is summed. ``counting``: the switch of `counted`, turned on for one more step
    on each count after the timed rounds (so its sizes hold one step's passes per count, and no
    timed step pays for the count)."""
    disc = build(bench.scene_for(method, n))
    step = bench.Stepping(disc)
    previous = parallel.set_threads(1)      # the setting itself (None: $SKDGMPM_THREADS or every core), put back
    try:
        times = pass_gaps.paired_rounds(step, marks, (1, threads), bench._use_threads, rounds, warmup)
        if counting is not None:
            counting[0] = True
            try:
                for t in (1, threads):
                    bench._use_threads(t)
                    step()
            finally:
                counting[0] = False
    finally:
        parallel.set_threads(previous)
    return times, int(disc.stepper.grid.submesh.nelements)


def between(times, threads):
    """Per round, on 1 and ``threads`` threads, the passes' summed time and the step's time
    outside them (the serial Python between passes, and the compiled code that is not a
    threaded pass): {count: (passes, rest)}, arrays (rounds,), from `measure`'s times. The
    passes' own speed-up is what the step would gain with nothing between them."""
    out = {}
    for count in (1, threads):
        passes = sum(np.array(v) for name, v in times[count].items() if name != "step")
        out[count] = (passes, np.array(times[count]["step"]) - passes)
    return out


def rounds_parser():
    """The command line of the scripts that step the bench plate on 1 and ``--threads`` threads in
    turn (this one, step_replay.py)."""
    parser = argparse.ArgumentParser()
    parser.add_argument("--method", default="dgmpm-ctu")
    parser.add_argument("--size", type=int, default=256)
    parser.add_argument("--threads", type=int, default=2)
    parser.add_argument("--rounds", type=int, default=40)
    return parser


def main():
    args = rounds_parser().parse_args()
    marks, sizes = [], collections.defaultdict(list)
    pass_gaps.timestamped(marks)
    switch = counted(sizes)
    times, cells = measure(args.method, args.size, args.threads, args.rounds, marks, switch)
    t = args.threads
    print(f"{args.method} {args.size}^2, 1 and {t} threads in turn, {args.rounds} rounds (ABBA); "
          f"per pass: median us per step, speed-up (quartiles), bytes per cell streamed + whole, GB/s streamed")
    for name in times[1]:
        one, many = np.array(times[1][name]), np.array(times[t][name])
        q25, median, q75 = np.percentile(one / many, [25, 50, 75])
        line = (f"  {name:20s} {1e6 * np.median(one):8.0f} / {1e6 * np.median(many):8.0f} us  "
                f"x{median:.2f} ({q25:.2f}-{q75:.2f})")
        if name in sizes:
            calls = len(sizes[name]) / 2                # calls per step: one counted step on each count
            streamed, whole = (calls * np.mean([s[i] for s in sizes[name]]) for i in (0, 1))
            line += (f"  {streamed / cells:6.0f} + {whole / cells:5.0f} B/cell  "
                     f"{streamed / np.median(one) / 1e9:5.1f} / {streamed / np.median(many) / 1e9:5.1f} GB/s")
        print(line)
    split = between(times, t)
    (p1, r1), (pt, rt) = split[1], split[t]
    print(f"  passes alone         x{np.median(p1 / pt):.2f}; outside them {1e6 * np.median(r1):.0f} / "
          f"{1e6 * np.median(rt):.0f} us a step ({100 * np.median(rt / (pt + rt)):.1f} % of the {t}-thread step)")
    speeds = bench.memory_bandwidth([1, t])
    print(f"  triad (bench.memory_bandwidth): {speeds[1]:.1f} / {speeds[t]:.1f} GB/s (x{speeds[t] / speeds[1]:.2f})")


if __name__ == "__main__":
    main()
