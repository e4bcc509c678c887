"""A body held only by contact (issue 17): a pad 2 units above an inclined plane (30°), its
bottom parallel to it, pressed down by a vertical traction, nothing else holding it in the
contact direction. Every contact row is open at the first iteration, so the first operator is
singular; the solver then starts the rows closed and the active set opens those that pull.
Default settings (no ``closed``): it converges, lands on the plane, and the contact forces
balance the load to 1e-10; identical on 1, 2 and 3 ranks."""

from __future__ import annotations

import numpy as np
import pytest
from mpi4py import MPI

ANGLE = np.pi / 6
LIFT, LX, LY, P = 2.0, 1.0, 0.5, 10.0
T = np.array([np.cos(ANGLE), np.sin(ANGLE)])     # along the plane (rising)
N = np.array([-np.sin(ANGLE), np.cos(ANGLE)])    # the plane's normal


def pad_mesh(path, nx: int = 8, ny: int = 4, soft: int = 2) -> None:
    """An LX × LY pad of quads, its bottom on the line at LIFT along N from the plane through
    the origin, parallel to it, under a layer of ``soft`` rows of cells (height LY / 2).
    Groups: pad, layer (cells), bottom, top (the pad's top), hold (the layer's top)."""
    import meshio

    eta = np.concatenate([np.linspace(0, LY, ny + 1), LY + np.linspace(0, LY / 2, soft + 1)[1:]])
    xi, eta = np.meshgrid(np.linspace(0, LX, nx + 1), eta)
    pts = (xi[..., None] * T + (eta[..., None] + LIFT) * N).reshape(-1, 2)
    ids = np.arange(pts.shape[0]).reshape(ny + soft + 1, nx + 1)
    quads = np.stack([ids[:-1, :-1], ids[:-1, 1:], ids[1:, 1:], ids[1:, :-1]], -1).reshape(-1, 4)

    def edges(line):
        return np.stack([line[:-1], line[1:]], -1)

    blocks = [("quad", quads[:ny * nx]), ("quad", quads[ny * nx:]), ("line", edges(ids[0])),
              ("line", edges(ids[ny][::-1])), ("line", edges(ids[-1][::-1]))]
    phys = [np.full(len(b[1]), tag) for b, tag in zip(blocks, (1, 2, 10, 11, 12))]
    field = {"pad": np.array([1, 2]), "layer": np.array([2, 2]), "bottom": np.array([10, 1]),
             "top": np.array([11, 1]), "hold": np.array([12, 1])}
    meshio.write(str(path), meshio.Mesh(np.column_stack([pts, np.zeros(len(pts))]), blocks,
                                        cell_data={"gmsh:physical": phys,
                                                   "gmsh:geometrical": phys},
                                        field_data=field), file_format="gmsh22", binary=False)


def scene(mesh, mu: float, load, guide: str = "", layer: str = "") -> str:
    return f"""
[mesh]
file = "{mesh}"
[model]
hypothesis = "plane_strain"
[regions]
corner = {{ point = [{(LIFT + LY) * N[0]!r}, {(LIFT + LY) * N[1]!r}] }}
[[materials]]
region = "pad"
E = 1000.0
nu = 0.3
{layer}
[[loads]]
name = "press"
region = "pad"
body = [{load[0] / (LX * LY)!r}, {load[1] / (LX * LY)!r}]
{guide}
[[contact]]
name = "base"
slave = "bottom"
obstacle = {{ plane = {{ origin = [0.0, 0.0], normal = [{N[0]!r}, {N[1]!r}] }} }}
friction = {mu}
[steps]
count = 4
"""


# a tangential guide at the top corner (t · u = 0): the frictionless pad pressed along -N
GUIDE = f"""[[relations]]
name = "guide"
type = "linear"
terms = [{{ region = "corner", component = "x", coefficient = {T[0]!r} }},
         {{ region = "corner", component = "y", coefficient = {T[1]!r} }}]
value = 0.0
"""

# the layer on top: soft (1e-9 of the pad) and held at its top, or void (nothing holds it)
SOFT = """[[materials]]
region = "layer"
E = 1e-6
nu = 0.3
[[relations]]
name = "hang"
type = "dirichlet"
region = "hold"
components = ["x", "y"]
value = 0.0
"""
VOID = """[[materials]]
region = "layer"
E = 1e-9
nu = 0.3
"""

CASES = {
    # rough (μ = 0.8 > tan 30°): held by contact alone, the vertical press
    "rough": (0.8, (0.0, -P), "", VOID),
    # frictionless, pressed along -N, guided along the plane at one node
    "frictionless": (0.0, tuple(-P * N), GUIDE, VOID),
    # rough, hanging from a soft layer (a weak elastic support: the first solve's operator is
    # ill-conditioned, not singular; the layer carries 1e-9 of the load)
    "soft_support": (0.8, (0.0, -P), "", SOFT),
}


@pytest.mark.parametrize("case", list(CASES))
def test_pad_floating_until_contact_converges_with_defaults(run, shared_tmp, case):
    mesh = shared_tmp / "pad.msh"
    if MPI.COMM_WORLD.rank == 0:
        pad_mesh(mesh)
    MPI.COMM_WORLD.Barrier()
    mu, load, guide, layer = CASES[case]
    res = run(scene(mesh, mu, load, guide, layer), name=f"pad_{case}")
    t = res["steps/time"]
    force = np.outer(t, np.asarray(load))                 # the press's resultant (ramped)
    rn = res["relations/base_normal/normal_force"][:, 0]
    rt = res["relations/base_normal/tangential_force"][:, 0]
    # the plane balances the press: Rn = -F·N, Rt (along the plane's tangent t = (-N_y, N_x)
    # = -T) = F·T ... to 1e-10 of the load
    held = 0.0
    if case == "soft_support":   # the layer's share (λ is minus the reaction), ~1e-9 of it
        hang = res["relations/hang/multiplier"].reshape(len(t), -1, 2).sum(axis=1)
        held = -hang
        assert np.abs(hang).max() < 1e-6 * P
    np.testing.assert_allclose(rn, -(force + held) @ N, rtol=0, atol=1e-10 * P)
    if mu > 0:
        np.testing.assert_allclose(rt, (force + held) @ T, rtol=0, atol=1e-10 * P)
        assert np.all(np.abs(rt) <= mu * rn)
    else:
        assert np.all(rt == 0.0)
    # the pad has landed: nothing penetrates, the bottom moved by LIFT along -N on average
    assert res["fields/base_gap"].min() >= -1e-12
    slave = res["fields/base_state"][-1, :, 0] >= 0
    closed = res["fields/base_state"][-1, :, 0] > 0
    u = res["fields/displacement"][-1]
    np.testing.assert_allclose(u[closed] @ N, -LIFT, rtol=1e-12)
    assert abs(u[slave].mean(axis=0) @ N + LIFT) < 0.01 * LIFT
    assert res["steps/cuts"].max() == 0
