"""The penalty baseline's pairs held per rank: each rank pairs the slave nodes it owns (the
relations form's pairing per rank: against the master facets near them, or projected on the
obstacle), their areas from its own facets; a pair's tuple is declared by that rank alone (the
entries of the rows another rank owns travel to it: ``la.tuple_rows``), the forces on nodes
another rank owns sent there at each evaluation. On a narrow punch on a deformable master
(2D, friction) and the shipped block on a rough plane: the union of the ranks' pairs (slaves,
gaps, areas) is the one-rank pairing and the union of the declared tuples the one-rank
tuples, each declared once. At 4 ranks on a block on a foundation one rank owns whole (the
master surface): no rank declares more than 0.35 of the tuples, nor receives more entries in
its rows than the pairs' master rows hold. (The runs on the parts equal the one-rank runs:
test_contact_penalty_master.py, test_contact_distributed.py.)"""

from __future__ import annotations

import tomllib

import numpy as np
import pytest
from mpi4py import MPI

from helpers.contact import FOUNDATION, write_mesh
from helpers.scene import CONFIGS
from parsolve.la.tuple_rows import TupleRows
from parsolve.model import build_model
from parsolve.scene import load_scene, parse_scene
from tests.effects.test_contact_penalty_master import punch_2d, scene_2d, written

COMM = MPI.COMM_WORLD


def penalty(path, comm):
    """The penalty effect of the scene at ``path`` built on ``comm``."""
    model = build_model(load_scene(path), comm)
    return next(e for e in model.effects if getattr(e, "pairing", None) is not None)


def case_path(shared_tmp, case: str):
    if case == "punch":
        mesh = written(shared_tmp / f"narrow_rank_{COMM.size}.msh", punch_2d, 0.5)
        text = scene_2d(mesh, 'friction = 0.3\nformulation = "penalty"\npenalty = 1e6')
    else:
        text = (CONFIGS / "contact_block_friction.toml").read_text(encoding="utf-8")
        text = text.replace("[[contact]]\n", '[[contact]]\nformulation = "penalty"\n')
    path = shared_tmp / f"penalty_rank_{case}.toml"
    if COMM.rank == 0:
        path.write_text(text)
    COMM.Barrier()
    return path


@pytest.mark.parametrize("case", ["punch", "block"])
def test_each_rank_holds_its_pairs_and_together_the_one_rank_pairing(shared_tmp, case):
    path = case_path(shared_tmp, case)
    here, alone = penalty(path, COMM), penalty(path, MPI.COMM_SELF)
    assert here.geo.ids is not None
    p, p1 = here.pairing, alone.pairing
    own, _ = here.values.owned_nodes(p.slave)
    assert own.all()                                    # its own slave nodes only
    at = here.geo.ids
    assert COMM.allreduce(len(p)) == len(p1)
    np.testing.assert_array_equal(p.slave, p1.slave[at])
    np.testing.assert_allclose(p.gap, p1.gap[at], rtol=0, atol=1e-14)
    np.testing.assert_allclose(here.eps_n, alone.eps_n[at], rtol=1e-12)
    assert here.penalty == pytest.approx(alone.penalty, rel=1e-12)
    # the declared tuples: this rank's pairs' alone; each declared once, together the one
    # rank's
    nodes = here.term.nodes
    np.testing.assert_array_equal(nodes, here.geo.new_of(here.tuple_ids).reshape(nodes.shape))
    def tuples(p):   # (as input node sets)
        return [frozenset(t.tolist()) for t in np.column_stack([p.slave, p.master])]
    every = [t for ts in COMM.allgather(tuples(p)) for t in ts]
    assert len(every) == len(set(every)) and set(every) == set(tuples(p1))
    if COMM.size > 1 and case == "punch":   # rows another rank owns: their entries sent there
        rows = TupleRows(COMM, nodes, here.values.node_ranges)
        assert COMM.allreduce(len(rows.received)) > 0


@pytest.mark.skipif(COMM.size != 4, reason="the count at 4 ranks")
@pytest.mark.parametrize("sliding", ["small", "finite"])
def test_at_four_ranks_no_rank_declares_every_tuple_when_one_owns_the_master(shared_tmp,
                                                                             sliding):
    """A block (64 elements along its bottom, the slave) pressed on a foundation (8 along its
    top, the master) that one rank owns whole, split over 4 ranks (checked: every pair's
    master nodes on one rank): each rank declares ≤ 0.35 of the one-rank tuples (measured
    0.28; the slave side split over the ranks), where a tuple was declared by each owner of
    its nodes (the master's owner: all of them, 1.0). The master's owner receives the
    entries of its rows alone, summed per (row, column) over each sender's pairs: ≤ 0.35 of
X: its operator's rows
    hold a column per slave paired on its facets, what no partition of the slave side
    takes off it."""
    mesh = shared_tmp / "penalty_master_count.msh"
    write_mesh(mesh, 8, 64, ny_low=1, ny_up=1, seed=4)
    extra = 'formulation = "penalty"\npenalty = 1e5\n' + \
        ('sliding = "finite"\n' if sliding == "finite" else "")
    text = FOUNDATION.format(mesh=mesh, discretization="node_to_segment").replace(
        "friction = 0.3\n", "friction = 0.3\n" + extra)

    def held(comm):
        model = build_model(parse_scene(tomllib.loads(text), "count.toml", text), comm)
        effect = next(e for e in model.effects if getattr(e, "pairing", None) is not None)
        if sliding == "finite":
            q = np.zeros(model.mesh.num_points * effect.fields_.ncomp)
            effect.begin_step(q, {}, None)   # (paired again on the current configuration)
        return effect

    alone, here = held(MPI.COMM_SELF), held(COMM)
    k, m = alone.term.nodes.shape
    assert k == 65
    ranges = here.values.node_ranges
    masters = here.term.nodes[:, 1:]
    owners = np.unique(np.searchsorted(ranges, masters, side="right") - 1)
    assert len(set().union(*COMM.allgather(set(owners.tolist())))) == 1   # one master owner
    declared = COMM.allreduce(len(here.term.nodes), op=MPI.MAX)
    assert COMM.allreduce(len(here.term.nodes)) == k
    assert declared <= 0.35 * k, (declared, k)
    received = COMM.allreduce(len(TupleRows(COMM, here.term.nodes, ranges).received),
                              op=MPI.MAX)
    assert 0 < received <= 0.35 * k * m * m, (received, k * m * m)
