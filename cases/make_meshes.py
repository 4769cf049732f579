"""Write the mesh files shipped with the scenes (gmsh 2.2 through meshio, named boundaries).

    python cases/make_meshes.py

A mesh for a new scene can come from gmsh directly: quads (``Mesh.RecombineAll = 1``) with
physical line groups for the boundaries the scene's ``[bc.NAME]`` tables refer to.
"""
from pathlib import Path

import meshio
import numpy as np


def plate(path, lx=4.0, ly=3.0, nx=33, ny=25, impact=1.0, distort=0.0, split=None):
    """Rectangular plate [0, lx] x [0, ly]; boundaries impact (left, y <= impact), left (rest),
    bottom, right, top. ``distort`` > 0 moves the interior nodes by up to that fraction of a cell
    (a non-uniform quad mesh with straight boundaries). One physical surface ``body``, or with
    ``split = (x, left_name, right_name)`` two: the cells centred left of x and those right of it
    (a two-material part, ``[[regions]] subdomain = "NAME"``)."""
    x, y = np.linspace(0, lx, nx + 1), np.linspace(0, ly, ny + 1)
    X, Y = np.meshgrid(x, y)
    if distort:
        inner = (X > 0) & (X < lx) & (Y > 0) & (Y < ly)
        X = X + inner * distort * lx / nx * np.sin(2 * np.pi * Y / ly) * np.sin(3 * np.pi * X / lx)
        Y = Y + inner * distort * ly / ny * np.sin(2 * np.pi * X / lx) * np.sin(np.pi * Y / ly)
    points = np.column_stack([X.ravel(), Y.ravel()])
    n = np.arange(points.shape[0]).reshape(ny + 1, nx + 1)
    quads = np.column_stack([n[:-1, :-1].ravel(), n[:-1, 1:].ravel(), n[1:, 1:].ravel(), n[1:, :-1].ravel()])
    lines = {
        "bottom": np.column_stack([n[0, :-1], n[0, 1:]]),
        "right": np.column_stack([n[:-1, -1], n[1:, -1]]),
        "top": np.column_stack([n[-1, 1:], n[-1, :-1]]),
        "left": np.column_stack([n[1:, 0], n[:-1, 0]]),
    }
    left_mid = points[lines["left"]].mean(axis=1)[:, 1]
    lines["impact"] = lines["left"][left_mid <= impact]
    lines["left"] = lines["left"][left_mid > impact]
    names = ["bottom", "right", "top", "left", "impact"]
    cells = [("line", lines[k]) for k in names] + [("quad", quads)]
    surface = np.full(len(quads), 10)
    field_data = {k: np.array([i + 1, 1]) for i, k in enumerate(names)}
    if split is None:
        field_data["body"] = np.array([10, 2])
    else:
        x_split, left_name, right_name = split
        surface[points[quads].mean(axis=1)[:, 0] > x_split] = 11
        field_data[left_name], field_data[right_name] = np.array([10, 2]), np.array([11, 2])
    tags = [np.full(len(lines[k]), i + 1) for i, k in enumerate(names)] + [surface]
    mesh = meshio.Mesh(points, cells, cell_data={"gmsh:physical": tags, "gmsh:geometrical": tags},
                       field_data=field_data)
    meshio.write(path, mesh, file_format="gmsh22", binary=False)


if __name__ == "__main__":
    here = Path(__file__).parent
    plate(here / "plate_4x3.msh")
    plate(here / "plate_steel_alu_4x3.msh", nx=16, ny=12, split=(2.0, "steel", "alu"))
