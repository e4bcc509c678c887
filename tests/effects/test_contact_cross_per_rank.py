"""3D friction with ``direction = "reaction"`` on a master region, rows built per rank: the
cross stiffness (``row_terms``) lies on each sliding row's tuple (its slave node, owned by the
row's rank, and master nodes anywhere); the tuple is declared by its nodes' owners, its values
sent to them at each evaluation (``effects.row_terms``). A block pushed on a meshed rough
foundation (node-to-face and mortar): each rank holds its own slaves' rows and the tuples of
its nodes only, together the one-rank tuples; the run equals the one-rank run (1e-10, states,
active rows and iterations exactly)."""

from __future__ import annotations

import numpy as np
import pytest
from mpi4py import MPI

from conftest import assert_same_results
from parsolve.model import build_model
from parsolve.scene import parse_scene
from parsolve.solvers.system import SaddleSystem
from tests.effects.test_contact_mortar3d import FRICTION3D, write_mesh

import tomllib

COMM = MPI.COMM_WORLD


def scene(mesh, discretization: str) -> str:
    text = FRICTION3D.format(mesh=mesh).replace("count = 6", "count = 4")
    return text.replace('discretization = "mortar"', f'discretization = "{discretization}"')


def cross_tuples(text: str, comm) -> tuple[object, set]:
    """(the contact effect, the tuples of its rows held here as sets of input node ids)."""
    model = build_model(parse_scene(tomllib.loads(text), "cross.toml", text), comm)
    SaddleSystem(comm, model)
    effect = next(e for e in model.effects if type(e).__name__ == "Contact")
    return effect, {frozenset(t.tolist()) for t in effect.cross.layout.nodes}


@pytest.mark.parametrize("discretization", ["node_to_segment", "mortar"])
def test_cross_stiffness_per_rank_is_the_one_rank_run(run, shared_tmp, discretization):
    mesh = shared_tmp / "cross_per_rank.msh"
    write_mesh(mesh, 3, 4, "hexahedron", seed=5)
    text = scene(mesh, discretization)
    effect, mine = cross_tuples(text, COMM)
    assert effect.here and effect.ids is not None and effect.cross is not None
    own, _ = effect.values.owned_nodes(effect.pairing.slave)
    assert own.all()
    # each rank declares the tuples of its rows and those touching a node it owns, no other
    lo, hi = effect.values.node_ranges[COMM.rank], effect.values.node_ranges[COMM.rank + 1]
    nodes = effect.cross.term.nodes
    assert np.all(np.any((nodes >= lo) & (nodes < hi), axis=1))
    held = effect.cross.layout.nodes.shape[0]
    assert held == len(effect.pairing)
    # together: the one-rank tuples (as input node sets)
    every = set().union(*COMM.allgather(mine))
    _, alone = cross_tuples(text, MPI.COMM_SELF)
    assert every == alone
    parts = run(text, name=f"cross_{discretization}")
    whole = run(text, name=f"cross_{discretization}_whole", comm=MPI.COMM_SELF)
    assert_same_results(parts, whole)
    assert np.array_equal(parts["steps/iterations"], whole["steps/iterations"])
    state = parts["fields/base_state"][-1, :, 0]
    assert np.any(state == 2)          # sliding nodes: the cross term in use
