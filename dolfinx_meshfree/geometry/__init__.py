"""Where the particles are and how the patch is integrated: particle sets, patches, quadrature,
stress points."""
