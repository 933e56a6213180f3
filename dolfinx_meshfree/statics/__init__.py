"""Static solves: pure EFG, the coupled model, the form-based problems, PETSc block systems."""
