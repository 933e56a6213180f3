# # The Kalthoff–Winkler experiment: dynamic crack growth under impact (reduced)
#
# Belytschko et al. 1995, sec. 5.2.2, Fig. 10–12; issue 11, item 5. The half plate (the
# specimen's symmetry plane ``y = 0``, ``u_y = 0`` there): 100 mm x 100 mm, a notch from the
# impacted edge ``x = 0`` to ``x = 50`` mm at ``y = 25`` mm, the impact on ``x = 0``,
# ``0 < y < 25`` mm (between the notches), maraging steel 18Ni1900 (E = 190 GPa, nu = 0.30,
# rho = 8000 kg/m^3, K_Ic = 68 MPa sqrt(m), plane strain). The crack grows by
# :class:`~dolfinx_meshfree.dynamics.DynamicCrackGrowth`: K_I, K_II by the dynamic interaction
# integral (inertia term; no crack-velocity terms), initiation and direction by the maximum
# hoop stress, the tip at 0.15 c_s (the paper), straight segments of 3.5 spacings, the model
# rebuilt after each.
#
# The impact (``--impact``): ``velocity`` (default, the paper's model of the projectile): the
# impacted edge driven at ``u_x' = v0`` (FE nodes strongly, particles of pure EFG by their facet
# multipliers: ``fixed_facets`` triples, :mod:`dolfinx_meshfree.dynamics.prescribed`), ramped
# over ``--rise`` (1 us); ``traction``: the traction ``rho c_d v0``, the load whose plane wave
# gives the edge the velocity ``v0``.
#
# Crack-face contact (``--contact F``, default 10; 0 turns it off): the faces of the crack (the
# notch in pure EFG, its part inside the particle box in the coupled models) are kept from
# interpenetrating by a one-sided penalty ``k = F E / h``
# (:class:`~dolfinx_meshfree.dynamics.CrackContact`). The impact presses the notch's faces
# together; without contact they interpenetrate, K_I at initiation is about -0.4 K_II and the
# hoop-stress criterion turns the crack to about 78 deg instead of the 70.5 deg of pure mode
# II. The penalty lowers the stable step to about 0.3x (about 3x the steps).
#
# Energy bookkeeping (printed, ``energy`` in the JSON): kinetic + strain + fracture energy
# against the external work (the work of the impact: the driving reaction or the traction),
# with the fracture energy either the strain energy each extension releases (the model's own
# account) or G x crack area, ``G = (1 - nu^2) / E (K_I^2 + K_II^2)`` at each extension times
# the segment (plane strain, per unit thickness); the drift is the largest change of
# ``discrete energy + fracture - work`` over the run, relative to the largest kinetic + strain
# energy. With efg among several methods, the SIF histories of the others before initiation
# are compared with efg's (``sif_difference``: the largest difference relative to max |K_II|).
#
# Reductions (this is the coarse version that runs in about a minute):
#
# * The notch: the FE side cannot carry a crack, so in the coupled models the notch is a slot of
#   one cell cut out of the mesh (``y`` from 25 mm to 25 mm + h) up to the particle box
#   (``x = 50 mm - 6h``), and a crack from the slot's end face (its mouth) to the notch tip
#   ``(50 mm, 25 mm + h/2)``; in pure EFG the whole notch is a crack from ``(0, 25 mm + h/2)``
#   (a slot one spacing wide would not separate the MLS of its two faces). The crack runs half
#   a spacing off the particle rows. Bridging's patch reaches ``OVERLAP`` cells further out, so
#   that its band (whose FE field no crack cuts) lies beyond the slot's end and the crack is the
#   other couplings' (a crack through the band is refused: the FE field would bond its faces).
# * The MLS weight: the package's quartic spline (``dilation`` 2), not the paper's Gaussian.
# * The PNG (the particles, the particle box whose border is the FE interface, the notch and
#   the path; K_I(t), K_II(t)) needs matplotlib. ``--xdmf P``: every ``--xdmf-every`` checks
#   the FE fields (``P_<method>_fe.xdmf``), the particle cloud with its displacement and
#   velocity (``P_<method>_particles.xdmf``, :class:`~dolfinx_meshfree.io.DynamicsWriter`) and
#   the crack polyline (``P_<method>_crack.xdmf``, :class:`~dolfinx_meshfree.output.
#   CloudSeriesWriter`).
#
# Methods: ``efg`` (particles everywhere) and the couplings of ``CRACK_COUPLINGS``
# (``lagrange``, ``edge-to-edge``, ``bridging``) with the particles in the box
# ``x >= 50 mm - 6h``, ``y >= 25 mm - 6h`` around the notch tip and the expected path, FE
# elsewhere. Printed and in the JSON: the kink angle of the first segment (counterclockwise from
# the notch; target 70 +- 3 deg), the mean angle of the path, K_I(t), K_II(t), the timings.
#
# ``--adaptive-patch K`` (issue 25): each coupled method runs again on a patch that starts as the
# cells within K spacings of the notch tip, beyond the slot (which then ends K spacings behind
# the tip), and grows K spacings about the running tip (``mf.NearTips(K, region=...)``). The
# cells it takes are converted into particles during the run: the state is carried over, with
# mass and momentum conserved (``mf.dynamics.DynamicCrackGrowth(..., adapt=)``,
# ``dynamics/patch_conversion.py``). A table compares the fixed and adaptive patches: kink,
# mean angle, path deviation from the fixed box in spacings, K before initiation against efg,
# particles, conversions and time relative to efg. JSON adds ``conversions`` (per event: mass
# and momentum errors, the energy change), ``particles_final``, ``mass_error``,
# ``momentum_error``, ``momentum_reaction``, ``momentum_correction``, ``energy_change`` and
# ``path_deviation``. Every coupling converts (master-slave refuses crack-face contact).
# Measured at the paper's 101 nodes and 80 us with K = 10: kink 70.02-70.77 deg, mean
# 65.9-70.3 deg, path within 0.84 spacings of the fixed box's; K_II before initiation off efg
# by 4.4 / 4.2 % (lagrange / edge-to-edge; the fixed box 7.4 / 8.3 %, its slot ending 6
# spacings behind the tip), 8.7 / 9.6 % (ramp / ramp-cubic; box 10.6 / 11.7 %), 14.2 %
# (bridging; box 20.9 %); about 1,130-1,330 particles (the box 4,674); 0.29-0.38x efg's time
# in two runs (the box 0.41-0.75x; issue 25's target 0.3x, met by lagrange and edge-to-edge in
# one run of the two), when every extension rebuilt the model with crack-face contact. Those
# times are PETSc's product; with the compiled products (the default with numba) every run is
# faster and the ratio higher: EFG 11.7 s against 15.5 s, lagrange and edge-to-edge
# 0.35-0.38x (their boxes 0.56-0.58x), with the same kink, path and K to the printed digits.
# The local update now carries the contact (``--update local``, the default): EFG 6.1 s
# against 12.1 s with ``--update full`` in the same session, the boxes 4.1 s (0.68x), the
# adaptive patches 4.1 s (0.67-0.68x: their conversions still rebuild); the paths the same to
# 0.045 spacings, the amplified round-off of the two updates (``docs/guide/cracks.md``).
#
#     python demos/kalthoff_winkler.py --method lagrange efg --nodes 41 --t-end 40e-6 --json kw.json

