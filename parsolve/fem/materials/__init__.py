"""Constitutive models evaluated at quadrature points (vectorised numpy).

Voigt order: 2D (xx, yy, xy), 3D (xx, yy, zz, yz, xz, xy). Strains use engineering shear
(gamma = 2 eps), stresses plain components. Every model follows the interface of
:class:`parsolve.fem.materials.base.Material`.
"""
