"""3D dual mortar rows on triangle6 faces (parsolve.contact.mortar3d, the modified basis of
Popp et al. 2012): on flat non-matching interfaces, distorted, with the midside nodes at their
edges' midpoints (affine faces), the rows transfer constants and linear fields exactly, the
weights ∫Ñ_i are positive (2α/3 of the adjacent faces' area at a corner, (1 − 2α)/3 at a
midside), and a uniform pressure gives, through the rows' slave and master entries, the
consistent nodal forces p ∫N_j on both sides (0 at the corners, A/3 per face at the midsides):
the 3D contact patch test's condition, to round-off."""

from __future__ import annotations

import numpy as np
import pytest

from parsolve.contact.mortar3d import ALPHA, mortar_pairing_3d
from parsolve.mesh.generators import rectangle

TRI6_FLIP = [0, 2, 1, 5, 4, 3]   # the same triangle6 face, the other orientation


def tri6_faces(n: int, z: float, slave: bool, seed: int | None = None, side: float = 1.0):
    """triangle6 faces of the square [½ − side/2, ½ + side/2]² at height z, the interior corner
    nodes moved at random (by up to a fifth of a cell), the midside nodes at their edges'
    midpoints; slave faces look down (the bottom of an upper body), master faces up."""
    m = rectangle(side, side, n, n, "triangle", origin=(0.5 - side / 2, 0.5 - side / 2))
    p = m.points.copy()
    if seed is not None:
        lo, hi = 0.5 - side / 2, 0.5 + side / 2
        inner = np.all((p > lo + 1e-9) & (p < hi - 1e-9), axis=1)
        p[inner] += np.random.default_rng(seed).uniform(-0.2, 0.2, (inner.sum(), 2)) * side / n
    tri = m.cells
    edges = np.sort(np.concatenate([tri[:, [0, 1]], tri[:, [1, 2]], tri[:, [2, 0]]]), axis=1)
    keys, inv = np.unique(edges, axis=0, return_inverse=True)
    mids = len(p) + inv.reshape(3, -1).T
    points = np.vstack([p, 0.5 * (p[keys[:, 0]] + p[keys[:, 1]])])
    faces = np.hstack([tri, mids])
    faces = faces[:, TRI6_FLIP] if slave else faces
    return np.column_stack([points, np.full(len(points), z)]), faces


CASES = [((2, None), (3, None)), ((3, 1), (2, 2)), ((4, 3), (3, 4)), ((3, 5), (5, 6))]


def interface(case):
    (ns, ss), (nm, sm) = case
    ps, fs = tri6_faces(ns, 0.0, True, ss)
    pm, fm = tri6_faces(nm, 0.0, False, sm)
    return np.vstack([ps, pm]), fs, fm + len(ps)


def consistent_forces(pts, faces, npts):
    """p ∫N_j dA for p = 1 (triangle6: 0 at the corners, A/3 at each midside)."""
    xy = pts[faces[:, :3], :2]
    area = 0.5 * np.abs(np.cross(xy[:, 1] - xy[:, 0], xy[:, 2] - xy[:, 0]))
    f = np.zeros(npts)
    np.add.at(f, faces[:, 3:].ravel(), np.repeat(area / 3, 3))
    return f


@pytest.mark.parametrize("case", CASES)
def test_triangle6_rows_transfer_constants_and_linears(case):
    """Every slave node has a row; its weights sum to one and reproduce the coordinates (the
    corners of a midside's edge among them, with α), zero gap, normal +z; ∫Ñ_i > 0 and as the
    modified basis says at an undistorted slave."""
    pts, fs, fm = interface(case)
    mortar = mortar_pairing_3d(pts, fs, fm, "triangle6")
    p = mortar.pairing
    assert np.array_equal(p.slave, np.unique(fs))
    np.testing.assert_allclose(p.weights.sum(axis=1), 1.0, atol=1e-13)
    transfer = np.einsum("mk,mkx->mx", p.weights, pts[p.master])
    np.testing.assert_allclose(transfer, pts[p.slave], atol=1e-14)
    np.testing.assert_allclose(p.gap, 0.0, atol=1e-15)
    np.testing.assert_allclose(p.normal, np.tile([0.0, 0.0, 1.0], (len(p), 1)), atol=1e-15)
    assert np.all(mortar.weight > 0)
    if case[0][1] is None:   # a regular slave: faces of area 1/(2 n²)
        n = case[0][0]
        corner = np.isin(p.slave, fs[:, :3])
        adjacent = np.bincount(fs.ravel(), minlength=len(pts))[p.slave] / (2 * n * n)
        # Mortar.weight: ∫Ñ_c at a corner, ∫Ñ_m / (1 − 2α) = ∫N_m at a midside
        np.testing.assert_allclose(mortar.weight[corner], 2 * ALPHA / 3 * adjacent[corner],
                                   rtol=1e-12)
        np.testing.assert_allclose(mortar.weight[~corner], adjacent[~corner] / 3, rtol=1e-12)