from __future__ import annotations

import argparse
import functools
import json
import sys
import time

import dolfinx_meshfree as mf
from dolfinx_meshfree import _compat
from dolfinx_meshfree.dynamics import CrackContact, DynamicCrackGrowth
from dolfinx_meshfree.io import DynamicsWriter
from dolfinx_meshfree.output import CloudSeriesWriter

import dolfinx
import numpy as np
from mpi4py import MPI

L = 0.1  # the half plate's side (m)
NOTCH_Y, NOTCH_A = 0.025, 0.05  # the notch: from x = 0 to x = A at y = 25 mm
V0 = 16.5  # impact velocity (m/s)
K_IC = 68e6  # Pa sqrt(m)
MATERIAL = mf.LinearElastic(190e9, 0.30, plane="strain", rho=8000.0)
CS = float(np.sqrt(MATERIAL.mu / MATERIAL.rho))
#: The tip speed (the paper: 0.15 c_s), the segment and the domain radii (in spacings).
SPEED, SEGMENT, RADII = 0.15 * CS, 3.5, (2.0, 3.0)
#: The particle box starts this many spacings behind and below the notch tip.
BOX = 6.0
#: Bridging's band (cell layers; the package's default), added to its particle box.
OVERLAP = 2
#: The rise time of the prescribed impact velocity (s).
RISE = 1e-6
IMPACTS = ("velocity", "traction")


