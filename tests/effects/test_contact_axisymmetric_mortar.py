"""Axisymmetric mortar contact: the contact patch test on a surface of revolution. Two stacked
cylinders of radius 1 (heights 0.5 and 0.5, 3 and 4 quads across: a non-matching interface),
the lower one held axially at its base, the upper one pressed by δ at its top, both on the
axis (u_r = 0 there), frictionless. The exact field is uniaxial, σ_zz = −E δ / h, u_r =
ν δ r / h, u_z = −δ z / h: mortar rows weighted by r (the integrals over the surface of
revolution) transmit it to round-off; node-to-segment rows on the same interface do not (the
nodes' forces of a uniform pressure are not r-proportional on a non-matching mesh)."""

from __future__ import annotations

import numpy as np
import pytest
from mpi4py import MPI

from conftest import assert_same_results
from helpers.scene import scene as build
from helpers.scripts import load_script

E, NU, H1, H2, DELTA = 1000.0, 0.3, 0.5, 0.5, 0.01
MESHES = load_script("make_ironing_2d_mesh")


@pytest.fixture
def mesh(shared_tmp):
    path = shared_tmp / "stacked_cylinders.msh"
    if MPI.COMM_WORLD.rank == 0:
        MESHES.base_and_die(path, (1.0, H1, 3, 2), (1.0, H2, 4, 2, 0.0))
    MPI.COMM_WORLD.Barrier()
    return path


def scene(mesh, discretization: str) -> str:
    return build(
        mesh={"file": str(mesh)}, model={"hypothesis": "axisymmetric"},
        materials=[{"E": E, "nu": NU}],
        regions={"axis": "x < 1e-12"},
        relations=[{"name": "base", "type": "dirichlet", "region": "base_bottom",
                    "component": "y"},
                   {"name": "axis", "type": "dirichlet", "region": "axis", "component": "x"},
                   {"name": "press", "type": "dirichlet", "region": "die_top", "component": "y",
                    "value": -DELTA}],
        contact=[{"name": "joint", "slave": "die_bottom", "master": "base_top",
                  "discretization": discretization}],
        steps={"count": 1})


def exact(pts: np.ndarray) -> np.ndarray:
    strain = -DELTA / (H1 + H2)
    return np.column_stack([-NU * strain * pts[:, 0], strain * pts[:, 1]])


def test_mortar_passes_the_axisymmetric_patch_test(run, mesh):
    text = scene(mesh, "mortar")
    res = run(text, name="axisym_mortar")
    pts = res["mesh/points"][:, :2]
    u = res["fields/displacement"][-1][:, :2]
    np.testing.assert_allclose(u, exact(pts), rtol=0, atol=1e-10 * DELTA)
    # the contact force is the uniform pressure over the disc, π r² p (forces for the ring)
    pressure = E * DELTA / (H1 + H2)
    force = res["relations/joint_normal/normal_force"][-1, 0]
    ring = res["relations/press/resultant"][-1, 1]
    np.testing.assert_allclose(abs(ring), force, rtol=1e-10)
    print("contact force / (π p):", force / (np.pi * pressure))
    np.testing.assert_allclose(force, np.pi * pressure, rtol=1e-10)
    if MPI.COMM_WORLD.size > 1:
        assert_same_results(res, run(text, name="axisym_mortar_serial", comm=MPI.COMM_SELF))


def test_node_to_segment_does_not(run, mesh):
    res = run(scene(mesh, "node_to_segment"), name="axisym_nts")
    pts = res["mesh/points"][:, :2]
    u = res["fields/displacement"][-1][:, :2]
    error = np.abs(u - exact(pts)).max() / DELTA
    print("node-to-segment, axisymmetric patch test error:", error)
    assert error > 1e-6
