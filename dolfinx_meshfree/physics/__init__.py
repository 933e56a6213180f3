"""Constitutive laws, forces and stiffness from shape tables, loads."""

__all__: list[str] = []  # the public API is dolfinx_meshfree's