def geometry(nodes: int, comm=MPI.COMM_WORLD, slot: bool = True, box: float = BOX):
    """The mesh with the notch slot (``slot``: else the plate, the notch being all crack), the
    spacing h, the slot's end (0 without) and the crack's y."""
    n = nodes - 1
    h = L / n
    full = dolfinx.mesh.create_rectangle(
        comm, [np.array([0.0, 0.0]), np.array([L, L])], [n, n],
        dolfinx.mesh.CellType.quadrilateral,
    )  # fmt: skip
    mid = _cell_midpoints(full)
    slot_end = NOTCH_A - box * h if slot else 0.0
    if not slot:
        return full, h, slot_end, NOTCH_Y + 0.5 * h
    in_slot = (mid[:, 0] < slot_end) & (mid[:, 1] > NOTCH_Y) & (mid[:, 1] < NOTCH_Y + h)
    keep = np.flatnonzero(~in_slot).astype(np.int32)
    msh = dolfinx.mesh.create_submesh(full, 2, keep)[0]
    # a submesh has no ghost cells in DOLFINx 0.11, which a particle patch on several ranks
    # needs: the same cells redistributed with facet ghosts (and equal cells per rank)
    msh = mf.balanced_mesh(msh, lambda x: np.ones(x.shape[1]), ghosted=True)
    return msh, h, slot_end, NOTCH_Y + 0.5 * h


def ahead_of_slot(k: float, slot_end: float) -> mf.NearTips:
    """``mf.NearTips(k)`` in the cells beyond the slot's end. Particles on both sides of the
    one-cell slot would see each other across it (the MLS knows cracks, not the gaps of the
    mesh): with the patch reaching 6 spacings behind the slot's end, K_II before initiation was
    22 % of max |K_II| off pure EFG's at 41 nodes, against 7 % without."""
    return mf.NearTips(k, region=lambda x: x[:, 0] > slot_end)


def particle_box(method: str, box: float) -> float:
    """How many spacings behind and below the notch tip a coupled model's particles start:
    ``box``, and for bridging ``OVERLAP`` more, so that its band lies beyond the slot's end."""
    return box + (OVERLAP if method == "bridging" else 0)


def _cell_midpoints(msh) -> np.ndarray:
    n = msh.topology.index_map(2).size_local
    return msh.geometry.x[_compat.geometry_dofmap(msh)[:n], :2].mean(axis=1)


def builder(
    method: str,
    msh,
    h: float,
    impact: str = "velocity",
    rise: float = RISE,
    box: float = BOX,
    contact: CrackContact | None = None,
    quadrature: mf.AdaptiveQuadrature | None = None,
):
    """``build(crack) -> ExplicitDynamics``: the model with the crack, the impact (``velocity``:
    the edge driven at ``v0``, ramped over ``rise``; ``traction``: ``rho c_d v0``), the
    symmetry plane and the crack faces' ``contact`` (none if ``None``); ``quadrature``: the
    particle cells' ``mf.AdaptiveQuadrature`` (``None``: the uniform rule)."""
    if impact not in IMPACTS:
        raise ValueError(f"impact={impact!r} is not known; use one of {IMPACTS}")
    edge = mf.boundary_facets(msh, lambda x: np.isclose(x[0], 0.0) & (x[1] <= NOTCH_Y + 1e-12))
    symmetry = mf.boundary_facets(msh, lambda x: np.isclose(x[1], 0.0))
    fixed = [(symmetry, (1,))]
    if impact == "velocity":  # the paper's model of the projectile
        fixed.append((edge, (0,), lambda t: V0 * min(t / rise, 1.0) if rise > 0 else V0))
    sigma = MATERIAL.rho * MATERIAL.wave_speed() * V0  # the plane wave of edge velocity v0
    mid = _cell_midpoints(msh)
    reach = particle_box(method, box)
    in_box = (mid[:, 0] > NOTCH_A - reach * h) & (mid[:, 1] > NOTCH_Y - reach * h)

    def build(crack: mf.Crack, cells=None) -> mf.ExplicitDynamics:
        """The model; ``cells``: the patch's cells (an adaptive patch), else the box."""
        if method == "efg":
            P = mf.ParticleSet.from_cells(msh, h)
            dyn = mf.ExplicitDynamics.efg(
                P, MATERIAL, cracks=[crack], fixed_facets=fixed, crack_contact=contact,
                quadrature=quadrature,
            )  # fmt: skip
        else:
            V = _compat.vector_function_space(msh)
            chosen = np.flatnonzero(in_box) if cells is None else cells
            patch = mf.ParticlePatch(msh, chosen, h, cracks=[crack], quadrature=quadrature)
            band = {"overlap": OVERLAP} if method == "bridging" else {}
            prob = mf.CoupledElasticity(V, patch, MATERIAL, coupling=method, **band)
            dyn = mf.ExplicitDynamics.coupled(prob, fixed_facets=fixed, crack_contact=contact)
        if impact == "traction":
            dyn.add_traction(edge, lambda x, n: np.stack([np.full(len(x), sigma), 0 * x[:, 0]], 1))
        return dyn

    return build


