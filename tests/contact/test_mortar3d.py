"""3D dual mortar rows (parsolve.contact.mortar3d): the segments cover a flat interface exactly
on non-matching and rotated meshes, the rows transfer constants and linear fields exactly, the
slave weights are ∫φ_i, matching meshes give identity rows, the gap and the frame, partial
cover, quad8 faces refused."""

from __future__ import annotations

import numpy as np
import pytest

from parsolve.contact.mortar import mortar_rows
from parsolve.contact.mortar3d import mortar_pairing_3d, overlap_areas, tangent_basis
from parsolve.mesh.generators import rectangle


def face_mesh(n: tuple[int, int], cell: str, z: float, slave: bool, side: float = 1.0,
              rot: float = 0.0, seed: int | None = None):
    """A flat face mesh of the square [0, side]² (centred on (½, ½) and rotated by ``rot``
    about it when side ≠ 1 or rot ≠ 0) at height z: slave faces look down (outward −z, the
    bottom of an upper body), master faces up. ``seed``: interior nodes moved at random."""
    m = rectangle(side, side, n[0], n[1], cell, origin=(0.5 - side / 2, 0.5 - side / 2))
    p = m.points.copy()
    if seed is not None:
        inner = np.all((p > 1e-9) & (p < 1 - 1e-9), axis=1)
        p[inner] += np.random.default_rng(seed).uniform(-0.2, 0.2, (inner.sum(), 2)) / max(n)
    c, s = np.cos(rot), np.sin(rot)
    p = (p - 0.5) @ np.array([[c, -s], [s, c]]).T + 0.5
    faces = m.cells[:, ::-1] if slave else m.cells
    return np.column_stack([p, np.full(len(p), z)]), faces


def interface(slave, master):
    """Points and (slave faces, master faces) of the two face meshes in one numbering."""
    (ps, fs), (pm, fm) = slave, master
    return np.vstack([ps, pm]), fs, fm + len(ps)


CASES = [
    ("quad", face_mesh((3, 3), "quad", 0.0, True), face_mesh((4, 5), "quad", 0.0, False)),
    ("quad", face_mesh((3, 3), "quad", 0.0, True, seed=1),
     face_mesh((4, 4), "quad", 0.0, False, side=2.0, rot=0.3)),
    ("triangle", face_mesh((3, 3), "triangle", 0.0, True),
     face_mesh((4, 5), "triangle", 0.0, False)),
    ("triangle", face_mesh((3, 3), "triangle", 0.0, True, seed=2),
     face_mesh((5, 4), "triangle", 0.0, False, side=2.0, rot=0.3)),
]


@pytest.mark.parametrize("cell, slave, master", CASES)
def test_segments_cover_the_interface(cell, slave, master):
    """The overlap polygons of a fully covered unit square sum to its area, face by face to
    the face's own area (the master larger and rotated, or non-matching on the same square)."""
    pts, fs, fm = interface(slave, master)
    areas = overlap_areas(pts, fs, fm, cell)
    assert abs(areas.sum() - 1.0) < 1e-12
    xy = pts[fs][:, :, :2]
    shoelace = 0.5 * np.abs(np.sum(xy[:, :, 0] * np.roll(xy[:, :, 1], -1, axis=1)
                                   - np.roll(xy[:, :, 0], -1, axis=1) * xy[:, :, 1], axis=1))
    np.testing.assert_allclose(areas, shoelace, rtol=1e-12)


@pytest.mark.parametrize("cell, slave, master", CASES)
def test_rows_transfer_constants_and_linears(cell, slave, master):
    """Σ_a M_ia = D_ii = w_i (normalised weights sum to one), Σ_a M_ia x_a = w_i x_i (a linear
    field is transferred exactly), w_i = ∫φ_i (sum: the area; regular slave mesh: h² per
    adjacent face its area over its node count), every slave node paired, zero gap,
    the normal +z (out of the master)."""
    pts, fs, fm = interface(slave, master)
    mortar = mortar_pairing_3d(pts, fs, fm, cell)
    p = mortar.pairing
    assert np.array_equal(p.slave, np.unique(fs))
    np.testing.assert_allclose(p.weights.sum(axis=1), 1.0, atol=1e-13)
    transfer = np.einsum("mk,mkx->mx", p.weights, pts[p.master])
    np.testing.assert_allclose(transfer, pts[p.slave], atol=1e-14)
    np.testing.assert_allclose(p.gap, 0.0, atol=1e-15)
    np.testing.assert_allclose(p.normal, np.tile([0.0, 0.0, 1.0], (len(p), 1)), atol=1e-15)
    assert abs(mortar.weight.sum() - 1.0) < 1e-12
    if np.allclose(pts[p.slave][:, :2] * 3, np.round(pts[p.slave][:, :2] * 3)):   # regular
        k = fs.shape[1]                   # ∫φ_i = area / k on each adjacent face
        share = {4: 1 / 4, 3: 1 / 6}[k]     # a quad h², a triangle h²/2, over k nodes
        expected = np.bincount(fs.ravel(), minlength=len(pts))[p.slave] * share / 9
        np.testing.assert_allclose(mortar.weight, expected, rtol=1e-12)
    # the integrated rows: slave coefficient w_i, master coefficients summing to −w_i
    rn, _, _ = mortar_rows(mortar, integrated=True)
    z = rn.comp == 2
    slave_part = np.isin(np.arange(rn.coef.size) % rn.width, [2])
    np.testing.assert_allclose(np.bincount(rn.row[z], rn.coef[z], len(p)), 0.0, atol=1e-14)
    np.testing.assert_allclose(rn.coef[slave_part], mortar.weight, rtol=1e-14)


