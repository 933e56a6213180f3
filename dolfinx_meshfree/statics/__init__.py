"""Static solves: pure EFG, the coupled model, the form-based problems, PETSc block systems."""

__all__: list[str] = []  # the public API is dolfinx_meshfree's
