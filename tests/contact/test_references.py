"""Analytic references: Hertz (Johnson), block on a plane, and the V-wedge stick/slip field,
the last two checked against the discrete equilibrium of P1/Q1 meshes (exact to round-off)."""

from __future__ import annotations

import math

import numpy as np
import pytest

from parsolve.contact import obstacles
from parsolve.contact.friction import (SLIP, STICK, cone_margin, contact_states,
                                       friction_update)
from parsolve.contact.references import (block_on_plane, effective_modulus, hertz_cylinder,
                                         hertz_sphere, sheared_block, wedge_stick_slip)
from parsolve.contact.rows import normal_rows, tangential_components
from parsolve.fem.kernels import CellGeometry, cell_dofs, internal_forces
from parsolve.mesh.generators import rectangle
from parsolve.mesh.topology import boundary_facets


# ----------------------------------------------------------------------------- Hertz


def test_effective_modulus_steel_on_steel():
    # Johnson's E* for two identical bodies: E / (2 (1 - nu^2)); steel 210 GPa, nu 0.3
    assert math.isclose(effective_modulus(210e9, 0.3, 210e9, 0.3), 210e9 / (2 * 0.91), rel_tol=1e-15)
    assert math.isclose(effective_modulus(70e9, 0.25), 70e9 / (1 - 0.0625), rel_tol=1e-15)


def test_hertz_cylinder_against_johnson_forms():
    P, R, E = 1.5e5, 0.02, effective_modulus(210e9, 0.3, 210e9, 0.3)
    h = hertz_cylinder(P, R, E)
    # Johnson (4.45)-(4.46): p0 = (P E* / (pi R))^(1/2), a = 2 R p0 / E* ... a^2 = 4 P R / (pi E*)
    assert math.isclose(h.p0, math.sqrt(P * E / (math.pi * R)), rel_tol=1e-14)
    assert math.isclose(h.a, 2 * R * h.p0 / E, rel_tol=1e-14)
    # the pressure integrates to the load (Gauss-Chebyshev of the second kind, exact here)
    n = 50
    k = np.arange(1, n + 1)
    x = np.cos(k * np.pi / (n + 1))
    w = np.pi / (n + 1) * np.sin(k * np.pi / (n + 1)) ** 2
    assert math.isclose(h.a * h.p0 * w.sum(), P, rel_tol=1e-13)
    assert np.allclose(h.pressure(h.a * x), h.p0 * np.sqrt(1 - x**2), rtol=1e-14)
    assert h.pressure(np.array([1.01 * h.a]))[0] == 0.0
    # by hand: P = 2, R = 1/2, E* = 4/pi give a^2 = 4 * 2 * (1/2) / 4 = 1 and p0 = 2 * 2 / pi
    h = hertz_cylinder(2.0, 0.5, 4.0 / math.pi)
    assert math.isclose(h.a, 1.0, rel_tol=1e-15) and math.isclose(h.p0, 4.0 / math.pi, rel_tol=1e-15)


def test_hertz_sphere_against_johnson_forms():
    P, R, E = 100.0, 0.01, effective_modulus(210e9, 0.3, 210e9, 0.3)
    h = hertz_sphere(P, R, E)
    # Johnson (4.22)-(4.23): delta = (9 P^2 / (16 R E*^2))^(1/3), p0 = (6 P E*^2/(pi^3 R^2))^(1/3)
    assert math.isclose(h.delta, (9 * P**2 / (16 * R * E**2)) ** (1 / 3), rel_tol=1e-14)
    assert math.isclose(h.p0, (6 * P * E**2 / (math.pi**3 * R**2)) ** (1 / 3), rel_tol=1e-14)
    # P = 4 E* a^3 / (3 R) and the pressure integrates to P: 2 pi a^2 p0 / 3
    assert math.isclose(4 * E * h.a**3 / (3 * R), P, rel_tol=1e-14)
    r = np.linspace(0, h.a, 200001)
    f = 2 * np.pi * r * h.pressure(r)
    assert math.isclose(np.sum((f[1:] + f[:-1]) / 2) * (r[1] - r[0]), P, rel_tol=1e-6)
    # by hand: P = 8, R = 1, E* = 3/4 give a^3 = 3 * 8 / 3 = 8, p0 = 24 / (8 pi), delta = 4
    h = hertz_sphere(8.0, 1.0, 0.75)
    assert math.isclose(h.a, 2.0, rel_tol=1e-15) and math.isclose(h.p0, 3.0 / math.pi, rel_tol=1e-15)
    assert math.isclose(h.delta, 4.0, rel_tol=1e-15)


