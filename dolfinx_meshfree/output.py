"""XDMF time series for ParaView of the fields of a (static or dynamic) sequence of solutions:
the FE fields, the particle cloud and polylines (e.g. the cracks), one output per step.

Files written by :class:`SeriesWriter` for a prefix ``out/growth``:

* ``out/growth_fe.xdmf`` (+ ``.h5``): the mesh and the FE functions passed to
  :meth:`SeriesWriter.write`, one temporal collection per function name, written collectively by
  DOLFINx's ``XDMFFile`` (HDF5; each rank its own part);
* ``out/growth_particles.xdmf`` (+ ``.h5``): the particle cloud, a temporal collection of
  ``Polyvertex`` grids: the positions (``XYZ``, ``z = 0`` in 2D; written once, every step
  refers to them) and per step the named particle values (vectors padded to 3 components,
  scalars), gathered on rank 0 from the owners of the particles;
* ``out/growth_cracks.xdmf`` (+ ``.h5``): the polylines of each step (``Polyline`` grids of
  two-node segments; their number of points may change from step to step).

DOLFINx has no particle writer (0.5 to 0.11), so the particle and polyline files are written by
rank 0 alone with h5py (serial HDF5: one group ``/step_<k>`` per output) and addressed by
``Format="HDF"`` DataItems (``growth_particles.h5:/step_0/displacement``), which ParaView's
XDMF readers read. The HDF5 file is closed and the XML rewritten atomically after every
output, so an interrupted run leaves readable files.
"""

from __future__ import annotations

import os
import pathlib
import xml.etree.ElementTree as ET
from collections.abc import Callable, Mapping, Sequence
from typing import TYPE_CHECKING

import dolfinx.fem
import dolfinx.io
import numpy as np
from mpi4py import MPI

from .parallel import raise_on_all_ranks

if TYPE_CHECKING:
    from .geometry.particles import ParticleSet

__all__ = ["CloudSeriesWriter", "SeriesWriter", "check_prefix", "gather_rows", "on_rank0"]

# -- the output prefix -------------------------------------------------------------------------


def check_prefix(prefix: str | os.PathLike, comm: MPI.Comm) -> pathlib.Path:
    """Check an output prefix on every rank (collective) and return it as a path.

    The prefix is a path without suffix (``"out/rod"`` gives ``out/rod_fe.xdmf``, ...): it must
    be the same on every rank, name a file (not end in a separator), and its directory must
    exist and be writable on every rank.

    Raises:
        ValueError: on every rank, naming the prefix and the fix.
    """
    names = comm.allgather(str(prefix) if isinstance(prefix, str | os.PathLike) else None)

    def check() -> pathlib.Path:
        if not isinstance(prefix, str | os.PathLike):
            raise ValueError(
                f"the output prefix should be a path (str or os.PathLike), got {prefix!r}"
            )
        if len(set(names)) != 1:
            raise ValueError(f"the output prefix must be the same on every rank, got {names}")
        text = str(prefix)
        path = pathlib.Path(prefix)
        if not text or text.endswith(("/", os.sep)) or path.name in ("", ".", ".."):
            raise ValueError(
                f"the output prefix {text!r} should name files, e.g. 'out/rod' (which writes "
                "out/rod_fe.xdmf, out/rod_particles.xdmf, ...)"
            )
        folder = path.parent
        if not folder.is_dir():
            raise ValueError(
                f"the directory {str(folder)!r} of the output prefix {text!r} does not exist; "
                "create it first"
            )
        if not os.access(folder, os.W_OK | os.X_OK):
            raise ValueError(
                f"the directory {str(folder)!r} of the output prefix {text!r} is not writable"
            )
        return path

    return raise_on_all_ranks(comm, check)


