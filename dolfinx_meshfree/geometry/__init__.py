"""Where the particles are and how the patch is integrated: particle sets, patches, quadrature,
stress points."""

__all__: list[str] = []  # the public API is dolfinx_meshfree's
