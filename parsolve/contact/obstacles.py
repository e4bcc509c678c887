"""Rigid obstacles: plane, cylinder (2D circle / 3D axis + radius), sphere.

Each returns a :class:`~parsolve.contact.pairing.Pairing` of the slave nodes with the obstacle,
with no master nodes (``master`` and ``weights`` have 0 columns, ``facet`` is -1). The normal
points from the obstacle towards the slave (the admissible side), the tangents follow the
pairing's convention (2D: ``t = (-n_y, n_x)``; 3D: ``(t1, t2, n)`` right-handed), and the gap is
the signed distance to the obstacle surface (negative: penetration).

A moving obstacle (rigid displacement ``d`` of the obstacle) changes the gap by ``-n . d``:
the relation value of the normal row becomes ``-g0 + n . d`` (see rows.py).
"""

from __future__ import annotations

import numpy as np

from parsolve.contact.pairing import Pairing, empty_pairing
from parsolve.errors import InputError


def _vector(v, dim: int, what: str, source: str | None, key: str | None,
            unit: bool = False) -> np.ndarray:
    v = np.asarray(v, dtype=float).ravel()
    if v.shape != (dim,) or not np.all(np.isfinite(v)):
        raise InputError(f"{what} must have {dim} finite coordinates, got {v.tolist()}", source, key)
    if unit:
        norm = np.linalg.norm(v)
        if norm == 0.0:
            raise InputError(f"{what} must be a non-zero vector", source, key)
        v = v / norm
    return v


def _positive(r, what: str, source: str | None, key: str | None) -> float:
    r = float(r)
    if not r > 0.0 or not np.isfinite(r):
        raise InputError(f"{what} must be positive, got {r!r}", source, key)
    return r


def tangent_basis(normal: np.ndarray) -> np.ndarray:
    """Tangents (n, dim-1, dim) of unit normals (n, dim), in the pairing's convention.

    3D: t1 is the normalised projection of the coordinate axis least aligned with n (ties:
    the first), a deterministic and smooth-enough choice; t2 = n x t1.
    """
    if normal.shape[1] == 2:
        return np.column_stack([-normal[:, 1], normal[:, 0]])[:, None, :]
    axis = np.argmin(np.abs(normal), axis=1)
    e = np.eye(3)[axis]
    t1 = e - np.einsum("mx,mx->m", e, normal)[:, None] * normal
    t1 /= np.linalg.norm(t1, axis=1)[:, None]
    return np.stack([t1, np.cross(normal, t1)], axis=1)


def _from_normals(slave_nodes, xs, normal, gap, tangents=None) -> Pairing:
    dim = xs.shape[1]
    out = empty_pairing(slave_nodes, dim, 0)
    out.paired[:] = True
    out.normal[:] = normal
    out.tangents[:] = tangent_basis(normal) if tangents is None else tangents
    out.gap[:] = gap
    out.point[:] = xs - gap[:, None] * normal
    return out


def plane(points: np.ndarray, slave_nodes: np.ndarray, origin, normal,
          source: str | None = None, key: str | None = None) -> Pairing:
    """Half-space {x : normal . (x - origin) >= 0}; ``normal`` (any length) points to the slave."""
    points = np.asarray(points, dtype=float)
    dim = points.shape[1]
    origin = _vector(origin, dim, "plane point", source, key)
    n = _vector(normal, dim, "plane normal", source, key, unit=True)
    xs = points[np.asarray(slave_nodes, dtype=np.int64)]
    normal = np.broadcast_to(n, xs.shape)
    return _from_normals(slave_nodes, xs, normal, (xs - origin) @ n)


def _radial(xs, centre, axis, radius, inside):
    r = xs - centre
    if axis is not None:  # 3D cylinder: remove the axial part
        r = r - (r @ axis)[:, None] * axis
    dist = np.linalg.norm(r, axis=1)
    if np.any(dist == 0.0):
        raise ValueError("a slave node lies on the obstacle's centre/axis: no normal there")
    er = r / dist[:, None]
    if inside:  # the slave lives inside the cylinder/sphere (a bore, a cavity)
        return -er, radius - dist
    return er, dist - radius


def cylinder(points: np.ndarray, slave_nodes: np.ndarray, centre, radius: float,
             axis=None, inside: bool = False,
             source: str | None = None, key: str | None = None) -> Pairing:
    """Rigid cylinder: a circle of centre and radius in 2D, an axis (point ``centre``,
    direction ``axis``) and radius in 3D. ``inside``: the slave is inside (a bore)."""
    points = np.asarray(points, dtype=float)
    dim = points.shape[1]
    centre = _vector(centre, dim, "cylinder centre", source, key)
    radius = _positive(radius, "cylinder radius", source, key)
    if dim == 3:
        if axis is None:
            raise InputError("a 3D cylinder needs an axis direction", source, key)
        axis = _vector(axis, 3, "cylinder axis", source, key, unit=True)
    else:
        axis = None
    xs = points[np.asarray(slave_nodes, dtype=np.int64)]
    normal, gap = _radial(xs, centre, axis, radius, inside)
    tangents = None
    if dim == 3:  # t1 along the axis (sign: the axis), t2 = n x t1 around it
        t1 = np.broadcast_to(axis, xs.shape)
        tangents = np.stack([t1, np.cross(normal, t1)], axis=1)
    return _from_normals(slave_nodes, xs, normal, gap, tangents)


def sphere(points: np.ndarray, slave_nodes: np.ndarray, centre, radius: float,
           inside: bool = False, source: str | None = None, key: str | None = None) -> Pairing:
    """Rigid sphere (3D; a circle in 2D, same as :func:`cylinder`)."""
    points = np.asarray(points, dtype=float)
    dim = points.shape[1]
    centre = _vector(centre, dim, "sphere centre", source, key)
    radius = _positive(radius, "sphere radius", source, key)
    xs = points[np.asarray(slave_nodes, dtype=np.int64)]
    normal, gap = _radial(xs, centre, None, radius, inside)
    return _from_normals(slave_nodes, xs, normal, gap)
