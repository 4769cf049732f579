"""Which scenes compile a kernel after their first step (docs/bench/session40.md).

    python bench/late_compiles.py [SCENE ...] [--steps 40] [--set KEY=VALUE ...]

Runs each scene (default: every scene of cases/) for ``--steps`` steps in this process, on an
empty kernel cache (a temporary NUMBA_CACHE_DIR, removed afterwards: the user's cache is neither
read nor filled), and times numba's outermost compilations by the step they happen in. A run
reports such a compilation in its start-up (`skdgmpm.run`), but the user still waits for it in
the middle of the run; the first step is where a scene should compile. The scenes share the
process: a kernel an earlier scene compiled is not compiled again, so each row says what that
scene added. Timings are the machine's at hand, not test results.
"""
import argparse
import os
import sys
import tempfile
from pathlib import Path

from numba.core import config, event

CASES = Path(__file__).resolve().parent.parent / "cases"


def compiles_by_step():
    """A `CompileClock` that keeps each outermost compilation as (step, seconds, function name) in
    ``found``, ``step`` set by the caller (0: the build and the initial state; k: the k-th step)."""
    from skdgmpm.run import CompileClock

    class Compiles(CompileClock):
        def __init__(self):
            super().__init__()
            self.step, self.found = 0, []

        def compiled(self, seconds, ev):
            self.found.append((self.step, seconds, ev.data["dispatcher"].py_func.__qualname__))

    return Compiles()


def main():
    parser = argparse.ArgumentParser()
    parser.add_argument("scenes", nargs="*")
    parser.add_argument("--steps", type=int, default=40)
    parser.add_argument("--set", action="append", default=[], metavar="KEY=VALUE")
    args = parser.parse_args()
    scenes = args.scenes or sorted(p.stem for p in CASES.glob("*.toml"))
    with tempfile.TemporaryDirectory() as work:
        config.CACHE_DIR = os.path.join(work, "cache")      # before the package's kernels are made
        from skdgmpm.run import run
        print(f"{'scene':32} {'first s':>8} {'later s':>8}  compiled after the first step")
        for scene in scenes:
            compiles = compiles_by_step()

            def on_step(state, disc):               # called with the initial state, then after each step
                compiles.step = state.step + 1          # the step about to run

            with event.install_listener("numba:compile", compiles):
                try:
                    run(scene, args.set, progress=False, max_steps=args.steps, on_step=on_step, notice=False)
                except Exception as exc:            # a scene that stops (unstable, bad input) is reported
                    print(f"{scene:32} {type(exc).__name__}: {exc}")
            first = sum(s for step, s, _ in compiles.found if step <= 1)
            later = [(step, s, name) for step, s, name in compiles.found if step > 1]
            where = ", ".join(f"{name} at step {step} ({s:.1f} s)" for step, s, name in later)
            print(f"{scene:32} {first:8.1f} {sum(s for _, s, _ in later):8.1f}  {where or '-'}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
