"""Output of explicit dynamics: XDMF time series of the FE fields and of the particle cloud, and a
progress bar for long runs.

Files written by :class:`DynamicsWriter` for a prefix ``out/rod``:

* ``out/rod_fe.xdmf`` (+ ``out/rod_fe.h5``): the mesh and the FE displacement and velocity as
  DOLFINx :class:`~dolfinx.fem.Function` named ``"displacement"`` and ``"velocity"``, one
  temporal collection each, written collectively by DOLFINx's ``XDMFFile`` (HDF5). In a coupled
  model the FE nodes that only patch cells touch hold zero (they carry no mass);
* with a rate-form law (:class:`~dolfinx_meshfree.HolmquistJohnsonCook`,
  :class:`~dolfinx_meshfree.JohnsonCook`), in the same file: each scalar state variable
  (``"damage"``, ``"plastic_strain"``, ...) per cell, the largest over its points, as a DG0
  function (:func:`~dolfinx_meshfree.state_fields.state_fields`);
* ``out/rod_particles.xdmf`` (+ ``out/rod_particles.h5``): the particle cloud, one temporal
  collection of ``Polyvertex`` grids; per output time the particle positions (reference
  configuration, ``XYZ`` with ``z = 0``) and the displacement and velocity *values* at the
  particles (``u_h(x_J)``, ``v_h(x_J)``: the MLS, blended or FE field evaluated there, not the
  MLS coefficients), as 3-component vectors, written by
  :class:`~dolfinx_meshfree.output.CloudSeriesWriter` (rank 0, h5py: datasets
  ``/step_0/geometry``, ``/step_0/vertices`` and ``/step_<k>/displacement``,
  ``/step_<k>/velocity``, addressed by ``Format="HDF"`` DataItems, which ParaView's XDMF
  readers read); positions are replicated, the values gathered from the owners of the
  particles. The HDF5 file is closed and the XML rewritten (atomically) after every output, so
  an interrupted run leaves readable files;
* ``out/rod_energy.csv``: the :class:`~dolfinx_meshfree.EnergyRecord` at each output (rank 0).

:func:`read_particles` reads a particle file back (tests, post-processing).
"""

from __future__ import annotations

import math
import os
import pathlib
import sys
import xml.etree.ElementTree as ET
from collections.abc import Callable
from typing import IO, TYPE_CHECKING

import dolfinx.io
import numpy as np
from mpi4py import MPI

from .output import CloudSeriesWriter, check_prefix, gather_rows, on_rank0
from .state_fields import state_fields

if TYPE_CHECKING:
    from .dynamics import ExplicitDynamics

__all__ = ["DynamicsWriter", "ProgressBar", "read_particles"]

_ENERGY_KEYS = (
    "step",
    "time",
    "kinetic",
    "internal",
    "external",
    "constraint",
    "transfer",
    "discrete",
    "residual",
)


# -- progress bar ------------------------------------------------------------------------------


