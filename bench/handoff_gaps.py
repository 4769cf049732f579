"""How long handing a pass to numba's OpenMP threads takes after the calling thread ran Python for a
while (docs/bench/session30.md §3): a near-empty chunked pass on two threads, timed after gaps of
0 µs to 3 ms of busy Python. Compare OpenMP's wait policies by environment, e.g.

    python bench/handoff_gaps.py default
    OMP_WAIT_POLICY=passive python bench/handoff_gaps.py passive

Timings are measurements on the machine at hand, not test results.
"""
import time, statistics, sys
import numpy as np
from skdgmpm import parallel, bench
bench._use_threads(2)
x = np.ones(1 << 16); y = np.empty_like(x)
from skdgmpm.bench import arithmetic_rows
def launch():
    parallel.chunked(len(x), arithmetic_rows, "rrw", (x, y, 0))
for _ in range(20): launch()
res = {}
for gap in (0, 20e-6, 100e-6, 300e-6, 1e-3, 3e-3):
    ts = []
    for r in range(200):
        launch()
        t_end = time.perf_counter() + gap
        while time.perf_counter() < t_end: pass     # Python busy in the main thread, as between passes
        t0 = time.perf_counter(); launch(); ts.append(time.perf_counter() - t0)
    res[gap] = statistics.median(ts)
print(sys.argv[1], " ".join(f"gap {g*1e6:.0f}us: {t*1e6:.1f}us" for g, t in res.items()))
