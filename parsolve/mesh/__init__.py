"""Meshes: the Mesh container, generators, meshio reading, selectors, partition."""

from parsolve.mesh.mesh import Mesh

__all__ = ["Mesh"]
