"""Coulomb friction logic on hand-made cases."""

from __future__ import annotations

import numpy as np
import pytest

from parsolve.contact.friction import (OPEN, SLIP, STICK, cone_margin, contact_states,
                                       friction_update, reactions, slip_direction)


def test_reactions_signs():
    # normal multipliers of ">=" rows are <= 0 when active: Rn = -lambda_n
    rn, rt = reactions(np.array([-2.0, -1.0, 0.0]), None, 0.3, None)
    assert np.allclose(rn, [2.0, 1.0, 0.0]) and np.allclose(rt, 0.0)
    # tangential rows (associated): force -lambda_t; friction dual adds -mu Rn s
    rn, rt = reactions(np.array([-2.0, -1.0]), np.array([[0.1], [0.0]]), 0.3,
                       np.array([[1.0], [-1.0]]))
    assert np.allclose(rt[:, 0], [-0.1 - 0.6, 0.3])
    # 3D: a direction in the tangent plane
    rn, rt = reactions(np.array([-1.0]), np.zeros((1, 2)), 0.5, np.array([[0.6, 0.8]]))
    assert np.allclose(rt, [[-0.3, -0.4]])
    assert np.isclose(cone_margin(rn, rt, 0.5)[0], 0.0, atol=1e-16)


def test_cone_margin():
    rn = np.array([1.0, 2.0, 1.0])
    rt = np.array([[0.3, 0.4], [0.0, 0.0], [-3.0, 4.0]])
    assert np.allclose(cone_margin(rn, rt, 0.5), [0.0, 1.0, -4.5])
    assert np.allclose(cone_margin(rn, np.array([0.2, -0.6, 0.0]), 0.5), [0.3, 0.4, 0.5])


def test_contact_states():
    gap = np.array([1e-3, 0.0, 0.0, 0.0, -1e-12])
    rn = np.array([0.0, 1.0, 1.0, 0.0, 2.0])
    du = np.array([0.5, 0.0, 1e-3, 1e-3, -2e-3])
    st = contact_states(gap, rn, du, tol_gap=1e-10, tol_slip=1e-9)
    assert st.dtype == np.int8
    assert st.tolist() == [OPEN, STICK, SLIP, OPEN, SLIP]


def test_slip_direction_modes():
    prev = np.array([[1.0, 0.0], [0.0, 1.0]])
    du = np.array([[3.0, 4.0], [0.0, 0.0]])
    assert np.allclose(slip_direction(prev, "displacement", slip_increment=du),
                       [[0.6, 0.8], [0.0, 1.0]])  # zero increment: keeps the previous one
    rt = np.array([[0.0, -2.0], [1.0, 0.0]])
    assert np.allclose(slip_direction(prev, "reaction", rt=rt), [[0.0, 1.0], [-1.0, 0.0]])
    # 2D: the sense
    assert np.allclose(slip_direction(np.ones(3), "reaction", rt=np.array([0.2, -0.1, 0.0])),
                       [[-1.0], [1.0], [1.0]])
    with pytest.raises(ValueError):
        slip_direction(prev, "velocity")


def test_update_2d_stick_to_slip_and_back():
    mu = 0.5
    state = np.array([STICK, STICK, SLIP, SLIP, OPEN, STICK], dtype=np.int8)
    direction = np.array([[0.0], [0.0], [1.0], [1.0], [0.0], [0.0]])
    closed = np.array([True, True, True, True, True, False])
    rn = np.array([1.0, 1.0, 1.0, 1.0, 0.0, 0.0])
    rt = np.array([0.4, -0.7, -0.5, -0.5, 0.0, 0.0])   # node 1 over the cone, pushing -x
    du = np.array([0.0, 0.0, 2e-3, -1e-3, 0.0, 0.0])    # node 3 slid backwards
    new, d, changed = friction_update(state, direction, closed, rn, rt, du, mu)
    assert changed
    assert new.tolist() == [STICK, SLIP, SLIP, STICK, STICK, OPEN]
    assert d[1, 0] == 1.0  # friction -0.7 along x: slip along +x
    assert d[2, 0] == 1.0
    # at a fixed point nothing changes
    new2, d2, changed2 = friction_update(new[:3], d[:3], closed[:3], rn[:3],
                                         np.array([0.4, -0.5, -0.5]),
                                         np.array([0.0, 1e-3, 2e-3]), mu)
    assert not changed2 and new2.tolist() == [STICK, SLIP, SLIP]


