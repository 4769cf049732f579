"""The interior faces built a chunk of facets at a time (to bound the set-up's memory) are the
faces built at once, bit for bit: normals, measures, cells, coordinates and both traces."""
import numpy as np
import pytest

from skdgmpm import faces
from skdgmpm.build import build
from skdgmpm.scene import load_scene


@pytest.mark.parametrize("pointwise, intorder", [(False, None), (True, 3)])
def test_chunked_interior_faces_are_the_same(monkeypatch, pointwise, intorder):
    g = build(load_scene("plate_impact_neohookean_2d", ["grid.cells=[30, 20]"])).stepper.grid
    whole = faces.interior_faces(g.submesh, g.element, pointwise, intorder)
    monkeypatch.setattr(faces, "FACET_CHUNK", 97)               # 12 chunks of unequal length
    chunked = faces.interior_faces(g.submesh, g.element, pointwise, intorder)
    for name in ("facets", "normal", "measure", "cell_L", "cell_R", "X"):
        assert np.array_equal(getattr(whole, name), getattr(chunked, name)), name
    for name in ("T_L", "T_R"):
        a, b = getattr(whole, name), getattr(chunked, name)
        assert a.shape == b.shape
        assert all(np.array_equal(x, y) for x, y in ((a.indptr, b.indptr), (a.indices, b.indices), (a.data, b.data)))