def gather_rows(comm: MPI.Comm, rows: np.ndarray, values: np.ndarray, n: int) -> np.ndarray | None:
    """The rows ``values`` (m, k) of the global rows ``rows`` (m,) of each rank assembled on
    rank 0 into an (n, k) array (collective; ``None`` on the other ranks; rows no rank gives are
    zero)."""
    values = np.asarray(values, dtype=np.float64)
    if values.ndim != 2:  # (m,) scalars or (m, ...) tensors; (0, k) stays as it is
        values = values.reshape(values.shape[0], int(np.prod(values.shape[1:])))
    parts = comm.gather((np.asarray(rows, dtype=np.int64), values), root=0)
    if comm.rank != 0:
        return None
    k = max((p[1].shape[1] for p in parts if p[1].size), default=values.shape[1])
    out = np.zeros((n, k))
    for idx, vals in parts:
        out[idx] = vals
    return out


def on_rank0(comm: MPI.Comm, fn: Callable[[], object], what: str) -> None:
    """Run ``fn`` on rank 0 alone (collective): an ``OSError`` or ``ValueError`` there is raised
    as a ``ValueError`` ``"{what} failed: ..."`` on every rank, so that no rank goes on into a
    collective call alone."""
    msg = None
    if comm.rank == 0:
        try:
            fn()
        except (OSError, ValueError) as e:
            msg = f"{what} failed: {e}"
    msg = comm.bcast(msg, root=0)
    if msg is not None:
        raise ValueError(msg)


def _pad3(x: np.ndarray) -> np.ndarray:
    """Points or vectors (n, d <= 3) as (n, 3) (XDMF's ``XYZ`` and vector attributes)."""
    x = np.asarray(x, dtype=np.float64)
    out = np.zeros((x.shape[0], 3))
    out[:, : x.shape[1]] = x
    return out


