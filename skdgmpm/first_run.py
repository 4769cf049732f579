"""The first run's notice: one line on stderr the first time a run compiles a kernel of this
package (the cache misses), with about how long it will take, and nothing when every kernel comes
from the cache (`compile_notice`, a context manager around a run). No compiled code here: its
estimates change without changing the kernel cache's key (`skdgmpm.kernel_cache`)."""
import json
import os
import sys
import time

from numba.core import event

from .kernel_cache import cache_base, cache_dir, ours

# Seconds of a cold first run's start-up, per method and dimension, on the 2-core VM of
# docs/bench/session39.md to session44.md, the rest of the step compiled by a second process
# meanwhile (`skdgmpm.compile_helper`, session44.md §1; one process in brackets):
# bar_elastic_1d 7-9 s (11-14 s, dgmpm); plate_impact_neohookean_2d 12-16 s (22-28 s, dgmpm),
# 11 s (16 s, mpm); the J2 plate and partial_impact_2d 15 s (21-23 s); standing_wave_2d 29-36 s
# (37-49 s, dgmpm, 2 x 2 particles per cell), 19-23 s (28 s, ader-dgfem P1), 17 s (22 s,
# rk-dgfem P1); multiholed_cell_j2_2d 29 s (37-44 s, ader-dgmpm, Hencky J2), lasat_2d 33 s (54 s);
# the others estimated alike. The notice says the last one measured on this machine instead
# (<base>/compile_seconds.json) where there is one.
# DGMPM on the grid's nodes (several particles a cell, RK2: `compile_helper.nodal`), two helpers
# (session45.md §2): the bar with two particles a cell 17-20 s (22-23 s with one helper);
# standing_wave_2d 25-32 s, the 2 x 2 plate 38-41 s, the RK2 plate 42-48 s (33-57 s).
EXPECTED_S = {"dgmpm": {1: 10, 2: 20}, "dgmpm on the nodes": {1: 20, 2: 35}, "mpm": {1: 15, 2: 20},
              "rk-dgfem": {1: 25, 2: 30}, "ader-dgfem": {1: 25, 2: 35}, "ader-dgmpm": {1: 25, 2: 35}}


def _measured_path():
    return os.path.join(cache_base(), "compile_seconds.json")


def _measured():
    try:
        with open(_measured_path()) as f:
            return json.load(f)
    except (OSError, ValueError):
        return {}


NOTICE = "compiling kernels for "       # the notice's first words (a reader of stderr can set it aside)


class compile_notice(event.Listener):
    """A context manager around a run (re-enterable): within, the first time one of this
    package's kernels is compiled (the cache lacks it), print `NOTICE` "<method>, <d>D (first
    run, about N s; cached afterwards in <dir>)" on ``stream`` (stderr); nothing when every
    kernel comes from the cache. ``seconds``: the CPU time spent compiling within (and the time
    the run waited for its compile helper, `skdgmpm.compile_helper`, added by the run), remembered
    as the next estimate for this method and dimension. ``on_first``: called at that first
    compilation (the run's compile helper starts; true where it did: the line says "on two
    cores"); ``show`` False: only that, no line and no estimate kept."""

    def __init__(self, method, d, stream=None, on_first=None, show=True):
        self.what, self.stream, self.on_first, self.show = f"{method}, {d}D", stream, on_first, show
        self.expected = EXPECTED_S.get(method, {}).get(d)
        self.shown, self.depth, self.seconds, self._start = False, 0, 0.0, 0.0

    def __enter__(self):
        event.register("numba:compile", self)
        return self

    def __exit__(self, *exc):
        event.unregister("numba:compile", self)
        self.depth = 0
        if self.shown and self.show and self.seconds > 1:       # remember how long it took (best effort)
            try:
                measured = {**_measured(), self.what: round(self.seconds)}
                with open(_measured_path(), "w") as f:
                    json.dump(measured, f, indent=1)
            except OSError:
                pass

    def on_start(self, ev):
        self.depth += 1
        if self.depth > 1:
            return
        self._start = time.process_time()
        if not self.shown and ours(ev):
            self.shown = True
            helped = self.on_first is not None and self.on_first()
            if not self.show:
                return
            expected = _measured().get(self.what, self.expected)
            about = (f"about {expected} s" if expected else "") + (", on two cores" if helped else "")
            about += "; " if about else ""
            from tqdm import tqdm               # clears a progress bar on the stream, then redraws it
            tqdm.write(f"{NOTICE}{self.what} (first run, {about}cached afterwards in {cache_dir()})",
                       file=self.stream or sys.stderr)

    def on_end(self, ev):
        self.depth -= 1
        if self.depth == 0:
            self.seconds += time.process_time() - self._start
