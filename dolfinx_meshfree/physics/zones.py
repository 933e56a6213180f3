"""Several rate-form laws in one model: :class:`MaterialZones` (issue 27; the steel projectile and
the concrete slab of Rabczuk, Xiao & Sauer 2006, sec. 6.2.2, are two bodies of one explicit
model).

A zone is a rate-form law (:class:`~dolfinx_meshfree.JohnsonCook`,
:class:`~dolfinx_meshfree.HolmquistJohnsonCook`) and where it holds: a marker, ``marker(x) ->
bool`` on points ``x`` of shape ``(3, n)``, as DOLFINx's ``locate_entities`` takes it (a cell
belongs to the zone whose marker holds at its midpoint), or a tag of the cell tags (``MeshTags``
of the cells, e.g. a gmsh physical group read with the mesh). Each owned cell must belong to
exactly one zone (a cell in none or in two is refused, named by its midpoint), and each zone
must hold a cell; ghost cells take their owner's zone. Everything a cell carries then follows
its zone, so that a model's parts agree with each other by construction:

* the state and stress of every quadrature point in the cell (FE Gauss points, the particles'
  cell rule): the law's equations are those of its zone (the state is the union of the zones'
  state arrays, with the zone's index as the array ``"zone"``; a point's arrays that its law
  does not have stay at 0);
* the density of the lumped masses, ``M_II = sum_q rho(x_q) N_I(x_q) w_q`` (Belytschko et al.
  1995, eq. 4.5, with ``rho`` piecewise constant on the cells): a DG0 field on the FE cells and
  the cell's density at each particle quadrature point; ``rho V_I`` masses take the zone of
  the particle's own position;
* the tangent of the stable-step bound: each point's zone's stiffest linear twin.

Where one number stands for the whole model (the linear reference stiffness, the Courant
estimate), :attr:`MaterialZones.stiffest` gives it: the zone with the largest dilatational wave
speed in its stiffest state (the bulk modulus of its stiffest linear twin: HJC's fully dense
``K1`` makes the 48 MPa concrete's 6,550 m/s, above 4340 steel's 5,790). The contact penalty
``k = factor E / h`` takes the largest Young's modulus of the zones' twins (the steel's).
"""

from __future__ import annotations

from collections.abc import Callable, Sequence

import dolfinx
import numpy as np

from .. import _compat
from ..parallel import raise_on_all_ranks
from .state import is_rate_law

__all__ = ["MaterialZones"]

Marker = Callable[[np.ndarray], np.ndarray]


