"""What a scene's first run compiles, and for how long (docs/bench/session38.md).

    python bench/compile_times.py SCENE [--set KEY=VALUE ...] [--top 15] [--passes N] [--helper]

Runs ``skdgmpm run SCENE`` in this process on an empty kernel cache (a temporary
NUMBA_CACHE_DIR, removed afterwards: the user's cache is neither read nor filled), every
compilation of a numba function timed (`timed_compiles`; a function compiled while its caller
compiles is inside the caller's time, one level deeper). Prints the run's start-up, then the
kernels compiled at the top level, slowest first, each with numba's own split of it: its front
end (typing, inlining, lowering to LLVM IR) and LLVM's optimisation and code generation; then
the functions most often compiled inside them. The first run's notice says how long a scene
compiles; this says where it goes. The run's compile helpers (`skdgmpm.compile_helper`) are off
unless ``--helper``: then the list is what the run's own process still compiles. Timings are the
machine's at hand, not test results.
"""
import argparse
import collections
import contextlib
import os
import sys
import tempfile
import time

from numba.core import config, dispatcher


@contextlib.contextmanager
def timed_compiles():
    """Inside: every compilation of a numba function in this process timed, as (seconds, depth,
    dispatcher, signature) in the list yielded, in the order they end (depth 0: compiled from
    Python; a function compiled while another compiles: one more than it). A signature already
    compiled in this process is not counted again."""
    records, depth = [], [0]
    compile_ = dispatcher.Dispatcher.compile

    def timed(self, sig):
        start, known = time.perf_counter(), len(self.overloads)
        depth[0] += 1
        try:
            return compile_(self, sig)
        finally:
            depth[0] -= 1
            if len(self.overloads) > known:         # compiled, not found among those already made
                records.append((time.perf_counter() - start, depth[0], self, sig))

    dispatcher.Dispatcher.compile = timed
    try:
        yield records
    finally:
        dispatcher.Dispatcher.compile = compile_


def split(function):
    """(front end s, LLVM s) of a compiled function's first signature, from numba's timers (its
    compiler's time includes LLVM's)."""
    timers = {}
    for result in function.overloads.values():
        timers = (result.metadata or {}).get("timers", {})
        break
    llvm = timers.get("llvm_lock", float("nan"))
    return timers.get("compiler_lock", float("nan")) - llvm, llvm


def passes(function):
    """numba's compiler passes of a compiled function's first signature, slowest first:
    [(pass name, seconds)] (its ``pipeline_times``)."""
    for result in function.overloads.values():
        times = (result.metadata or {}).get("pipeline_times", {})
        runs = [(p.split("_", 1)[1], t.init + t.run + t.finalize) for pipeline in times.values()
                for p, t in pipeline.items()]
        return sorted(runs, key=lambda r: -r[1])
    return []


def name(function):
    """A kernel's readable name: module and qualified name, a factory's variant tag kept."""
    return f"{function.py_func.__module__}.{function.py_func.__qualname__.replace('.<locals>.', ':')}"


def main():
    parser = argparse.ArgumentParser()
    parser.add_argument("scene")
    parser.add_argument("--set", action="append", default=[], metavar="KEY=VALUE")
    parser.add_argument("--top", type=int, default=15)
    parser.add_argument("--passes", type=int, default=0, metavar="N",
                        help="numba's slowest compiler passes of each of the N slowest kernels")
    parser.add_argument("--helper", action="store_true",
                        help="with the run's compile helpers (skdgmpm.compile_helper): what the run's own process "
                             "compiles while they compile the step's face passes; without them, every kernel")
    args = parser.parse_args()
    if args.helper:                 # as a user's run has them
        os.environ.pop("SKDGMPM_COMPILE_HELPER", None)
    else:
        os.environ["SKDGMPM_COMPILE_HELPER"] = "0"
    with tempfile.TemporaryDirectory() as work:
        config.CACHE_DIR = os.path.join(work, "cache")      # before the package's kernels are made
        from skdgmpm.cli import main as skdgmpm
        argv = ["run", args.scene, "--out", os.path.join(work, "out"), "--quiet"]
        argv += [item for pair in args.set for item in ("--set", pair)]
        start = time.perf_counter()
        with timed_compiles() as records:
            status = skdgmpm(argv)
        elapsed = time.perf_counter() - start
    top = sorted((r for r in records if r[1] == 0), key=lambda r: -r[0])
    print(f"{args.scene}: exit status {status}, {elapsed:.1f} s in all; {len(records)} compilations, "
          f"{len(top)} from Python, {sum(r[0] for r in top):.1f} s")
    print(f"{'s':>7} {'front':>6} {'LLVM':>6}  kernel")
    for seconds, _, function, _ in top[:args.top]:
        front, llvm = split(function)
        print(f"{seconds:7.2f} {front:6.2f} {llvm:6.2f}  {name(function)}")
    for _, _, function, _ in top[:args.passes]:
        print(f"{name(function)}: " + ", ".join(f"{p} {s:.2f}" for p, s in passes(function)[:6]))
    inner = collections.Counter(name(function) for _, depth, function, _ in records if depth > 0)
    print("compiled most often inside them: " + ", ".join(f"{n} x{k}" for n, k in inner.most_common(5)))
    return status


if __name__ == "__main__":
    sys.exit(main())