class CloudSeriesWriter:
    """A temporal collection of point clouds (``Polyvertex``) or polylines (``Polyline``) in one
    XDMF file and its HDF5 file, written by rank 0 with h5py.

    Call every method on every rank (collective: an ``OSError`` on rank 0 is raised as a
    ``ValueError`` on every rank); the data arguments are read on rank 0 only.

    Args:
        path: The ``.xdmf`` file; the HDF5 file is the same path with suffix ``.h5``.
        comm: The ranks that call the writer.
        name: The grids' name (shown by ParaView).
    """

    def __init__(self, path: str | os.PathLike, comm: MPI.Comm, name: str = "particles") -> None:
        self.path = pathlib.Path(path)
        self.h5 = self.path.with_suffix(".h5")
        self.comm, self.name = comm, name
        #: per output: (time, geometry path, n points, segments path or None, attributes)
        self._grids: list[tuple[float, str, int, tuple[str, int] | None, list]] = []
        self._geometry: tuple[str, int] | None = None
        self._rank0(self._start)

    def _rank0(self, fn: Callable[[], object]) -> None:
        on_rank0(self.comm, fn, f"writing {str(self.path)!r}")

    def _start(self) -> None:
        import h5py

        with h5py.File(self.h5, "w"):
            pass
        self._write_xml()

    def write(
        self,
        time: float,
        points: np.ndarray | None = None,
        attributes: Mapping[str, np.ndarray] | None = None,
        segments: np.ndarray | None = None,
    ) -> None:
        """Append one output (collective; the data are read on rank 0).

        Args:
            time: The output's time (or step number).
            points: (n, gdim) positions; ``None``: those of the previous output.
            attributes: name -> (n,) scalars or (n, d <= 3) vectors at the points.
            segments: (s, 2) point indices of line segments (a ``Polyline`` grid); ``None``: a
                ``Polyvertex`` grid (each point a cell).
        """
        attributes = dict(attributes or {})
        self._rank0(lambda: self._append(float(time), points, attributes, segments))

    def _append(self, t: float, points, attributes: dict, segments) -> None:
        import h5py

        group = f"step_{len(self._grids)}"
        with h5py.File(self.h5, "a") as f:
            g = f.create_group(group)
            g.attrs["time"] = t
            if points is not None:
                g.create_dataset("geometry", data=_pad3(points))
                vertices = np.arange(len(points), dtype=np.int32)[:, None]
                g.create_dataset("vertices", data=vertices)  # Polyvertex: one per cell
                self._geometry = (f"/{group}/geometry", len(points))
            if self._geometry is None:
                raise ValueError("the first output of a CloudSeriesWriter needs points")
            geometry, n = self._geometry
            topo = None
            if segments is not None:
                seg = np.asarray(segments, dtype=np.int32).reshape(-1, 2)
                g.create_dataset("topology", data=seg)
                topo = (f"/{group}/topology", len(seg))
            atts = []
            for key, value in attributes.items():
                v = np.asarray(value, dtype=np.float64)
                if v.shape[0] != n:
                    raise ValueError(
                        f"attribute {key!r} has {v.shape[0]} rows for {n} points at time {t}"
                    )
                v = v if v.ndim == 1 else _pad3(v)
                g.create_dataset(key, data=v)
                atts.append((key, f"/{group}/{key}", v.shape))
        self._grids.append((t, geometry, n, topo, atts))
        self._write_xml()

    def _write_xml(self) -> None:
        h5 = self.h5.name
        root = ET.Element("Xdmf", Version="3.0")
        domain = ET.SubElement(root, "Domain")
        series = ET.SubElement(
            domain, "Grid", Name=self.name, GridType="Collection", CollectionType="Temporal"
        )

        def data(parent: ET.Element, path: str, shape: tuple, number: str) -> None:
            item = ET.SubElement(
                parent,
                "DataItem",
                Dimensions=" ".join(str(s) for s in shape),
                NumberType=number,
                Precision="4" if number == "Int" else "8",
                Format="HDF",
            )
            item.text = f"{h5}:{path}"

        for t, geometry, n, topo, atts in self._grids:
            grid = ET.SubElement(series, "Grid", Name=self.name, GridType="Uniform")
            ET.SubElement(grid, "Time", Value=repr(t))
            if topo is None:
                top = ET.SubElement(
                    grid, "Topology", TopologyType="Polyvertex", NumberOfElements=str(n),
                    NodesPerElement="1",
                )  # fmt: skip
                data(top, geometry.replace("/geometry", "/vertices"), (n, 1), "Int")
            else:
                top = ET.SubElement(
                    grid, "Topology", TopologyType="Polyline", NumberOfElements=str(topo[1]),
                    NodesPerElement="2",
                )  # fmt: skip
                data(top, topo[0], (topo[1], 2), "Int")
            geom = ET.SubElement(grid, "Geometry", GeometryType="XYZ")
            data(geom, geometry, (n, 3), "Float")
            for key, path, shape in atts:
                kind = "Scalar" if len(shape) == 1 else "Vector"
                att = ET.SubElement(grid, "Attribute", Name=key, AttributeType=kind, Center="Node")
                data(att, path, shape, "Float")
        ET.indent(root)
        tmp = self.path.with_name(self.path.name + ".tmp")
        with open(tmp, "w") as f:
            f.write('<?xml version="1.0"?>\n<!DOCTYPE Xdmf SYSTEM "Xdmf.dtd" []>\n')
            f.write(ET.tostring(root, encoding="unicode"))
            f.write("\n")
        os.replace(tmp, self.path)


