"""Boundary conditions: the boundary stationary state honours each condition exactly and stays on
the interior's characteristic (ghost-state construction of R18 §4.5)."""
import numpy as np
import pytest

from skdgmpm.bcs import Schedule, make_bc
from skdgmpm.errors import InputError


@pytest.fixture
def faces():
    rng = np.random.default_rng(0)
    nf, d = 12, 2
    N = rng.standard_normal((nf, d))
    N /= np.linalg.norm(N, axis=1, keepdims=True)
    B = rng.standard_normal((nf, d, d))
    Z = 4e7 * (np.einsum("fij,fkj->fik", B, B) + np.eye(d))        # SPD, coupled normal/shear
    return dict(t_L=1e8 * rng.standard_normal((nf, d)), v_L=10 * rng.standard_normal((nf, d)), Z=Z, N=N)


def on_characteristic(f, t, v):
    return np.allclose(t - f["t_L"], np.einsum("fij,fj->fi", f["Z"], v - f["v_L"]), rtol=1e-9, atol=1e-3)


def star(spec, f, time=0.0):
    return make_bc(spec, 2).star(time, f["t_L"], f["v_L"], f["Z"], f["N"])


def test_velocity(faces):
    t, v = star({"kind": "velocity", "value": [3.0, -1.0]}, faces)
    assert np.allclose(v, [3.0, -1.0]) and on_characteristic(faces, t, v)


def test_traction_and_free(faces):
    t, v = star({"kind": "traction", "value": [1e9, 2e8]}, faces)
    assert np.allclose(t, [1e9, 2e8]) and on_characteristic(faces, t, v)
    t, v = star({"kind": "free"}, faces)
    assert np.allclose(t, 0.0, atol=1e-6) and on_characteristic(faces, t, v)


def test_symmetry_in_the_local_frame(faces):
    t, v = star({"kind": "symmetry"}, faces)
    N = faces["N"]
    T = np.stack([-N[:, 1], N[:, 0]], axis=1)
    assert np.allclose(np.sum(v * N, axis=1), 0.0, atol=1e-12)
    assert np.allclose(np.sum(t * T, axis=1), 0.0, atol=1e-4)
    assert on_characteristic(faces, t, v)


def test_mixed_per_axis(faces):
    t, v = star({"kind": "mixed", "velocity": {"x": 5.0}, "traction": {"y": 0.0}}, faces)
    assert np.allclose(v[:, 0], 5.0) and np.allclose(t[:, 1], 0.0, atol=1e-4)
    assert on_characteristic(faces, t, v)


def test_transmissive_copies_interior(faces):
    t, v = star({"kind": "transmissive"}, faces)
    assert np.array_equal(t, faces["t_L"]) and np.array_equal(v, faces["v_L"])


def test_release_and_ramp(faces):
    spec = {"kind": "traction", "value": [1e9, 0.0], "release": 1e-3}
    assert np.allclose(star(spec, faces, 0.5e-3)[0][:, 0], 1e9)
    assert np.allclose(star(spec, faces, 1.5e-3)[0], 0.0, atol=1e-6)      # free after release
    assert Schedule(ramp=2.0)(1.0) == 0.5 and Schedule(ramp=2.0)(3.0) == 1.0


def test_boundary_values_follow_the_schedule_and_are_kept_while_it_stays():
    """`BoundaryGhosts.values_at`: each group's value times its schedule's amplitude at the time;
    the same array while no amplitude changes (a constant load: every step), a new one when one does."""
    from skdgmpm.bcs import BoundaryGhosts

    N = np.array([[1.0, 0.0], [0.0, 1.0], [-1.0, 0.0]])
    ramped = make_bc({"kind": "traction", "value": [1e9, 0.0], "ramp": 2e-3}, 2)
    constant = make_bc({"kind": "velocity", "value": [0.0, -3.0]}, 2)
    ghosts = BoundaryGhosts([(np.array([True, False, True]), ramped), (np.array([False, True, False]), constant)], N)
    a = ghosts.values_at(1e-3)
    np.testing.assert_array_equal(a, [[0.5e9, 0.0], [0.0, -3.0], [0.5e9, 0.0]])
    assert ghosts.values_at(1e-3) is a
    b = ghosts.values_at(4e-3)                              # the ramp is over: amplitude 1
    np.testing.assert_array_equal(b, [[1e9, 0.0], [0.0, -3.0], [1e9, 0.0]])
    assert ghosts.values_at(5e-3) is b
    np.testing.assert_array_equal(a, [[0.5e9, 0.0], [0.0, -3.0], [0.5e9, 0.0]])     # not written over


@pytest.mark.parametrize("spec, match", [
    ({"kind": "glue"}, "kind"),
    ({"kind": "velocity"}, "value"),
    ({"kind": "velocity", "value": [1.0]}, "2 number"),
    ({"kind": "traction", "value": ["a", 1]}, "value"),
    ({"kind": "mixed", "velocity": {"x": 1.0}}, "exactly one"),
    ({"kind": "free", "colour": 1}, "colour"),
])
def test_bad_specs(spec, match):
    with pytest.raises(InputError, match=match):
        make_bc(spec, 2, "bc.test")


def test_all_boundary_faces_in_one_pass_are_each_groups_star(faces):
    """`BoundaryGhosts` (every face under its group's condition, one compiled pass) gives, bit for
    bit, what each condition's own `star` gives on its faces: every kind, a schedule mid-ramp and
    one released, a transmissive group (its ghost the interior)."""
    from skdgmpm.bcs import BoundaryGhosts

    specs = [{"kind": "velocity", "value": [3.0, -1.0], "ramp": 2.0},
             {"kind": "traction", "value": [1e9, 2e8], "release": 0.5},
             {"kind": "free"}, {"kind": "symmetry"}, {"kind": "normal_velocity", "value": 4.0},
             {"kind": "transmissive"}, {"kind": "mixed", "velocity": {"x": 1.0}, "traction": {"y": -3e8}}]
    nf = len(faces["N"])
    group = np.arange(nf) % len(specs)
    groups = [(group == k, make_bc(spec, 2)) for k, spec in enumerate(specs)]
    time = 1.0
    t_s, v_s = BoundaryGhosts(groups, faces["N"]).star(time, faces["t_L"], faces["v_L"], faces["Z"])
    for sel, bc in groups:
        t, v = bc.star(time, faces["t_L"][sel], faces["v_L"][sel], faces["Z"][sel], faces["N"][sel])
        np.testing.assert_array_equal(t_s[sel], t)
        np.testing.assert_array_equal(v_s[sel], v)
    transmissive = group == 5
    assert np.array_equal(v_s[transmissive], faces["v_L"][transmissive])
