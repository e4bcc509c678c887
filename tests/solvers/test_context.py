"""The step context of a system (a shipped contact scene on the ranks' parts): the effects are
attached to it once (contact then reads rows through the system's DOF map), and its reductions
and relation values are the whole mesh's, whatever the number of ranks (1, 2, 3 ranks)."""

import tomllib

import numpy as np
import pytest
from mpi4py import MPI

from helpers.scene import scene, shipped
from parsolve.model import build_model
from parsolve.scene import parse_scene
from parsolve.solvers.system import SaddleSystem

COMM = MPI.COMM_WORLD


@pytest.fixture(scope="module")
def system():
    text = scene(shipped("contact_block_friction.toml"))
    return SaddleSystem(COMM, build_model(parse_scene(tomllib.loads(text), "t.toml", text), COMM))


def known_q(ctx) -> tuple[np.ndarray, np.ndarray]:
    """(local q, the whole mesh's q): 0.5 + 3 × the input DOF number (exact)."""
    nc, mesh = ctx.ncomp, ctx.mesh
    ids = (mesh.global_nodes.astype(np.int64)[:, None] * nc + np.arange(nc)).ravel()
    return 0.5 + 3.0 * ids, 0.5 + 3.0 * np.arange(mesh.num_global_points * nc)


def test_effects_are_attached(system):
    ctx = system.context
    contacts = [e for e in ctx.effects if e.refreshes]
    assert contacts and all(e.values is ctx.dofs for e in contacts)


def test_reductions_and_relation_values(system):
    ctx = system.context
    q, every = known_q(ctx)
    assert ctx.norm(q) == pytest.approx(float(np.sqrt(every @ every)), rel=1e-15)
    assert ctx.dot(q, q) == pytest.approx(float(every @ every), rel=1e-15)
    assert ctx.max_abs(q) == every.max()
    for r in ctx.all_relations:   # A q of every relation, eliminated ones included
        np.testing.assert_allclose(ctx.relation_primal(r, q), r.primal(every), rtol=1e-14)
    rows = np.arange(ctx.relations.nrelrows)
    views = ctx.views(rows)
    assert list(views) == [r.name for r in ctx.multiplied]
    np.testing.assert_array_equal(np.concatenate(list(views.values())), rows)
    # the owned rows of a local vector: the same norm as the local vector
    assert float(np.sqrt(COMM.allreduce(float(ctx.owned_rows(q) @ ctx.owned_rows(q))))) == \
        pytest.approx(ctx.norm(q), rel=1e-15)