class SeriesWriter:
    """XDMF time series of FE functions, a particle cloud and polylines (collective).

    Every rank constructs it and calls :meth:`write` and :meth:`close`; also a context manager.
    See the module docstring for the files.

    Args:
        prefix: Output path without suffix (its directory must exist; the same on every rank).
        comm: The ranks (default: the mesh's or the particles').
        mesh: The mesh of the FE functions (``None``: no FE file).
        particles: The :class:`~dolfinx_meshfree.ParticleSet` whose values are written
            (``None``: no particle file).
        polylines: Write a polyline file (e.g. the cracks).

    Attributes:
        files: The files written, by kind (``"fe"``, ``"particles"``, ``"polylines"``; the
            HDF5 files are the same paths with suffix ``.h5``).
    """

    def __init__(
        self,
        prefix: str | os.PathLike,
        *,
        comm: MPI.Comm | None = None,
        mesh: dolfinx.mesh.Mesh | None = None,
        particles: ParticleSet | None = None,
        polylines: bool = False,
    ) -> None:
        if comm is None:
            comm = mesh.comm if mesh is not None else getattr(particles, "comm", MPI.COMM_WORLD)
        self.comm = comm
        base = str(check_prefix(prefix, comm))
        self.files: dict[str, pathlib.Path] = {}
        self._fe = None
        self._fe_copies: dict[str, dolfinx.fem.Function] = {}
        self.particles, self._cloud, self._lines = particles, None, None
        if particles is not None:
            self.files["particles"] = pathlib.Path(base + "_particles.xdmf")
            self._cloud = CloudSeriesWriter(self.files["particles"], comm, "particles")
            self._owned = np.asarray(particles.owned, dtype=np.int64)
        if polylines:
            self.files["polylines"] = pathlib.Path(base + "_cracks.xdmf")
            self._lines = CloudSeriesWriter(self.files["polylines"], comm, "cracks")
        if mesh is not None:
            self.files["fe"] = pathlib.Path(base + "_fe.xdmf")
            self._fe = dolfinx.io.XDMFFile(comm, str(self.files["fe"]), "w")
            self._fe.write_mesh(mesh)
        self._first = True

    def write(
        self,
        time: float,
        functions: Mapping[str, dolfinx.fem.Function] | None = None,
        particle_values: Mapping[str, np.ndarray] | None = None,
        polylines: Sequence[np.ndarray] = (),
    ) -> None:
        """Append one output (collective).

        Args:
            time: The output's time (a growth step's number in statics).
            functions: name -> FE function on the mesh (written under that name; the caller's
                function is copied, not renamed).
            particle_values: name -> (n_owned, d) values at this rank's owned particles
                (``particles.positions[particles.owned]``), in that order.
            polylines: (m_k, gdim) point arrays, one per polyline (the same on every rank).
        """
        t = float(time)
        raise_on_all_ranks(self.comm, lambda: self._check(functions, particle_values))
        for name, u in (functions or {}).items():
            copy = self._fe_copies.get(name)
            if copy is None:
                copy = self._fe_copies[name] = dolfinx.fem.Function(u.function_space, name=name)
            copy.x.array[:] = u.x.array
            self._fe.write_function(copy, t)
        if self._cloud is not None:
            P = self.particles
            n = P.num_particles
            gathered = {
                k: gather_rows(self.comm, self._owned, v, n)
                for k, v in (particle_values or {}).items()
            }
            atts = {}
            if self.comm.rank == 0:
                atts = {k: (v[:, 0] if v.shape[1] == 1 else v) for k, v in gathered.items()}
            self._cloud.write(t, P.positions if self._first else None, atts)
        if self._lines is not None:
            pts = [np.asarray(p, dtype=np.float64) for p in polylines]
            sizes = [len(p) for p in pts]
            start = np.cumsum([0, *sizes[:-1]])
            seg = [np.stack([s + np.arange(m - 1), s + np.arange(1, m)], 1)
                   for s, m in zip(start, sizes, strict=True)]  # fmt: skip
            xy = np.concatenate(pts) if pts else np.zeros((0, 2))
            segs = np.concatenate(seg) if seg else np.zeros((0, 2), dtype=np.int32)
            self._lines.write(t, xy, None, segs)
        self._first = False

    def _check(self, functions, particle_values) -> None:
        if functions and self._fe is None:
            raise ValueError("this SeriesWriter has no mesh: pass mesh= to write FE functions")
        if particle_values and self._cloud is None:
            raise ValueError(
                "this SeriesWriter has no particles: pass particles= to write particle values"
            )
        for key, v in (particle_values or {}).items():
            m = len(np.asarray(v))
            if m != self._owned.size:
                raise ValueError(
                    f"particle_values[{key!r}] has values for {m} of the {self._owned.size} "
                    f"owned particles of rank {self.comm.rank}: give one row per owned particle, "
                    "in the order of particles.positions[particles.owned]"
                )

    def close(self) -> None:
        """Close the FE file (collective); the particle and polyline files are complete after
        every write."""
        if self._fe is not None:
            self._fe.close()
            self._fe = None
        self.comm.Barrier()

    def __enter__(self) -> SeriesWriter:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()
