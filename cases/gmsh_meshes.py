"""Write the gmsh quad meshes of the hard scenes (needs the ``gmsh`` package: ``pip install gmsh``).

    python cases/gmsh_meshes.py            # writes lasat_*.msh and multiholed_cell_*.msh here

Each mesh is made of quads only (recombined), saved as gmsh 2.2 ASCII, with physical line groups
naming the boundaries the scenes' ``[bc.NAME]`` tables refer to and a physical surface ``body``.

* ``lasat(n)``: the LASAT-like square of L23 §5.2, side l = 3 m, structured (transfinite) n x n
  quads; boundaries ``impact`` (left face, 0 <= Y <= l/3), ``left`` (rest of the left face),
  ``bottom``, ``right``, ``top``.
* ``multiholed(h)``: the multi-holed cell of L23 §5.3 (Fig. 9, Table 1), w = 5 mm, L = 11w/2,
  H = 9w/2, holes of radius r = 4 mm at (w, 3w), (3w, w), (4w, 7w/2); unstructured quads of size
  about h (Frontal-Delaunay for quads, Blossom recombination), finer (h/2) on the hole boundaries so
  the 1 mm ligaments between holes 2, 3 and the bottom, top faces get more than one cell;
  boundaries ``left``, ``right``, ``bottom``, ``top``, ``holes``.
* ``rectangle(lx, ly, h)``: unstructured quads on a rectangle (the distorted-mesh tests).
"""
from pathlib import Path

import numpy as np

HERE = Path(__file__).parent
LASAT_L = 3.0                                # m, side of the LASAT square
W = 5e-3                                     # m, w of L23 Table 1
HOLES = ((W, 3 * W), (3 * W, W), (4 * W, 3.5 * W))
R_HOLE = 4e-3                                # m


def _start(name):
    import gmsh

    gmsh.initialize(interruptible=False)
    gmsh.option.setNumber("General.Terminal", 0)
    gmsh.model.add(name)
    return gmsh


def _write(gmsh, path):
    gmsh.option.setNumber("Mesh.MshFileVersion", 2.2)
    gmsh.option.setNumber("Mesh.Binary", 0)
    gmsh.write(str(path))
    gmsh.finalize()


def lasat(path, n=30, length=LASAT_L, impact=LASAT_L / 3):
    """Square [0, l]^2, n x n structured quads, the left face split at Y = ``impact``."""
    gmsh = _start("lasat")
    geo = gmsh.model.geo
    pts = [geo.addPoint(*xy, 0.0) for xy in ((0, 0), (length, 0), (length, length), (0, length), (0, impact))]
    bottom = geo.addLine(pts[0], pts[1])
    right = geo.addLine(pts[1], pts[2])
    top = geo.addLine(pts[2], pts[3])
    left = geo.addLine(pts[3], pts[4])
    hit = geo.addLine(pts[4], pts[0])
    loop = geo.addCurveLoop([bottom, right, top, left, hit])
    surface = geo.addPlaneSurface([loop])
    n_hit = max(1, int(round(n * impact / length)))
    for curve, cells in ((bottom, n), (right, n), (top, n), (left, n - n_hit), (hit, n_hit)):
        geo.mesh.setTransfiniteCurve(curve, cells + 1)
    geo.mesh.setTransfiniteSurface(surface, cornerTags=pts[:4])
    geo.mesh.setRecombine(2, surface)
    geo.synchronize()
    for name, curve in (("bottom", bottom), ("right", right), ("top", top), ("left", left), ("impact", hit)):
        gmsh.model.addPhysicalGroup(1, [curve], name=name)
    gmsh.model.addPhysicalGroup(2, [surface], name="body")
    gmsh.model.mesh.generate(2)
    _write(gmsh, path)


