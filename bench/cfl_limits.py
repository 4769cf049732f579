"""Largest CFL (L23 eq 67) per high-order method and order on the exact standing wave.

    python bench/cfl_limits.py

Criterion: no instability, and after two periods (8 x 8 cells, no limiter) the total energy is
below its initial value and never exceeded it by 1 %. Results: docs/results.md.
"""
import numpy as np
from skdgmpm.run import run
LAY = {1: '[0.25,0.75]', 2: '[0.25,0.5,0.75]', 3: '[0.2,0.4,0.6,0.8]'}
for name in ("ader-dgfem", "ader-dgmpm", "rk-dgfem"):
    for order in (1, 2, 3):
        ok_max = None
        for cfl in np.arange(0.3, 1.51, 0.1):
            ex = [f"particles.per_cell={LAY[order]}"] if name == "ader-dgmpm" else []
            if name == "rk-dgfem":
                ex.append(f'method.integrator="{"rk2" if order == 1 else "rk4"}"')
            r = run("standing_wave_2d", [f'method.name="{name}"', f"method.order={order}", f"method.cfl={cfl:.2f}",
                                         "grid.cells=[8,8]", "run.t_end=5e-4", *ex], progress=False)
            total = r.history["total"]
            if r.status != "ok" or total[-1] > total[0] or total.max() > 1.01 * total[0]:
                break
            ok_max = cfl
        print(name, order, "stable up to CFL", None if ok_max is None else round(ok_max, 2), flush=True)
