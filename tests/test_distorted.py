"""Non-uniform quads: the high-order methods go through scikit-fem's isoparametric mapping, so a
distorted mesh (straight boundaries, interior nodes moved by up to 30 % of a cell) keeps the
convergence rates on the exact standing wave."""
import importlib.util
from pathlib import Path

import numpy as np
import pytest

from skdgmpm.run import run

spec = importlib.util.spec_from_file_location("make_meshes", Path(__file__).parents[1] / "cases" / "make_meshes.py")
make_meshes = importlib.util.module_from_spec(spec)
spec.loader.exec_module(make_meshes)


@pytest.mark.parametrize("method, order", [("ader-dgfem", 2), ("rk-dgfem", 2), ("ader-dgmpm", 1)])
def test_standing_wave_on_a_distorted_mesh(tmp_path, method, order):
    errors = {}
    for n in (4, 8):
        mesh = tmp_path / f"square_{n}.msh"
        make_meshes.plate(mesh, 1.0, 1.0, n, n, impact=0.0, distort=0.3)
        extra = ['method.integrator="rk4"'] if method == "rk-dgfem" else []
        if method == "ader-dgmpm":
            extra.append("particles.per_cell=[0.25, 0.75]")
        r = run("standing_wave_2d", [f'grid={{mesh = "{mesh}"}}', f'method.name="{method}"', f"method.order={order}",
                                     "method.cfl=0.5", *extra], progress=False)
        assert r.status == "ok"
        errors[n] = r.errors
    for field in ("eps11", "P11", "v1"):
        rate = np.log2(errors[4][field]["L2_rel"] / errors[8][field]["L2_rel"])
        assert rate >= order + 1 - 0.3, (field, rate)
