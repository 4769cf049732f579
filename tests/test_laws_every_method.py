"""Every law runs in every method: the Mooney-Rivlin law (added as one file plus its registration)
through DGMPM, ADER-DGMPM, ADER-DGFEM, RK-DGFEM and MPM.

References are independent computations: the neo-Hookean law's own code (Mooney-Rivlin with
beta = 0 is the neo-Hookean law term by term) and the linear elastic law at small strain.
"""
import numpy as np
import pytest

from skdgmpm.run import run

# every method on the 1D bar, at a size that runs in a second once compiled
METHODS = {
    "dgmpm": ['method.name="dgmpm"', "method.cfl=0.5"],
    "ader-dgmpm": ['method.name="ader-dgmpm"', "method.order=1", "particles.per_cell=2", "method.cfl=0.5"],
    "ader-dgfem": ['method.name="ader-dgfem"', "method.order=1", "method.cfl=0.5"],
    "rk-dgfem": ['method.name="rk-dgfem"', "method.order=1", 'method.integrator="rk2"', "method.cfl=0.5"],
    "mpm-cd": ['method.name="mpm"', 'method.update="cd"', "method.cfl=0.5"],
}
BAR = ["grid.cells=20", "run.t_end=3e-4", "material.nu=0.3"]


def bar(method, law, load=1.0e9, **params):
    extra = [f'material.law="{law}"'] + [f"material.{k}={v!r}" for k, v in params.items()]
    return run("bar_elastic_1d", METHODS[method] + BAR + extra + [f"bc.left.value=[{load!r}]"], progress=False)


@pytest.mark.parametrize("method", METHODS)
def test_mooney_rivlin_without_second_invariant_is_neo_hookean(method):
    """beta = 0: the same stresses and tangents as the neo-Hookean law, so the same run to
    round-off, in every method (a 0.5 % compression: the law's nonlinearity is active)."""
    mr, nh = bar(method, "mooney_rivlin", beta=0.0), bar(method, "neo_hookean")
    assert mr.status == nh.status == "ok" and mr.state.step == nh.state.step
    scale = np.abs(nh.state.Q).max(axis=0)
    assert np.all(np.abs(mr.state.Q - nh.state.Q) <= 1e-10 * scale)


@pytest.mark.parametrize("method", METHODS)
def test_mooney_rivlin_at_small_strain_is_linear_elastic(method):
    """beta = 0.5 at a 5e-6 strain: within 1e-4 of the linear elastic run of the same method (the
    difference is O(strain)); at a 0.5 % strain they differ by more (the I2 term is active)."""
    def gap(load):
        mr, le = bar(method, "mooney_rivlin", load, beta=0.5), bar(method, "linear_elastic", load)
        assert mr.status == le.status == "ok"
        return np.abs(mr.fields()["P11"] - le.fields()["P11"]).max() / load

    assert gap(1.0e6) < 1e-4
    assert gap(1.0e9) > 1e-3


# -------------------------------------------------------------------- elastoplastic bar (METHOD §10)
PLASTIC_BAR = ["grid.cells=60", "run.t_end=4e-4"]     # fronts at c_p t = 1.9 m and c_e t = 2.35 m of 6 m


def plateaus(result, exact):
    """Median of P11, v1 and eqp over the particles of each exact region, 3 cells away from the
    fronts, and the positions where P11 crosses the middle of each jump."""
    t, X = result.state.t, result.X[:, 0]
    c_p, c_e = exact.speeds
    h = 6.0 / 60
    f = result.fields()
    regions = {"plastic": X < c_p * t - 3 * h, "elastic": (X > c_p * t + 3 * h) & (X < c_e * t - 3 * h),
               "rest": X > c_e * t + 3 * h}
    out = {name: {k: float(np.median(f[k][sel])) for k in ("P11", "v1", "eqp")} for name, sel in regions.items()}
    order = np.argsort(X)
    P = f["P11"][order]
    for name, level in (("front_p", 0.5 * (exact.traction - exact.sigma_HEL)), ("front_e", -0.5 * exact.sigma_HEL)):
        out[name] = float(X[order][np.flatnonzero(P < level).max()])     # last particle beyond the level
    return out


@pytest.mark.parametrize("method", METHODS)
def test_elastoplastic_bar_two_waves_in_every_method(method, record_property):
    """A compressive step above the Hugoniot elastic limit: the elastic precursor (-sigma_HEL) and
    the plastic wave, with the history at each method's own points, against the exact two-front
    solution (skdgmpm.exact.ElastoplasticBarStep): plateaus of P11 and v1 within 1 %, eqp within
    3 %, no plastic strain ahead of the plastic front, both fronts within 2 cells."""
    r = run("bar_elastoplastic_1d", METHODS[method] + PLASTIC_BAR, progress=False)
    assert r.status == "ok"
    ex = r.exact
    found = plateaus(r, ex)
    record_property("plateaus", found)
    behind, between = ex.states[0], ex.states[1]
    for name, state in (("plastic", behind), ("elastic", between)):
        assert found[name]["P11"] == pytest.approx(state["P11"], rel=1e-2), name
        assert found[name]["v1"] == pytest.approx(state["v1"], rel=1e-2), name
    assert found["plastic"]["eqp"] == pytest.approx(behind["eqp"], rel=3e-2)
    assert found["elastic"]["eqp"] == found["rest"]["eqp"] == 0.0
    t = r.state.t
    assert abs(found["front_p"] - ex.c_p * t) < 2 * 0.1
    assert abs(found["front_e"] - ex.c_e * t) < 2 * 0.1
    h = r.history                                # plastic work done, the balance never grows
    assert h["dissipated"][-1] > 0.0
    assert np.diff(h["balance"]).max() <= 1e-9 * h["external_work"].max()
