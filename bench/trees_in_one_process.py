"""Two versions of the code stepped in one process, in turn: is a change faster (docs/bench/session53.md).

    python bench/trees_in_one_process.py REV [--method dgmpm-dcu] [--size 256] [--rounds 40]

REV (a commit, a branch, or "HEAD" to compare the working tree against its last commit; "." for
the working tree against a copy of itself: the protocol's own bias) is copied out of git into a
temporary folder as the package ``skdgmpm_rev`` (its imports renamed), beside the installed
``skdgmpm``; the bench plate of each is built and stepped on one and on two threads. Each round
is eight steps, A1 B2 B1 A2 B1 A2 A1 B2 (tree, threads): every step has the same predecessors as
its counterpart in the other tree (a two-thread step always follows a one-thread step of the
other tree, as the bench's pairing has it), so that neither tree's two-thread steps find numba's
threads awake more often. Prints each tree's median step on each count, its speed-up, and the
medians of the per-round ratios rev / this (above 1: this tree is faster).

Two trees in two processes, stepped in turn, read up to x1.14 apart on unchanged code: one
process's idle OpenMP threads still spin while the other steps. Here both trees' passes share
numba's threads. Each tree keeps its own kernel cache (its sources' digest) and registers its
own compile listener with numba (`kernel_cache.Vectorise`): the two restore numba's SLP setting
out of order, which is why the copy is loaded only in a process of its own. Timings are
measurements on the machine at hand, not test results.
"""
import argparse
import importlib
import re
import shutil
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
PACKAGES = {"skdgmpm": "", "forms": "forms", "materials": "materials", "cases": "cases"}   # folder: its place inside
NAME = "skdgmpm_rev"
ORDER = (("A", 1), ("B", 2), ("B", 1), ("A", 2), ("B", 1), ("A", 2), ("A", 1), ("B", 2))


def copy_of(rev, into):
    """The package of ``rev`` ("." the working tree) as ``NAME`` under ``into``: skdgmpm/ with
    forms/, materials/ and cases/ inside it (as an install lays them out), every import of
    skdgmpm renamed."""
    package = into / NAME
    for folder, inside in PACKAGES.items():
        target = package / inside if inside else package
        if rev == ".":
            shutil.copytree(ROOT / folder, target, ignore=shutil.ignore_patterns("__pycache__"), dirs_exist_ok=True)
        else:
            target.mkdir(parents=True, exist_ok=True)
            archive = subprocess.run(["git", "-C", str(ROOT), "archive", rev, folder], check=True,
                                     capture_output=True).stdout
            subprocess.run(["tar", "-x", "-C", str(target), "--strip-components=1"], input=archive, check=True)
    for path in package.rglob("*.py"):
        text = path.read_text()
        text = re.sub(r"\b(from|import) skdgmpm(?=[. ])", rf"\1 {NAME}", text)
        path.write_text(text.replace('"skdgmpm.cases"', f'"{NAME}.cases"'))
    return package


def stepping(package, method, n):
    """A `bench.Stepping` of the plate of ``package`` and its thread setter."""
    bench = importlib.import_module(f"{package}.bench")
    build = importlib.import_module(f"{package}.build").build
    return bench.Stepping(build(bench.scene_for(method, n))), bench._use_threads


def main():
    parser = argparse.ArgumentParser()
    parser.add_argument("rev")
    parser.add_argument("--method", default="dgmpm-dcu")
    parser.add_argument("--size", type=int, default=256)
    parser.add_argument("--rounds", type=int, default=40)
    args = parser.parse_args()
    with tempfile.TemporaryDirectory() as tmp:
        copy_of(args.rev, Path(tmp))
        sys.path.insert(0, tmp)
        trees = {"A": stepping("skdgmpm", args.method, args.size), "B": stepping(NAME, args.method, args.size)}
        for step, use in trees.values():
            for threads in (1, 2):
                use(threads)
                for _ in range(3):
                    step()
        times = {key: [] for key in set(ORDER)}
        ratios = {1: [], 2: []}
        for _ in range(args.rounds):
            spent = {key: [] for key in set(ORDER)}
            for tree, threads in ORDER:
                step, use = trees[tree]
                use(threads)
                t0 = time.perf_counter()
                step()
                spent[tree, threads].append(time.perf_counter() - t0)
            for key, values in spent.items():
                times[key].extend(values)
            for threads in (1, 2):
                ratios[threads].append(sum(spent["B", threads]) / sum(spent["A", threads]))
    med = {key: statistics.median(values) for key, values in times.items()}
    print(f"{args.method} {args.size}^2, {args.rounds} rounds of eight steps; this tree (A) and {args.rev} (B)")
    for tree in "AB":
        print(f"  {tree}: one thread {1e6 * med[tree, 1]:.0f} us, two {1e6 * med[tree, 2]:.0f} us a step, "
              f"x{med[tree, 1] / med[tree, 2]:.3f}")
    print(f"  B / A, median of the rounds: one thread {statistics.median(ratios[1]):.3f}, "
          f"two {statistics.median(ratios[2]):.3f}")


if __name__ == "__main__":
    main()
