"""Mesh-free particle methods coupled with DOLFINx finite elements."""
