"""The per-rank kinds (Dirichlet, equal, periodic) build only the rows of the nodes their rank
owns: what each kind's ``build`` returns on a rank is that rank's rows, numbered as in the whole
relation, and the rows of every rank together are the one-process build's, row for row (the
same ids, DOFs, coefficients and values), an eliminated Dirichlet relation included (it is
gathered whole after its build). The distributed pieces against their whole counterparts:
a key's place among every rank's keys, and periodic partners paired in slabs. Run at 1, 2 and
3 ranks."""

import dataclasses
import tomllib

import numpy as np
import pytest
from mpi4py import MPI

from parsolve.model import build_model
from parsolve.relation_kinds import periodic, registry
from parsolve.relation_kinds.spread import places
from parsolve.relations import Relation, lead_dofs
from parsolve.scene import parse_scene
from tests.helpers.scene import CONFIGS
from tests.relation_kinds.test_per_rank import EQUAL

COMM = MPI.COMM_WORLD
#: the laminate refined, its sides tied, its top and bottom held (the top's x by an
#: expression), the upper half's y equal (and the lower half's mean x: one row, whole), and the
#: lower left quarter's y held at 0 (its bottom row already held so by the bottom: those rows
#: dropped from it, the others numbered again)
SCENE = (CONFIGS / "periodic_shear_laminate.toml").read_text(encoding="utf-8") \
    .replace("[regions]", "[regions]\nquarter = { box = [[0.0, 0.0], [0.5, 0.5]] }") \
    .replace("nx = 6", "nx = 12").replace("ny = 8", "ny = 10") \
    .replace('value = 0.01', 'value = "0.01 + 0.002 * x"') + EQUAL + """
[[relations]]
name = "quarter_y"
type = "dirichlet"
region = "quarter"
components = ["y"]
"""
#: the relations the per-rank kinds build (the mean is built whole, after "top_even")
NAMES = ["bottom_held", "top_shear", "top_y", "cell", "top_even", "quarter_y"]


def built(text: str, comm, monkeypatch) -> tuple[np.ndarray, dict[str, Relation]]:
    """(input ids of the nodes this rank owns, what each kind's build returned here)."""
    seen = {}
    for kind in ("dirichlet", "equal", "periodic"):
        entry = registry.RELATIONS[kind]

        def spy(spec, where, evolution, build=entry.build):
            seen[spec.name] = r = build(spec, where, evolution)
            return r
        monkeypatch.setitem(registry.RELATIONS, kind, dataclasses.replace(entry, build=spy))
    model = build_model(parse_scene(tomllib.loads(text), "t.toml", text), comm)
    monkeypatch.undo()
    return np.sort(model.mesh.global_nodes[:model.mesh.n_owned]), seen


def rows(r: Relation) -> list[tuple]:
    """(global row, DOFs, coefficients, value) of each row built here, entries in order."""
    out = []
    for k, g in enumerate(r.row_ids()):
        at = r.a_rows == k
        out.append((int(g), tuple(r.a_dofs[at].tolist()), tuple(r.a_vals[at].tolist()),
                    float(r.values[k])))
    return out


def entries(r: Relation) -> np.ndarray:
    """(row, DOF, coefficient) of a whole relation's entries held here, by row then DOF."""
    out = np.column_stack([r.a_rows, r.a_dofs, r.a_vals]).reshape(-1, 3)
    return out[np.lexsort((out[:, 1], out[:, 0]))]


def union(r: Relation, comm=COMM) -> np.ndarray:
    """``entries`` of a spread relation over every rank, each (row, DOF) held once."""
    out = np.concatenate(comm.allgather(entries(r)))
    out = out[np.lexsort((out[:, 1], out[:, 0]))]
    assert not np.any((np.diff(out[:, 0]) == 0) & (np.diff(out[:, 1]) == 0))
    return out


