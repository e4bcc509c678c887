"""Hertz with 3D mortar rows: the shipped quarter model of an elastic sphere (paraboloid
profile, R = 10) pressed on an elastic block (configs/contact_mortar_sphere_3d.toml), both
E = 1000, ν = 0.3, non-matching graded hexahedral meshes (``sphere_on_block``), the flat block
top the slave surface. Checked against Johnson (4.22)-(4.23) for the total force P that the
solve gives: the peak pressure p0 = 3P/(2πa²) and the contact radius a = (3PR/(4E*))^(1/3)
within 3 %, the errors decreasing under refinement, the contact force equal to the applied
load to 1e-10, no penetration, the same results on any number of ranks (run at 1, 2 and 3).

The block and the sphere body are 10 a wide and deep: the finite size changes the pressure
under a given load by about (a/L)³ (a far boundary's correction to the surface displacement is
smooth on the body's scale, so its variation over the contact zone is (a/L)³ times Hertz's),
far below the discretisation's error. The approach δ = a²/R is not checked: it is measured
between points at infinity, and the bodies here are finite (its O(a/L) correction is not
small)."""

from __future__ import annotations

import numpy as np
from mpi4py import MPI

from conftest import CONFIGS, assert_same_results
from helpers.scene import scene, shipped
from parsolve.contact.references import hertz_sphere
from parsolve.mesh.generators import sphere_on_block

SCENE = CONFIGS / "contact_mortar_sphere_3d.toml"
E, NU = 1000.0, 0.3
E_STAR = 1.0 / (2 * (1 - NU * NU) / E)          # two equal bodies
SHIPPED = (0.0196, -0.0060)   # the shipped mesh's errors of p0 (tip) and a (moment), measured


def hertz_measures(res, mesh) -> dict:
    """Total force P (4 × the quarter's), Hertz's a and p0 for it, and the measured ones: the
    pressure at the tip node (its nodal force over ∫φ of its quarter cell: the multiplier of the
    normalised row is p w_i), a from the second moment of the nodal forces (Hertz's pressure
    has ∫p r² dA = (2/5) a² P), and the contact zone's edge (the farthest closed node, the
    nearest open one)."""
    x = mesh.points
    slave = np.unique(mesh.facet_groups["block_top"])
    rn = res["fields/hertz_normal_reaction"][-1, slave, 0]
    state = res["fields/hertz_state"][-1, slave, 0]
    force = 4.0 * res["relations/hertz_normal/normal_force"][-1, 0]
    ref = hertz_sphere(force, 10.0, E_STAR)
    r = np.hypot(x[slave, 0], x[slave, 1])
    closed = state > 0
    tip = np.argmin(r)
    return {"P": force, "a": ref.a, "p0": ref.p0,
            "p_tip": rn[tip] / tip_weight(mesh),
            "a_moment": np.sqrt(2.5 * (rn * r * r).sum() / rn.sum()),
            "edge": (r[closed].max(), r[~closed & (state >= 0)].min())}


def tip_weight(mesh) -> float:
    """∫φ of the tip node over the slave surface: a quarter of its (square) cell (hexahedra;
    the tetrahedra's top triangles would give it a third)."""
    top = mesh.points[np.unique(mesh.facet_groups["block_top"])]
    h = np.unique(top[:, 0])[1]
    return 0.25 * h * h


def mesh_of(text_or_path) -> object:
    """The scene's mesh, built by its generator (the node numbering of the result file)."""
    import tomllib

    data = tomllib.loads(text_or_path.read_text() if hasattr(text_or_path, "read_text")
                        else text_or_path)["mesh"]
    return sphere_on_block(**{k: v for k, v in data.items() if k != "generator"})


def errors(m: dict) -> tuple[float, float]:
    return m["p_tip"] / m["p0"] - 1.0, m["a_moment"] / m["a"] - 1.0