# ----------------------------------------------------------------------------- discrete checks


def contact_forces(mesh, stress: np.ndarray, contact_nodes: np.ndarray) -> np.ndarray:
    """Nodal forces (npts, 2) that the contact must supply for the homogeneous stress to be
    in discrete equilibrium: f_int - f_ext, with f_ext the consistent load of sigma . n on
    every boundary facet not lying on the contact."""
    geo = CellGeometry(mesh.points[mesh.cells], mesh.cell_type)
    B = geo.strain_operator()
    sig = np.broadcast_to([stress[0, 0], stress[1, 1], stress[0, 1]], B.shape[:2] + (3,))
    fe = internal_forces(B, geo.wdet, sig)
    f = np.zeros(mesh.num_points * 2)
    np.add.at(f, cell_dofs(mesh.cells, 2), fe)
    f = f.reshape(-1, 2)
    facets = boundary_facets(mesh)[0]
    on_contact = np.isin(facets, contact_nodes).all(axis=1)
    a, b = mesh.points[facets[~on_contact, 0]], mesh.points[facets[~on_contact, 1]]
    nl = np.column_stack([(b - a)[:, 1], -(b - a)[:, 0]])  # outward normal times length
    t = nl @ stress.T / 2.0                                # half the facet load to each end
    np.add.at(f, facets[~on_contact, 0], -t)
    np.add.at(f, facets[~on_contact, 1], -t)
    return f


def wedge_mesh(beta: float, cell: str, nx: int = 12, ny: int = 5, height: float = 1.0):
    """A block over the V: bottom y = -x tan(beta) for x < 0, y = 0 for x >= 0, top y = H."""
    m = rectangle(2.0, 1.0, nx, ny, cell, origin=(-1.0, 0.0))
    x, eta = m.points[:, 0], m.points[:, 1]
    yb = np.where(x < 0, -x * math.tan(beta), 0.0)
    m.points[:, 1] = yb + eta * (height + 1.0 - yb)
    return m


@pytest.mark.parametrize("cell", ["quad", "triangle"])
def test_wedge_stick_and_slip_side_by_side_is_exact(cell):
    E, nu, beta = 1000.0, 0.3, math.radians(35.0)
    lam, g = E * nu / ((1 + nu) * (1 - 2 * nu)), E / (2 * (1 + nu))
    ref = wedge_stick_slip(lam, g, beta, kappa=-2e-3)
    assert math.isclose(ref.mu, (1 - 2 * nu) / (2 * nu) / math.tan(beta), rel_tol=1e-14)
    mesh = wedge_mesh(beta, cell)
    bottom = mesh.node_groups["bottom"]
    f = contact_forces(mesh, ref.stress, bottom)
    scale = np.abs(f).max()
    free = np.setdiff1d(np.arange(mesh.num_points), bottom)
    assert np.abs(f[free]).max() < 1e-13 * scale  # equilibrium everywhere off the contact
    x = mesh.points[bottom, 0]
    face2, face1 = bottom[x < -1e-12], bottom[x > 1e-12]
    u = ref.displacement(mesh.points)

    # face 2: closed, slipping (s = -1 along t2), friction at the cone opposing the slip
    p2 = obstacles.plane(mesh.points, face2, [0.0, 0.0], ref.normal2)
    assert np.allclose(p2.gap, 0.0, atol=1e-14) and np.allclose(p2.tangents[:, 0], ref.tangent2)
    assert np.allclose(normal_rows(p2).apply(u), 0.0, atol=1e-16)
    slip = tangential_components(p2, u)[:, 0]
    assert np.all(slip < 0) and np.allclose(slip, ref.kappa * mesh.points[face2, 1], atol=1e-16)
    rn2, rt2 = f[face2] @ ref.normal2, f[face2] @ ref.tangent2
    assert np.all(rn2 > 0)
    assert np.allclose(rt2, ref.mu * rn2, rtol=1e-12, atol=0)  # Rt = -mu Rn s with s = -1
    assert np.abs(cone_margin(rn2, rt2, ref.mu)).max() < 1e-12 * rn2.max()
    assert np.all(contact_states(p2.gap, rn2, slip, 1e-12, 1e-12) == SLIP)
    st, d, changed = friction_update(np.full(face2.size, SLIP, np.int8), -np.ones(face2.size),
                                     np.ones(face2.size, bool), rn2, rt2, slip, ref.mu)
    assert not changed and np.all(st == SLIP)

    # face 1: stuck (u = 0), strictly inside the cone
    p1 = obstacles.plane(mesh.points, face1, [0.0, 0.0], ref.normal1)
    assert np.abs(u[face1]).max() == 0.0
    rn1, rt1 = f[face1] @ ref.normal1, f[face1] @ p1.tangents[0, 0]
    assert np.all(rn1 > 0)
    assert np.allclose(rt1 / rn1, g / (lam + 2 * g) / math.tan(beta), rtol=1e-12)
    assert np.all(cone_margin(rn1, rt1, ref.mu) > 0.5 * ref.mu * rn1)
    assert np.all(contact_states(p1.gap, rn1, np.zeros(face1.size), 1e-12, 1e-12) == STICK)
    # the analytic tractions, integrated, match the nodal forces face by face (each face has
    # 6 segments; the apex's half segment of each face is not counted in face1/face2)
    len2, share = 1.0 / math.cos(beta), 1.0 - 1.0 / 12.0
    assert math.isclose(rn2.sum(), ref.face2[0] * len2 * share, rel_tol=1e-12)
    assert math.isclose(rt2.sum(), ref.face2[1] * len2 * share, rel_tol=1e-12)
    assert math.isclose(rn1.sum(), ref.face1[0] * 1.0 * share, rel_tol=1e-12)
    assert math.isclose(rt1.sum(), ref.face1[1] * 1.0 * share, rel_tol=1e-12)
    # the apex carries half a facet of each face: stuck, inside the cone of face 1's normal
    apex = bottom[np.abs(x) <= 1e-12]
    fa = f[apex[0]]
    assert cone_margin(np.array([fa @ ref.normal1]), np.array([fa @ p1.tangents[0, 0]]), ref.mu)[0] > 0


