"""What a first-order DGMPM discretisation keeps once built (the bytes per cell of the issue
"Speed"): no array kept twice, no scikit-fem cache a step does not read. Each check is one way
the memory could silently grow back."""
import pytest

from skdgmpm.build import build
from skdgmpm.scene import load_scene

SCENE = ("plate_impact_neohookean_2d", ["grid.cells=[12, 10]", 'method.transverse="ctu"'])


def test_grid_keeps_one_copy_of_nodes_and_no_facet_caches():
    grid = build(load_scene(*SCENE)).grid
    sub = grid.submesh
    assert sub.p is grid.mesh.p and sub.t is grid.mesh.t        # every cell active: shared
    for m in (grid.mesh, sub):
        assert not {"_facets", "_t2f", "_f2t", "_dofs"} & set(vars(m))
    assert sub.t2f.shape == (4, sub.nelements)                  # still there when asked for


@pytest.mark.filterwarnings("ignore:.*touches no cell holding particles")
def test_a_partly_active_grid_keeps_its_own_nodes():
    grid = build(load_scene("plate_impact_neohookean_2d", ["grid.cells=[12, 10]",
                                                           'body.box={x = [0.0, 0.4], y = [0.0, 1.0]}'])).grid
    assert grid.submesh.nelements < grid.mesh.nelements
    assert grid.submesh.p is not grid.mesh.p
