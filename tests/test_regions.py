"""``[[regions]]`` by gmsh physical surface (``subdomain = "NAME"``) as well as by ``box``.

cases/plate_steel_alu_4x3.msh (cases/make_meshes.py) is the 4 m x 3 m plate of partial_impact_2d,
16 x 12 cells, with two physical surfaces: ``steel`` (cells centred at x < 2 m) and ``alu`` (x > 2 m).
"""
import numpy as np
import pytest

from skdgmpm.build import build
from skdgmpm.errors import InputError
from skdgmpm.run import run
from skdgmpm.scene import load_scene

MESH = 'grid.mesh="plate_steel_alu_4x3.msh"'
ALU = 'material = {law = "linear_elastic", E = 7.0e10, nu = 0.33, rho = 2700.0}'


def test_region_by_subdomain_gets_its_cells():
    disc = build(load_scene("partial_impact_2d", [MESH, f'regions=[{{subdomain = "alu", {ALU}}}]']))
    p = disc.particles
    centre = disc.grid.submesh.p[:, disc.grid.submesh.t].mean(axis=1)[0, p.cell]
    assert np.array_equal(p.material, (centre > 2.0).astype(int))
    assert np.count_nonzero(p.material == 1) == 96
    assert np.allclose(p.rho0[p.material == 1], 2700.0) and np.allclose(p.rho0[p.material == 0], 7800.0)


def test_subdomain_and_box_regions_agree():
    by_name = build(load_scene("partial_impact_2d", [MESH, f'regions=[{{subdomain = "alu", {ALU}}}]']))
    by_box = build(load_scene("partial_impact_2d", [MESH, f'regions=[{{box = {{x = [2.0, 4.0]}}, {ALU}}}]']))
    assert np.array_equal(by_name.particles.material, by_box.particles.material)


def test_bimaterial_plate_runs():
    r = run("partial_impact_2d", [MESH, f'regions=[{{subdomain = "alu", {ALU}}}]', "run.t_end=1e-4"],
            progress=False)
    assert r.status == "ok" and r.state.step > 0


@pytest.mark.parametrize("region, message", [
    ('{subdomain = "copper", ' + ALU + '}',
     r"regions\[0\].subdomain = 'copper' is not a physical surface of the mesh \(known: steel, alu\)"),
    ('{subdomain = "alu", box = {x = [0.0, 1.0]}, ' + ALU + '}', "one of box"),
    ('{subdomain = "alu"}', "must be a table with material"),
])
def test_bad_region_is_one_line(region, message):
    with pytest.raises(InputError, match=message) as info:
        build(load_scene("partial_impact_2d", [MESH, f"regions=[{region}]"]))
    assert "\n" not in str(info.value)


def test_subdomain_on_a_generated_grid_says_there_is_none():
    with pytest.raises(InputError, match="known: none"):
        build(load_scene("plane_wave_svk_2d", [f'regions=[{{subdomain = "alu", {ALU}}}]']))
