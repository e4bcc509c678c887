"""Solvers: linear presets and PETSc options handling, static step loop."""
