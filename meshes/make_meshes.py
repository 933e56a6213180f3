"""Regenerate the committed gmsh meshes of ``meshes/`` (run it only to change them).

The irregular patch-test meshes of ``demos/patch_test.py --mesh irregular``: the square
``[0, 2] x [0, 2]`` of Belytschko et al. 1995, sec. 5.1.1 meshed by gmsh's unstructured
Frontal-Delaunay algorithm, triangles or (recombined, Blossom) quadrilaterals. The square is
made of two surfaces, ``x <= 1`` and ``x >= 1``, that share the line ``x = 1``, so that no cell
crosses it: the couplings' patch (the cells right of ``x = 1``) then meets the FE cells on a
straight interface. That line is split uniformly into ``n`` segments, so its nodes sit on the
particle grid of spacing ``2 / n`` (the ramp couplings need a particle at every interface
node); the rest of the boundary and the interior follow a mesh size that grows from ``0.8 h`` at
the bottom to ``1.25 h`` at the top, ``h = 2 / n``, so that no two cells are alike.

The files are XDMF with the data inline (ASCII, no HDF5 file): topology and geometry of one
grid named ``mesh`` and nothing else, read by ``dolfinx.io.XDMFFile.read_mesh`` in both DOLFINx
lanes. Users need no gmsh: only this script does (``apt-get install python3-gmsh`` or ``pip
install gmsh``). It needs no DOLFINx.

    python3 meshes/make_meshes.py [--cells 6] [--out meshes]
"""

from __future__ import annotations

import argparse
import pathlib

import numpy as np

__all__ = ["generate", "main", "patch_mesh_name", "write_xdmf"]

SIZE = 2.0
CELL_TYPES = ("quadrilateral", "triangle")


def patch_mesh_name(cell: str, n: int) -> str:
    """File name of the irregular patch-test mesh with about ``n`` cells per side."""
    return f"patch_irregular_{cell}_{n}.xdmf"


def generate(cell: str, n: int) -> tuple[np.ndarray, np.ndarray]:
    """Mesh the square with gmsh.

    Returns:
        ``(x, cells)``: vertex coordinates (m, 2) and cell vertices (k, 3) or (k, 4),
        counterclockwise (the VTK/XDMF order).
    """
    import gmsh

    if cell not in CELL_TYPES:
        raise ValueError(f"cell={cell!r} should be one of {CELL_TYPES}")
    if n < 2:
        raise ValueError(f"n={n} should be at least 2 cells per side")
    h = SIZE / n
    gmsh.initialize(readConfigFiles=False)
    try:
        gmsh.option.setNumber("General.Terminal", 0)
        gmsh.model.add("patch")
        geo = gmsh.model.geo
        corners = [(0, 0), (1, 0), (2, 0), (2, 2), (1, 2), (0, 2)]
        p = [geo.addPoint(SIZE / 2 * a, SIZE / 2 * b, 0.0, h) for a, b in corners]
        bottom_left, bottom_right = geo.addLine(p[0], p[1]), geo.addLine(p[1], p[2])
        right = geo.addLine(p[2], p[3])
        top_right, top_left = geo.addLine(p[3], p[4]), geo.addLine(p[4], p[5])
        left = geo.addLine(p[5], p[0])
        interface = geo.addLine(p[1], p[4])
        west = geo.addCurveLoop([bottom_left, interface, top_left, left])
        east = geo.addCurveLoop([bottom_right, right, top_right, -interface])
        surfaces = [geo.addPlaneSurface([west]), geo.addPlaneSurface([east])]
        # the interface: n uniform segments, nodes on the particle grid of spacing h
        geo.mesh.setTransfiniteCurve(interface, n + 1)
        geo.synchronize()
        gmsh.model.addPhysicalGroup(2, surfaces, 1)
        # a mesh size growing upwards: 0.8 h at y = 0, 1.25 h at y = 2
        field = gmsh.model.mesh.field.add("MathEval")
        gmsh.model.mesh.field.setString(field, "F", f"{h} * (0.8 + 0.225 * y)")
        gmsh.model.mesh.field.setAsBackgroundMesh(field)
        gmsh.option.setNumber("Mesh.MeshSizeExtendFromBoundary", 0)
        gmsh.option.setNumber("Mesh.MeshSizeFromPoints", 0)
        gmsh.option.setNumber("Mesh.MeshSizeFromCurvature", 0)
        gmsh.option.setNumber("Mesh.RandomSeed", 1)
        # Frontal-Delaunay triangles, recombined into quadrilaterals by Blossom (gmsh's
        # "Frontal-Delaunay for quads", algorithm 8, segfaults in Debian 12's gmsh 4.8)
        gmsh.option.setNumber("Mesh.Algorithm", 6)
        if cell == "quadrilateral":
            gmsh.option.setNumber("Mesh.RecombinationAlgorithm", 1)
            for s in surfaces:
                gmsh.model.mesh.setRecombine(2, s)
        gmsh.model.mesh.generate(2)
        gmsh.model.mesh.removeDuplicateNodes()
        tags, coords, _ = gmsh.model.mesh.getNodes()
        x = np.asarray(coords).reshape(-1, 3)[:, :2]
        index = np.full(int(np.max(tags)) + 1, -1, dtype=np.int64)
        index[np.asarray(tags, dtype=np.int64)] = np.arange(len(tags))
        gmsh_type = 3 if cell == "quadrilateral" else 2
        blocks = []
        for s in surfaces:
            types, _, nodes = gmsh.model.mesh.getElements(2, s)
            for t, nd in zip(types, nodes, strict=True):
                if t != gmsh_type:
                    raise RuntimeError(
                        f"gmsh produced elements of type {t} in a {cell} mesh; "
                        "change the recombination options"
                    )
                blocks.append(np.asarray(nd, dtype=np.int64).reshape(-1, 4 if t == 3 else 3))
    finally:
        gmsh.finalize()
    cells = index[np.vstack(blocks)]
    # keep only the vertices used by cells, in first-use order
    used, inverse = np.unique(cells.ravel(), return_inverse=True)
    x, cells = x[used], inverse.reshape(cells.shape)
    # snap the straight lines exactly (gmsh places nodes on them to round-off)
    for k in range(2):
        for v in (0.0, SIZE / 2, SIZE):
            x[np.isclose(x[:, k], v, atol=1e-12), k] = v
    # counterclockwise orientation
    a, b, c = (x[cells[:, i]] for i in range(3))
    area = (b[:, 0] - a[:, 0]) * (c[:, 1] - a[:, 1]) - (b[:, 1] - a[:, 1]) * (c[:, 0] - a[:, 0])
    cells[area < 0] = cells[area < 0][:, ::-1]
    return x, cells


