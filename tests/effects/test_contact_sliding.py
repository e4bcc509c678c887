"""Finite sliding (``[[contact]] sliding = "finite"``, 2D node-to-segment): the pairing is made
again on the current configuration at each step over fixed row spans, the slip history
carried across facets.

A deformable base (the slave: its top nodes) under a die (the master: its bottom facets)
that presses it by δ and is dragged by d(t) over more than three of its own facets. The die's
nodes are all held (a rigid die moved by a rigid translation), so the base's field is the
homogeneous one of docs/contact.md §6 turned upside down: stick while G d / H < μ p, then full
slip with σ_xy = μ p; linear, so Q1 reproduces it to round-off at every step whichever die
facet each slave faces."""

from __future__ import annotations

import numpy as np
import pytest
from mpi4py import MPI

from parsolve.contact.friction import SLIP, STICK
from parsolve.mesh.generators import rectangle

E, NU = 1000.0, 0.3
LAM, G = E * NU / ((1 + NU) * (1 - 2 * NU)), E / (2 * (1 + NU))   # plane strain
HB, DELTA, MU = 0.5, 0.1, 0.5
P = (LAM + 2 * G) * DELTA / HB          # the base's uniform pressure
D_END = 0.55                            # the die's travel: 4.4 of its facets (0.125)


def base_and_die(path, nx_base: int = 6, ny_base: int = 3, nx_die: int = 16) -> None:
    """Gmsh 2.2 file: cells base ([0, 1] × [0, HB]) and die ([-0.75, 1.25] × [HB, HB + 0.25]),
    facet groups base_top/bottom/left/right and die_bottom; the interface nodes distinct."""
    import meshio

    base = rectangle(1.0, HB, nx_base, ny_base)
    die = rectangle(2.0, 0.25, nx_die, 1, origin=(-0.75, HB))
    off = base.num_points
    points = np.vstack([base.points, die.points])
    lines = [(f"base_{s}", base.facet_groups[s]) for s in ("top", "bottom", "left", "right")]
    lines += [("die_bottom", die.facet_groups["bottom"] + off)]
    blocks = [("quad", base.cells), ("quad", die.cells + off)] + [("line", f) for _, f in lines]
    tags = [1, 2] + [10 + i for i in range(len(lines))]
    phys = [np.full(len(b[1]), tag) for b, tag in zip(blocks, tags)]
    field = {"base": np.array([1, 2]), "die": np.array([2, 2])}
    field.update({name: np.array([10 + i, 1]) for i, (name, _) in enumerate(lines)})
    mesh = meshio.Mesh(np.column_stack([points, np.zeros(len(points))]), blocks,
                       cell_data={"gmsh:physical": phys, "gmsh:geometrical": phys},
                       field_data=field)
    meshio.write(str(path), mesh, file_format="gmsh22", binary=False)


def scene(mesh, sliding: str = "finite", steps: int = 10) -> str:
    gy = -DELTA / HB
    sxx, tau = LAM * gy, MU * P
    t_star = MU * P * HB / (G * D_END)
    return f"""
[mesh]
file = "{mesh}"
[model]
hypothesis = "plane_strain"
[[materials]]
E = {E}
nu = {NU}
[[loads]]
name = "side_n"
region = "base_right"
traction = [{sxx!r}, 0.0]
evolution = "constant"
[[loads]]
name = "side_n_left"
region = "base_left"
traction = [{-sxx!r}, 0.0]
evolution = "constant"
[[loads]]
name = "side_t"
region = "base_right"
traction = [0.0, {tau!r}]
evolution = "shear"
[[loads]]
name = "side_t_left"
region = "base_left"
traction = [0.0, {-tau!r}]
evolution = "shear"
[[relations]]
name = "ground"
type = "dirichlet"
region = "base_bottom"
components = ["x", "y"]
[[relations]]
name = "drag"
type = "dirichlet"
region = "die"
component = "x"
value = {D_END}
[[relations]]
name = "press"
type = "dirichlet"
region = "die"
component = "y"
value = {-DELTA}
evolution = "constant"
[[contact]]
name = "slide"
slave = "base_top"
master = "die_bottom"
friction = {MU}
search_radius = 0.7
sliding = "{sliding}"
[evolutions.shear]
times = [0.0, {t_star!r}, 2.0]
values = [0.0, 1.0, 1.0]
[steps]
count = {steps}
"""


def exact_base(pts: np.ndarray, d: float) -> tuple[np.ndarray, bool, float]:
    """The base's homogeneous field for the die at d: (u, sliding, σ_xy)."""
    tau = min(G * d / HB, MU * P)
    gx = tau / G
    u = np.column_stack([gx * pts[:, 1], -DELTA / HB * pts[:, 1]])
    return u, G * d / HB > MU * P * (1 + 1e-12), tau


@pytest.fixture
def mesh(shared_tmp):
    path = shared_tmp / "base_and_die.msh"
    if MPI.COMM_WORLD.rank == 0:
        base_and_die(path)
    MPI.COMM_WORLD.Barrier()
    return path


def test_die_dragged_over_four_facets_is_exact(run, mesh):
    res = run(scene(mesh), name="sliding_die")
    pts = res["mesh/points"]
    base = pts[:, 1] <= HB + 1e-12
    base &= np.arange(len(pts)) < 7 * 4        # the base's nodes come first (7 × 4)
    top = base & np.isclose(pts[:, 1], HB)
    die = np.arange(len(pts)) >= 28
    times = res["steps/time"]
    u_all = res["fields/displacement"]
    slid = []
    for k, t in enumerate(times):
        d = D_END * t
        u_ref, sliding, tau = exact_base(pts[base], d)
        scale = max(np.abs(u_all[k]).max(), 1e-300)
        # the base: the homogeneous field; the die: its rigid translation
        np.testing.assert_allclose(u_all[k][base], u_ref, atol=1e-10 * scale, rtol=0)
        np.testing.assert_allclose(u_all[k][die], np.tile([d, -DELTA], (die.sum(), 1)),
                                   atol=1e-12 * scale, rtol=0)
        state = res["fields/slide_state"][k, :, 0]
        assert np.all(state[top] == (SLIP if sliding else STICK)), (t, state[top])
        n_force = res["relations/slide_normal/normal_force"][k, 0]
        t_force = res["relations/slide_normal/tangential_force"][k, 0]
        np.testing.assert_allclose(n_force, P * 1.0, rtol=1e-10)
        np.testing.assert_allclose(t_force, tau * 1.0, rtol=1e-10)
        if sliding:   # full slip: T = μN
            np.testing.assert_allclose(abs(t_force), MU * n_force, rtol=1e-10)
        # the slip carried across facets: the base top relative to the die
        np.testing.assert_allclose(res["fields/slide_slip"][k, top, 0],
                                   u_ref[top[base]][:, 0] - d, atol=1e-10 * D_END, rtol=0)
        # global equilibrium: the held nodes' reactions balance (the side loads cancel)
        total = res["relations/ground/resultant"][k] + res["relations/drag/resultant"][k] \
            + res["relations/press/resultant"][k]
        np.testing.assert_allclose(total[:2], 0.0, atol=1e-10 * P)
        slid.append(sliding)
    assert not slid[0] and slid[-1]
    assert D_END > 3 * 0.125
    print("iterations per step:", list(res["steps/iterations"]))
