"""Contact rows against a rigid obstacle built per rank: each rank projects the slave nodes it
owns (never the gathered slave surface) and holds their rows; the union over the ranks is the
one-rank relation row by row (global ids, DOFs, coefficients of A and D) and so is the pairing,
on the shipped 3D friction box (a plane, friction with the slip direction from the reaction),
the shipped Hertz cylinder (a circle) and a 3D block sliding finitely over a rigid cylinder.
At 4 ranks each rank holds at most 0.35× the one-rank contact entries (the box's base splits
over the ranks)."""

import numpy as np
import pytest
from mpi4py import MPI

from helpers.scene import CONFIGS, scene
from tests.contact.test_rows_per_rank import contact_rows

COMM = MPI.COMM_WORLD

SLIDING_3D = scene(
    mesh={"generator": "box", "lx": 2.0, "ly": 0.5, "lz": 0.5, "nx": 8, "ny": 2, "nz": 2,
          "origin": [-1.0, 0.0, 10.0]},
    model={"hypothesis": "3d"}, materials=[{"E": 1000.0, "nu": 0.3}],
    relations=[{"name": "top_z", "type": "dirichlet", "region": "zmax", "component": "z",
                "value": -0.1}],
    contact=[{"name": "shoe", "slave": "zmin", "friction": 0.3, "sliding": "finite",
              "obstacle": {"cylinder": {"centre": [0.0, 0.0, 0.0], "radius": 10.0,
                                        "axis": [0.0, 1.0, 0.0]}}}],
    steps={"count": 1})

CASES = {"friction_3d": (CONFIGS / "contact_friction_3d.toml").read_text(encoding="utf-8"),
         "hertz": (CONFIGS / "contact_hertz_cylinder.toml").read_text(encoding="utf-8"),
         "sliding_3d": SLIDING_3D}


def held_entries(rows: dict) -> int:
    """The contact entries a rank holds: its rows' A and D entries."""
    return sum(sum(r.shape[0] for r in a) + sum(r.shape[0] for r in d)
               for _, _, a, d in rows.values())


@pytest.mark.parametrize("case", sorted(CASES))
def test_each_rank_projects_its_own_slaves_and_together_the_one_rank_rows(case):
    text = CASES[case]
    here, effect, dofmap = contact_rows(text, f"{case}.toml", COMM)
    alone, whole, _ = contact_rows(text, f"{case}.toml", MPI.COMM_SELF)
    assert effect.ids is not None and not effect.here
    own, _ = dofmap.owned_nodes(effect.pairing.slave)
    assert own.all()                                 # only its own slave nodes
    assert COMM.allreduce(len(effect.pairing)) == len(whole.pairing) == effect.entries
    assert set(here) == set(alone)
    for rel, (ids, total, a_rows, d_rows) in here.items():
        ids_1, total_1, a_1, d_1 = alone[rel]
        assert total == total_1
        every = np.concatenate(COMM.allgather(ids))
        assert np.array_equal(np.sort(every), np.arange(total_1))   # each row on one rank
        for k, i in enumerate(ids):
            for mine, one in ((a_rows[k], a_1[i]), (d_rows[k], d_1[i])):
                np.testing.assert_array_equal(mine[:, 0], one[:, 0])
                np.testing.assert_allclose(mine[:, 1], one[:, 1], rtol=0, atol=1e-14)
    p, p1 = effect.pairing, whole.pairing
    np.testing.assert_array_equal(p.slave, p1.slave[effect.ids])
    np.testing.assert_allclose(p.gap, p1.gap[effect.ids], rtol=0, atol=1e-14)
    np.testing.assert_allclose(p.normal, p1.normal[effect.ids], rtol=0, atol=1e-14)


@pytest.mark.skipif(COMM.size != 4, reason="the count at 4 ranks")
def test_at_four_ranks_each_holds_at_most_035_of_the_contact_entries():
    text = CASES["friction_3d"]
    here, effect, _ = contact_rows(text, "friction_3d.toml", COMM)
    alone, _, _ = contact_rows(text, "friction_3d.toml", MPI.COMM_SELF)
    most = COMM.allreduce(held_entries(here), op=MPI.MAX)
    pairs = COMM.allreduce(len(effect.pairing), op=MPI.MAX)
    assert most <= 0.35 * held_entries(alone), (most, held_entries(alone))
    assert pairs <= 0.35 * effect.entries
