"""XDMF time series of FE fields, particle clouds and polylines (``dolfinx_meshfree.output``),
serial and on 2 ranks (files in a directory shared by the ranks).

Oracle: the written files are read back without the package (``xml.etree`` for the XDMF, ``h5py``
for the heavy data) and compared with fields evaluated independently at the coordinates read
from the files: the particle values at the particle positions, the FE nodal values at the FE
geometry DOLFINx wrote, the polylines' points and segments.
"""

from __future__ import annotations

import xml.etree.ElementTree as ET

import dolfinx_meshfree as mf
from dolfinx_meshfree import _compat
from dolfinx_meshfree.output import SeriesWriter

import dolfinx
import h5py
import numpy as np
import pytest
from mpi4py import MPI

COMM = MPI.COMM_WORLD


def field(x: np.ndarray, step: int) -> np.ndarray:
    """A vector field (m, 2) at points (m, >= 2), different per step."""
    return np.stack([x[:, 0] + 2.0 * x[:, 1] + step, (1.0 + step) * x[:, 0] * x[:, 1]], axis=1)


def load(path, item: ET.Element) -> np.ndarray:
    dims = tuple(int(d) for d in item.get("Dimensions").split())
    name, dataset = item.text.strip().split(":", 1)
    with h5py.File(path.parent / name, "r") as f:
        arr = np.asarray(f[dataset])
    assert arr.shape == dims
    return arr


def crack_at(step: int) -> np.ndarray:
    return np.array([[0.0, 0.3], [0.4, 0.35], [0.5 + 0.1 * step, 0.4]])[: 2 + min(step, 1)]


def test_series_writer_round_trip(shared_dir):
    msh = dolfinx.mesh.create_rectangle(
        COMM, [np.zeros(2), np.ones(2)], [6, 5], dolfinx.mesh.CellType.quadrilateral
    )
    P = mf.ParticleSet.from_cells(msh, 0.25)
    V = _compat.vector_function_space(msh)
    u = dolfinx.fem.Function(V)
    prefix = shared_dir / "series"
    times = [0.0, 1.0, 2.0]
    with SeriesWriter(prefix, mesh=msh, particles=P, polylines=True) as w:
        for k, t in enumerate(times):
            u.interpolate(lambda x, k=k: field(x.T, k).T)
            own = P.positions[P.owned]
            w.write(t, {"u": u}, {"displacement": field(own, k), "s": own[:, 0]}, [crack_at(k)])
    COMM.Barrier()
    assert u.name != "u"  # the writer copies, it does not rename the caller's function

    # particles: positions once, values gathered from every rank's owned particles
    root = ET.parse(w.files["particles"]).getroot()
    grids = root.findall("./Domain/Grid[@CollectionType='Temporal']/Grid")
    assert [float(g.find("Time").get("Value")) for g in grids] == times
    n = P.num_particles
    for k, g in enumerate(grids):
        top = g.find("Topology")
        assert top.get("TopologyType") == "Polyvertex" and int(top.get("NumberOfElements")) == n
        xyz = load(w.files["particles"], g.find("Geometry/DataItem"))
        assert np.array_equal(xyz[:, :2], P.positions) and not xyz[:, 2].any()
        atts = {a.get("Name"): a for a in g.findall("Attribute")}
        assert atts["displacement"].get("AttributeType") == "Vector"
        assert atts["s"].get("AttributeType") == "Scalar"
        disp = load(w.files["particles"], atts["displacement"].find("DataItem"))
        assert np.array_equal(disp[:, :2], field(xyz, k)) and not disp[:, 2].any()
        assert np.array_equal(load(w.files["particles"], atts["s"].find("DataItem")), xyz[:, 0])

    # cracks: one polyline per step, two-node segments
    root = ET.parse(w.files["polylines"]).getroot()
    grids = root.findall("./Domain/Grid[@CollectionType='Temporal']/Grid")
    assert len(grids) == 3
    for k, g in enumerate(grids):
        top = g.find("Topology")
        assert top.get("TopologyType") == "Polyline" and top.get("NodesPerElement") == "2"
        xyz = load(w.files["polylines"], g.find("Geometry/DataItem"))
        seg = load(w.files["polylines"], top.find("DataItem"))
        pts = crack_at(k)
        assert np.array_equal(xyz[:, :2], pts)
        assert seg.tolist() == [[i, i + 1] for i in range(len(pts) - 1)]

    # FE (DOLFINx's XDMFFile): the nodal values at the geometry it wrote
    root = ET.parse(w.files["fe"]).getroot()
    series = root.find("./Domain/Grid[@CollectionType='Temporal'][@Name='u']")
    steps = series.findall("Grid")
    assert [float(g.find("Time").get("Value")) for g in steps] == times
    mesh_grid = root.find("./Domain/Grid[@GridType='Uniform']")
    xyz = load(w.files["fe"], mesh_grid.find("Geometry/DataItem"))
    assert xyz.shape[0] == (6 + 1) * (5 + 1)
    for k, g in enumerate(steps):
        values = load(w.files["fe"], g.find("Attribute/DataItem"))
        # the exact nodal values of the interpolated field (to round-off of interpolation)
        assert np.abs(values[:, :2] - field(xyz, k)).max() <= 1e-13


def test_series_writer_bad_input(shared_dir):
    msh = dolfinx.mesh.create_rectangle(
        COMM, [np.zeros(2), np.ones(2)], [2, 2], dolfinx.mesh.CellType.quadrilateral
    )
    P = mf.ParticleSet.from_cells(msh, 0.5)
    with pytest.raises(ValueError, match="does not exist"):
        SeriesWriter(shared_dir / "missing" / "x", particles=P)
    w = SeriesWriter(shared_dir / "bad", particles=P)
    with pytest.raises(ValueError, match=r"has no mesh: pass mesh="):
        w.write(0.0, {"u": dolfinx.fem.Function(_compat.vector_function_space(msh))})
    own = P.positions[P.owned]
    # values for fewer rows than the owned particles: refused on every rank
    with pytest.raises(ValueError, match=r"values for \d+ of the \d+ owned particles"):
        w.write(0.0, particle_values={"u": own[:-1] if COMM.rank == 0 else own})
    w.close()


def test_gather_rows_with_a_rank_holding_none():
    """A rank that owns no rows (a coupled model's particles all on one rank) gathers (0, k) and
    (0,) arrays; rank 0 gets every row in place (an empty rank once raised there and hung the
    others in the collective)."""
    from dolfinx_meshfree.output import gather_rows

    comm = MPI.COMM_WORLD
    n = 5
    mine = np.arange(n) if comm.rank == 0 else np.zeros(0, dtype=np.int64)
    vec = gather_rows(comm, mine, np.column_stack([mine, 2.0 * mine]), n)
    sca = gather_rows(comm, mine, 3.0 * mine, n)
    if comm.rank == 0:
        assert np.array_equal(vec, np.column_stack([np.arange(n), 2.0 * np.arange(n)]))
        assert np.array_equal(sca[:, 0], 3.0 * np.arange(n))
    else:
        assert vec is None and sca is None