@pytest.mark.parametrize("eliminate", [True, False])
def test_each_rank_builds_its_rows_only(eliminate, monkeypatch):
    text = SCENE + ("" if eliminate else "\n[solver]\neliminate = false\n")
    owned, here = built(text, COMM, monkeypatch)
    _, alone = built(text, MPI.COMM_SELF, monkeypatch)
    assert list(here) == list(alone) == NAMES
    # one rank alone: the laminate 12 × 10: bottom and top 13 nodes, the sides 9 tied nodes
    # × 2 components, the upper half's 13 × 6 nodes but its first, the quarter 7 × 6 nodes
    assert [alone[n].total for n in alone] == [26, 13, 13, 18, 77, 42]
    for name, r in here.items():
        assert not r.whole and r.total == alone[name].total
        # every row built here is of a node this rank owns, and there are as many as the
        # region's owned nodes times its components
        lead = lead_dofs(r) // 2
        assert np.isin(lead, owned).all()
        assert np.all(np.diff(r.ids) > 0)
        assert COMM.allreduce(r.nrows) == r.total
        # every rank's rows together: the one-process build's, row for row
        gathered = sorted(sum(COMM.allgather(rows(r)), []))
        assert gathered == rows(alone[name])
    # the values of an expression: 0.01 + 0.002 x at the top's nodes (x = 0, 1/12, ..., 1)
    top = alone["top_shear"]
    x = (top.a_dofs // 2 % 13) / 12.0
    np.testing.assert_allclose(top.values, 0.01 + 0.002 * x, rtol=0, atol=1e-15)


@pytest.mark.parametrize("eliminate", [True, False])
def test_the_relations_after_the_checks_keep_their_numbers(eliminate):
    """After the checks (the quarter's 7 bottom rows dropped: the bottom holds them at the
    same value) the rows held per rank are numbered from 0 in the whole relation's order on
    every rank count, each the one-process model's; eliminated or not, held per rank (no
    rank gathers an eliminated relation's rows)."""
    text = SCENE + ("" if eliminate else "\n[solver]\neliminate = false\n")
    model = build_model(parse_scene(tomllib.loads(text), "t.toml", text), COMM)
    alone = build_model(parse_scene(tomllib.loads(text), "t.toml", text), MPI.COMM_SELF)
    assert [r.name for r in model.relations] == NAMES[:5] + ["mean_x", "quarter_y"]
    assert [r.total for r in model.relations] == [26, 13, 13, 18, 77, 1, 35]
    assert [r.whole for r in model.relations] == [False] * 5 + [True, False]
    assert [r.eliminable() for r in model.relations] == [eliminate] * 3 + [False] * 3 \
        + [eliminate]
    for r, one in zip(model.relations, alone.relations):
        assert r.total == one.nrows
        assert r.spread == (r.name == "mean_x")   # (its entries on their DOFs' owners)
        if r.spread:
            np.testing.assert_array_equal(r.values, one.values)
            np.testing.assert_allclose(union(r), entries(one), rtol=1e-14, atol=0)
            continue
        if r.whole:
            assert rows(r) == rows(one)
            continue
        ids = np.concatenate(COMM.allgather(r.row_ids()))
        assert np.array_equal(np.sort(ids), np.arange(r.total))
        assert sorted(sum(COMM.allgather(rows(r)), [])) == rows(one)


def test_places_are_the_sorted_positions():
    rng = np.random.default_rng(7 + COMM.rank)
    keys = np.unique(rng.integers(0, 1000, size=50 + 13 * COMM.rank)) * COMM.size + COMM.rank
    every = np.sort(np.concatenate(COMM.allgather(keys)))
    np.testing.assert_array_equal(places(COMM, keys, 1000 * COMM.size),
                                  np.searchsorted(every, keys))
    empty = places(COMM, np.zeros(0, dtype=np.int64), 10)
    assert empty.shape == (0,)


def test_partners_in_slabs_are_the_whole_pairing():
    """Each rank's points and candidates (its share of a 3D grid, partners at x + (1, 0, 0)):
    the pairs found in slabs are those of ``partners`` on every candidate."""
    g = np.stack(np.meshgrid(np.arange(4.0), np.arange(5.0), np.arange(3.0), indexing="ij"),
                 axis=-1).reshape(-1, 3)
    ids = np.arange(g.shape[0], dtype=np.int64) * 3 + 1
    mine = np.arange(g.shape[0]) % COMM.size == COMM.rank
    a = mine & (g[:, 0] < 3)
    got = periodic.spread_partners(COMM, g[a], ids[mine], g[mine], [1.0, 0.0, 0.0], 1e-9)
    whole = periodic.partners(g[a], ids, g, [1.0, 0.0, 0.0], 1e-9)
    np.testing.assert_array_equal(got, whole)
    assert np.all(got == ids[a] + 3 * 15)   # the node one step along x
    lost = periodic.spread_partners(COMM, g[a], ids[mine], g[mine], [0.5, 0.0, 0.0], 1e-9)
    assert np.all(lost == -1)
