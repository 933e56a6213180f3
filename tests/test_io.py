"""Output of explicit dynamics: XDMF of the FE fields and of the particle cloud over time, the
energy CSV, and the progress bar; serial and on 2 ranks (files in a directory shared by the
ranks)."""

from __future__ import annotations

import csv
import io
import os
import pathlib
import xml.etree.ElementTree as ET

import dolfinx_meshfree as mf
from dolfinx_meshfree import _compat
from dolfinx_meshfree.dynamics import ExplicitDynamics
from dolfinx_meshfree.io import DynamicsWriter, ProgressBar, read_particles
from dolfinx_meshfree.verification.waves import GaussianPulseRod

import h5py
import numpy as np
import pytest
from conftest import CELL_TYPES, load_demo, rectangle
from mpi4py import MPI

ROD = GaussianPulseRod()
STEEL = mf.LinearElastic(ROD.E, 0.0, "strain", rho=ROD.rho)
LENGTH, HEIGHT, H = 60.0, 5.0, 2.5


def build(method: str) -> ExplicitDynamics:
    """A coarse rod (24 x 2 cells): pure FE, pure EFG, or a coupling with particles on x > 30."""
    comm = MPI.COMM_WORLD
    msh = rectangle(comm, [0.0, 0.0], [LENGTH, HEIGHT], [24, 2], CELL_TYPES["quadrilateral"])
    if method == "fe":
        return ExplicitDynamics.fe(_compat.vector_function_space(msh), STEEL)
    if method == "efg":
        particles = mf.ParticleSet.from_cells(msh, H)
        return ExplicitDynamics.efg(particles, STEEL, quadrature_degree=3)
    n = msh.topology.index_map(2).size_local
    xc = msh.geometry.x[_compat.geometry_dofmap(msh)[:n], 0].mean(axis=1)
    patch = mf.ParticlePatch(msh, np.flatnonzero(xc > 30.0), H / 2)
    V = _compat.vector_function_space(msh)
    problem = mf.CoupledElasticity(V, patch, STEEL, coupling=method, quadrature_degree=3)
    return ExplicitDynamics.coupled(problem)


def temporal_grids(path: pathlib.Path) -> dict[str, list[ET.Element]]:
    """The grids of every temporal collection of an XDMF file, by collection name."""
    root = ET.parse(path).getroot()
    return {
        c.get("Name"): c.findall("Grid")
        for c in root.iter("Grid")
        if c.get("CollectionType") == "Temporal"
    }


def xdmf_particles(path: pathlib.Path) -> tuple[list[float], dict[str, list[np.ndarray]]]:
    """The particle file read independently of the package (xml.etree and h5py): times and the
    arrays of every temporal grid, following the XDMF's HDF DataItems (``file.h5:/dataset``)."""
    times, arrays = [], {"geometry": [], "topology": [], "displacement": [], "velocity": []}
    for g in temporal_grids(path)["particles"]:
        times.append(float(g.find("Time").get("Value")))
        items = [
            ("geometry", g.find("Geometry/DataItem")),
            ("topology", g.find("Topology/DataItem")),
        ]
        items += [(a.get("Name"), a.find("DataItem")) for a in g.findall("Attribute")]
        for name, item in items:
            assert item.get("Format") == "HDF"
            fname, dataset = item.text.strip().split(":")
            with h5py.File(path.parent / fname, "r") as f:
                arr = f[dataset][()]
            assert arr.shape == tuple(int(d) for d in item.get("Dimensions").split())
            arrays[name].append(arr)
    return times, arrays


def particle_values(dyn: ExplicitDynamics) -> tuple[np.ndarray, np.ndarray]:
    """What the solver reports at every particle, on rank 0 (collective)."""
    comm = dyn.comm
    x = dyn.particles.positions if comm.rank == 0 else np.zeros((0, 2))
    return dyn.displacement_at(x), dyn.velocity_at(x)


# --- XDMF ----------------------------------------------------------------------------------------


