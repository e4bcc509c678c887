"""Thermal expansion with the axisymmetric hypothesis: a thick cylinder (r from 0.5 to 1.5,
height 1) heated uniformly by ΔT. Free (its base held axially only), it expands without
stress: u = α ΔT (r, z), which needs the eigenstrain's hoop term (without it u_r / r would
be strained). Held radially on both faces (u_r = 0), its top free: ε_rr = ε_θθ = 0, σ_zz = 0,
so σ_rr = σ_θθ = −E α ΔT / (1 − ν) and u_z = α ΔT (1 + ν) / (1 − ν) z. Both linear: Q1 gives
them to round-off, on 1, 2, 3 ranks."""

from __future__ import annotations

import numpy as np
import pytest

from helpers.scene import scene as build

E, NU, ALPHA, DT, T0 = 1000.0, 0.3, 1e-3, 50.0, 20.0


def scene(held_radially: bool) -> str:
    relations = [{"name": "heater", "type": "dirichlet", "field": "T", "region": "all",
                  "value": T0 + DT},
                 {"name": "base", "type": "dirichlet", "region": "bottom", "component": "y"}]
    if held_radially:
        relations.append({"name": "faces", "type": "dirichlet", "region": "faces",
                          "component": "x"})
    return build(
        mesh={"generator": "rectangle", "lx": 1.0, "ly": 1.0, "nx": 4, "ny": 3,
              "origin": [0.5, 0.0]},
        model={"hypothesis": "axisymmetric"},
        regions={"faces": "x < 0.5 + 1e-12 or x > 1.5 - 1e-12"},
        materials=[{"E": E, "nu": NU}],
        diffusion=[{"field": "T", "initial": T0, "materials": [{"conductivity": 1.0}]}],
        thermal_expansion=[{"field": "T", "alpha": ALPHA, "reference": T0}],
        relations=relations, steps={"count": 1})


@pytest.mark.parametrize("held_radially", [False, True])
def test_heated_thick_cylinder_is_exact(run, held_radially):
    res = run(scene(held_radially), name=f"axisym_heated_{held_radially}")
    pts = res["mesh/points"][:, :2]
    u = res["fields/displacement"][-1][:, :2]
    sigma = res["cell_fields/stress"][-1]          # (rr, zz, rz, θθ)
    e = ALPHA * DT
    if held_radially:
        expected_u = np.column_stack([0 * pts[:, 0], e * (1 + NU) / (1 - NU) * pts[:, 1]])
        expected_s = np.array([1.0, 0.0, 0.0, 1.0]) * (-E * e / (1 - NU))
    else:
        expected_u, expected_s = e * pts, np.zeros(4)
    np.testing.assert_allclose(u, expected_u, rtol=0, atol=1e-10 * e * 1.5)
    np.testing.assert_allclose(sigma, np.broadcast_to(expected_s, sigma.shape), rtol=0,
                               atol=1e-10 * E * e)
    nodal = res["fields/stress"][-1]
    np.testing.assert_allclose(nodal, np.broadcast_to(expected_s, nodal.shape), rtol=0,
                               atol=1e-10 * E * e)
