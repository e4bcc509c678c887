"""Where the multiplier rows of shipped contact scenes live (1, 2, 3 ranks): on a rigid obstacle
every row of A and column of D names only its slave node, so all of them are in their owner's
diagonal block; rows tying a slave node to master nodes (the mortar sphere) go where most of
their DOFs are, so most of their entries are."""

import tomllib

import numpy as np
import pytest
from mpi4py import MPI

from parsolve.model import build_model
from parsolve.scene import parse_scene
from parsolve.solvers.system import SaddleSystem
from tests.helpers.scene import CONFIGS

COMM = MPI.COMM_WORLD


def off_rank_entries(name: str) -> tuple[int, int, int]:
    """(A entries whose primal column another rank owns, D entries whose multiplier column
    another rank owns, all entries of either), summed over the ranks."""
    text = (CONFIGS / name).read_text(encoding="utf-8")
    model = build_model(parse_scene(tomllib.loads(text), str(CONFIGS / name), text), COMM)
    system = SaddleSystem(COMM, model)
    rs, dm = system.relation_set, system.dofmap
    q0, q1, l0, l1 = dm.owned()
    own_a = (rs.a_rows >= l0) & (rs.a_rows < l1)
    own_d = (rs.d_rows >= q0) & (rs.d_rows < q1)
    a_off = ((rs.a_cols[own_a] < q0) | (rs.a_cols[own_a] >= q1)).sum()
    d_off = ((rs.d_cols[own_d] < l0) | (rs.d_cols[own_d] >= l1)).sum()
    counts = np.array([a_off, d_off, own_a.sum() + own_d.sum()], dtype=np.int64)
    COMM.Allreduce(MPI.IN_PLACE, counts)
    assert np.diff(dm.l_ranges).sum() == rs.nrows
    return tuple(int(c) for c in counts)


def test_rows_on_a_rigid_obstacle_are_all_local():
    a_off, d_off, total = off_rank_entries("contact_friction_3d.toml")
    assert total == 2 * 441 and a_off == 0 and d_off == 0


@pytest.mark.slow
def test_mortar_rows_live_with_most_of_their_entries():
    a_off, d_off, total = off_rank_entries("contact_mortar_sphere_3d.toml")
    # near-equal blocks of rows (the layout before) left 49–75 % off-rank at 2–4 ranks
    assert (a_off + d_off) <= 0.15 * total