@pytest.mark.parametrize("method", ["fe", "efg", "lagrange", "master-slave"])
def test_xdmf_files_parse_and_hold_what_the_solver_reports(method, shared_dir):
    comm = MPI.COMM_WORLD
    dyn = build(method)
    dyn.set_initial(velocity=ROD.initial_velocity, displacement=lambda x: 1e-4 * np.ones_like(x))
    t_end = 0.3 * ROD.transit_time
    reported: list = []

    def record(d, n, t):
        reported.append((t, *(particle_values(d) if d.particles is not None else ())))

    prefix = shared_dir / f"rod_{method}"
    res = dyn.run(t_end, outputs=[0.0, 0.1 * ROD.transit_time, t_end], on_output=record,
                  xdmf=prefix)  # fmt: skip
    times = [t for _, t in res.outputs]
    assert len(times) == 3
    fe_file = shared_dir / f"rod_{method}_fe.xdmf"
    part_file = shared_dir / f"rod_{method}_particles.xdmf"
    assert fe_file.exists() == (method != "efg")
    assert (shared_dir / f"rod_{method}_fe.h5").exists() == (method != "efg")
    assert part_file.exists() == (method != "fe")
    if method != "efg":  # DOLFINx's file: mesh, then one temporal collection per field
        grids = temporal_grids(fe_file)
        assert set(grids) == {"displacement", "velocity"}
        n_nodes = dyn.V.dofmap.index_map.size_global
        for name, gs in grids.items():
            assert [float(g.find("Time").get("Value")) for g in gs] == pytest.approx(times)
            for g in gs:
                att = g.find("Attribute")
                assert att.get("Name") == name and att.get("Center") == "Node"
                assert att.find("DataItem").get("Dimensions") == f"{n_nodes} 3"
    if method != "fe":
        n = dyn.particles.num_particles
        grids = temporal_grids(part_file)
        assert list(grids) == ["particles"] and len(grids["particles"]) == 3
        for g in grids["particles"]:
            topo = g.find("Topology")
            assert topo.get("TopologyType") == "Polyvertex"
            assert topo.get("NumberOfElements") == str(n)
            assert {a.get("Name") for a in g.findall("Attribute")} == {"displacement", "velocity"}
            for item in g.iter("DataItem"):
                assert item.get("Format") == "HDF"
                assert item.text.startswith(f"rod_{method}_particles.h5:/")
        # read independently (xml.etree + h5py) and compared with what the dynamics had
        xtimes, arrays = xdmf_particles(part_file)
        assert xtimes == pytest.approx(times, rel=1e-15)
        for geometry, topology in zip(arrays["geometry"], arrays["topology"], strict=True):
            assert np.array_equal(geometry[:, :2], dyn.particles.positions)
            assert np.all(geometry[:, 2] == 0.0)
            assert np.array_equal(topology[:, 0], np.arange(n))
        if comm.rank == 0:
            assert len(reported) == 3
            for k, (t, u, v) in enumerate(reported):
                assert t == pytest.approx(xtimes[k], rel=1e-15)
                scale = np.abs(v).max()
                assert np.abs(arrays["velocity"][k][:, :2] - v).max() <= 1e-12 * scale
                du = arrays["displacement"][k][:, :2] - u
                assert np.abs(du).max() <= 1e-12 * np.abs(u).max()
                assert np.all(arrays["velocity"][k][:, 2] == 0.0)
            # and the initial state is the Gaussian pulse (collocated at the particles; Lagrange
            # projects it onto the constraint, master-slave slaves its first particle layer to
            # the FE edge: interface values move by up to about 1 %)
            v0 = ROD.initial_velocity(dyn.particles.positions)
            assert np.abs(arrays["velocity"][0][:, :2] - v0).max() < 0.02
        # the package's own reader gives the same arrays
        data = read_particles(part_file)
        assert np.array_equal(data["times"], xtimes)
        assert np.array_equal(data["velocity"], np.asarray(arrays["velocity"]))
        assert np.array_equal(data["displacement"], np.asarray(arrays["displacement"]))
        assert np.array_equal(data["positions"], np.asarray(arrays["geometry"]))
    with open(shared_dir / f"rod_{method}_energy.csv") as f:
        rows = list(csv.DictReader(f))
    assert [int(r["step"]) for r in rows] == [n for n, _ in res.outputs]
    by_step = {r.step: r for r in res.energies}
    for r in rows:
        assert float(r["kinetic"]) == by_step[int(r["step"])].kinetic
    dyn.destroy()


def test_writer_as_callback_appends_over_runs(shared_dir):
    """One writer over two runs: the time where the second run starts is not written twice."""
    dyn = build("lagrange")
    dyn.set_initial(velocity=ROD.initial_velocity)
    t1 = 0.1 * ROD.transit_time
    with DynamicsWriter(shared_dir / "two", dyn) as writer:
        dyn.run(t1, outputs=[0.0, t1], on_output=writer)
        dyn.run(2 * t1, outputs=[t1, 2 * t1], on_output=writer)
        writer.write()  # the final state again: skipped
    assert writer.times == pytest.approx([0.0, t1, 2 * t1])
    assert len(temporal_grids(shared_dir / "two_fe.xdmf")["velocity"]) == 3
    data = read_particles(shared_dir / "two_particles.xdmf")
    assert data["times"] == pytest.approx([0.0, t1, 2 * t1])
    _, v = particle_values(dyn)  # after the run: the final state
    if dyn.comm.rank == 0:
        assert np.abs(data["velocity"][-1, :, :2] - v).max() <= 1e-12 * np.abs(v).max()
    dyn.destroy()


def test_xdmf_without_outputs_writes_start_and_end(shared_dir):
    dyn = build("fe")
    dyn.set_initial(velocity=ROD.initial_velocity)
    res = dyn.run(0.05 * ROD.transit_time, xdmf=str(shared_dir / "ends"))
    assert [n for n, _ in res.outputs] == [0, res.steps]
    assert len(temporal_grids(shared_dir / "ends_fe.xdmf")["displacement"]) == 2
    dyn.destroy()