def write_xdmf(path: pathlib.Path, x: np.ndarray, cells: np.ndarray) -> None:
    """XDMF 3 with the data inline (``Format="XML"``): one grid named ``mesh``."""
    topology = "Quadrilateral" if cells.shape[1] == 4 else "Triangle"
    conn = "\n".join(" ".join(str(int(v)) for v in c) for c in cells)
    geom = "\n".join(f"{p[0]!r} {p[1]!r}" for p in x.astype(float).tolist())
    path.write_text(
        '<?xml version="1.0"?>\n'
        '<!DOCTYPE Xdmf SYSTEM "Xdmf.dtd" []>\n'
        '<Xdmf Version="3.0" xmlns:xi="http://www.w3.org/2001/XInclude">\n'
        "  <Domain>\n"
        '    <Grid Name="mesh" GridType="Uniform">\n'
        f'      <Topology TopologyType="{topology}" NumberOfElements="{len(cells)}" '
        f'NodesPerElement="{cells.shape[1]}">\n'
        f'        <DataItem Dimensions="{len(cells)} {cells.shape[1]}" NumberType="Int" '
        'Format="XML">\n'
        f"{conn}\n"
        "        </DataItem>\n"
        "      </Topology>\n"
        '      <Geometry GeometryType="XY">\n'
        f'        <DataItem Dimensions="{len(x)} 2" Format="XML">\n'
        f"{geom}\n"
        "        </DataItem>\n"
        "      </Geometry>\n"
        "    </Grid>\n"
        "  </Domain>\n"
        "</Xdmf>\n"
    )


def main(argv: list[str] | None = None) -> list[pathlib.Path]:
    p = argparse.ArgumentParser(description="Regenerate the irregular patch-test meshes (gmsh)")
    p.add_argument("--cells", type=int, default=6, help="about this many cells per side")
    p.add_argument("--out", default=str(pathlib.Path(__file__).resolve().parent))
    args = p.parse_args(argv)
    if args.cells < 2:
        p.error(f"--cells must be at least 2, got {args.cells}")
    out = pathlib.Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    written = []
    for cell in CELL_TYPES:
        x, cells = generate(cell, args.cells)
        path = out / patch_mesh_name(cell, args.cells)
        write_xdmf(path, x, cells)
        print(f"{path}: {len(cells)} {cell} cells, {len(x)} vertices")
        written.append(path)
    return written


if __name__ == "__main__":
    main()
