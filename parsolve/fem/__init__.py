"""Finite-element building blocks: reference elements, quadrature, geometry, assembly kernels."""
