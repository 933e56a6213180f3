"""Regenerate the committed bushing meshes of ``demos/plug_into_existing_model.py`` (gmsh).

A bushing: the annulus ``A <= r <= B`` (A = 1, B = 2), meshed by gmsh's unstructured
Frontal-Delaunay algorithm with a uniform size ``h``. The circle ``r = C`` (C = 1.4) is embedded
as a mesh line, so that the cells of the inner ring ``r <= C`` (where the hoop stress of an
internal pressure concentrates, and where the demo puts its particles) meet the rest on a
polygonal circle rather than a staircase.

Files: ``bushing_<cell>_h<h>.xdmf``, XDMF with the data inline (see ``make_meshes.py``), read by
``dolfinx.io.XDMFFile.read_mesh`` in both DOLFINx lanes; users need no gmsh.

    python3 meshes/make_bushing.py [--h 0.2 0.1 0.05] [--cell triangle|quadrilateral]
"""

from __future__ import annotations

import argparse
import pathlib
import sys

import numpy as np

sys.path.insert(0, str(pathlib.Path(__file__).resolve().parent))
from make_meshes import write_xdmf

__all__ = ["RADII", "bushing_mesh_name", "generate", "main"]

#: Inner radius, radius of the embedded circle (patch boundary), outer radius.
RADII = (1.0, 1.4, 2.0)


def bushing_mesh_name(cell: str, h: float) -> str:
    """File name of the bushing mesh of size ``h``."""
    return f"bushing_{cell}_h{h:g}.xdmf"


def generate(cell: str, h: float) -> tuple[np.ndarray, np.ndarray]:
    """Mesh the annulus with gmsh; returns vertex coordinates (m, 2) and cells (k, 3 or 4),
    counterclockwise."""
    import gmsh

    gmsh.initialize(readConfigFiles=False)
    try:
        gmsh.option.setNumber("General.Terminal", 0)
        gmsh.model.add("bushing")
        geo = gmsh.model.geo
        centre = geo.addPoint(0.0, 0.0, 0.0, h)

        def circle(r: float) -> int:
            angles = np.pi / 2 * np.arange(4)
            p = [geo.addPoint(r * np.cos(t), r * np.sin(t), 0.0, h) for t in angles]
            arcs = [geo.addCircleArc(p[i], centre, p[(i + 1) % 4]) for i in range(4)]
            return geo.addCurveLoop(arcs)

        inner, middle, outer = (circle(r) for r in RADII)
        geo.addPlaneSurface([middle, inner])
        geo.addPlaneSurface([outer, middle])
        geo.synchronize()
        gmsh.option.setNumber("Mesh.Algorithm", 6)  # Frontal-Delaunay
        if cell == "quadrilateral":
            gmsh.option.setNumber("Mesh.RecombineAll", 1)
            gmsh.option.setNumber("Mesh.RecombinationAlgorithm", 1)  # Blossom
        gmsh.model.mesh.generate(2)
        tags, coords, _ = gmsh.model.mesh.getNodes()
        x = coords.reshape(-1, 3)[:, :2]
        index = {int(t): i for i, t in enumerate(tags)}
        etype = 3 if cell == "quadrilateral" else 2
        blocks = []
        for dim, surface in gmsh.model.getEntities(2):
            types, _, nodes = gmsh.model.mesh.getElements(dim, surface)
            for t, n in zip(types, nodes, strict=True):
                if t != etype:
                    raise RuntimeError(f"gmsh produced element type {t}, expected {etype}")
                blocks.append(np.asarray(n, dtype=np.int64).reshape(-1, 4 if etype == 3 else 3))
        cells = np.vectorize(index.__getitem__)(np.concatenate(blocks))
    finally:
        gmsh.finalize()
    used, cells = np.unique(cells, return_inverse=True)
    cells = cells.reshape(-1, blocks[0].shape[1])
    x = x[used]
    # counterclockwise
    e1, e2 = x[cells[:, 1]] - x[cells[:, 0]], x[cells[:, 2]] - x[cells[:, 0]]
    cw = e1[:, 0] * e2[:, 1] - e1[:, 1] * e2[:, 0] < 0
    cells[cw] = cells[cw, ::-1]
    return x, cells


def main(argv: list[str] | None = None) -> list[pathlib.Path]:
    p = argparse.ArgumentParser(description="Regenerate the bushing meshes (gmsh)")
    p.add_argument("--h", type=float, nargs="+", default=[0.2, 0.1, 0.05])
    p.add_argument("--cell", choices=("triangle", "quadrilateral"), default="triangle")
    p.add_argument("--out", default=str(pathlib.Path(__file__).resolve().parent))
    args = p.parse_args(argv)
    out = pathlib.Path(args.out)
    written = []
    for h in args.h:
        x, cells = generate(args.cell, h)
        path = out / bushing_mesh_name(args.cell, h)
        write_xdmf(path, x, cells)
        print(f"{path}: {len(cells)} {args.cell} cells, {len(x)} vertices")
        written.append(path)
    return written


if __name__ == "__main__":
    main()
