"""Contact rows that depend on other relations (issue 17): a corner that a Dirichlet condition
holds on a contact surface, a periodic tie between two contact nodes, two contact surfaces
sharing a node. Each is solved (the dependent rows left out, ``parsolve.contact.dependent``)
and gives the displacements of the same scene with the node out of the (second) surface, to
round-off; on 1, 2 and 3 ranks."""

from __future__ import annotations

import numpy as np
import pytest

from parsolve.contact.dependent import dependent_rows

# a block pressed on a rigid plane and pushed sideways, a top corner held along x (the
# frictionless block would slide away); the shear stays below μ N
BLOCK = """
[mesh]
generator = "rectangle"
lx = 1.0
ly = 0.5
nx = 8
ny = 4
cell = "quad"
[model]
hypothesis = "plane_strain"
[regions]
corner = {{ point = [0.0, 0.0] }}
top_left = {{ point = [0.0, 0.5] }}
pair = "y < 1e-9 and (abs(x - 0.25) < 1e-9 or abs(x - 0.75) < 1e-9)"
but_corner = "y < 1e-9 and x > 1e-9"
but_b = "y < 1e-9 and abs(x - 0.75) > 1e-9"
left = "y < 1e-9 and x <= 0.5"
right = "y < 1e-9 and x >= 0.5"
[[materials]]
E = 1000.0
nu = 0.3
[[loads]]
name = "press"
region = "top"
traction = [2.0, -10.0]
evolution = "constant"
[[relations]]
name = "side"
type = "dirichlet"
region = "top_left"
component = "x"
value = 0.0
{relations}
{contacts}
[steps]
count = 2
"""

PLANE = 'obstacle = {{ plane = {{ origin = [0.0, 0.0], normal = [0.0, 1.0] }} }}'


def contact(name: str, slave: str, mu: float) -> str:
    return (f'[[contact]]\nname = "{name}"\nslave = "{slave}"\n'
            f'{PLANE.format()}\nfriction = {mu}\n')


HOLD = '[[relations]]\nname = "hold"\ntype = "dirichlet"\nregion = "corner"\n' \
       'components = ["x", "y"]\nvalue = 0.0\n'
TIE = ''.join(f'[[relations]]\nname = "tie_{c}"\ntype = "equal"\nregion = "pair"\n'
              f'component = "{c}"\n' for c in "xy")

CASES = {
    # a held corner in the contact surface / out of it
    "held_corner": (HOLD, [("base", "bottom")], HOLD, [("base", "but_corner")]),
    # a periodic tie between two contact nodes / the second node out of the surface
    "tie": (TIE, [("base", "bottom")], TIE, [("base", "but_b")]),
    # two surfaces sharing the middle node / one surface
    "shared_node": ("", [("base", "left"), ("more", "right")], "", [("base", "bottom")]),
}


def scene(relations: str, contacts: list, mu: float) -> str:
    return BLOCK.format(relations=relations,
                        contacts="".join(contact(n, s, mu) for n, s in contacts))


@pytest.mark.parametrize("mu", [0.0, 0.3])
@pytest.mark.parametrize("case", list(CASES))
def test_dependent_rows_give_the_answer_without_them(run, case, mu):
    rel, con, ref_rel, ref_con = CASES[case]
    res = run(scene(rel, con, mu), name=f"dep_{case}_{mu}")
    ref = run(scene(ref_rel, ref_con, mu), name=f"dep_{case}_{mu}_ref")
    u, u_ref = res["fields/displacement"], ref["fields/displacement"]
    assert np.abs(u_ref[-1]).max() > 1e-3
    np.testing.assert_allclose(u, u_ref, rtol=0, atol=1e-12 * np.abs(u_ref).max())
    # the plane and the hold carry the press (λ is minus the reaction; the node's share goes
    # to the rows its contact row depends on)
    names = [n for n, _ in con]
    total = sum(res[f"relations/{n}_normal/normal_force"][:, 0] for n in names)
    held = res["relations/hold/multiplier"][:, 1] if case == "held_corner" else 0.0
    np.testing.assert_allclose(total - held, 10.0, rtol=1e-11)
    for n in names:
        assert res[f"fields/{n}_gap"].min() >= -1e-12
    if case == "held_corner":   # the corner's reaction is the one without the contact row
        np.testing.assert_allclose(res["relations/hold/multiplier"],
                                   ref["relations/hold/multiplier"], atol=1e-11)
    assert res["steps/iterations"].max() <= 3


# ----------------------------------------------------------------------------- the row test


def _coo(dense: np.ndarray):
    rows, dofs = np.nonzero(dense)
    return rows, dofs, dense[rows, dofs]


def test_dependent_rows_on_known_blocks():
    """Rows (in order): a tie u1 - u2, contact rows on u1 and u2 (the second depends on the
    first and the tie), a contact row on a held DOF u0 (no free entry left), a contact row
    with a DOF of its own (u3), a contact row equal to 2× the first contact row."""
    a = np.array([[0, 1, -1, 0, 0],
                  [0, 1, 0, 0, 0],
                  [0, 0, 1, 0, 0],
                  [1, 0, 0, 0, 0],
                  [0, 1, 1, 1, 0],
                  [0, 2, 0, 0, 0]], dtype=float)
    rows, dofs, vals = _coo(a)
    candidate = np.array([False, True, True, True, True, True])
    enforced = np.ones(6, dtype=bool)
    dep = dependent_rows(rows, dofs, vals, 6, enforced, candidate, np.array([0]))
    assert dep.tolist() == [False, False, True, True, False, True]
    # the second contact row released: the last one now depends on the first alone
    enforced[2] = False
    dep = dependent_rows(rows, dofs, vals, 6, enforced, candidate, np.array([0]))
    assert dep.tolist() == [False, False, False, True, False, True]
    # nothing held, the tie not enforced: only the doubled row depends
    enforced[:] = [False, True, True, True, True, True]
    dep = dependent_rows(rows, dofs, vals, 6, enforced, candidate, np.zeros(0, np.int64))
    assert dep.tolist() == [False, False, False, False, False, True]


