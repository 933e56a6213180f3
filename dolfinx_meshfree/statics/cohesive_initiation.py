"""Where a cohesive crack starts in a body without a notch: the stress criterion of issue 24
(the largest principal stress, averaged over a stated radius, reaches ``f_t``), applied to a
linear-elastic solve.

Before the first crack the bulk of the fictitious crack model (Hillerborg, Modéer & Petersson
1976) is linear elastic, so under proportional loading its stress is the linear-elastic solve's
times the load factor ``t``. The crack therefore starts where the averaged largest principal
stress of that solve, ``sigma_1``, is highest, at ``t = f_t / sigma_1``, and runs normal to it.
The average is :class:`~dolfinx_meshfree.CohesiveGrowth`'s (the Gaussian weight ``exp(-r^2 /
(2 l^2))`` over the disc ``r <= 3 l`` in the body: Wells & Sluys 2001, IJNME 50, sec. 4.1), so
that the crack starts by the rule it then grows by.

:func:`initiation_site` searches the particles' cells: their midpoints (a crack inside the body,
with two tips) and the midpoints of their exterior facets (an edge crack: a traction-free edge is
where bending and stress concentrations put the largest stress). Its :meth:`InitiationSite.crack`
is the first, bonded stretch of the crack (``Crack(..., through=True)``: its faces carry the
law); follow the path with :class:`~dolfinx_meshfree.CohesiveGrowth` on it. The FE side of a
coupled model is screened too: where its averaged stress exceeds the particles' largest, the
crack would start where the FE side cannot carry it, and the search is refused, naming the point.
A ``margin`` to the best candidate away from the site says how clear the choice is.

Scope: the *first* crack of a body whose bulk is elastic (the linear solve is its field until
then). A further crack that starts once the first has softened (multiple cracking) is found
during the path, from the bulk's stress at each converged step (:func:`bulk_stress_peak`,
:func:`site_at`; :class:`~dolfinx_meshfree.CrackInitiation`). The switch from a damaging bulk to
a crack (issue 24) is not built.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING

import dolfinx
import numpy as np
import scipy.sparse as sp
from scipy.sparse.csgraph import connected_components
from scipy.spatial import cKDTree

from ..geometry.crack import (
    Crack,
    CrackDomain,
    gathered_segments,
    particle_spacing,
    point_segment_distance,
)
from ..geometry.quadrature import QuadraturePoints, boundary_facets
from ..parallel import raise_on_all_ranks
from ..physics.materials import LinearElastic
from .cohesive_growth import CohesiveGrowth, _inside, _polar_rule

if TYPE_CHECKING:  # annotations only
    from collections.abc import Callable, Sequence

    import numpy.typing as npt
    from mpi4py import MPI

    from ..couplings.base import CoupledSolution
    from ..geometry.patch import ParticlePatch
    from .efg import EFGSolution

__all__ = [
    "REGION_SPACINGS",
    "BulkStrengthWarning",
    "InitiationSite",
    "bulk_stress_peak",
    "bulk_stress_peaks",
    "initiation_site",
    "region_mask",
    "site_at",
]

#: Candidates whose screened stress is highest, averaged exactly (each side of the runner-up's
#: separation): the screen is a coarse average of the cell midpoints' stresses.
_SHORTLIST = 16


class BulkStrengthWarning(UserWarning):
    """The elastic bulk of a cohesive-crack model reached ``f_t`` away from its cracks: a
    further crack would start there, which the model does not follow (:func:`bulk_stress_peak`;
    :attr:`~dolfinx_meshfree.PathResult.bulk_stress`)."""


@dataclass(frozen=True)
class InitiationSite:
    """Where and when the first cohesive crack starts (:func:`initiation_site`).

    Attributes:
        point: (2,) the site: a midpoint of an exterior facet (``on_edge``) or of a cell.
        direction: (2,) unit, normal to the averaged largest principal stress (into the body
            for an edge site).
        stress: the averaged largest principal stress at ``point`` of the solve.
        load_factor: ``f_t / stress``: the factor on the solve's load at which the crack starts.
        on_edge: whether the site lies on the exterior boundary (an edge crack, one tip).
        runner_up: (2,) the best candidate at least ``separation`` from ``point``, or ``None``.
        margin: ``1 - stress(runner_up) / stress``: near 0, another place starts a crack at
            nearly the same load, and which one wins is for the discretisation or the round-off
            to decide (a uniform bar): restrict ``region`` to choose. ``1.0`` without a runner-up.
        spacing: the particle spacing ``h`` of the model.
    """

    point: np.ndarray
    direction: np.ndarray
    stress: float
    load_factor: float
    on_edge: bool
    runner_up: np.ndarray | None
    margin: float
    spacing: float

    def crack(self, lead: float | None = None) -> Crack:
        """The crack's first, bonded stretch (``through=True``: its faces must carry a law):
        from the edge point ``lead`` along :attr:`direction` (an edge crack, one tip), or
        ``lead`` each way from an interior site (two tips). Default ``lead``: ``(ahead + 1)``
        spacings of :class:`~dolfinx_meshfree.CohesiveGrowth`'s default ``ahead``, so that the
        tip is ahead of the faces that soften first. Add it to a model (the ``ParticlePatch``'s
        or ``EFGElasticity``'s ``cracks``), ``model.add_cohesive(crack, law)`` on all its
        segments, then ``follow_path(..., growth=CohesiveGrowth(crack))``."""
        lead = (CohesiveGrowth.ahead + 1.0) * self.spacing if lead is None else lead
        if isinstance(lead, bool) or not (
            isinstance(lead, int | float) and np.isfinite(lead) and lead > 0
        ):
            raise ValueError(f"lead={lead!r} must be a positive length (the bonded stretch)")
        p, d = self.point, self.direction
        start = p if self.on_edge else p - lead * d
        return Crack([start, p + lead * d], through=True)


def initiation_site(
    solution: EFGSolution | CoupledSolution,
    ft: float,
    region: Callable[[np.ndarray], np.ndarray] | None = None,
    radius: float | None = None,
    separation: float | None = None,
) -> InitiationSite:
    """Where the first cohesive crack starts in a linear-elastic ``solution``: the candidate
    (a midpoint of a particle cell or of its exterior facets) of the highest averaged largest
    principal stress (module docstring). Collective; the same on every rank.

    Args:
        solution: a linear-elastic solve (``model.solve()``) under the reference load the path
            will scale (pure EFG or coupled); the body may have cracks (their faces' near field,
            1.5 spacings, is left out of the averages and the candidates).
        ft: the tensile strength (the cohesive law's ``ft``) for the load factor.
        region: ``region(x)`` (m, 2) -> (m,) bool: the candidates allowed (default: all); the
            points are rows, ``x[:, 1] > 40.0`` (not DOLFINx's marker layout).
        radius: the Gaussian averaging length ``l`` (default: :class:`CohesiveGrowth`'s, one
            spacing; give the one the growth will use).
        separation: the least distance of the runner-up from the site (default ``6 l``).

    Returns:
        The :class:`InitiationSite`.

    Raises:
        ValueError: ``ft``, ``radius`` or ``separation`` not positive; no candidate in
            ``region``; no tension anywhere (the load does not start a crack).
    """
    for name, v in (("ft", ft), ("radius", radius), ("separation", separation)):
        if v is None and name != "ft":
            continue
        if isinstance(v, bool) or not (isinstance(v, int | float) and np.isfinite(v) and v > 0):
            raise ValueError(f"initiation_site: {name}={v!r} must be a positive number")
    if region is not None and not callable(region):
        raise TypeError(f"initiation_site: region must be a callable on points, got {region!r}")
    if not isinstance(solution.material, LinearElastic):
        raise ValueError(
            f"initiation_site: the solution's law is {type(solution.material).__name__}, not "
            "LinearElastic: the site is found from a linear-elastic solve (the bulk before the "
            "first crack); solve the model with mf.LinearElastic"
        )
    coupled, domain, cracks = _body(solution)
    if domain is None:
        raise ValueError(
            "initiation_site: the solution does not say where its particles are; pass the "
            "solution of model.solve() (EFGElasticity or CoupledElasticity)"
        )
    comm = domain.comm
    if domain.mesh.geometry.dim != 2:
        raise ValueError(
            f"initiation_site: cracks are 2D; the mesh has gdim={domain.mesh.geometry.dim}"
        )
    h = particle_spacing(domain)
    l_avg = CohesiveGrowth.radius * h if radius is None else float(radius)
    sep = 6.0 * l_avg if separation is None else float(separation)
    clear = CohesiveGrowth.clearance * h

    # the candidates: the particles' (where the crack may start) and the FE side's (checked
    # below)
    x, on_edge, particle, mid, sig_mid = _candidates(solution, domain, coupled)
    keep = np.ones(len(x), dtype=bool)
    if region is not None:
        keep &= region_mask(region, x, comm, "initiation_site: region")
    distance = _CrackDistance(cracks)
    if cracks:
        keep &= distance(x) >= clear
    n_cand = int((keep & particle).sum())

    def check_candidates() -> None:
        if n_cand == 0:
            raise ValueError(
                "initiation_site: no candidate point: region selects none of the particle cells' "
                "midpoints or exterior facets (away from the cracks); widen region"
            )

    raise_on_all_ranks(comm, check_candidates)

    # the screen: a Gaussian average of the stresses at the cell midpoints
    use = np.ones(len(mid), dtype=bool) if not cracks else distance(mid) >= clear
    screened = _screen(x, mid[use], sig_mid[use], l_avg)
    fe = np.flatnonzero(keep & ~particle)
    fe_best = fe[np.argmax(screened[fe])] if fe.size else None
    keep &= particle
    p_best = np.flatnonzero(keep)[np.argmax(screened[keep])]

    def check_fe() -> None:
        if fe_best is not None and screened[fe_best] > screened[p_best]:
            raise ValueError(
                f"initiation_site: the averaged principal stress at "
                f"{x[fe_best].round(6).tolist()} on the FE side ({screened[fe_best]:.6g}, "
                f"screened) exceeds the particles' largest ({screened[p_best]:.6g} at "
                f"{x[p_best].round(6).tolist()}): the crack would start outside the patch, where "
                "the FE side cannot carry it; add the cells around that point to the patch (or "
                "exclude it with region)"
            )

    raise_on_all_ranks(comm, check_fe)
    order = np.flatnonzero(keep)[np.argsort(-screened[keep], kind="stable")]
    first = order[:_SHORTLIST]
    sigma = _averaged(solution, x[first], l_avg, domain, distance if cracks else None, clear)
    s1 = np.linalg.eigvalsh(0.5 * (sigma + sigma.transpose(0, 2, 1)))[:, -1]
    k = int(np.argmax(s1))
    best, s_best = first[k], float(s1[k])

    def check_tension() -> None:
        if not s_best > 0.0:
            raise ValueError(
                f"initiation_site: the largest averaged principal stress is {s_best:.6g} <= 0 at "
                f"{x[best].round(6).tolist()}: the load compresses the whole region, no crack "
                "starts under it; check the load's sign"
            )

    raise_on_all_ranks(comm, check_tension)
    # the runner-up: the best of the screen's first candidates `separation` or more from the
    # site; one that averages higher (the screen ranked them otherwise) is the site instead
    far = order[np.linalg.norm(x[order] - x[best], axis=1) >= sep][:_SHORTLIST]
    if far.size:
        sig_far = _averaged(solution, x[far], l_avg, domain, distance if cracks else None, clear)
        first, sigma = np.concatenate([first, far]), np.concatenate([sigma, sig_far])
        s1 = np.linalg.eigvalsh(0.5 * (sigma + sigma.transpose(0, 2, 1)))[:, -1]
        k = int(np.argmax(s1))
        best, s_best = first[k], float(s1[k])
    apart = np.linalg.norm(x[first] - x[best], axis=1) >= sep
    runner, margin = None, 1.0
    if apart.any():
        j = int(np.flatnonzero(apart)[np.argmax(s1[apart])])
        runner, margin = x[first[j]].copy(), float(1.0 - s1[j] / s_best)
    return InitiationSite(
        point=x[best].copy(),
        direction=_crack_direction(sigma[k], x[best], bool(on_edge[best]), domain, h),
        stress=s_best,
        load_factor=float(ft) / s_best,
        on_edge=bool(on_edge[best]),
        runner_up=runner,
        margin=margin,
        spacing=h,
    )


def site_at(
    solution: EFGSolution | CoupledSolution,
    point: npt.ArrayLike,
    ft: float,
    material: LinearElastic | None = None,
) -> InitiationSite:
    """The :class:`InitiationSite` of a crack that starts at ``point`` (a candidate of
    :func:`bulk_stress_peak`: a midpoint of a cell or of an exterior facet) in ``solution``:
    normal to the averaged largest principal stress there (:func:`initiation_site`'s average,
    the faces' near field of the solution's cracks left out), into the body from an edge
    (collective; ``material``: the bulk's law, default the solution's). ``runner_up`` is
    ``None``: nothing else is searched."""
    coupled, domain, cracks = _body(solution)
    h = particle_spacing(domain)
    x = np.asarray(point, dtype=float).reshape(2)
    facets = boundary_facets(domain.mesh) if coupled else domain.exterior_facets
    edge = gathered_segments(domain, facets)
    on_edge = bool(point_segment_distance(x[None], edge[:, 0], edge[:, 1]).min() <= 1e-9 * h)
    distance = _CrackDistance(cracks) if cracks else None
    clear = CohesiveGrowth.clearance * h
    length = CohesiveGrowth.radius * h
    sigma = _averaged(solution, x[None], length, domain, distance, clear, material)[0]
    stress = float(np.linalg.eigvalsh(0.5 * (sigma + sigma.T))[-1])
    return InitiationSite(
        point=x.copy(),
        direction=_crack_direction(sigma, x, on_edge, domain, h),
        stress=stress,
        load_factor=float(ft) / stress if stress > 0.0 else np.inf,
        on_edge=on_edge,
        runner_up=None,
        margin=1.0,
        spacing=h,
    )


def _crack_direction(
    sigma: np.ndarray, x: np.ndarray, on_edge: bool, domain: ParticlePatch | CrackDomain, h: float
) -> np.ndarray:
    """The unit direction (2,) normal to the largest principal stress of ``sigma`` (2, 2) at
    ``x``: into the body from an edge point, else upwards (else rightwards), so that the same
    crack comes out of every run (collective)."""
    _, vecs = np.linalg.eigh(0.5 * (sigma + sigma.T))
    n = vecs[:, -1]
    d = np.array([-n[1], n[0]])
    if on_edge:  # into the body
        probe = x + 0.25 * h * np.stack([d, -d])
        inside = _inside(domain, probe)
        if not inside[0] and inside[1]:
            d = -d
    elif d[1] < -1e-12 or (abs(d[1]) <= 1e-12 and d[0] < 0.0):
        d = -d  # a fixed orientation (upwards, else rightwards): the same crack every run
    return d


#: Candidates closer than this many particle spacings are neighbours in a region of tension
#: (:func:`bulk_stress_peaks`' ``exclude``): the candidates (cell and facet midpoints) lie half a
#: spacing to a spacing apart.
REGION_SPACINGS = 1.5


def bulk_stress_peak(
    solution: EFGSolution | CoupledSolution,
    clearance: float | None = None,
    material: LinearElastic | None = None,
) -> tuple[np.ndarray, float]:
    """The largest averaged largest principal stress of ``solution`` away from its cracks (by
    ``clearance``, default three spacings: the process zone and the tips' fields left out),
    FE side included, and where: the screen of :func:`initiation_site` (the Gaussian average of
    the cells' midpoint stresses, length one spacing) over the midpoints of every cell and
    exterior facet (``material``: the bulk's law, default the solution's). Above ``f_t`` a crack
    would start there (collective)."""
    return bulk_stress_peaks(solution, clearance, material)[0]


def bulk_stress_peaks(
    solution: EFGSolution | CoupledSolution,
    clearance: float | None = None,
    material: LinearElastic | None = None,
    exclude: Sequence[np.ndarray] = (),
    above: float = np.inf,
    region: Callable[[np.ndarray], np.ndarray] | None = None,
) -> tuple[tuple[np.ndarray | None, float], tuple[np.ndarray | None, float]]:
    """From one screen of the stresses: ``(the bulk's peak, the peak of the candidates
    allowed)``, the first :func:`bulk_stress_peak`'s (collective).

    ``exclude``: points (sites that could not start a crack) whose regions of tension are left
    out: the candidate nearest each point and, when it is above ``above`` (``f_t``), the
    candidates above ``above`` joined to it through neighbours :data:`REGION_SPACINGS`
    spacings apart. So the second peak is that of another region, never a site beside a
    refused one, where a crack would stand for the refused one, displaced. ``region(x)`` (m, 2)
    -> (m,) bool: the candidates allowed (:class:`~dolfinx_meshfree.CrackInitiation`'s
    ``region``). The second is ``(None, -inf)`` when no candidate is left."""
    coupled, domain, cracks = _body(solution)
    h = particle_spacing(domain)
    clear = 3.0 * h if clearance is None else float(clearance)
    x, _, _, mid, sig_mid = _candidates(solution, domain, coupled, material)
    distance = _CrackDistance(cracks)
    use = distance(mid) >= CohesiveGrowth.clearance * h if cracks else slice(None)
    screened = _screen(x, mid[use], sig_mid[use], CohesiveGrowth.radius * h)
    if cracks:
        screened[distance(x) < clear] = -np.inf
    k = int(np.argmax(screened))
    overall = x[k].copy(), float(screened[k])
    if not len(exclude) and region is None:
        return overall, overall
    allowed = screened.copy()
    if len(exclude):
        allowed[_regions(x, screened, exclude, above, REGION_SPACINGS * h)] = -np.inf
    if region is not None:
        allowed[~region_mask(region, x, domain.comm, "CrackInitiation.region")] = -np.inf
    k = int(np.argmax(allowed))
    if not np.isfinite(allowed[k]):
        return overall, (None, -np.inf)
    return overall, (x[k].copy(), float(allowed[k]))


def region_mask(
    region: Callable[[np.ndarray], np.ndarray], x: np.ndarray, comm: MPI.Comm, name: str
) -> np.ndarray:
    """``region(x)`` on the candidates ``x`` (m, 2) as a bool mask (m,), refused on every rank
    (naming ``name``) when it has another shape (collective)."""
    mask = np.asarray(region(x.copy()), dtype=bool).reshape(-1)

    def check() -> None:
        if mask.shape != (len(x),):
            raise ValueError(
                f"{name} returned shape {mask.shape} for {len(x)} points; it gets the points as "
                "rows (m, 2), x[:, 0] and x[:, 1], not as DOLFINx markers do (x[0], x[1]), and "
                "must return one bool per point"
            )

    raise_on_all_ranks(comm, check)
    return mask


def _regions(
    x: np.ndarray, stress: np.ndarray, seeds: Sequence[np.ndarray], above: float, reach: float
) -> np.ndarray:
    """Whether each candidate (m,) lies in the region of tension of one of ``seeds``: the
    candidate nearest a seed and, when it is above ``above``, the candidates above ``above``
    connected to it through pairs closer than ``reach`` (local)."""
    tree = cKDTree(x)
    start = tree.query(np.asarray(seeds, dtype=float).reshape(len(seeds), -1))[1]
    hot = stress > above
    pairs = tree.query_pairs(reach, output_type="ndarray")
    pairs = pairs[hot[pairs[:, 0]] & hot[pairs[:, 1]]]
    graph = sp.coo_matrix((np.ones(len(pairs)), (pairs[:, 0], pairs[:, 1])), shape=(len(x), len(x)))
    _, label = connected_components(graph, directed=False)
    out = np.isin(label, label[start[hot[start]]]) & hot
    out[start] = True
    return out


class _CrackDistance:
    """Distance (m,) of points to the nearest of ``cracks`` (a Crack's ``distance``)."""

    def __init__(self, cracks: Sequence[Crack]) -> None:
        self.cracks = list(cracks)

    def __call__(self, x: np.ndarray) -> np.ndarray:
        d = np.full(len(x), np.inf)
        for c in self.cracks:
            d = np.minimum(d, c.distance(x))
        return d


def _body(
    solution: EFGSolution | CoupledSolution,
) -> tuple[bool, ParticlePatch | CrackDomain | None, list[Crack]]:
    """Whether ``solution`` is coupled, where its particles lie (a pure EFG model without a
    crack: from its particles; ``None`` when the solution does not say) and its cracks."""
    coupled = hasattr(solution, "patch")
    domain = solution.patch if coupled else solution.domain
    if domain is None and getattr(solution, "particles", None) is not None:
        domain = CrackDomain.from_particles(solution.particles)
    return coupled, domain, list(solution.patch.cracks if coupled else solution.cracks)


def _candidates(
    solution: EFGSolution | CoupledSolution,
    domain: ParticlePatch | CrackDomain,
    coupled: bool,
    material: LinearElastic | None = None,
) -> tuple[np.ndarray, ...]:
    """The candidate sites, replicated and ordered by their coordinates (equal candidates of a
    symmetric body are then chosen alike on any partition): the midpoints (m, 2) of the cells
    and of the exterior facets of the whole body, whether each is on an edge and whether in the
    particles; and the cells' midpoints and stresses (:func:`_cell_midpoint_stresses`)
    (collective)."""
    mid, sig_mid, in_particles = _cell_midpoint_stresses(solution, domain, coupled, material)
    facets = boundary_facets(domain.mesh) if coupled else domain.exterior_facets
    edge = gathered_segments(domain, facets).mean(axis=1)
    edge_particles = np.concatenate(domain.comm.allgather(np.isin(facets, domain.exterior_facets)))
    x = np.concatenate([mid, edge])
    on_edge = np.arange(len(x)) >= len(mid)
    particle = np.concatenate([in_particles, edge_particles.astype(bool)])
    by = np.lexsort((x[:, 1], x[:, 0]))
    return x[by], on_edge[by], particle[by], mid, sig_mid


def _cell_midpoint_stresses(
    solution: EFGSolution | CoupledSolution,
    domain: ParticlePatch | CrackDomain,
    coupled: bool,
    material: LinearElastic | None = None,
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The midpoints (m, 2) of the owned cells (pure EFG: the particles' cells; coupled: every
    cell), the solution's stress (m, 2, 2) there (FE in FE cells, particles in patch cells) and
    whether each is a particle cell, gathered from every rank (collective)."""
    msh = domain.mesh
    n_own = msh.topology.index_map(2).size_local
    if coupled:
        cells = np.arange(n_own, dtype=np.int32)
        particle = np.asarray(solution.patch.in_patch[:n_own], dtype=bool)
    else:
        cells = domain.cells[domain.cells < n_own].astype(np.int32)
        particle = np.ones(len(cells), dtype=bool)
    mid = dolfinx.mesh.compute_midpoints(msh, 2, cells)[:, :2]
    if not len(mid):
        grad = np.zeros((0, 2, 2))
    elif coupled:
        q = QuadraturePoints(mid, np.ones(len(mid)), cells)
        grad = solution.evaluate_at_quadrature(q)[1]
    else:
        grad = solution.mls.tabulate(mid).gradient(solution.coefficients)
    law = solution.material if material is None else material
    sig = law.stress(grad) if len(mid) else grad
    comm = domain.comm
    return (
        np.concatenate(comm.allgather(mid)).reshape(-1, 2),
        np.concatenate(comm.allgather(sig)).reshape(-1, 2, 2),
        np.concatenate(comm.allgather(particle)).astype(bool),
    )


def _screen(x: np.ndarray, y: np.ndarray, sig: np.ndarray, length: float) -> np.ndarray:
    """The largest principal stress (m,) of the Gaussian average (length ``length``, disc of
    ``3 length``) of the stresses ``sig`` at the points ``y`` about each of ``x`` (local)."""
    out = np.full(len(x), -np.inf)
    if not len(x) or not len(y):
        return out
    near = cKDTree(y).query_ball_point(x, 3.0 * length)
    counts = np.fromiter((len(n) for n in near), dtype=np.int64, count=len(x))
    rows = np.repeat(np.arange(len(x)), counts)
    cols = np.fromiter((j for n in near for j in n), dtype=np.int64, count=int(counts.sum()))
    w = np.exp(-0.5 * (np.linalg.norm(y[cols] - x[rows], axis=1) / length) ** 2)
    s = np.zeros((len(x), 2, 2))
    np.add.at(s, rows, w[:, None, None] * sig[cols])
    total = np.bincount(rows, weights=w, minlength=len(x))
    some = counts > 0
    s = s[some] / total[some, None, None]
    out[some] = np.linalg.eigvalsh(0.5 * (s + s.transpose(0, 2, 1)))[:, -1]
    return out


def _averaged(
    solution: EFGSolution | CoupledSolution,
    centres: np.ndarray,
    length: float,
    domain: ParticlePatch | CrackDomain,
    cracks: _CrackDistance | None,
    clearance: float,
    material: LinearElastic | None = None,
) -> np.ndarray:
    """The averaged stress (k, 2, 2) about each of ``centres`` by the rule of
    :func:`~dolfinx_meshfree.statics.cohesive_growth.principal_direction` (collective: the
    points in the domain; ``material``: default the solution's)."""
    xs, ws = zip(*(_polar_rule(c, length) for c in centres), strict=True)
    owner = np.repeat(np.arange(len(centres)), [len(p) for p in xs])
    x, w = np.concatenate(xs), np.concatenate(ws)
    keep = np.ones(len(x), dtype=bool) if cracks is None else cracks(x) >= clearance
    keep[keep] = _inside(domain, x[keep])
    x, w, owner = x[keep], w[keep], owner[keep]
    law = solution.material if material is None else material
    sig = law.stress(solution.mls.tabulate(x).gradient(solution.coefficients))
    out = np.zeros((len(centres), 2, 2))
    np.add.at(out, owner, w[:, None, None] * sig)
    return out / np.bincount(owner, weights=w, minlength=len(centres))[:, None, None]
