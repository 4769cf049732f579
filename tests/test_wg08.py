"""MPM/GIMP against the manufactured solutions of Wallstedt & Guilkey 2008 (WG08 §6), with WG08's
error measure: the largest displacement error over all particles and all steps.

The reference behaviour is WG08's (METHOD §8): centred-difference cpGIMP is second order in space
on the axis-aligned problem, uGIMP (particle sizes that do not follow the deformation) stops
converging on fine grids, USF converges poorly. The full study (up to 56 x 56 cells) is in
docs/results.md; here the same runs at coarse size and over part of a period.
"""
import numpy as np
import pytest

from skdgmpm.study import convergence

T_SHORT = "run.t_end=0.0075"      # 3/8 of the period 2/c: particles cross several cells at 32^2


def rates(rows, method):
    return [r["rate_u"] for r in rows if r["method"] == method][1:]


def test_cd_cpgimp_is_second_order_and_usf_is_not():
    rows = convergence("mms_axis_aligned_2d", ["mpm/cd-cpgimp", "mpm/usf-cpgimp"], [1], [8, 16],
                       progress=False, measure="wg08")
    assert all(r["status"] == "ok" for r in rows)
    (cd,), (usf,) = rates(rows, "mpm/cd-cpgimp"), rates(rows, "mpm/usf-cpgimp")
    assert cd > 1.8                  # 1.98 measured (2.01, 2.05 on 32, 56 cells)
    assert usf < 1.6                 # 1.48 measured (1.15, 0.98 on 32, 56 cells)
    errors = {r["method"]: r["Linf_u"] for r in rows if r["cells"] == 16}
    assert errors["mpm/cd-cpgimp"] < 0.6 * errors["mpm/usf-cpgimp"]


def test_uvf_is_second_order_like_cd_and_hat_functions_diverge():
    """UVF (CD with the updated particle velocities projected again before the strain update) with
    cpGIMP: second order and within 10 % of CD (1.96e-2, 4.82e-3, rate 2.02). With hat functions
    every variant's error grows with refinement (CD 3.37e-2, 5.53e-2, 1.03e-1 on 8, 16, 32 cells;
    UVF 3.47e-2, 6.14e-2, 1.19e-1): the particles cross cells (up to 3 cells at 32^2) and each
    crossing costs an O(1) error of the hat functions' gradient, more crossings on finer grids:
    the 0.15-0.18 'UVF' errors of issue 16 were hat-function runs. WG08 use GIMP for this reason."""
    rows = convergence("mms_axis_aligned_2d", ["mpm/uvf-cpgimp", "mpm/cd-cpgimp", "mpm/cd-hat"], [1], [8, 16],
                       progress=False, measure="wg08")
    assert all(r["status"] == "ok" for r in rows)
    (uvf,) = rates(rows, "mpm/uvf-cpgimp")
    assert uvf > 1.8
    errors = {(r["method"], r["cells"]): r["Linf_u"] for r in rows}
    assert errors["mpm/uvf-cpgimp", 16] < 1.1 * errors["mpm/cd-cpgimp", 16]
    assert errors["mpm/cd-hat", 16] > 1.3 * errors["mpm/cd-hat", 8]


@pytest.mark.slow
def test_ugimp_stops_converging_where_cpgimp_does_not():
    rows = convergence("mms_axis_aligned_2d", ["mpm/cd-cpgimp", "mpm/cd-ugimp"], [1], [16, 32],
                       progress=False, measure="wg08", overrides=[T_SHORT])
    (cp,), (u,) = rates(rows, "mpm/cd-cpgimp"), rates(rows, "mpm/cd-ugimp")
    assert cp > 1.8                  # 1.92 measured
    assert u < 0.5                   # 0.01 measured: the error stalls at 3.3e-3


def test_displacement_error_is_zero_for_the_exact_state():
    # the measure itself: a run of zero steps has the exact initial positions x = X + u(X, 0)
    rows = convergence("mms_axis_aligned_2d", ["mpm/cd-cpgimp", "dgmpm"], [1], [4], progress=False,
                       measure="wg08", overrides=["run.t_end=1e-12"])
    assert all(np.isfinite(r["Linf_u"]) and r["Linf_u"] < 1e-9 for r in rows)


def test_usl_cpgimp_goes_unstable_above_wg08_cfl_limit():
    # WG08's temporal study takes a fixed step dt = CFL h / sqrt(E / rho0) (method.time_step =
    # "bar"); on that scale USL-cpGIMP runs at 0.8 and blows up from 0.9 at 16^2 (0.75 / 0.8 at 32^2,
    # docs/results.md), about WG08's 0.7. The default step from the current wave speed (which grows
    # where the neo-Hookean square is compressed) keeps the same CFL number stable.
    rows = convergence("mms_axis_aligned_2d", ["mpm/usl-cpgimp"], [1], [16], cfls=[0.8, 0.9], progress=False,
                       measure="wg08", overrides=['method.time_step="bar"'])
    status = {r["cfl"]: (r["status"], r["Linf_u"]) for r in rows}
    assert status[0.8][0] == "ok" and status[0.8][1] < 1e-2       # 6.1e-3 measured
    assert status[0.9] == ("unstable", 1.0)                       # WG08's convention for a blow-up
    (current,) = convergence("mms_axis_aligned_2d", ["mpm/usl-cpgimp"], [1], [16], cfls=[0.9],
                             progress=False, measure="wg08")
    assert current["status"] == "ok"


@pytest.mark.slow
def test_ring_is_about_first_order():
    # stair-stepped free surface where the exact traction is not zero: WG08 find about first order
    rows = convergence("mms_ring_2d", ["mpm/cd-cpgimp"], [1], [28, 56], progress=False, measure="wg08",
                       overrides=[T_SHORT])
    (rate,) = rates(rows, "mpm/cd-cpgimp")
    assert 0.7 < rate < 1.5          # 1.08 measured (0.26 from 14 to 28 cells: pre-asymptotic)
