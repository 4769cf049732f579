"""Each paired round's two-thread speed-up against the arithmetic probe's in the same round, over
the bench's JSON files (docs/bench/session52.md §2).

    python bench/rounds_vs_probe.py [--since 48] [--cells 65536] [FILES ...]

`skdgmpm bench --threads 1,2 --json F` keeps, per method and repeat, every round's wall time of
one step on one and on two threads and the probe's time on each (the probe on t threads does t
times the work). This prints per method, over the rounds of the files (default: the sessions'
files in docs/bench from ``--since`` on), how often a round's step reached x1.8, and how that
changes when only the rounds whose probe reached x1.8, x1.9, x1.95 are kept: whether the misses
come with the host's minutes or with the code. A method's rounds whose two-thread step came
right after the other count's (every round before the forty-fifth session, and the untimed
settling steps since: `bench.SETTLE`) are counted apart, as "<method>, first step after a switch".
Measurements of the machine they ran on.
"""
import argparse
import collections
import glob
import json
import re

import numpy as np

SWITCHED = ", first step after a switch"      # the label of rounds whose step followed the other count's


def rounds(files, cells):
    """{method: array (rounds, 2) of (the step's speed-up, the probe's)} over the files' paired
    two-thread rows on ``cells`` cells."""
    out = collections.defaultdict(list)
    for path in files:
        with open(path) as fh:
            data = json.load(fh)
        for row in data.get("threads_paired", []) if isinstance(data, dict) else []:
            if row.get("cells") != cells or "probe_s" not in row or "2" not in row["wall_s"]:
                continue
            p1, p2 = np.array(row["probe_s"]["1"]), np.array(row["probe_s"]["2"])
            # since docs/bench/session54.md §1 each timed step follows a step on its own count, and
            # the first step after each switch is kept apart: before, every timed step was such
            timed = "" if "settle" in row else SWITCHED
            for kind, key in ((timed, "wall_s"), (SWITCHED, "switch_wall_s")):
                if key in row:
                    w1, w2 = np.array(row[key]["1"]), np.array(row[key]["2"])
                    out[row["method"] + kind] += list(zip(w1 / w2, 2 * p1 / p2))
    return {m: np.array(v) for m, v in out.items()}


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("files", nargs="*")
    parser.add_argument("--since", type=int, default=48, help="first session's files (without FILES)")
    parser.add_argument("--cells", type=int, default=65536)
    args = parser.parse_args(argv)
    files = args.files or [f for f in sorted(glob.glob("docs/bench/session*.json"))
                           if int(re.search(r"session(\d+)", f).group(1)) >= args.since]
    for method, r in sorted(rounds(files, args.cells).items()):
        print(f"{method}: {len(r)} rounds")
        for floor in (0.0, 1.8, 1.9, 1.95):
            kept = r[r[:, 1] >= floor]
            if len(kept):
                step, share = np.median(kept[:, 0]), np.median(kept[:, 0] / kept[:, 1])
                print(f"  probe >= {floor:.2f}: {len(kept):5d} rounds, step x{step:.2f} (median), "
                      f"{np.mean(kept[:, 0] >= 1.8):.0%} at 1.8 or more, the step {share:.2f} of the probe")


if __name__ == "__main__":
    main()
