"""Multiplied Dirichlet, equal and periodic rows are built per rank: each row held by the rank
owning the DOF or node it constrains (``relations.lead_dofs``), numbered by its place in the
whole relation; gathered over the ranks, the rows are the one-process model's, entry for
entry. An eliminated Dirichlet relation stays whole; a mean (one row over a region) is whole
and spread, each rank holding the entries of its owned nodes."""

import tomllib
from pathlib import Path

import numpy as np
import pytest
from mpi4py import MPI

from parsolve.model import build_model
from parsolve.relations import Relation, lead_dofs
from parsolve.scene import parse_scene

COMM = MPI.COMM_WORLD
CONFIGS = Path(__file__).resolve().parents[2] / "configs"
LAMINATE = (CONFIGS / "periodic_shear_laminate.toml").read_text(encoding="utf-8")
EQUAL = """
[[relations]]
name = "top_even"
type = "equal"
region = "upper"
component = "y"
[[relations]]
name = "mean_x"
type = "mean"
region = "lower"
component = "x"
value = 0.0
"""


def relations_of(text: str, comm) -> tuple[np.ndarray, dict[str, Relation]]:
    """(the input ids of the nodes this rank owns, the model's relations by name)."""
    model = build_model(parse_scene(tomllib.loads(text), "t.toml", text), comm)
    return model.mesh.global_nodes[:model.mesh.n_owned], {r.name: r for r in model.relations}


def rows(r: Relation) -> list[tuple]:
    """(global row, sorted (DOF, coefficient) entries, value) of each row held here."""
    out = []
    for k, g in enumerate(r.row_ids()):
        at = r.a_rows == k
        order = np.argsort(r.a_dofs[at])
        out.append((int(g), tuple(r.a_dofs[at][order].tolist()),
                    tuple(r.a_vals[at][order].tolist()), float(r.values[k])))
    return out


def test_lead_dofs_are_the_constrained_ones():
    """A Dirichlet row's DOF, a tie's u_a (coefficient +1, whatever the entries' order), a row
    with no positive entry its first entry, a row with none -1."""
    r = Relation("r", 4, np.array([0, 1, 1, 2, 2]), np.array([7, 3, 9, 5, 4]),
                 np.array([1.0, -1.0, 1.0, -2.0, -1.0]), 0.0)
    np.testing.assert_array_equal(lead_dofs(r), [7, 9, 5, -1])


@pytest.mark.parametrize("eliminate", [True, False])
def test_rows_per_rank_are_the_whole_relations(eliminate):
    text = LAMINATE + EQUAL + ("" if eliminate else "\n[solver]\neliminate = false\n")
    owned, here = relations_of(text, COMM)
    _, alone = relations_of(text, MPI.COMM_SELF)
    assert list(here) == list(alone)
    held = {"bottom_held", "top_shear", "top_y"}   # (eliminated or not: held per rank)
    assert {n for n, r in here.items() if not r.whole} == {"cell", "top_even"} | held
    for name, r in here.items():
        whole = alone[name]
        assert r.total == whole.nrows
        if r.spread:   # the mean: every rank its owned nodes' entries of its one row
            assert name == "mean_x" and r.whole
            gathered = sorted(sum(COMM.allgather(rows(r)[0][1]), ()))
            assert tuple(gathered) == rows(whole)[0][1]
            assert COMM.allreduce(len(rows(r)[0][1])) == len(gathered)
            continue
        if r.whole:
            assert rows(r) == rows(whole)
            continue
        assert r.eliminable() == (eliminate and name in held)
        # each row on one rank, the rank owning its constrained node
        gathered = sorted(sum(COMM.allgather(rows(r)), []))
        assert gathered == rows(whole)
        assert np.isin(lead_dofs(r) // 2, owned).all()
    # the numbers of one rank: bottom 2 × 7 nodes, top 7 + 7, the tie 2 × 7 side nodes, the
    # upper half's 7 × 5 nodes tied to its first
    assert [alone[n].nrows for n in ("bottom_held", "top_shear", "top_y", "cell", "top_even",
                                     "mean_x")] == [14, 7, 7, 14, 34, 1]