def energy_balance(growth: DynamicCrackGrowth, segment: float) -> dict:
    """Kinetic + strain + fracture energy against the external work (J per m of thickness).

    The work: the loads' and the constraint forces' (the reaction of a prescribed velocity on
    FE nodes is an external force, on particles a constraint force; the interface's net work
    is zero). The fracture energy: the strain energy released by each extension (the model's
    account), and G x crack area with ``G = (1 - nu^2) / E (K_I^2 + K_II^2)`` at each
    extension. The drift: ``max_n |B_n - B_0| / max_n (kinetic + strain)`` with
    ``B = discrete energy + fracture - work``.
    """
    records = growth.model.stepper.records
    nu, E = MATERIAL.nu, MATERIAL.E
    ext = [c for c in growth.history if c.extended]
    g_area = [(c.time, (1 - nu**2) / E * (c.K_I**2 + c.K_II**2) * segment) for c in ext]
    released = list(growth.released)

    def fracture(events: list, i: int) -> float:
        """The events up to record i (a record at an extension's time counts its energy if it
        follows another record at that time: the first is the old model's, before it)."""
        r, prev = records[i], records[i - 1] if i else None
        after = prev is not None and np.isclose(prev.time, r.time, rtol=1e-12, atol=0)
        return sum(
            e for t, e in events
            if t < r.time * (1 - 1e-12) or (after and np.isclose(t, r.time, rtol=1e-12, atol=0))
        )  # fmt: skip

    work = [r.external + r.constraint for r in records]
    scale = max(max(r.kinetic + r.internal for r in records), 1e-300)
    drifts = {}
    for key, events in (("released", released), ("G_area", g_area)):
        b = [r.discrete + fracture(events, i) - work[i] for i, r in enumerate(records)]
        drifts[key] = max(abs(x - b[0]) for x in b) / scale
    last = records[-1]
    return {
        "time": last.time,
        "kinetic": last.kinetic,
        "strain": last.internal,
        "fracture_released": sum(e for _, e in released),
        "fracture_G_area": sum(e for _, e in g_area),
        "external_work": work[-1],
        "drift_released": drifts["released"],
        "drift_G_area": drifts["G_area"],
        "history": [
            [r.time, r.kinetic, r.internal, fracture(released, i), work[i]]
            for i, r in enumerate(records)
        ],
    }


def xdmf_output(growth: DynamicCrackGrowth, prefix: str, every: int) -> tuple:
    """Write the FE fields, the particle cloud and the crack polyline after every ``every``
    checks (and the last): wraps ``growth.check``. Returns the writers (close them)."""
    fields = DynamicsWriter(prefix, growth.model, energy=False)
    crack = CloudSeriesWriter(f"{prefix}_crack.xdmf", growth.model.comm, "crack")
    check = growth.check

    def write() -> None:
        fields.dynamics = growth.model  # the same mesh and particles after a rebuild
        fields.write()
        pts = growth.crack.points
        seg = np.stack([np.arange(len(pts) - 1), np.arange(1, len(pts))], axis=1)
        crack.write(growth.model.time, pts, segments=seg)

    def checked():
        rec = check()
        if (len(growth.history) - 1) % every == 0:
            write()
        return rec

    growth.check = checked
    return fields, crack, write


