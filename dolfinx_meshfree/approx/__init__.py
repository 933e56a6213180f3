"""Approximations tabulated at points: MLS/EFG and SPH kernels, neighbour search, FE basis at
points, shape tables."""