def check_contact(res, mesh) -> None:
    """Equilibrium (contact force = applied load = support reaction, 1e-10), no penetration,
    closed rows at zero gap, frictionless (no tangential force)."""
    contact = res["relations/hertz_normal/normal_force"][-1, 0]
    applied = res["relations/press/multiplier"][-1].sum()      # the top pushed down
    support = -res["relations/ground/multiplier"][-1].sum()
    assert contact > 0
    np.testing.assert_allclose([applied, support], contact, rtol=1e-10)
    slave = np.unique(mesh.facet_groups["block_top"])
    state = res["fields/hertz_state"][-1, slave, 0]
    gap = res["fields/hertz_gap"][-1, slave, 0]
    paired = state >= 0
    assert gap[paired].min() >= -1e-12 * 0.027
    np.testing.assert_allclose(gap[state > 0], 0.0, atol=1e-12 * 0.027)
    assert np.all(res["fields/hertz_normal_reaction"][-1, slave[state == 0], 0] == 0.0)
    np.testing.assert_allclose(res["relations/hertz_normal/tangential_force"][-1], 0.0,
                               atol=1e-12 * contact)


def test_shipped_sphere_matches_hertz_on_any_partition(run):
    """The shipped scene on the ranks' parts and on one rank alone: the same results (1e-10),
    equilibrium and no penetration, and Hertz: p0 and a within 3 % (measured: p0 +1.96 %,
    a −0.60 % from the moment, the contact zone's edge between +1.9 % and +2.7 % of a: the
    dual multipliers close the nodes within a fifth of a cell of the edge)."""
    parts = run(SCENE, name="mortar_sphere_parts")
    alone = run(SCENE, name="mortar_sphere_alone", comm=MPI.COMM_SELF)
    assert_same_results(parts, alone)
    mesh = mesh_of(SCENE)
    check_contact(parts, mesh)
    m = hertz_measures(parts, mesh)
    e_p, e_a = errors(m)
    print(f"\nHertz, shipped mesh: P = {m['P']:.6g}, a = {m['a']:.5f}, p0 = {m['p0']:.5f}; "
          f"p_tip {e_p:+.4f}, a_moment {e_a:+.4f}, edge {m['edge'][0] / m['a'] - 1:+.4f}.."
          f"{m['edge'][1] / m['a'] - 1:+.4f}")
    assert abs(e_p) < 0.03 and abs(e_a) < 0.03
    assert m["a"] * 0.97 < m["edge"][1] and m["edge"][0] < m["a"] * 1.03
    assert abs(e_p - SHIPPED[0]) < 1e-3 and abs(e_a - SHIPPED[1]) < 1e-3   # this mesh's
    assert np.all(parts["steps/iterations"] <= 8)


def test_hertz_errors_decrease_under_refinement(run):
    """The fine zone's cells 1.5 × larger (n_fine 8, n_coarse 4, n_depth 6) than the shipped
    mesh's: the tip pressure's error larger (measured +3.0 % against the shipped +1.96 %, which
    the test above holds to 1e-3; docs/contact.md §2c has the table to n_fine = 20: +1.05 %,
    +0.75 %). The moment's error is too small against the fine zone's to decrease steadily
    over these two meshes (−0.52 %, −0.60 %; −0.20 %, −0.10 % on the finer ones): below 1 %."""
    text = scene(shipped("contact_mortar_sphere_3d.toml"),
                 mesh={"n_fine": 8, "n_coarse": 4, "n_depth": 6})
    res = run(text, name="mortar_sphere_coarse")
    mesh = mesh_of(text)
    check_contact(res, mesh)
    e_p, e_a = errors(hertz_measures(res, mesh))
    print(f"\nHertz, coarse mesh: p_tip error {e_p:+.4f} (shipped {SHIPPED[0]:+.4f}), a_moment "
          f"{e_a:+.4f} (shipped {SHIPPED[1]:+.4f})")
    assert SHIPPED[0] < 0.7 * e_p < 0.03
    assert abs(e_a) < 0.01