class MaterialZones:
    """Rate-form laws on zones of one model's cells (module docstring).

    Args:
        zones: ``[(law, where), ...]``: a rate-form law and where it holds: ``marker(x)`` (``x``
            of shape ``(3, n)``) -> ``n`` booleans, or an ``int`` tag of ``cell_tags``.
        cell_tags: The cells' ``MeshTags`` (of the model's mesh), needed by the ``int`` tags.

    Raises:
        TypeError: a law is not a rate-form law, ``where`` is neither callable nor an ``int``,
            or a tag is given without ``cell_tags``.
        ValueError: no zone; laws of different dimensions (``plane``); state arrays of one name
            but different sizes.

    Example::

        zones = MaterialZones([
            (JohnsonCook.steel_4340(plane="strain"), lambda x: x[1] > 0.05),
            (HolmquistJohnsonCook.concrete_48mpa(plane="strain"), lambda x: x[1] < 0.05),
        ])
        dyn = ExplicitDynamics.fe(V, zones)
        zones = MaterialZones([(steel, 1), (concrete, 2)], cell_tags=cell_tags)  # gmsh groups
    """

    def __init__(
        self, zones: Sequence[tuple[object, Marker | int]], cell_tags: object | None = None
    ) -> None:
        zones = list(zones)
        if not zones:
            raise ValueError("MaterialZones(zones=[]): give at least one (law, marker) pair")
        for k, pair in enumerate(zones):
            if not (isinstance(pair, tuple | list) and len(pair) == 2):
                raise TypeError(
                    f"MaterialZones: zone {k} is {pair!r}; give a (law, marker) pair, marker(x) "
                    "-> bool array for x of shape (3, n)"
                )
            law, marker = pair
            if isinstance(law, MaterialZones):
                raise TypeError(
                    f"MaterialZones: zone {k}'s law is itself a MaterialZones; list its "
                    "(law, marker) pairs in one MaterialZones"
                )
            if not is_rate_law(law):
                raise TypeError(
                    f"MaterialZones: zone {k}'s law is a {type(law).__name__}; zones take "
                    "rate-form laws (JohnsonCook, HolmquistJohnsonCook), whose state explicit "
                    "dynamics carries point by point"
                )
            tag = isinstance(marker, int | np.integer) and not isinstance(marker, bool)
            if not (callable(marker) or tag):
                raise TypeError(
                    f"MaterialZones: zone {k}'s marker is a {type(marker).__name__}; give a "
                    "callable marker(x) -> bool array, x of shape (3, n), or an int cell tag"
                )
            if tag and cell_tags is None:
                raise TypeError(
                    f"MaterialZones: zone {k} is the cell tag {marker}, but no cell_tags were "
                    "given; pass cell_tags= (the cells' MeshTags)"
                )
        self.laws: list[object] = [law for law, _ in zones]
        self.markers: list[Marker | int] = [marker for _, marker in zones]
        self.cell_tags = cell_tags
        planes = {getattr(law, "plane", None) for law in self.laws}
        if len(planes) > 1:
            raise ValueError(
                f"MaterialZones: the laws have planes {[law.plane for law in self.laws]}; one "
                "model has one dimension: build every law with the same plane"
            )
        self.plane = self.laws[0].plane
        fields: dict[str, int] = {}
        for law in self.laws:
            for name, size in law.state_fields.items():
                if fields.setdefault(name, size) != size:
                    raise ValueError(
                        f"MaterialZones: the state array {name!r} has {fields[name]} components "
                        f"in one law and {size} in {type(law).__name__}; the zones' states "
                        "cannot be joined"
                    )
        fields["zone"] = 1
        #: The union of the zones' state arrays, and ``"zone"``: the index of the point's zone.
        self.state_fields: dict[str, int] = fields
        # the stiffest state's dilatational speed of each law (its stiffest linear twin's)
        speeds = [
            np.sqrt((law.stiffest_bulk_modulus + 4.0 * law.G / 3.0) / law.rho) for law in self.laws
        ]
        #: The zone whose law has the largest dilatational wave speed in its stiffest state:
        #: the model's single numbers (module docstring).
        self.stiffest: object = self.laws[int(np.argmax(speeds))]

    def __repr__(self) -> str:
        return f"MaterialZones([{', '.join(type(law).__name__ for law in self.laws)}])"

    # -- the one-law view: the stiffest zone --------------------------------------------------

    @property
    def gdim(self) -> int:
        """3, or 2 for ``plane="strain"``."""
        return int(self.laws[0].gdim)

    @property
    def rho(self) -> float:
        """The stiffest zone's density (the zones' own densities make the masses)."""
        return float(self.stiffest.rho)

    @property
    def G(self) -> float:
        """The stiffest zone's shear modulus."""
        return float(self.stiffest.G)

    @property
    def stiffest_bulk_modulus(self) -> float:
        """The stiffest zone's."""
        return float(self.stiffest.stiffest_bulk_modulus)

    # -- zones of points and cells ----------------------------------------------------------

    def _inside(self, x: np.ndarray, cells: np.ndarray | None) -> np.ndarray:
        """(zones, n) booleans: which zones hold each point ``x`` (n, 3); a tag zone by the tags
        of ``cells`` (the points' local cells)."""
        n = len(x)
        inside = np.zeros((len(self.laws), n), dtype=bool)
        for k, where in enumerate(self.markers):
            if callable(where):
                hit = np.asarray(where(np.ascontiguousarray(x.T)))
                if hit.shape != (n,) or hit.dtype != bool:
                    raise ValueError(
                        f"MaterialZones: zone {k}'s marker gave {hit.dtype} of shape {hit.shape} "
                        f"for {n} points; it must return n booleans for x of shape (3, n)"
                    )
                inside[k] = hit
            elif cells is None:
                raise ValueError(
                    f"MaterialZones: zone {k} is the cell tag {where}: a point's zone needs its "
                    "cell; with cell tags use particle_mass='row-sum' (the default), or markers"
                )
            else:
                tagged = np.asarray(self.cell_tags.indices)[
                    np.asarray(self.cell_tags.values) == where
                ]
                inside[k] = np.isin(cells, tagged)
        return inside

    def _one_zone(self, x: np.ndarray, inside: np.ndarray) -> np.ndarray:
        count = inside.sum(axis=0)
        for bad, what in ((count == 0, "no zone"), (count > 1, "more than one zone")):
            if bad.any():
                i = int(np.flatnonzero(bad)[0])
                raise ValueError(
                    f"MaterialZones: the point {np.array2string(x[i], precision=6)} (a cell's "
                    f"midpoint or a particle) lies in {what} ({int(bad.sum())} such on this rank); "
                    "make the markers and tags cover every cell of the model exactly once"
                )
        return np.argmax(inside, axis=0).astype(np.int64)

    def zone_of(self, x: np.ndarray) -> np.ndarray:
        """The zone of each point ``x`` (n, gdim or 3), by the markers (local).

        Raises:
            ValueError: a marker gives no boolean array of ``n`` values, a point lies in no
                zone or in two (named by its coordinates), or a zone is a cell tag.
        """
        x = np.asarray(x, dtype=float).reshape(len(x), -1)
        x3 = np.zeros((len(x), 3))
        x3[:, : x.shape[1]] = x
        return self._one_zone(x3, self._inside(x3, None))

    def cell_zones(self, msh: dolfinx.mesh.Mesh) -> np.ndarray:
        """The zone of every local cell of ``msh`` (owned, then ghost: their owner's zone). The
        owned cells' by their midpoints and tags (raised on every rank as :meth:`zone_of`, or
        when a zone holds no cell or the tags are not of the cells); collective."""
        tdim = msh.topology.dim
        imap = msh.topology.index_map(tdim)
        owned = np.arange(imap.size_local, dtype=np.int32)

        def locate() -> np.ndarray:
            if self.cell_tags is not None and self.cell_tags.dim != tdim:
                raise ValueError(
                    f"MaterialZones: cell_tags are of dimension {self.cell_tags.dim}, the mesh's "
                    f"cells of {tdim}; give the cells' MeshTags"
                )
            mid = dolfinx.mesh.compute_midpoints(msh, tdim, owned)
            return self._one_zone(mid, self._inside(mid, owned))

        zone = raise_on_all_ranks(msh.comm, locate)
        counts = msh.comm.allreduce(np.bincount(zone, minlength=len(self.laws)))
        if np.any(counts == 0):  # the same on every rank
            k = int(np.flatnonzero(counts == 0)[0])
            raise ValueError(
                f"MaterialZones: zone {k} ({type(self.laws[k]).__name__}, "
                f"{self.markers[k] if isinstance(self.markers[k], int) else 'a marker'}) holds no "
                "cell of the mesh; check its marker or tag"
            )
        V0 = _compat.scalar_function_space(msh, "DG", 0)  # the ghosts: their owner's zone
        z = dolfinx.fem.Function(V0)
        dofs = _compat.dofmap_array(V0)[:, 0]
        z.x.array[dofs[: len(owned)]] = zone
        z.x.scatter_forward()
        return np.rint(z.x.array[dofs]).astype(np.int64)

    def densities(self) -> np.ndarray:
        """The density of each zone (k,)."""
        return np.array([float(law.rho) for law in self.laws])

    # -- the rate-form law, point by point ----------------------------------------------------

    def initial_state(self, m: int, zone: np.ndarray | None = None) -> dict[str, np.ndarray]:
        """The virgin state of ``m`` points of the given zones (m,) (``None``: zone 0): each
        point its law's virgin arrays, 0 in the arrays its law does not have."""
        zone = np.zeros(m, dtype=np.int64) if zone is None else np.asarray(zone, dtype=np.int64)
        if zone.shape != (m,):
            raise ValueError(f"MaterialZones.initial_state: {zone.shape} zones for {m} points")
        state = {name: np.zeros((m, size)) for name, size in self.state_fields.items()}
        state["zone"][:, 0] = zone
        for k, law in enumerate(self.laws):
            idx = np.flatnonzero(zone == k)
            for name, value in law.initial_state(len(idx)).items():
                state[name][idx] = value
        return state

    def _split(self, state: dict[str, np.ndarray]) -> list[np.ndarray]:
        zone = np.asarray(state["zone"][:, 0]).astype(np.int64)
        return [np.flatnonzero(zone == k) for k in range(len(self.laws))]

    def update(
        self,
        F: np.ndarray,
        dt: float,
        state: dict[str, np.ndarray],
        hoop: np.ndarray | None = None,
    ) -> tuple[np.ndarray, dict[str, np.ndarray]]:
        """``(sigma (m, 3, 3), new state)``: each zone's points by its law's ``update`` (the
        committed ``state`` is never modified)."""
        F = np.asarray(F, dtype=float)
        m = len(F)
        sigma = np.zeros((m, 3, 3))
        new = {name: np.array(value, dtype=float, copy=True) for name, value in state.items()}
        for law, idx in zip(self.laws, self._split(state), strict=True):
            if not idx.size:
                continue
            sub = {name: state[name][idx] for name in law.state_fields}
            s, out = law.update(F[idx], dt, sub, None if hoop is None else hoop[idx])
            sigma[idx] = s
            for name, value in out.items():
                new[name][idx] = value
        return sigma, new

    def zone_wave_speeds(self, state: dict[str, np.ndarray]) -> np.ndarray:
        """Per zone (k,), the largest current dilatational wave speed of its points in
        ``state`` (0 for a zone without points)."""
        speeds = np.zeros(len(self.laws))
        for k, (law, idx) in enumerate(zip(self.laws, self._split(state), strict=True)):
            if idx.size:
                speeds[k] = law.wave_speed({name: state[name][idx] for name in law.state_fields})
        return speeds

    def wave_speed(self, state: dict[str, np.ndarray] | None = None) -> float:
        """The largest dilatational wave speed: of the zones' laws at reference density, or of
        the points of ``state`` at their current one (0 without points)."""
        if state is None:
            return max(float(law.wave_speed()) for law in self.laws)
        return float(self.zone_wave_speeds(state).max())
