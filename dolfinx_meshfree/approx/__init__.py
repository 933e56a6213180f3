"""Approximations tabulated at points: MLS/EFG and SPH kernels, neighbour search, FE basis at
points, shape tables."""

__all__: list[str] = []  # the public API is dolfinx_meshfree's