@pytest.mark.parametrize("shift", [0.5e-3, 3e-3])
@pytest.mark.parametrize("cell", ["quad", "triangle"])
def test_sheared_block_stick_and_uniform_slip(shift, cell):
    E, nu, p, mu, H = 200.0, 0.25, 1.0, 0.4, 0.5
    lam, g = E * nu / ((1 + nu) * (1 - 2 * nu)), E / (2 * (1 + nu))
    ref = sheared_block(lam, g, p, mu, H, shift)
    assert ref.sliding == (g * shift / H >= mu * p)
    mesh = rectangle(1.0, H, 6, 3, cell)
    bottom = mesh.node_groups["bottom"]
    f = contact_forces(mesh, ref.stress, bottom)
    free = np.setdiff1d(np.arange(mesh.num_points), bottom)
    assert np.abs(f[free]).max() < 1e-13 * np.abs(f).max()
    u = ref.displacement(mesh.points)
    assert np.allclose(u[mesh.node_groups["top"], 0], shift, atol=1e-16)
    pl = obstacles.plane(mesh.points, bottom, [0, 0], [0, 1])
    rn, rt = f[bottom, 1], f[bottom] @ pl.tangents[0, 0]
    assert np.isclose(rn.sum(), p * 1.0, rtol=1e-13)
    res = block_on_plane(rn.sum(), g * shift / H * 1.0, mu)
    assert res.sliding == ref.sliding
    # friction along t = (-1, 0): Rt = tau; the resultant equals the reference's T
    assert np.isclose(rt.sum(), res.tangential, rtol=1e-12)
    slip = tangential_components(pl, u)[:, 0]
    if ref.sliding:
        assert np.allclose(cone_margin(rn, rt, mu), 0.0, atol=1e-13)
        assert np.allclose(slip, -ref.slip) and ref.slip > 0  # slides along +x = -t
        assert np.all(contact_states(pl.gap, rn, slip, 0, 1e-12) == SLIP)
    else:
        assert np.all(cone_margin(rn, rt, mu) > 0) and np.all(slip == 0.0)
        assert np.all(contact_states(pl.gap, rn, slip, 0, 1e-12) == STICK)


def test_block_resultants():
    r = block_on_plane(10.0, 2.0, 0.3)
    assert not r.sliding and r.tangential == 2.0
    r = block_on_plane(10.0, -5.0, 0.3)
    assert r.sliding and r.tangential == -3.0


def test_wedge_rejects_bad_parameters():
    with pytest.raises(ValueError):
        wedge_stick_slip(1.0, 1.0, 0.0)
    with pytest.raises(ValueError):
        wedge_stick_slip(1.0, 1.0, 0.5, kappa=1e-3)