def run(
    method: str,
    nodes: int,
    t_end: float,
    check_every: int = 5,
    comm=MPI.COMM_WORLD,
    impact: str = "velocity",
    rise: float = RISE,
    xdmf: str | None = None,
    xdmf_every: int = 5,
    dt: float | None = None,
    box: float = BOX,
    contact: CrackContact | None = None,
    quadrature=None,
    update: str = "local",
    adaptive: float | None = None,
):
    """One run: the growth history, the path, the energies and the timings (a JSON-ready
    dict); ``contact``: the crack faces' :class:`~dolfinx_meshfree.dynamics.CrackContact`
    (``None``: the faces may interpenetrate); ``quadrature(h)``, if given, returns the
    particle cells' ``mf.AdaptiveQuadrature``; ``update``: ``"local"`` (re-integrate the cells
    near each new segment) or ``"full"`` (rebuild the model after each extension);
    ``adaptive``: K, the patch starts as the cells within K spacings of the notch tip and
    within min(K, ``BOX``) spacings of the notch's part in the particles (the slot ending
    min(K, ``BOX``) spacings behind the tip) and grows K spacings about the tip
    (``mf.NearTips(K)``, the state converted at each growth)."""
    tic = time.perf_counter()
    if adaptive is not None:  # the slot ends K spacings behind the tip
        box = float(adaptive)
    msh, h, slot_end, yc = geometry(nodes, comm, slot=method != "efg", box=box)
    reach = particle_box(method, box)  # the particle box's corner
    crack = mf.Crack([[slot_end, yc], [NOTCH_A, yc]])
    build = builder(method, msh, h, impact, rise, box, contact, quadrature and quadrature(h))
    adapt = None
    if adaptive is not None:  # the first model: the cells near the tip, ahead of the slot
        # (bridging: OVERLAP more, its band over the slot's end, as its box)
        adapt = ahead_of_slot(reach, slot_end - (reach - box) * h)
        build = functools.partial(build, cells=adapt.cells(msh, crack.points[-1], h))
    growth = DynamicCrackGrowth(
        build, crack, K_Ic=K_IC, speed=SPEED,
        segment=SEGMENT * h, check_every=check_every, radius=np.asarray(RADII) * h, dt=dt,
        update=update, adapt=adapt,
    )  # fmt: skip
    setup = time.perf_counter() - tic
    writers = xdmf_output(growth, f"{xdmf}_{method}", xdmf_every) if xdmf else None
    growth.run(t_end)
    if writers is not None:
        if (len(growth.history) - 1) % xdmf_every:
            writers[2]()  # the final state
        writers[0].close()
    total = time.perf_counter() - tic
    path = growth.path
    ext = [c for c in growth.history if c.extended]
    kink = float(np.degrees(ext[0].theta)) if ext else None
    d = path[-1] - path[0]
    mean = float(np.degrees(np.arctan2(d[1], d[0]))) if len(path) > 1 else None
    tm = growth.timings
    return {
        "method": method + ("+adaptive" if adaptive is not None else ""),
        "impact": impact,
        "update": update,
        "local_updates": growth.timings["local"],
        "contact": None if contact is None else contact.factor,
        "nodes": nodes,
        "h": h,
        "dofs": growth.model.num_dofs(),
        "path": (path * 1e3).tolist(),
        "kink_angle_deg": kink,
        "mean_angle_deg": mean,
        "initiation_time": growth.initiation.time if growth.initiation else None,
        "initiation_angle_deg": (
            float(np.degrees(growth.initiation.theta)) if growth.initiation else None
        ),
        "extensions": len(ext),
        "KI_history": growth.KI_history(),
        "KII_history": growth.KII_history(),
        "steps": growth.model.step,
        "rebuilds": tm["rebuilds"],
        "time_setup": setup,
        "time_steps": tm["steps"],
        "time_sifs": tm["sifs"],
        "time_crack": tm["rebuild"],
        "time_total": total,
        "per_step": tm["per_step"],
        "adaptive_patch": adaptive,
        "conversions": [c.as_dict() for c in growth.conversions],
        "particles_final": growth.model.particles.num_particles,
        "mass_error": max((c.mass_error for c in growth.conversions), default=None),
        "momentum_error": max((c.momentum_error for c in growth.conversions), default=None),
        "momentum_reaction": max((c.momentum_reaction for c in growth.conversions), default=None),
        "momentum_correction": max(
            (c.momentum_correction for c in growth.conversions), default=None
        ),
        "energy_change": sum(c.energy_change for c in growth.conversions),
        "released_energy": [[t, e] for t, e in growth.released],
        "energy": energy_balance(growth, SEGMENT * h),
        "checks": [c.as_dict() for c in growth.history],
        "xdmf": {k: str(v) for k, v in writers[0].files.items()} if writers else None,
        "_particles": growth.model.particles.positions[:, :2] * 1e3,
        "_growth": growth,
        "box": box if method != "efg" else None,
        "_box": [(NOTCH_A - reach * h) * 1e3, (NOTCH_Y - reach * h) * 1e3]
        if method != "efg"
        else None,
    }


