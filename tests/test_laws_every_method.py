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
