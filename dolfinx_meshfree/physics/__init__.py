"""Constitutive laws, forces and stiffness from shape tables, loads."""
