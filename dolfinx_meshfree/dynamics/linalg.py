"""Small PETSc helpers of explicit dynamics: a private MUMPS factorisation, entrywise absolute
values, the row layout of a matrix."""

from __future__ import annotations

import itertools

import numpy as np
from petsc4py import PETSc

from ..parallel import Layout

__all__ = ["absolute", "mumps_lu", "row_layout"]

_prefix_counter = itertools.count()


def absolute(A: PETSc.Mat) -> PETSc.Mat:
    """``|A|`` (entrywise absolute values), a new AIJ matrix with the layout of ``A``."""
    ai, aj, av = A.getValuesCSR()
    B = PETSc.Mat().createAIJ(A.getSizes(), csr=(ai, aj, np.abs(av)), comm=A.getComm())
    B.assemble()
    return B


def mumps_lu(A: PETSc.Mat) -> PETSc.KSP:
    """A private KSP (own options prefix) holding the MUMPS LU factorisation of ``A``; the
    caller destroys it."""
    ksp = PETSc.KSP().create(A.getComm())
    ksp.setOptionsPrefix(f"dolfinx_meshfree_dyn_{next(_prefix_counter)}_")
    ksp.setOperators(A)
    ksp.setType(PETSc.KSP.Type.PREONLY)
    pc = ksp.getPC()
    pc.setType(PETSc.PC.Type.LU)
    pc.setFactorSolverType("mumps")
    ksp.setUp()
    pc.destroy()  # our handle only (the KSP keeps its PC): see petsc.solve_lu
    return ksp


def row_layout(A: PETSc.Mat) -> Layout:
    """The :class:`~dolfinx_meshfree.parallel.Layout` of the rows of ``A``."""
    lo, hi = A.getOwnershipRange()
    return Layout(hi - lo, A.getSize()[0], lo)