def path_deviation(rec: dict, ref: dict) -> float:
    """The largest distance (in spacings) from a point of ``rec``'s path to ``ref``'s path
    (a polyline), over the part both reached (``rec``'s points up to ``ref``'s last one)."""
    a, b = np.asarray(rec["path"]), np.asarray(ref["path"])
    if len(b) < 2:
        return float(np.linalg.norm(a - b[0], axis=1).max() / (rec["h"] * 1e3))
    d = mf.geometry.crack.point_segment_distance(a, b[:-1], b[1:]).min(axis=1)
    return float(d[: len(b)].max() / (rec["h"] * 1e3))


def table(records: list[dict]) -> None:
    """Fixed and adaptive patches side by side (issue 25's table; times relative to efg's
    in this run)."""
    efg = next((r for r in records if r["method"] == "efg"), None)
    print(
        "\n method                 kink   mean   path dev.  K_I diff  K_II diff  particles  "
        "conversions  time     vs efg"
    )
    for r in records:
        d = r.get("sif_difference", {})
        dev = r.get("path_deviation")
        print(
            f" {r['method']:21s} {r['kink_angle_deg'] or float('nan'):6.2f} "
            f"{r['mean_angle_deg'] or float('nan'):6.2f}  "
            f"{'-' if dev is None else f'{dev:.2f} h':9s}  "
            f"{d.get('KI', float('nan')):8.2%}  {d.get('KII', float('nan')):8.2%}  "
            f"{r['particles_final']:9d}  {len(r['conversions']):11d}  {r['time_total']:6.2f} s "
            f"{r['time_total'] / efg['time_total'] if efg else float('nan'):6.2f}x"
        )


def sif_difference(rec: dict, ref: dict) -> dict:
    """K_I(t), K_II(t) of ``rec`` against ``ref`` (pure EFG) before initiation (up to the
    earlier of the two, on ``ref``'s check times, ``rec`` interpolated linearly unless its
    checks fall at the same times, ``same_times``: one ``--dt`` for both): the largest
    difference relative to ``max |K_II|`` of ``ref`` there (the dominant mode)."""
    ends = [r["initiation_time"] for r in (rec, ref) if r["initiation_time"] is not None]
    t_max = min(ends) if ends else min(rec["KI_history"][-1][0], ref["KI_history"][-1][0])
    t_ref = np.asarray(ref["KI_history"])[:, 0]
    keep = t_ref <= t_max * (1 + 1e-12)
    t_rec = np.asarray(rec["KI_history"])[:, 0]
    same = t_rec.size >= keep.sum() and np.allclose(t_rec[: keep.sum()], t_ref[keep], rtol=1e-9)
    out = {"against": ref["method"], "t_max": t_max, "same_times": bool(same)}
    scale = np.abs(np.asarray(ref["KII_history"])[keep, 1]).max()
    for key in ("KI", "KII"):
        a, b = np.asarray(rec[f"{key}_history"]), np.asarray(ref[f"{key}_history"])
        diff = np.interp(t_ref[keep], a[:, 0], a[:, 1]) - b[keep, 1]
        out[key] = float(np.abs(diff).max() / scale)
    return out


