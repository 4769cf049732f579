"""The inputs of issue 17 that ended in a traceback (or were accepted) give one-line errors, exit 2,
naming the file (or --set), the key and the value; meshes are checked on read."""
import os

import meshio
import numpy as np
import pytest

from skdgmpm.cli import main

SCENE = """dim = 2
[grid]
mesh = "{mesh}"
[material]
law = "linear_elastic"
E = 2.0e11
nu = 0.3
rho = 7800.0
[method]
name = "{method}"
{extra}
[run]
t_end = 1.0e-5
"""


def cli(capsys, *argv):
    capsys.readouterr()                  # what writing the test's mesh printed
    rc = main([str(a) for a in argv])
    captured = capsys.readouterr()
    return rc, captured.out, captured.err


def one_line_error(capsys, argv, *words):
    rc, out, err = cli(capsys, *argv)
    assert rc == 2, (rc, err)
    assert "Traceback" not in err and err.count("\n") == 1 and err.startswith("error: "), repr(err)
    for w in words:
        assert w in err, (w, err)
    return err


@pytest.fixture
def here(tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    return tmp_path


def quads(here, points, cells, name="m.msh", kind="quad"):
    meshio.write(here / name, meshio.Mesh(np.asarray(points, float), [(kind, np.asarray(cells))]),
                 file_format="gmsh22", binary=False)
    scene = here / "s.toml"
    scene.write_text(SCENE.format(mesh=name, method="dgmpm", extra="cfl = 0.5"))   # DCU: 2D limit 0.651
    return scene


SQUARES = [[0, 0, 0], [1, 0, 0], [2, 0, 0], [0, 1, 0], [1, 1, 0], [2, 1, 0]]


def run_args(scene, here):
    return ["run", scene, "--out", here / "out", "--quiet"]


def test_a_scene_file_that_is_not_utf8(capsys, here):
    scene = here / "latin1.toml"
    scene.write_bytes('title = "Barre d\'acier à 20 °C"\n'.encode("latin-1"))
    one_line_error(capsys, run_args(scene, here), str(scene), "not a UTF-8 text file", "0xe0")
    assert not (here / "out").exists()


def test_ader_dgmpm_with_more_particles_than_gauss_points(capsys):
    """Order 1 projects from 2 x 2 Gauss points: 3 x 3 particles made numpy's singular-matrix
    traceback."""
    one_line_error(capsys, ["run", "standing_wave_2d", "--set", 'method.name="ader-dgmpm"', "--set",
                            "particles.per_cell=3", "--quiet"], "particles.per_cell", "9 particles in a cell",
                   "at most 4")


def test_a_mesh_node_at_nan(capsys, here):
    points = [list(p) for p in SQUARES]
    points[4][1] = np.nan
    scene = quads(here, points, [[0, 1, 4, 3], [1, 2, 5, 4]])
    one_line_error(capsys, run_args(scene, here), "m.msh", "node 4", "non-finite coordinates")


@pytest.mark.parametrize("cells, words", [
    ([[0, 1, 4, 3], [1, 2, 2, 4]], ["cell 1", "degenerate"]),             # a repeated node
    ([[0, 1, 4, 3], [1, 2, 4, 5]], ["cell 1", "bow-tie"]),                # self-intersecting
])
def test_degenerate_and_bow_tie_quads(capsys, here, cells, words):
    scene = quads(here, SQUARES, cells)
    one_line_error(capsys, run_args(scene, here), "m.msh", *words, "fix the mesh")


def test_an_inverted_quad_is_turned_not_refused(capsys, here):
    """A clockwise quad is a valid quad listed the other way round: reordered, it runs."""
    scene = quads(here, SQUARES, [[0, 1, 4, 3], [1, 4, 5, 2]])
    rc, out, err = cli(capsys, *run_args(scene, here))
    assert rc == 0, err


def test_a_binary_garbage_mesh(capsys, here):
    (here / "m.msh").write_bytes(bytes(np.random.default_rng(0).integers(0, 256, 4000, dtype=np.uint8)))
    scene = here / "s.toml"
    scene.write_text(SCENE.format(mesh="m.msh", method="dgmpm", extra=""))
    one_line_error(capsys, run_args(scene, here), "m.msh", "cannot read mesh")


def test_a_lines_only_mesh_says_one_line_only(capsys, here):
    scene = quads(here, SQUARES, [[0, 1], [1, 2], [3, 4]], kind="line")
    one_line_error(capsys, run_args(scene, here), "m.msh")


@pytest.mark.parametrize("value", ['"x"', "true"])
def test_grid_origin_of_the_wrong_type(capsys, here, value):
    one_line_error(capsys, ["run", "bar_elastic_1d", "--out", here / "out", "--set", f"grid.origin={value}"],
                   "--set", "grid.origin", "wrong type", "list/int/float")


def test_set_values_are_named_as_set(capsys, here):
    err = one_line_error(capsys, ["run", "bar_elastic_1d", "--out", here / "out", "--set", "material.E=-1"],
                         "--set material.E", "E = -1")
    assert "bar_elastic_1d.toml with --set material.E" in err
    one_line_error(capsys, ["run", "bar_elastic_1d", "--out", here / "out", "--set", "run.t_end=-1"],
                   "--set run.t_end = -1")


@pytest.mark.parametrize("method, key", [("ader-dgfem", "limiter"), ("rk-dgfem", "limiter"), ("ader-dgmpm", "backmap")])
def test_limiter_and_backmap_errors_name_the_file(capsys, here, method, key):
    scene = here / "s.toml"
    points = SQUARES
    meshio.write(here / "m.msh", meshio.Mesh(np.asarray(points, float), [("quad", np.array([[0, 1, 4, 3], [1, 2, 5, 4]]))]),
                 file_format="gmsh22", binary=False)
    scene.write_text(SCENE.format(mesh="m.msh", method=method, extra=f'{key} = "bogus"'))
    one_line_error(capsys, run_args(scene, here), f"{scene}: method.{key} = 'bogus'", "expected one of")


@pytest.mark.parametrize("value", ['["1e9"]', '[true]', '"1e9"'])
def test_a_string_is_not_a_load(capsys, here, value):
    one_line_error(capsys, ["run", "bar_elastic_1d", "--out", here / "out", "--set", f"bc.left.value={value}"],
                   "bc.left.value", "number")


def test_initial_velocity_as_a_string(capsys, here):
    one_line_error(capsys, ["run", "bar_elastic_1d", "--out", here / "out", "--set", 'initial.velocity=["1"]'],
                   "initial.velocity", "'1'")


def test_a_scene_file_that_cannot_be_read(capsys, here):
    if os.geteuid() == 0:
        pytest.skip("root reads everything")
    scene = here / "locked.toml"
    scene.write_text("dim = 1\n")
    scene.chmod(0)
    one_line_error(capsys, run_args(scene, here), str(scene), "cannot read")


def test_duplicated_nodes_that_split_the_body_are_warned_about(capsys, here):
    """Two squares whose shared edge has its nodes twice: decoupled halves (a crack). A crack can be
    meant, so a warning naming the place, not an error."""
    points = SQUARES + [[1, 0, 0], [1, 1, 0]]                  # nodes 6, 7 duplicate 1, 4
    scene = quads(here, points, [[0, 1, 4, 3], [6, 2, 5, 7]])
    with pytest.warns(UserWarning) as record:
        from skdgmpm.grid import load_mesh
        load_mesh(here / "m.msh")
    text = " ".join(str(w.message) for w in record)
    assert "2 node(s) duplicate another node's position (first at (1, 0))" in text and "crack" in text
    assert "2 pieces that share no facet" in text
    with pytest.warns(UserWarning, match="crack"):
        rc, out, err = cli(capsys, *run_args(scene, here))
    assert rc == 0, err


def test_shipped_meshes_read_without_warnings():
    import warnings
    from importlib import resources
    from pathlib import Path

    from skdgmpm.grid import load_mesh
    meshes = sorted(Path(str(resources.files("skdgmpm.cases"))).glob("*.msh"))
    assert meshes
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        for m in meshes:
            load_mesh(m)


def test_keys_a_mesh_file_overrides_are_not_silently_ignored(here):
    from skdgmpm.run import run
    with pytest.warns(UserWarning, match=r"--set grid.cells: no effect, the mesh file grid.mesh = 'plate_4x3.msh'"):
        run("partial_impact_2d", ["grid.cells=[0, 3]", "run.t_end=1e-6"], progress=False)


def test_a_limiter_name_is_checked_for_every_method(capsys, here):
    one_line_error(capsys, ["run", "bar_elastic_1d", "--out", here / "o", "--set", 'method.limiter="bogus"'],
                   "--set method.limiter = 'bogus'", "expected one of")