class ProgressBar:
    """A progress bar on rank 0's ``stderr`` for long runs, drawn by ``tqdm``.

    On a terminal the line is redrawn in place at most every ``interval`` seconds; forced onto a
    stream that is not a terminal, it is redrawn once per ``step_percent`` of the run (each
    draw starts with ``\\r``, so ``str.splitlines`` gives one line per draw). In automatic
    mode (``enabled=None``) nothing is drawn before ``delay`` seconds have passed, so that short
    runs stay silent. Other ranks print nothing; ``update`` never communicates, so calling it on
    some ranks only is safe.

    Args:
        total: Number of steps of the run (> 0).
        comm: Communicator: only its rank 0 prints (``None``: ``MPI.COMM_WORLD``).
        enabled: ``True``: on (rank 0), even if the stream is not a terminal; ``False``: off;
            ``None``: on when the stream is a terminal.
        stream: Where to print (default ``sys.stderr`` at construction).
        interval: Seconds between redraws on a terminal.
        step_percent: Percent of the run between draws when the stream is not a terminal.
        label: Text before the bar.
        delay: Seconds before the first draw; default 2 in automatic mode, 0 when forced.
    """

    def __init__(
        self,
        total: int,
        comm: MPI.Comm | None = None,
        enabled: bool | None = None,
        stream: IO[str] | None = None,
        interval: float = 0.5,
        step_percent: float = 10.0,
        label: str = "",
        delay: float | None = None,
    ) -> None:
        if enabled not in (None, True, False):
            raise ValueError(f"progress={enabled!r} should be True, False or None (automatic)")
        if isinstance(total, bool) or not isinstance(total, int | np.integer) or total < 1:
            raise ValueError(f"total={total!r} should be a positive number of steps")
        comm = MPI.COMM_WORLD if comm is None else comm
        self.stream = sys.stderr if stream is None else stream
        self.total = int(total)
        self.tty = _isatty(self.stream)
        on = self.tty if enabled is None else enabled
        self.enabled = bool(on) and comm.rank == 0
        self._done = 0
        self._bar = None
        if not self.enabled:
            return
        from tqdm import tqdm

        if self.tty:
            every = {"mininterval": float(interval), "miniters": 1}
        else:  # a log file: one draw per step_percent, whatever the time
            every = {"mininterval": 0.0, "miniters": max(1, math.ceil(total * step_percent / 100))}
        self._bar = tqdm(
            total=self.total,
            desc=label.rstrip(),
            file=self.stream,
            delay=float(delay) if delay is not None else (2.0 if enabled is None else 0.0),
            maxinterval=math.inf,  # tqdm's monitor would otherwise lower miniters
            dynamic_ncols=False,
            ascii=not self.tty,
            bar_format="{desc} {percentage:5.1f}%|{bar:24}| step {n}/{total}{postfix} "
            "[{elapsed}<{remaining}]",
            **every,
        )

    def update(self, done: int, t: float | None = None) -> None:
        """Report ``done`` steps of ``total`` (and the simulated time ``t``); cheap when not due."""
        if self._bar is None or done <= self._done:
            return
        if t is not None:
            self._bar.set_postfix_str(f"t = {t:.6g}", refresh=False)
        self._bar.update(done - self._done)
        self._done = done

    def close(self, done: int | None = None, t: float | None = None) -> None:
        """Draw the final state (if ``done`` is given) and end the line."""
        if self._bar is None:
            return
        if done is not None and done > self._done:
            if t is not None:
                self._bar.set_postfix_str(f"t = {t:.6g}", refresh=False)
            self._bar.n = done
            self._done = done
        self._bar.close()
        self._bar = None


def _isatty(stream: IO[str]) -> bool:
    try:
        return bool(stream.isatty())
    except (AttributeError, ValueError, OSError):
        return False


# -- XDMF writer -------------------------------------------------------------------------------


