"""Exact solutions and error norms for tests, demos and benchmarks."""