def multiholed(path, h=1e-3, seed=0):
    """The multi-holed cell of L23 Fig. 9 with unstructured quads of size about ``h`` (m)."""
    gmsh = _start("multiholed")
    occ = gmsh.model.occ
    length, height = 5.5 * W, 4.5 * W
    box = occ.addRectangle(0, 0, 0, length, height)
    disks = [occ.addDisk(x, y, 0, R_HOLE, R_HOLE) for x, y in HOLES]
    occ.cut([(2, box)], [(2, d) for d in disks])
    occ.synchronize()
    eps = 1e-3 * W                               # OCC bounding boxes are padded by ~1e-7
    names = {}
    for dim, tag in gmsh.model.getEntities(1):
        x0, y0, _, x1, y1, _ = gmsh.model.getBoundingBox(dim, tag)
        if x1 - x0 < eps and abs(x0) < eps:
            names.setdefault("left", []).append(tag)
        elif x1 - x0 < eps and abs(x0 - length) < eps:
            names.setdefault("right", []).append(tag)
        elif y1 - y0 < eps and abs(y0) < eps:
            names.setdefault("bottom", []).append(tag)
        elif y1 - y0 < eps and abs(y0 - height) < eps:
            names.setdefault("top", []).append(tag)
        else:
            names.setdefault("holes", []).append(tag)
    for name in ("left", "right", "bottom", "top", "holes"):
        gmsh.model.addPhysicalGroup(1, names[name], name=name)
    surfaces = [tag for _, tag in gmsh.model.getEntities(2)]
    gmsh.model.addPhysicalGroup(2, surfaces, name="body")
    size = 2 * h                                 # before the subdivision into quads
    gmsh.option.setNumber("Mesh.MeshSizeMax", size)
    gmsh.option.setNumber("Mesh.MeshSizeMin", size / 2)
    for tag in names["holes"]:                   # circle segments: about h apart after subdivision
        gmsh.model.mesh.setTransfiniteCurve(tag, int(np.ceil(2 * np.pi * R_HOLE / size)) + 1)
    gmsh.option.setNumber("Mesh.Algorithm", 8)                # Frontal-Delaunay for quads
    gmsh.option.setNumber("Mesh.RecombinationAlgorithm", 1)   # Blossom
    gmsh.option.setNumber("Mesh.RecombineAll", 1)
    gmsh.option.setNumber("Mesh.SubdivisionAlgorithm", 1)     # split what is left: all quads, size / 2
    gmsh.option.setNumber("Mesh.RandomSeed", seed)
    gmsh.model.mesh.generate(2)
    _write(gmsh, path)


def rectangle(path, lx=2.0, ly=0.5, h=0.1, seed=0):
    """Rectangle [0, lx] x [0, ly] with unstructured (distorted) quads of size about ``h``:
    boundaries ``left``, ``right``, ``bottom``, ``top`` (patch test and plane wave of the tests)."""
    gmsh = _start("rectangle")
    occ = gmsh.model.occ
    occ.addRectangle(0, 0, 0, lx, ly)
    occ.synchronize()
    eps = 1e-6 * max(lx, ly)
    for dim, tag in gmsh.model.getEntities(1):
        x0, y0, _, x1, y1, _ = gmsh.model.getBoundingBox(dim, tag)
        name = ("left" if abs(x1) < eps else "right" if abs(x0 - lx) < eps
                else "bottom" if abs(y1) < eps else "top")
        gmsh.model.addPhysicalGroup(1, [tag], name=name)
    gmsh.model.addPhysicalGroup(2, [tag for _, tag in gmsh.model.getEntities(2)], name="body")
    gmsh.option.setNumber("Mesh.MeshSizeMax", 2 * h)
    gmsh.option.setNumber("Mesh.MeshSizeMin", h)
    gmsh.option.setNumber("Mesh.Algorithm", 8)
    gmsh.option.setNumber("Mesh.RecombinationAlgorithm", 1)
    gmsh.option.setNumber("Mesh.RecombineAll", 1)
    gmsh.option.setNumber("Mesh.SubdivisionAlgorithm", 1)
    gmsh.option.setNumber("Mesh.RandomSeed", seed)
    gmsh.model.mesh.generate(2)
    _write(gmsh, path)


MESHES = {
    "rectangle_2x05_unstructured.msh": lambda p: rectangle(p, 2.0, 0.5, 0.1),
    "lasat_30.msh": lambda p: lasat(p, 30),
    "lasat_12.msh": lambda p: lasat(p, 12),
    "multiholed_cell_1mm.msh": lambda p: multiholed(p, 1e-3),
    "multiholed_cell_2mm.msh": lambda p: multiholed(p, 2e-3),
}

if __name__ == "__main__":
    for name, make in MESHES.items():
        make(HERE / name)
        print("wrote", HERE / name)
