"""The penalty baseline's pairs held per rank: each rank pairs the slave nodes it owns (the
relations form's pairing per rank: against the master facets near them, or projected on the
obstacle), their areas from its own facets; a pair's tuple is declared by the owners of its
nodes, its stiffness and forces sent to them at each evaluation. On a narrow punch on a
deformable master (2D, friction) and the shipped block on a rough plane: the union of the
ranks' pairs (slaves, gaps, areas) is the one-rank pairing and the union of the declared
tuples the one-rank tuples; each rank declares only tuples touching a node it owns. (The
runs on the parts equal the one-rank runs: test_contact_penalty_master.py,
test_contact_distributed.py.)"""

from __future__ import annotations

import numpy as np
import pytest
from mpi4py import MPI

from helpers.scene import CONFIGS
from parsolve.model import build_model
from parsolve.scene import load_scene
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
    # the declared tuples: each touches a node this rank owns; together the one rank's
    lo, hi = here.values.node_ranges[COMM.rank], here.values.node_ranges[COMM.rank + 1]
    nodes = here.term.nodes
    assert np.all(np.any((nodes >= lo) & (nodes < hi), axis=1))
    def tuples(p):   # (as input node sets)
        return {frozenset(t.tolist()) for t in np.column_stack([p.slave, p.master])}
    every = set().union(*COMM.allgather(tuples(p)))
    assert every == tuples(p1)
    if COMM.size > 1 and case == "punch":   # tuples sent to another owner of their nodes
        assert COMM.allreduce(nodes.shape[0] - len(p)) > 0
