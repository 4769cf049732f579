"""The step contract: every scheme's step is its list of named stages, and they run.

A step of each method runs exactly the stages its ``stages`` lists (those a scene needs: CTU's
transverse_flux only in 2D CTU, RK2's nodal_state only with RK2, ...), each timed by the
`skdgmpm.scheme.stage` clock, and the stages' own times add up to the step's wall time; the
time integrators (`skdgmpm.integrators`) are written once and reach their order on y' = y.
"""
import time

import numpy as np
import pytest

from skdgmpm import integrators
from skdgmpm.build import build
from skdgmpm.scene import load_scene

TRIES = 5                       # three steps each; the best covers the step (see the test)
ADER_DGMPM = ['method.name="ader-dgmpm"', "method.cfl=0.4", "particles.per_cell=[0.25, 0.75]"]
CASES = {   # (scene, overrides): the stages that must not run
    "dgmpm-ctu": ("plate_impact_neohookean_2d", ["grid.cells=[6, 6]"], {"nodal_state", "source"}),
    "dgmpm-rk2": ("bar_elastic_1d", ["particles.per_cell=2", 'method.integrator="rk2"'],
                  {"transverse_flux", "source"}),
    "rk-dgfem": ("plate_impact_neohookean_2d", ['method.name="rk-dgfem"', 'method.integrator="rk2"',
                                                "method.cfl=0.4", "grid.cells=[6, 6]"], {"source"}),
    "ader-dgmpm": ("plate_impact_neohookean_2d", [*ADER_DGMPM, "grid.cells=[6, 6]"], {"source"}),
    "mpm-usf": ("bar_elastic_1d", ['method.name="mpm"', 'method.update="usf"'], set()),
    "mms-dgmpm": ("mms_axis_aligned_2d", ["grid.cells=[4, 4]"], {"nodal_state"}),
}


@pytest.mark.parametrize("case", CASES)
def test_a_step_runs_the_listed_stages_and_their_times_add_up(case):
    scene, overrides, idle = CASES[case]
    disc = build(load_scene(scene, overrides))
    stepper, state = disc.stepper, disc.initial
    state = stepper.step(state)                 # compiles (or loads) the kernels
    shares = []
    for _ in range(TRIES):
        stepper.stage_times(reset=True)
        t0 = time.perf_counter()
        for _ in range(3):
            state = stepper.step(state)
        wall = time.perf_counter() - t0
        times = stepper.stage_times()
        ran = set(times)
        assert ran <= set(stepper.stages)                               # nothing unlisted is timed
        expected = set(stepper.stages) - idle
        if getattr(stepper, "ctu", None) is None:
            expected -= {"transverse_flux"}
        assert ran == expected, (sorted(ran), sorted(expected))
        assert all(calls >= 3 for _, calls in times.values())
        own = sum(seconds for seconds, _ in times.values())
        assert own <= wall * 1.001                                      # own times: no double counting
        assert list(times) == [name for name in stepper.stages if name in times]
        shares.append(own / wall)
    # the stages cover the step: more than half of it in the best try (a try the host preempts
    # between two stages, e.g. beside another test process on two cores, counts that pause outside
    # them: it measures the host, not the step)
    assert max(shares) > 0.5, shares


@pytest.mark.parametrize("name, order", [("euler", 1), ("rk2", 2), ("rk4", 4)])
def test_each_integrator_reaches_its_order_on_the_exponential(name, order):
    def stage(U, base, t, step):                # y' = y: base + step L(U), the base formed in numpy
        return integrators.formed(base) + step * U, 1.0

    errors = []
    for n in (8, 16):
        y, dt = np.ones(1), 0.5 / n
        for k in range(n):
            y, work = integrators.INTEGRATORS[name](stage, y, k * dt, dt)
        errors.append(abs(y[0] - np.exp(0.5)))
        assert work == pytest.approx(dt)                                # the power 1 W over dt
    assert np.log2(errors[0] / errors[1]) == pytest.approx(order, abs=0.15)
