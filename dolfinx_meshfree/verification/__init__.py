"""Exact solutions and error norms for tests, demos and benchmarks."""

__all__: list[str] = []  # the public API is dolfinx_meshfree's
