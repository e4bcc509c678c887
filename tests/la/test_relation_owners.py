"""Where the multiplier rows of shipped contact scenes live (1, 2, 3 ranks): on a rigid obstacle
every row of A and column of D names only its slave node, so all of them are in their owner's
diagonal block; rows tying a slave node to master nodes (the mortar sphere) are built and held
by the rank owning their slave node, so their slave entries are in the diagonal block and
their master entries wherever the partition put the master body (0.82 / 0.81 of the entries
off-rank at 2 / 3 ranks: the two bodies mostly on different ranks; 0.05 / 0.09 when such rows
went with the majority of their DOFs, every rank holding the whole relation)."""

import tomllib

import numpy as np
import pytest
from mpi4py import MPI

from parsolve.model import build_model
from parsolve.scene import parse_scene
from parsolve.solvers.system import SaddleSystem
from tests.helpers.scene import CONFIGS

COMM = MPI.COMM_WORLD


def off_rank_entries(name: str, slave_rows: bool = False) -> tuple[int, int, int]:
    """(A entries whose primal column another rank owns, D entries whose multiplier column
    another rank owns, all entries of either), summed over the ranks. ``slave_rows``: also
    check that every owned row has at least one node's components (its slave node's) in the
    diagonal block."""
    text = (CONFIGS / name).read_text(encoding="utf-8")
    model = build_model(parse_scene(tomllib.loads(text), str(CONFIGS / name), text), COMM)
    system = SaddleSystem(COMM, model)
    rs, dm = system.relation_set, system.dofmap
    q0, q1, l0, l1 = dm.owned()
    own_a = (rs.a_rows >= l0) & (rs.a_rows < l1)
    own_d = (rs.d_rows >= q0) & (rs.d_rows < q1)
    a_off = ((rs.a_cols[own_a] < q0) | (rs.a_cols[own_a] >= q1)).sum()
    if slave_rows:
        local = (rs.a_cols >= q0) & (rs.a_cols < q1) & own_a
        per_row = np.bincount(rs.a_rows[local] - l0, minlength=l1 - l0)
        assert np.all(per_row >= model.mesh.dim)
    d_off = ((rs.d_cols[own_d] < l0) | (rs.d_cols[own_d] >= l1)).sum()
    counts = np.array([a_off, d_off, own_a.sum() + own_d.sum()], dtype=np.int64)
    COMM.Allreduce(MPI.IN_PLACE, counts)
    assert np.diff(dm.l_ranges).sum() == rs.nrows
    return tuple(int(c) for c in counts)


def test_rows_on_a_rigid_obstacle_are_all_local():
    a_off, d_off, total = off_rank_entries("contact_friction_3d.toml")
    assert total == 2 * 441 and a_off == 0 and d_off == 0


@pytest.mark.slow
def test_mortar_rows_live_with_their_slave_nodes():
    a_off, d_off, total = off_rank_entries("contact_mortar_sphere_3d.toml", slave_rows=True)
    assert total == 2 * 16473 and a_off == d_off   # each A entry's D twin across the ranks
    if COMM.size == 1:
        assert a_off == 0