def test_update_3d_direction_follows_the_increment():
    mu = 0.3
    state = np.array([SLIP, SLIP], dtype=np.int8)
    direction = np.array([[1.0, 0.0], [0.0, 1.0]])
    closed = np.ones(2, dtype=bool)
    rn = np.array([1.0, 1.0])
    rt = -mu * direction
    du = np.array([[1.0, 1.0], [0.0, 2.0]])
    new, d, changed = friction_update(state, direction, closed, rn, rt, du, mu, "displacement")
    assert changed and new.tolist() == [SLIP, SLIP]
    assert np.allclose(d, [[np.sqrt(0.5), np.sqrt(0.5)], [0.0, 1.0]])
    new, d2, changed = friction_update(new, d, closed, rn, -mu * d, du, mu, "displacement")
    assert not changed and np.allclose(d2, d)
    # reaction mode: the total tangential reaction (with a blocked orthogonal row) sets it
    rt = np.array([[-0.2, -0.2], [0.0, -0.3]])
    new, d3, changed = friction_update(state, direction, closed, rn, rt, du, mu, "reaction")
    assert np.allclose(d3, [[np.sqrt(0.5), np.sqrt(0.5)], [0.0, 1.0]]) and changed


def test_check_mu():
    from parsolve.contact.friction import check_mu
    from parsolve.errors import InputError
    assert check_mu(0) == 0.0 and check_mu("0.3") == 0.3
    for bad in (-0.1, float("nan"), "x", None):
        with pytest.raises(InputError) as e:
            check_mu(bad, "scene.toml", "friction.mu")
        assert "scene.toml: friction.mu:" in str(e.value)


def test_signed_angles():
    from parsolve.contact.friction import signed_angle
    a = np.array([[1.0, 0.0], [0.0, 1.0], [1.0, 0.0]])
    b = np.array([[0.0, 1.0], [1.0, 0.0], [-1.0, 0.0]])
    np.testing.assert_allclose(signed_angle(a, b), [np.pi / 2, -np.pi / 2, np.pi])




@pytest.mark.parametrize("total", [0, 1, 2, 7, 40])
def test_the_surface_median_over_the_ranks_is_numpys(total):
    """The surface stiffness' median over the ranks sharing the surface (by reductions, no
    rank holding another's values) is ``np.median`` of every rank's values together, whatever
    their split (a rank holding none, ties, signed zeros, both parities); None without any.
    Run at 1, 2 and 3 ranks."""
    from mpi4py import MPI

    from parsolve.contact.friction import median

    comm = MPI.COMM_WORLD
    values = np.random.default_rng(total).normal(size=total) * 10.0 ** np.arange(total) % 7
    values[: total // 3] = values[total // 2] if total else 0.0   # (ties)
    if total > 4:
        values[:2] = [0.0, -0.0]
    cut = np.sort(np.random.default_rng(1).integers(0, total + 1, size=comm.size - 1))
    mine = np.split(values, cut)[comm.rank]
    got = median(comm, mine)
    assert got is None if total == 0 else got == np.median(values)
    assert median(None, values) == (np.median(values) if total else None)
    if total:   # a NaN on one rank: NaN on every rank, as np.median
        mine = np.append(mine, np.nan) if comm.rank == comm.size - 1 else mine
        assert np.isnan(median(comm, mine))
