"""Linear elastic fracture mechanics on any displacement field (FE, EFG or coupled): the
near-tip Williams fields, stress intensity factors by the interaction integral, and the maximum
hoop stress growth criterion. Pure numpy, independent of meshes and particles."""

__all__: list[str] = []  # the public API is dolfinx_meshfree's