class DynamicsWriter:
    """XDMF time series of an :class:`~dolfinx_meshfree.ExplicitDynamics` (collective).

    Use as the output callback, ``dyn.run(t_end, outputs=times, on_output=writer)``, or let
    :meth:`ExplicitDynamics.run <dolfinx_meshfree.ExplicitDynamics.run>` make one with
    ``xdmf=prefix``. Every rank must construct, call and close it; DOLFINx writes the FE file
    collectively and rank 0 alone writes the particle and energy files (see the module
    docstring for the files). A time equal to the last one written is skipped (a continued run
    starts where the previous one ended). Also a context manager.

    Args:
        prefix: Output path without suffix (its directory must exist).
        dynamics: The model to write.
        fe: Write the FE fields (when the model has an FE space).
        particles: Write the particle cloud (when the model has particles).
        energy: Write the energy records (``{prefix}_energy.csv``).

    Attributes:
        files: The files this writer produces, by kind (``"fe"``, ``"fe_h5"``, ``"particles"``,
            ``"particles_h5"``, ``"energy"``); the same on every rank.
        times: Output times written so far.

    Raises:
        ValueError: on every rank for a bad prefix (:func:`check_prefix`).
    """

    def __init__(
        self,
        prefix: str | os.PathLike,
        dynamics: ExplicitDynamics,
        *,
        fe: bool = True,
        particles: bool = True,
        energy: bool = True,
    ) -> None:
        self.dynamics = dynamics
        self.comm = dynamics.comm
        self.prefix = check_prefix(prefix, self.comm)
        base = str(self.prefix)
        self.files: dict[str, pathlib.Path] = {}
        self.times: list[float] = []
        self._fe_file = None
        self._closed = False
        self._with_fe = bool(fe) and dynamics.V is not None
        self._with_particles = bool(particles) and dynamics.particles is not None
        self._with_energy = bool(energy)
        if self._with_fe:
            self.files["fe"] = pathlib.Path(base + "_fe.xdmf")
            self.files["fe_h5"] = pathlib.Path(base + "_fe.h5")
        if self._with_particles:
            self.files["particles"] = pathlib.Path(base + "_particles.xdmf")
            self.files["particles_h5"] = pathlib.Path(base + "_particles.h5")
            self._owned = np.asarray(dynamics.particles.owned, dtype=np.int64)
        if self._with_energy:
            self.files["energy"] = pathlib.Path(base + "_energy.csv")
        # rank 0's files first (errors are shared before DOLFINx's collective open)
        self._cloud = None
        if self._with_particles:
            self._cloud = CloudSeriesWriter(self.files["particles"], self.comm, "particles")
        self._rank0(self._start_energy_file)
        if self._with_fe:
            self._fe_file = dolfinx.io.XDMFFile(self.comm, str(self.files["fe"]), "w")
            self._fe_file.write_mesh(dynamics.mesh)

    # -- rank 0 files --------------------------------------------------------------------------

    def _rank0(self, fn: Callable[[], object]) -> None:
        on_rank0(self.comm, fn, f"writing the output files of prefix {str(self.prefix)!r}")

    def _start_energy_file(self) -> None:
        if self._with_energy:
            with open(self.files["energy"], "w") as f:
                f.write(",".join(_ENERGY_KEYS) + "\n")

    # -- writing -------------------------------------------------------------------------------

    def __call__(self, dynamics: ExplicitDynamics, step: int, time: float) -> None:
        """The ``on_output`` callback of :meth:`ExplicitDynamics.run`: :meth:`write`."""
        if dynamics is not self.dynamics:
            raise ValueError("this DynamicsWriter was made for another ExplicitDynamics")
        self.write(time)

    def write(self, time: float | None = None) -> None:
        """Write the current state (collective): at an output time of a run (in ``on_output``)
        the state ``d_n, v_n``; after a run the final state. ``time`` defaults to the model's."""
        if self._closed:
            raise ValueError("this DynamicsWriter is closed")
        dyn = self.dynamics
        t = float(dyn.time if time is None else time)
        if self.times and math.isclose(t, self.times[-1], rel_tol=1e-12, abs_tol=0.0):
            return
        self.times.append(t)
        if self._with_fe:
            for f in dyn.fe_functions():
                self._fe_file.write_function(f, t)
            for f in state_fields(dyn):  # a rate-form law's state, the largest per cell
                self._fe_file.write_function(f, t)
        if self._cloud is not None:
            P = dyn.particles
            x = P.positions[self._owned]
            n = P.num_particles
            u = gather_rows(self.comm, self._owned, dyn.displacement_at(x), n)
            v = gather_rows(self.comm, self._owned, dyn.velocity_at(x), n)
            attributes = None if u is None else {"displacement": u, "velocity": v}
            first = len(self.times) == 1  # positions once: the reference configuration
            self._cloud.write(t, P.positions if first else None, attributes)
        record = dyn.energy_record

        def rank0() -> None:
            if self._with_energy and record is not None:
                with open(self.files["energy"], "a") as f:
                    f.write(",".join(repr(getattr(record, k)) for k in _ENERGY_KEYS) + "\n")

        self._rank0(rank0)

    def close(self) -> None:
        """Close the FE file (collective); the particle files are complete after every write."""
        if self._closed:
            return
        self._closed = True
        if self._fe_file is not None:
            self._fe_file.close()
            self._fe_file = None
        self.comm.Barrier()

    def __enter__(self) -> DynamicsWriter:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()


# -- reading back ------------------------------------------------------------------------------


def read_particles(path: str | os.PathLike) -> dict[str, np.ndarray]:
    """Read a particle XDMF file written by :class:`DynamicsWriter` (any process, no MPI).

    Returns:
        A dict with the arrays ``"times"`` ``(k,)``, ``"positions"`` ``(k, n, 3)``,
        ``"displacement"`` ``(k, n, 3)`` and ``"velocity"`` ``(k, n, 3)`` for the ``k`` output
        times of ``n`` particles.
    """
    import h5py

    path = pathlib.Path(path)
    root = ET.parse(path).getroot()
    grids = root.findall("./Domain/Grid[@CollectionType='Temporal']/Grid")
    out: dict[str, list] = {"times": [], "positions": [], "displacement": [], "velocity": []}
    files: dict[str, h5py.File] = {}

    def load(item: ET.Element) -> np.ndarray:
        dims = tuple(int(d) for d in item.get("Dimensions").split())
        name, dataset = item.text.strip().split(":", 1)
        if name not in files:
            files[name] = h5py.File(path.parent / name, "r")
        arr = np.asarray(files[name][dataset])
        if arr.shape != dims:
            raise ValueError(f"{path}: {item.text.strip()} has shape {arr.shape}, not {dims}")
        return arr

    try:
        for g in grids:
            out["times"].append(float(g.find("Time").get("Value")))
            out["positions"].append(load(g.find("Geometry/DataItem")))
            for att in g.findall("Attribute"):
                out[att.get("Name")].append(load(att.find("DataItem")))
    finally:
        for f in files.values():
            f.close()
    return {k: np.asarray(v) for k, v in out.items()}
