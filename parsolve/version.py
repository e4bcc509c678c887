"""Versions written into result files."""

from __future__ import annotations


def petsc_version() -> str:
    from petsc4py import PETSc

    return ".".join(map(str, PETSc.Sys.getVersion()))
