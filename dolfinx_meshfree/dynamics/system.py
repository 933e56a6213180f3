"""The semi-discrete system of explicit dynamics: masses, internal force, tangent, constraints.

Central differences need only these (Belytschko et al. 1995, eq. 4.4–4.5; Rabczuk et al. 2006,
eq. 86–92): the lumped masses ``M``, the internal force ``f^int(d)``, the constraint blocks
``G`` of ``G \\dot d = 0`` and, for the stable step, the tangent ``df^int/dd``:

.. math::
    M \\ddot d + f^{int}(d) = f^{ext} + G^T \\lambda, \\qquad G \\dot d = 0.

:class:`SemiDiscreteSystem` is that interface; :class:`LinearSystem` is its linear member,
wrapping the assembled blocks of today's builders: ``f^int(d) = K d`` and the strain energy
``1/2 d^T K d``. A finite-deformation system gives ``f^int(d) = sum_q B_0^T P(F_q) w_q`` and
the stored energy ``W(F)`` through the same methods.

Each system is split into fields (:class:`Field`: FE nodes, particles), one PETSc vector per
field; the lists of vectors below have one entry per field, in the order of the fields.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Collection, Sequence
from typing import Protocol, runtime_checkable

import numpy as np
from petsc4py import PETSc

from .compiled_product import CompiledProduct, blockable, multiply, resolve_product
from .linalg import BLOCK_FORMATS, blocked

__all__ = [
    "Field",
    "LinearSystem",
    "SemiDiscreteSystem",
    "WrappedSystem",
    "inverse_masses",
    "wrapped",
]

Blocks = dict[tuple[int, int], PETSc.Mat]


@dataclasses.dataclass
class Field:
    """One discretisation of an explicit system: stiffness and lumped masses of its dofs.

    Attributes:
        name: ``"fe"`` or ``"particles"``.
        K: Assembled stiffness (PETSc, owned rows).
        mass: Lumped masses (PETSc vector, same layout); 0 marks dofs outside the field (FE nodes
            that only patch cells touch), which the integrator holds at rest.
        spacing: Smallest node or particle spacing (for the Courant condition).
        points: (owned nodes, gdim) positions of the owned nodes/particles in PETSc order (gdim dofs
            each); ``None``: derived from the field's space or particle set.
        fixed: bool per owned dof: held at zero velocity and acceleration (strong essential
            conditions: ``M^{-1} = 0`` there); ``None``: none.
        block_size: Dofs per node, numbered ``block_size * node + component`` (the geometric
            dimension); ``None``: the block size ``K`` carries (DOLFINx's FE stiffness: gdim).
    """

    name: str
    K: PETSc.Mat
    mass: PETSc.Vec
    spacing: float
    points: np.ndarray | None = None
    fixed: np.ndarray | None = None
    block_size: int | None = None

    def dofs_per_node(self) -> int:
        """:attr:`block_size`, or that of ``K``."""
        return self.block_size if self.block_size is not None else self.K.getBlockSize()


def inverse_masses(
    fields: Sequence[Field],
) -> tuple[list[PETSc.Vec], list[np.ndarray], list[np.ndarray]]:
    """``M^{-1}`` per field (0 on dofs held at rest: massless or fixed), and per field the
    dofs with mass (``active``) and those free to move (``free``)."""
    minv, active, free = [], [], []
    for f in fields:
        mi = f.mass.duplicate()
        m = f.mass.array_r
        on = m > 0.0
        if f.fixed is not None:
            on &= ~f.fixed
        mi.array[:] = np.where(on, 1.0 / np.where(m > 0.0, m, 1.0), 0.0)
        minv.append(mi)
        active.append(m > 0.0)
        free.append(on)
    return minv, active, free


@runtime_checkable
class SemiDiscreteSystem(Protocol):
    """What explicit dynamics asks of a discretisation (collective methods).

    Attributes:
        fields: The fields, FE first: each gives its lumped masses and node spacing.
    """

    fields: list[Field]

    def mass(self) -> list[PETSc.Vec]:
        """The lumped masses of each field (owned dofs; the system keeps ownership)."""
        ...

    def internal_force(
        self, u: Sequence[PETSc.Vec], out: Sequence[PETSc.Vec] | None = None
    ) -> list[PETSc.Vec]:
        """``f^int(u)`` per field, into ``out`` (or new vectors the caller owns)."""
        ...

    def tangent(self, u: Sequence[PETSc.Vec] | None = None) -> Blocks:
        """The blocks ``{(k, l): df^int_k / du_l}`` at ``u`` (``None``: the reference state);
        diagonal blocks first, in field order."""
        ...

    def constraints(self) -> list[PETSc.Mat | None] | None:
        """The constraint blocks ``G_f`` of each field (``None`` for a field without), or
        ``None``: no constraint."""
        ...

    def strain_energy(self, u: Sequence[PETSc.Vec], f_int: Sequence[PETSc.Vec]) -> float:
        """The stored energy at ``u``, given ``f_int = f^int(u)`` (every rank)."""
        ...

    def rebuild(self, changed: Collection[str]) -> bool:
        """Rebuild what depends on the ``changed`` inputs (e.g. ``"approximation"`` when a
        crack changes which particles see each other); ``True`` when the masses, tangent or
        constraints changed, so that their consumers (the velocity projection, the stable
        step) rebuild too."""
        ...


class WrappedSystem:
    """A :class:`SemiDiscreteSystem` that adds a term to another one, ``inner`` (crack-face
    contact, contact between bodies): a subclass overrides the internal force, the strain energy
    and the tangent; the fields, masses, constraints, rebuild and any other attribute (the
    blocks, master–slave's shared sides) are the inner system's."""

    def __init__(self, inner: SemiDiscreteSystem) -> None:
        self.inner = inner

    def __getattr__(self, name: str):  # the inner system's attributes (blocks, shared, ...)
        if name == "inner":
            raise AttributeError(name)
        return getattr(self.inner, name)

    @property
    def fields(self) -> list[Field]:
        return self.inner.fields

    def mass(self) -> list[PETSc.Vec]:
        return self.inner.mass()

    def constraints(self) -> list[PETSc.Mat | None] | None:
        return self.inner.constraints()

    def rebuild(self, changed: Collection[str]) -> bool:
        return self.inner.rebuild(changed)


class LinearSystem:
    """Small-strain linear elasticity: ``f^int(u) = K u`` with assembled blocks.

    ``K`` has a diagonal block per field (:attr:`Field.K`) and off-diagonal blocks
    ``{(k, l): K_kl}`` (rows of field ``k``, columns of field ``l``: the ramp couplings, the
    bridging penalty, master–slave's reduced blocks, the hybrid coupling). The system holds
    references; :meth:`destroy` destroys them.

    Args:
        fields: One or two :class:`Field` (FE first).
        blocks: The off-diagonal blocks, or ``None``.
        constraint: The constraint blocks ``G_f`` of each field (``None`` for a field without),
            or ``None``: no constraint.
        matrix_format: Storage of the stiffness blocks, whose products are most of a step:
            ``"baij"`` (the default): blocks of ``gdim x gdim``
            (:func:`~dolfinx_meshfree.dynamics.linalg.blocked`; also a block between two
            fields when both are node-interleaved), or ``"aij"``: as assembled (PETSc's AIJ
            with i-nodes; blocks assembled as BAIJ, the ramps', are copied to AIJ). Measured
            on the rod (41k dofs, 86 entries per particle row, PETSc 3.18, one core,
            ``benchmarks/bench_blocks.py``): BAIJ multiplies the particle stiffness
            1.14-1.25x faster (a step of EFG or lagrange 1.2-1.3x), the FE stiffness alike
            (0.95-1.01x); the results agree to round-off (the summation order changes).
            These are PETSc's products (``product="petsc"``).
        product: Who multiplies the blocks in :meth:`internal_force`: ``"numba"`` (the default
            with numba): :class:`~dolfinx_meshfree.dynamics.compiled_product.CompiledProduct`
            for every block of node-interleaved ``gdim x gdim`` blocks (PETSc's product for the
            others), or ``"petsc"``: PETSc's ``MatMult`` of the stored format; ``None``: the
            default (``$DOLFINX_MESHFREE_PRODUCT``, else ``"numba"`` with numba). The blocks stay
            PETSc matrices for everything else (the tangent, the stable step).
    """

    def __init__(
        self,
        fields: Sequence[Field],
        blocks: Blocks | None = None,
        constraint: Sequence[PETSc.Mat | None] | None = None,
        matrix_format: str = "baij",
        product: str | None = None,
    ) -> None:
        if matrix_format not in BLOCK_FORMATS:
            raise ValueError(
                f"matrix_format={matrix_format!r} is not known; use one of {list(BLOCK_FORMATS)}"
            )
        #: ``"numba"`` or ``"petsc"`` (see ``product`` above).
        self.product = resolve_product(product)
        #: per block: the matrix, its PETSc handle and its compiled product (None: PETSc's)
        self._products: dict[tuple[int, int], tuple[PETSc.Mat, int, CompiledProduct | None]] = {}
        self.fields = list(fields)
        self._comm = self.fields[0].mass.getComm().tompi4py()
        self.blocks: Blocks = dict(blocks or {})
        self.store_as(matrix_format)
        self.G: list[PETSc.Mat | None] | None = None
        if constraint is not None and any(g is not None for g in constraint):
            self.G = list(constraint)

    def store_as(self, fmt: str) -> None:
        """Replace every stiffness block by its ``fmt`` copy (``"aij"``: AIJ with the block
        size set, ``"baij"``) where the fields' dofs are node-interleaved with one block size
        and the block is not stored so already (:func:`~dolfinx_meshfree.dynamics.linalg.
        blocked`); the replaced matrices are destroyed (collective). The entries are unchanged."""
        if fmt not in BLOCK_FORMATS:
            raise ValueError(f"fmt={fmt!r} is not known; use one of {list(BLOCK_FORMATS)}")
        bs = [f.dofs_per_node() for f in self.fields]
        for k, f in enumerate(self.fields):
            B = blocked(f.K, bs[k], fmt)
            if B is not None:
                f.K.destroy()
                self.fields[k] = dataclasses.replace(f, K=B)
        for (k, j), A in self.blocks.items():
            B = blocked(A, bs[k], fmt) if bs[k] == bs[j] else None
            if B is not None:
                A.destroy()
                self.blocks[k, j] = B

    def mass(self) -> list[PETSc.Vec]:
        """The lumped masses of each field."""
        return [f.mass for f in self.fields]

    def internal_force(
        self, u: Sequence[PETSc.Vec], out: Sequence[PETSc.Vec] | None = None
    ) -> list[PETSc.Vec]:
        """``K u``: the diagonal blocks, then the off-diagonal ones added (collective)."""
        y = list(out) if out is not None else [f.mass.duplicate() for f in self.fields]
        steps = [
            (self._compiled(k, k, f.K) or f.K, u[k], y[k], False) for k, f in enumerate(self.fields)
        ]
        for (k, j), B in self.blocks.items():
            steps.append((self._compiled(k, j, B) or B, u[j], y[k], True))
        multiply(steps, self._comm)  # one collective check for every compiled block
        return y

    def compiled_product(self, k: int, j: int) -> CompiledProduct | None:
        """The compiled product the steps use for block ``(k, j)`` (made now if no step has yet;
        ``None``: PETSc's product, for ``product="petsc"`` or a block without whole node
        blocks; collective)."""
        A = self.fields[k].K if k == j else self.blocks.get((k, j))
        if A is None:
            raise ValueError(
                f"block ({k}, {j}) is not stored: the blocks are {sorted(self.tangent())}"
            )
        return self._compiled(k, j, A)

    def _compiled(self, k: int, j: int, A: PETSc.Mat) -> CompiledProduct | None:
        """The compiled product of block ``(k, j)`` (``None``: PETSc's), made for the matrix
        object ``A`` now stored there (a replaced block gets a new one; collective)."""
        if self.product == "petsc":
            return None
        made = self._products.get((k, j))
        if made is not None and made[0] is A and made[1] == A.handle:  # the same PETSc matrix
            return made[2]
        if made is not None and made[2] is not None:
            made[2].destroy()
        bs = self.fields[k].dofs_per_node()
        same = bs == self.fields[j].dofs_per_node()
        prod = CompiledProduct(A, bs) if same and blockable(A, bs) else None
        self._products[k, j] = (A, A.handle, prod)
        return prod

    def tangent(self, u: Sequence[PETSc.Vec] | None = None) -> Blocks:
        """``K`` as blocks, whatever ``u``: the diagonal blocks, then the off-diagonal ones."""
        out: Blocks = {(k, k): f.K for k, f in enumerate(self.fields)}
        out.update(self.blocks)
        return out

    def constraints(self) -> list[PETSc.Mat | None] | None:
        """The constraint blocks (``None``: no constraint)."""
        return self.G

    def strain_energy(self, u: Sequence[PETSc.Vec], f_int: Sequence[PETSc.Vec]) -> float:
        """``1/2 u^T K u`` from ``f_int = K u``, summed field by field (collective)."""
        energy = 0.0
        for x, f in zip(u, f_int, strict=True):
            energy += 0.5 * x.dot(f)
        return energy

    def rebuild(self, changed: Collection[str]) -> bool:
        """Nothing to rebuild when nothing changed (``False``).

        Raises:
            NotImplementedError: ``changed`` is not empty: the assembled blocks cannot follow a
                changed approximation; build a new model instead.
        """
        if changed:
            raise NotImplementedError(
                f"changed={sorted(changed)!r}: a LinearSystem wraps assembled blocks and cannot "
                "rebuild them; build a new ExplicitDynamics from the changed model"
            )
        return False

    def destroy(self) -> None:
        """Destroy the blocks, masses and constraint blocks (collective)."""
        for _, _, prod in self._products.values():
            if prod is not None:
                prod.destroy()
        self._products.clear()
        objs = [*self.blocks.values()]
        for f in self.fields:
            objs += [f.K, f.mass]
        objs += [g for g in (self.G or []) if g is not None]
        for obj in objs:
            obj.destroy()


def wrapped(system: object, kind: type) -> list:
    """The systems of type ``kind`` in a model's chain of wrapped systems (``system``, its
    ``inner``, ...), outermost first (the projectiles', the contacts' added to a model)."""
    found = []
    while system is not None:
        if isinstance(system, kind):
            found.append(system)
        system = system.inner if isinstance(system, WrappedSystem) else None
    return found