BOX = """
[mesh]
generator = "box"
lx = 1.0
ly = 1.0
lz = 0.5
nx = 4
ny = 4
nz = 2
[model]
hypothesis = "3d"
[regions]
corner = {{ point = [0.0, 0.0, 0.0] }}
but_corner = "z < 1e-9 and (x > 1e-9 or y > 1e-9)"
[[materials]]
E = 1000.0
nu = 0.3
[[loads]]
name = "press"
region = "zmax"
traction = [1.0, 0.5, -10.0]
evolution = "constant"
[[relations]]
name = "hold"
type = "dirichlet"
region = "corner"
components = ["x", "y", "z"]
value = 0.0
[[contact]]
name = "base"
slave = "{slave}"
obstacle = {{ plane = {{ origin = [0.0, 0.0, 0.0], normal = [0.0, 0.0, 1.0] }} }}
friction = 0.3
[steps]
count = 2
"""


def test_held_corner_in_3d_with_friction(run):
    """The 3D box on a rough plane (three rows per node: normal, along s and across it), its
    bottom corner held in x, y, z: the corner's three rows are left out, the answer is the
    one with the corner out of the contact surface."""
    res = run(BOX.format(slave="zmin"), name="dep_box")
    ref = run(BOX.format(slave="but_corner"), name="dep_box_ref")
    u, u_ref = res["fields/displacement"], ref["fields/displacement"]
    assert np.abs(u_ref[-1]).max() > 1e-3
    np.testing.assert_allclose(u, u_ref, rtol=0, atol=1e-12 * np.abs(u_ref).max())
    np.testing.assert_allclose(res["relations/hold/multiplier"],
                               ref["relations/hold/multiplier"], atol=1e-11)
    np.testing.assert_allclose(res["relations/base_normal/normal_force"],
                               ref["relations/base_normal/normal_force"], rtol=1e-12)


def test_rows_of_one_node_on_an_inclined_surface_are_peeled():
    """The normal and tangential rows of a node on an inclined plane share both its DOFs (no
    DOF of their own) but are independent there: set aside by their node, so the dense block
    is not the whole surface. A third row on the node (a tie along x to another node) keeps
    them in it, and there the tangential row of the second node depends on the rest."""
    from parsolve.contact.dependent import _own_node

    n, t = np.array([-0.5, np.sqrt(3) / 2]), np.array([np.sqrt(3) / 2, 0.5])
    a = np.zeros((4, 4))             # nodes 0, 1 (DOFs 0, 1 and 2, 3), ncomp = 2
    a[0, :2], a[1, :2], a[2, 2:], a[3, 2:] = n, t, n, t
    rows, dofs, vals = _coo(a)
    assert _own_node(rows, dofs, vals, 4, 2).all()
    tie = np.vstack([a, [[1.0, 0, -1.0, 0], [0, 1.0, 0, -1.0]]])
    rows, dofs, vals = _coo(tie)
    assert not _own_node(rows, dofs, vals, 6, 2).any()
    candidate = np.array([True, True, True, True, False, False])
    dep = dependent_rows(rows, dofs, vals, 6, np.ones(6, bool), candidate, np.zeros(0, np.int64), 2)
    assert dep.tolist() == [False, False, True, True, False, False]


def test_held_corner_pushed_into_the_plane_is_an_error(run):
    """The hold moves the corner 0.01 into the plane: its contact row, left out, is violated by
    the rows it depends on. An error naming the row and the node, not a penetrating answer."""
    from parsolve.errors import SolverError

    pushed = HOLD.replace("value = 0.0", "value = -0.01")
    with pytest.raises(SolverError, match=r"row 0 of 'base_normal' \(node 0\).*into the obstacle"):
        run(scene(pushed, [("base", "bottom")], 0.0), name="dep_pushed")


@pytest.mark.parametrize("mu", [0.0, 0.3])
def test_a_held_contact_node_is_written_open(run, mu):
    """The held corner's contact row is left out (the hold carries its reaction): its state
    is written open (0) with its normal reaction 0, never stick without a force; every other
    node of the surface that the written state says is closed carries a normal reaction."""
    rel, con, _, _ = CASES["held_corner"]
    res = run(scene(rel, con, mu), name=f"held_state_{mu}")
    x = res["mesh/points"]
    corner = np.flatnonzero((np.abs(x[:, 0]) < 1e-12) & (np.abs(x[:, 1]) < 1e-12))
    state = res["fields/base_state"][:, :, 0]
    rn = res["fields/base_normal_reaction"][:, :, 0]
    assert state[:, corner].tolist() == [[0]] * len(state) and not rn[:, corner].any()
    closed = state > 0
    assert closed.sum() >= len(state) * 7   # the rest of the bottom (8 nodes) is in contact
    assert (rn[closed] > 1e-6 * rn.max()).all(), (state, rn)