def report(rec: dict) -> None:
    """Print one run: the checks, the path, the angles and the timings."""
    print(
        f"{rec['method']} ({rec['impact']} impact): h = {rec['h'] * 1e3:.3g} mm, dofs "
        f"{rec['dofs']}, steps {rec['steps']}"
    )
    print("   t (us)   K_I (MPa m^.5)  K_II       K_eq   theta (deg)  state")
    for c in rec["checks"]:
        mark = "  extended" if c["extended"] else ""
        print(
            f"  {c['time'] * 1e6:7.2f}  {c['K_I'] / 1e6:9.2f}  {c['K_II'] / 1e6:9.2f}  "
            f"{c['K_eq'] / 1e6:9.2f}  {np.degrees(c['theta']):8.2f}   {c['state']}{mark}"
        )
    print(f"  path (mm): {np.round(rec['path'], 2).tolist()}")
    print(
        f"  kink angle (first segment) {rec['kink_angle_deg']} deg, at initiation "
        f"{rec['initiation_angle_deg']} deg, mean angle {rec['mean_angle_deg']} deg"
    )
    print(
        f"  times: setup {rec['time_setup']:.2f} s, steps {rec['time_steps']:.2f} s "
        f"({rec['per_step'] * 1e3:.2f} ms/step), SIFs {rec['time_sifs']:.2f} s, rebuilds "
        f"{rec['time_crack']:.2f} s ({rec['rebuilds']}, {rec['local_updates']} local), "
        f"total {rec['time_total']:.2f} s"
    )
    e = rec["energy"]
    print(
        f"  energy at {e['time'] * 1e6:.2f} us (J/m): kinetic {e['kinetic']:.6g}, strain "
        f"{e['strain']:.6g}, fracture {e['fracture_released']:.6g} (released) / "
        f"{e['fracture_G_area']:.6g} (G x area), external work {e['external_work']:.6g}; "
        f"drift {e['drift_released']:.3g} (released) / {e['drift_G_area']:.3g} (G x area)"
    )
    if rec["conversions"]:
        cv = rec["conversions"]
        print(
            f"  adaptive patch (K = {rec['adaptive_patch']:g}): {len(cv)} conversion(s), "
            f"particles {cv[0]['particles_before']} -> {rec['particles_final']}, cells added "
            f"{sum(c['cells_added'] for c in cv)}; mass error <= {rec['mass_error']:.1e}, "
            f"momentum error <= {rec['momentum_error']:.1e} (of which the supports' "
            f"reaction {rec['momentum_reaction']:.1e}; the fit's correction <= "
            f"{rec['momentum_correction']:.1e}); energy change "
            f"{rec['energy_change']:.4g} J/m (kinetic {sum(c['kinetic_change'] for c in cv):.4g},"
            f" strain {sum(c['strain_change'] for c in cv):.4g})"
        )
    if "sif_difference" in rec:
        d = rec["sif_difference"]
        print(
            f"  SIFs against {d['against']} up to {d['t_max'] * 1e6:.2f} us: K_I {d['KI']:.3%}, "
            f"K_II {d['KII']:.3%} of max |K_II|"
        )