@pytest.mark.parametrize("case", CASES)
def test_triangle6_uniform_pressure_gives_consistent_nodal_forces(case):
    """Multipliers λ_i = p × Mortar.weight_i (the dual basis sums to one): the forces of the
    rows on the slave nodes (own coefficient 1, the corners of a midside's row −α) and on the
    master nodes are p ∫N_j of each side, and each sums to p × area (the rows' slave shares,
    1 and 1 − 2α, weigh the multipliers to the resultant)."""
    pts, fs, fm = interface(case)
    mortar = mortar_pairing_3d(pts, fs, fm, "triangle6")
    p, lam = mortar.pairing, mortar.weight
    on_slave = np.isin(p.master, fs)
    slave_f = np.bincount(p.slave, lam, len(pts))
    np.add.at(slave_f, p.master[on_slave], -(p.weights * lam[:, None])[on_slave])
    master_f = np.zeros(len(pts))
    np.add.at(master_f, p.master[~on_slave], (p.weights * lam[:, None])[~on_slave])
    np.testing.assert_allclose(slave_f, consistent_forces(pts, fs, len(pts)), atol=1e-15)
    np.testing.assert_allclose(master_f, consistent_forces(pts, fm, len(pts)), atol=1e-15)
    share = 1.0 - np.where(on_slave, p.weights, 0.0).sum(axis=1)
    assert abs((lam * share).sum() - 1.0) < 1e-13
    assert set(np.round(share, 14)) == {1.0, round(1 - 2 * ALPHA, 14)}


def test_triangle6_partial_cover_keeps_the_identities():
    """A master larger than the slave on one side, smaller on the other (the slave's faces
    along x = 1 half covered): constants and linears still exact on every row."""
    ps, fs = tri6_faces(3, 0.0, True, 2)
    pm, fm = tri6_faces(4, 0.0, False, 3, side=1.0)
    pm[:, 0] -= 0.4                                          # covers x < 0.6 of the slave
    pts, fm = np.vstack([ps, pm]), fm + len(ps)
    mortar = mortar_pairing_3d(pts, fs, fm, "triangle6")
    p = mortar.pairing
    assert 0 < len(p) < np.unique(fs).size and np.all(mortar.weight > 0)
    np.testing.assert_allclose(p.weights.sum(axis=1), 1.0, atol=1e-12)
    transfer = np.einsum("mk,mkx->mx", p.weights, pts[p.master])
    np.testing.assert_allclose(transfer, pts[p.slave], atol=1e-13)


def test_triangle6_gap_over_the_share_is_the_separation():
    """The master 0.01 below the slave: a row's gap is its share of the separation (1 at a
    corner, 1 − 2α at a midside, whose row is scaled), so gap / share (the contact effect's
    gap output) is 0.01 at every node."""
    ps, fs = tri6_faces(3, 0.0, True, 4)
    pm, fm = tri6_faces(4, -0.01, False, 5)
    pts, fm = np.vstack([ps, pm]), fm + len(ps)
    p = mortar_pairing_3d(pts, fs, fm, "triangle6").pairing
    share = 1.0 - np.where(np.isin(p.master, fs), p.weights, 0.0).sum(axis=1)
    corner = np.isin(p.slave, fs[:, :3])
    np.testing.assert_allclose(share[corner], 1.0, rtol=1e-15)
    np.testing.assert_allclose(share[~corner], 1 - 2 * ALPHA, rtol=1e-14)
    np.testing.assert_allclose(p.gap / share, 0.01, rtol=1e-12)
