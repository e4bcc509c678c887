"""Finite sliding on a master region built per rank: each rank pairs the slave nodes it owns,
on the current configuration, against the master facets near them (``contact.distributed``:
the facets that came within reach as the bodies moved are sent to it then, never the whole
master surface) and holds their rows over their spans. At the start the union over the ranks
is the one-rank relation row by row (the shipped ironing scenes, 2D and 3D, node-to-face and
mortar); a die dragged over a slab with spans made again collects the slab's facets as it
goes and gives the one-rank answers; at 4 ranks each rank holds at most 0.35× the one-rank
contact entries and surface on a block whose bottom (the slave) splits over the ranks."""

from __future__ import annotations

import tomllib

import numpy as np
import pytest
from mpi4py import MPI

from conftest import assert_same_results
from helpers.contact import FOUNDATION, write_mesh
from helpers.scene import CONFIGS
from parsolve.contact import distributed
from parsolve.model import build_model
from parsolve.scene import parse_scene
from tests.contact.test_obstacle_rows_per_rank import held_entries
from tests.contact.test_rows_per_rank import check_rows, contact_rows
from tests.effects import test_contact_sliding as sliding_scenes

COMM = MPI.COMM_WORLD
MORTAR = 'discretization = "mortar"\n'


def shipped(name: str, extra: str = "") -> str:
    """A shipped ironing scene as is (finite sliding), its mesh found, ``extra`` keys added."""
    text = (CONFIGS / name).read_text(encoding="utf-8")
    mesh = name.replace(".toml", ".msh")
    text = text.replace(f'file = "{mesh}"', f'file = "{CONFIGS / mesh}"')
    return text.replace('sliding = "finite"\n', 'sliding = "finite"\n' + extra)


@pytest.mark.parametrize("name, extra", [("contact_ironing_2d.toml", ""),
                                         ("contact_ironing_3d.toml", ""),
                                         ("contact_ironing_2d.toml", MORTAR),
                                         ("contact_ironing_3d.toml", MORTAR)])
def test_each_rank_holds_its_slaves_rows_over_their_spans(name, extra):
    """Each rank's rows (over the spans: A, and D with friction) are those of its own slave
    nodes, and together the one-rank rows (ids, DOFs, coefficients), the pairing too."""
    check_rows(shipped(name, extra), str(CONFIGS / name), True, False)


@pytest.fixture
def base_and_die(shared_tmp):
    path = shared_tmp / "sliding_per_rank.msh"
    if COMM.rank == 0:
        sliding_scenes.base_and_die(path)
    COMM.Barrier()
    return path


@pytest.mark.parametrize("discretization", ["node_to_segment", "mortar"])
def test_facets_sent_as_they_come_near_give_the_one_rank_run(run, base_and_die, monkeypatch,
                                                             discretization):
    """The die dragged over four of the base's facets with spans of radius 0.3 (made again
    as the slaves leave them): on the parts, the facets a rank's slaves come near are sent to
    it during the run (some rank receives facets after the start at 2 and 3 ranks), the
    answers those of the one-rank run (1e-10; states, active rows and iterations exactly)."""
    sent = []
    update = distributed.update_near

    def counted(*args):
        near, new = update(*args)
        sent.append(new)
        return near, new
    text = sliding_scenes.scene(base_and_die, discretization=discretization, search_radius=0.3,
                                friction=sliding_scenes.MU)
    whole = run(text, name=f"near_{discretization}_whole", comm=MPI.COMM_SELF)
    monkeypatch.setattr(distributed, "update_near", counted)
    from parsolve.effects import contact_sliding
    monkeypatch.setattr(contact_sliding, "update_near", counted)
    parts = run(text, name=f"near_{discretization}")
    assert_same_results(parts, whole)
    assert np.array_equal(parts["steps/iterations"], whole["steps/iterations"])
    assert parts["timings/pattern"].max() > 0.0      # spans made again
    if COMM.size > 1:
        assert any(sent[1:])                         # facets sent after the start


@pytest.mark.skipif(COMM.size != 4, reason="the count at 4 ranks")
@pytest.mark.parametrize("discretization", ["node_to_segment", "mortar"])
def test_at_four_ranks_each_holds_at_most_035_of_the_sliding_entries(shared_tmp,
                                                                     discretization):
    """A block (64 elements along its bottom, the slave) in finite sliding on a meshed rough
    foundation (8 along its top), split over 4 ranks: each rank's contact entries (its rows
    over their spans) ≤ 0.35× those of one rank (measured: 0.31), the nodes of its surfaces
    (its slaves, the master facets near them; mortar: its slave facets) ≤ 0.4× (0.34
    node-to-segment, 0.38 mortar)."""
    mesh = shared_tmp / "sliding_count.msh"
    write_mesh(mesh, 8, 64, ny_low=1, ny_up=1, seed=4)
    text = FOUNDATION.format(mesh=mesh, discretization=discretization).replace(
        "friction = 0.3\n", 'friction = 0.3\nsliding = "finite"\n')
    here, effect, _ = contact_rows(text, "count.toml", COMM)
    alone, whole, _ = contact_rows(text, "count.toml", MPI.COMM_SELF)
    most = COMM.allreduce(held_entries(here), op=MPI.MAX)
    assert most <= 0.35 * held_entries(alone), (most, held_entries(alone))
    nodes = COMM.allreduce(effect.span.surf.ids.size, op=MPI.MAX)
    assert nodes <= 0.4 * whole.span.surf.ids.size, (nodes, whole.span.surf.ids.size)


@pytest.mark.skipif(COMM.size != 4, reason="the count at 4 ranks")
def test_at_four_ranks_the_sliding_penalty_holds_at_most_035_of_the_pairs(shared_tmp):
    """The penalty baseline in finite sliding (``SlidingPenalty``) on the same block (64
    elements along its bottom, the slave, on 8 along the foundation's top) split over 4
    ranks, paired again at a step's start: each rank's pairs (and so the entries of their
    tuples, computed there) and its surface nodes (its slaves, the master facets near them)
    are ≤ 0.35× those of one rank (measured: 0.28, 0.34): no rank holds the whole pairing
    or the whole surfaces. (A pair's tuple is declared by its rank alone: the one rank owning
    the foundation declares its own slaves' only, test_contact_penalty_per_rank.py.)"""
    mesh = shared_tmp / "sliding_penalty_count.msh"
    write_mesh(mesh, 8, 64, ny_low=1, ny_up=1, seed=4)
    text = FOUNDATION.format(mesh=mesh, discretization="node_to_segment").replace(
        "friction = 0.3\n", 'friction = 0.3\nsliding = "finite"\nformulation = "penalty"\n'
                            "penalty = 1e5\n")

    def held(comm) -> np.ndarray:
        model = build_model(parse_scene(tomllib.loads(text), "count.toml", text), comm)
        effect = next(e for e in model.effects if type(e).__name__ == "SlidingPenalty")
        q = np.zeros(model.mesh.num_points * effect.fields_.ncomp)
        effect.begin_step(q, {}, None)   # (paired again on the current configuration)
        assert np.array_equal(effect.term.nodes[:len(effect.pairing)],
                              effect.geo.new_of(effect.tuple_ids))   # its own tuples first
        return np.array([len(effect.pairing), effect.surf.ids.size], dtype=float)

    alone = held(MPI.COMM_SELF)
    most = held(COMM)
    COMM.Allreduce(MPI.IN_PLACE, most, op=MPI.MAX)
    assert alone[0] == 65
    share = most / alone
    assert np.all(share <= 0.35), share