@pytest.mark.parametrize("cell", ["quad", "triangle"])
def test_matching_meshes_give_node_to_node_rows(cell):
    """Coincident meshes (the master 0.1 below, facing): each row pairs its slave node with the
    master node beneath it alone (∫ψ_i φ_a = δ_ia w_i), gap 0.1, tangents orthonormal with
    (t1, t2, n) right-handed."""
    pts, fs, fm = interface(face_mesh((3, 2), cell, 0.0, True),
                            face_mesh((3, 2), cell, -0.1, False))
    p = mortar_pairing_3d(pts, fs, fm, cell).pairing
    big = np.argmax(np.abs(p.weights), axis=1)
    main = p.master[np.arange(len(p)), big]
    np.testing.assert_allclose(p.weights[np.arange(len(p)), big], 1.0, atol=1e-13)
    np.testing.assert_allclose(np.abs(p.weights).sum(axis=1), 1.0, atol=1e-13)
    np.testing.assert_allclose(pts[main][:, :2], pts[p.slave][:, :2], atol=1e-15)
    np.testing.assert_allclose(p.gap, 0.1, rtol=1e-13)
    t = p.tangents
    np.testing.assert_allclose(np.cross(t[:, 0], t[:, 1]), p.normal, atol=1e-15)
    np.testing.assert_allclose(np.einsum("mjx,mkx->mjk", t, t),
                               np.broadcast_to(np.eye(2), (len(p), 2, 2)), atol=1e-15)


def test_tangent_basis_of_an_oblique_normal():
    n = np.array([[1.0, 2.0, 2.0], [0.0, 0.0, -1.0]])
    n /= np.linalg.norm(n, axis=1)[:, None]
    t = tangent_basis(n)
    np.testing.assert_allclose(np.einsum("mjx,mx->mj", t, n), 0.0, atol=1e-15)
    np.testing.assert_allclose(np.cross(t[:, 0], t[:, 1]), n, atol=1e-15)


def test_partial_cover_keeps_the_identities():
    """A master covering the slave square's left part only (x ≤ 0.5, not on a slave node line):
    the half-covered faces get a dual basis biorthogonal on their covered part, so every kept
    row still transfers constants and linears exactly, and Σ w_i is the covered area."""
    slave = face_mesh((3, 3), "quad", 0.0, True)
    m = rectangle(0.5, 1.0, 2, 3, "quad")
    master = (np.column_stack([m.points, np.zeros(len(m.points))]), m.cells)
    pts, fs, fm = interface(slave, master)
    mortar = mortar_pairing_3d(pts, fs, fm, "quad")
    p = mortar.pairing
    assert np.all(pts[p.slave, 0] < 0.5 + 1 / 3)
    np.testing.assert_allclose(p.weights.sum(axis=1), 1.0, atol=1e-12)
    transfer = np.einsum("mk,mkx->mx", p.weights, pts[p.master])
    np.testing.assert_allclose(transfer, pts[p.slave], atol=1e-12)
    assert abs(mortar.weight.sum() - 0.5) < 1e-12


def test_other_faces_are_refused():
    """quad8 (no element of parsolve has them) and line faces: refused (triangle6: see
    test_mortar3d_quadratic.py)."""
    for kind, k in (("quad8", 8), ("line", 2)):
        with pytest.raises(ValueError, match="need triangle, quad or triangle6 faces"):
            faces = np.zeros((1, k), dtype=int)
            mortar_pairing_3d(np.zeros((k, 3)), faces, faces, kind)


@pytest.mark.parametrize("cell", ["quad", "triangle"])
def test_curved_interface_keeps_the_identities(cell):
    """Both sides on the cylinder z = 0.3 x² (non-matching 4×3 against 5×4, the master 0.01
    below): the rows still transfer a constant exactly (weights summing to one, so a rigid
    translation leaves the gaps unchanged), every slave node is paired, the normals unit and
    upward, the gaps the offset 0.01 within the chords' sag (κ h²/8 per side, κ = 0.6, h ≤ ¼)."""
    def bent(mesh, dz):
        p, faces = mesh
        p = p.copy()
        p[:, 2] = 0.3 * p[:, 0] ** 2 + dz
        return p, faces
    pts, fs, fm = interface(bent(face_mesh((4, 3), cell, 0.0, True), 0.0),
                            bent(face_mesh((5, 4), cell, 0.0, False), -0.01))
    p = mortar_pairing_3d(pts, fs, fm, cell).pairing
    assert np.array_equal(p.slave, np.unique(fs))
    np.testing.assert_allclose(p.weights.sum(axis=1), 1.0, atol=1e-13)
    np.testing.assert_allclose(np.linalg.norm(p.normal, axis=1), 1.0, atol=1e-15)
    assert np.all(p.normal[:, 2] > 0.8)
    assert np.all(np.abs(p.gap - 0.01) <= 2 * 0.6 * 0.25**2 / 8)


def test_surfaces_out_of_reach_give_no_rows():
    """A master 0.5 below the slave with a search radius of 0.1, or one beside it (no face
    overlapping): no row, no weight."""
    below = interface(face_mesh((2, 2), "quad", 0.0, True), face_mesh((2, 2), "quad", -0.5, False))
    beside = interface(face_mesh((2, 2), "quad", 0.0, True), face_mesh((2, 2), "quad", 0.0, False))
    beside[0][9:, 0] += 3.0
    for (pts, fs, fm), radius in ((below, 0.1), (beside, None)):
        mortar = mortar_pairing_3d(pts, fs, fm, "quad", search_radius=radius)
        assert len(mortar.pairing) == 0 and mortar.weight.size == 0
        assert overlap_areas(pts, fs, fm, "quad", radius).sum() == 0.0
