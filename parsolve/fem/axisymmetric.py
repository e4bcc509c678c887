"""The out-of-plane measure of a 2D model: a constant thickness t (plane stress, plane strain)
or, for the axisymmetric hypothesis (x = r ≥ 0, y = z), the circumference 2π r of the point.

Every 2D integral of the kernels is Σ_q w |J| × measure: with ``thickness`` a float the
measure is t, with an ``Axisymmetric`` it is 2π r_q at the quadrature point. Integrals are
thus over the whole ring (2π, not per radian): stiffness, loads (a traction is a force per
unit area of the revolved surface, a ``nodal`` load the total force on the node's ring),
reactions and resultants are whole-body forces, as in Abaqus (code_aster and Cast3M count
forces per radian: theirs times 2π are ours).

Axisymmetric strains and stresses have four components in the order (rr, zz, rz, θθ): the
plane order (xx, yy, xy) with x = r, y = z, then the hoop component θθ = u_r / r.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from parsolve.errors import InputError

TWO_PI = 2.0 * np.pi


@dataclass(frozen=True)
class Axisymmetric:
    """The axisymmetric out-of-plane measure 2π r; ``mesh_source`` (file, key) is what an
    error on the mesh's coordinates names."""

    mesh_source: tuple = (None, None)

    def check_mesh(self, points: np.ndarray, comm) -> None:
        """InputError (naming the mesh) unless every node has r = x ≥ 0, raised on every rank
        of ``comm``. ``points``: the rank's owned nodes (a bad node may be on one rank only;
        the count and the lowest node are over every rank). Collective."""
        bad = np.flatnonzero(points[:, 0] < 0.0)
        # the lowest x, then y: the same node whatever the partition
        first = bad[np.lexsort((points[bad, 1], points[bad, 0]))[:1]]
        lowest = tuple(points[first[0], :2]) if bad.size else None
        count = comm.allreduce(int(bad.size))
        if count:
            p = min((q for q in comm.allgather(lowest) if q is not None), key=lambda q: (q[0], q[1]))
            raise InputError(f"an axisymmetric model needs r = x >= 0 at every node: "
                             f"{count} nodes have x < 0 (the lowest at "
                             f"({p[0]:.6g}, {p[1]:.6g}))", *self.mesh_source)


def is_axisymmetric(thickness) -> bool:
    return isinstance(thickness, Axisymmetric)


def scale(weights: np.ndarray, r: np.ndarray | None, thickness) -> np.ndarray:
    """``weights`` (w |J|) times the out-of-plane measure: 2π r (``r`` at the same points,
    same shape) or the constant thickness."""
    if is_axisymmetric(thickness):
        return weights * (TWO_PI * r)
    return weights * thickness


def radius_at(N: np.ndarray, coords: np.ndarray) -> np.ndarray:
    """r = x at the points of N (nq, nen) of cells coords (nc, nen, d): (nc, nq)."""
    return coords[:, :, 0] @ N.T