def plot(rec: dict, png: str) -> None:
    """The path and K_I(t), K_II(t) (rank 0; needs matplotlib)."""
    try:
        import matplotlib

        matplotlib.use("Agg")
        import matplotlib.pyplot as plt
    except ImportError:
        print("matplotlib is not installed: PNG skipped")
        return
    fig, (a, b) = plt.subplots(1, 2, figsize=(10, 4.5))
    p = np.asarray(rec["path"])
    x = rec["_particles"]
    a.plot(x[:, 0], x[:, 1], ".", color="0.6", ms=1, label="particles")
    if rec["_box"] is not None:  # the particle box; FE outside it
        x0, y0 = rec["_box"]
        a.plot([x0, x0, 100], [100, y0, y0], "b-", lw=0.8, label="FE interface")
    a.plot([0, NOTCH_A * 1e3], [NOTCH_Y * 1e3] * 2, "k-", lw=2, label="notch")
    a.plot(p[:, 0], p[:, 1], "r.-", label="crack path")
    a.set(xlim=(0, 100), ylim=(0, 100), aspect="equal", xlabel="x (mm)", ylabel="y (mm)")
    a.legend()
    t = np.asarray(rec["KI_history"])[:, 0] * 1e6
    b.plot(t, np.asarray(rec["KI_history"])[:, 1] / 1e6, label="K_I")
    b.plot(t, np.asarray(rec["KII_history"])[:, 1] / 1e6, label="K_II")
    b.axhline(K_IC / 1e6, color="k", ls=":", label="K_Ic")
    b.set(xlabel="t (us)", ylabel="K (MPa m^0.5)")
    b.legend()
    fig.tight_layout()
    fig.savefig(png, dpi=120)


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("--method", nargs="+", default=["lagrange"])
    parser.add_argument("--nodes", type=int, default=41, help="nodes per side (the paper: 101)")
    parser.add_argument("--t-end", type=float, default=40e-6)
    parser.add_argument("--check-every", type=int, default=5)
    parser.add_argument("--impact", choices=IMPACTS, default="velocity")
    parser.add_argument("--rise", type=float, default=RISE, help="rise time of the velocity (s)")
    parser.add_argument(
        "--dt", type=float, default=None,
        help="time step (default: each model's stable step); one dt for all methods puts their "
        "SIF checks at the same times (the paper: 1e-7 s at 101 nodes)",
    )  # fmt: skip
    parser.add_argument(
        "--box", type=float, default=BOX,
        help="the particle box starts this many spacings behind and below the notch tip",
    )  # fmt: skip
    parser.add_argument(
        "--contact", type=float, default=10.0, metavar="F",
        help="crack-face contact, penalty k = F E / h (0: none, the faces may interpenetrate)",
    )  # fmt: skip
    parser.add_argument("--update", choices=["local", "full"], default="local")
    parser.add_argument(
        "--adaptive", type=float, default=0.0, metavar="R",
        help="adaptive quadrature: 4x4 Gauss within R spacings of the tip, 2x2 elsewhere "
        "(0: 4x4 everywhere)",
    )  # fmt: skip
    parser.add_argument(
        "--adaptive-patch", type=float, default=None, metavar="K",
        help="each coupled method runs again on a patch that starts as the cells within K "
        "spacings of the notch tip (beyond the slot) and grows K spacings about the tip during "
        "the run (mf.NearTips(K); the state converted at each growth), compared with the fixed "
        "box and with efg",
    )  # fmt: skip
    parser.add_argument("--json", default=None)
    parser.add_argument("--png", default=None)
    parser.add_argument("--xdmf", default=None, metavar="P", help="XDMF prefix")
    parser.add_argument("--xdmf-every", type=int, default=5, help="checks between XDMF outputs")
    args = parser.parse_args(argv)
    comm = MPI.COMM_WORLD
    options = {"impact": args.impact, "rise": args.rise, "xdmf": args.xdmf, "dt": args.dt}
    options["box"] = args.box
    options["contact"] = CrackContact(factor=args.contact) if args.contact > 0 else None
    options["update"] = args.update
    if args.adaptive > 0:
        options["quadrature"] = lambda h: mf.AdaptiveQuadrature(args.adaptive * h)
    runs = [(m, None) for m in args.method]
    if args.adaptive_patch is not None:
        runs += [(m, args.adaptive_patch) for m in args.method if m != "efg"]
    records = [
        run(m, args.nodes, args.t_end, args.check_every, comm, xdmf_every=args.xdmf_every,
            adaptive=k, **options)
        for m, k in runs
    ]  # fmt: skip
    ref = next((r for r in records if r["method"] == "efg"), None)
    for rec in records:
        if ref is not None and rec is not ref:
            rec["sif_difference"] = sif_difference(rec, ref)
        if rec["method"].endswith("+adaptive"):  # against the same coupling's fixed box
            fixed = next(r for r in records if r["method"] == rec["method"].split("+")[0])
            rec["path_deviation"] = path_deviation(rec, fixed)
    if comm.rank == 0:
        for rec in records:
            report(rec)
        if args.adaptive_patch is not None:
            table(records)
        if args.json:
            with open(args.json, "w") as f:
                plain = [{k: v for k, v in r.items() if not k.startswith("_")} for r in records]
                json.dump(plain, f, indent=1)
        if args.png:
            plot(records[0], args.png)
    return 0


if __name__ == "__main__":
    sys.exit(main())