@pytest.mark.parametrize(
    ("kind", "match"),
    [
        ("missing", "does not exist"),
        ("trailing", "should name files"),
        ("per-rank", "same on every rank"),
        ("type", "should be a path"),
    ],
)
def test_bad_prefix_raises_on_every_rank(kind, match, shared_dir):
    comm = MPI.COMM_WORLD
    if kind == "per-rank" and comm.size == 1:
        pytest.skip("needs more than one rank")
    prefix = {
        "missing": shared_dir / "no" / "such" / "dir" / "rod",
        "trailing": str(shared_dir) + os.sep,
        "per-rank": shared_dir / f"rank{comm.rank}",
        "type": 42,
    }[kind]
    dyn = build("lagrange")
    dyn.set_initial(velocity=ROD.initial_velocity)
    with pytest.raises(ValueError, match=match):
        dyn.run(0.05 * ROD.transit_time, xdmf=prefix)
    comm.Barrier()
    assert not list(shared_dir.glob("*.xdmf"))
    dyn.destroy()


# --- progress bar --------------------------------------------------------------------------------


class _FakeTTY(io.StringIO):
    def isatty(self) -> bool:
        return True


def test_progress_bar_forced_prints_on_rank_zero_only(capsys):
    comm = MPI.COMM_WORLD
    dyn = build("fe")
    dyn.set_initial(velocity=ROD.initial_velocity)
    capsys.readouterr()
    res = dyn.run(0.2 * ROD.transit_time, progress=True)
    err = capsys.readouterr().err
    lines = [line for line in err.splitlines() if "explicit dynamics" in line]
    if comm.rank == 0:
        # not a terminal: one draw per 10 % of the run (tqdm, each after a \r), the last at
        # 100 % (drawn again by close)
        assert 2 <= len(lines) <= 13
        assert lines[-1].split("explicit dynamics")[1].strip().startswith("100.0%")
        assert f"step {res.steps}/{res.steps}" in lines[-1]
        assert err.endswith("\n")
    else:
        assert not lines
    dyn.destroy()


def test_progress_bar_is_off_by_default_when_not_a_terminal(capsys):
    dyn = build("fe")
    dyn.set_initial(velocity=ROD.initial_velocity)
    capsys.readouterr()
    res_auto = dyn.run(0.1 * ROD.transit_time)
    res_off = dyn.run(0.2 * ROD.transit_time, progress=False)
    assert "explicit dynamics" not in capsys.readouterr().err
    assert res_auto.steps > 0 and res_off.steps > 0
    with pytest.raises(ValueError, match="progress="):
        dyn.run(0.3 * ROD.transit_time, progress="yes")
    dyn.destroy()


def test_progress_bar_on_a_terminal_redraws_in_place_at_most_every_interval():
    comm = MPI.COMM_WORLD
    stream = _FakeTTY()
    bar = ProgressBar(1000, comm, stream=stream, interval=3600.0, label="run ", delay=0.0)
    for done in range(1, 1001):
        bar.update(done, 1e-3 * done)
    bar.close(1000, 1.0)
    out = stream.getvalue()
    if comm.rank == 0:
        # the first draw and the last (forced by close), redrawn with \r, then a newline
        assert out.count("\r") == 2 and out.endswith("\n")
        assert "step 1000/1000" in out and "t = 1" in out
    else:
        assert out == ""
    silent = _FakeTTY()
    ProgressBar(10, comm, enabled=False, stream=silent).update(5)
    assert silent.getvalue() == ""
    # automatic mode on a terminal: a run shorter than the delay stays silent
    short = _FakeTTY()
    bar = ProgressBar(10, comm, stream=short)
    for done in range(1, 11):
        bar.update(done)
    bar.close(10)
    assert short.getvalue() == ""
    with pytest.raises(ValueError, match="total="):
        ProgressBar(0, comm)


# --- the demos' --xdmf flag ----------------------------------------------------------------------


def test_rod_gauss_demo_writes_xdmf_per_method(shared_dir):
    demo = load_demo("rod_gauss", "demo_rod_gauss_io")
    prefix = shared_dir / "gauss"
    demo.main(["--method", "fe", "lagrange", "--nodes", "200", "--t-end", "0.002",
               "--no-check", "--xdmf", str(prefix)])  # fmt: skip
    for method in ("fe", "lagrange"):
        grids = temporal_grids(shared_dir / f"gauss_{method}_fe.xdmf")
        assert len(grids["velocity"]) == 11  # 11 frames; t1, t2 lie after t_end
    data = read_particles(shared_dir / "gauss_lagrange_particles.xdmf")
    assert data["times"][0] == 0.0 and data["times"][-1] == pytest.approx(0.002)
    assert not (shared_dir / "gauss_fe_particles.xdmf").exists()
    with pytest.raises(SystemExit):
        demo.parse(["--xdmf", str(shared_dir / "missing" / "x")])
