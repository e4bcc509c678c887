"""Rows over regions (``mean``, ``linear``, ``strain``: one row each) and a control's load
pattern are spread over the ranks: every rank holds every row, and of its entries those on the
DOFs it owns (``Relation.spread``; a strain's cells built by the rank counting them, their
entries sent to their DOFs' owners, the pattern's each rank's owned part). A per-cell strain
under a maximum is built per rank (each cell's row by the rank counting it). Over the ranks the
entries are the one-process build's, entry by entry, each (row, DOF) held once; the stacked A
entries of each row reach its multiplier row's owner alone; each rank holds at most 1.4 / ranks
of the entries (0.35 at 4 ranks); and the scenes answer their closed forms at every rank count.
Run at 1, 2, 3 and 4 ranks."""

import tomllib

import numpy as np
import pytest
from mpi4py import MPI

from parsolve.model import build_model
from parsolve.relation_kinds.strain import row_cell
from parsolve.relations import Relation
from parsolve.scene import parse_scene
from parsolve.solvers.system import SaddleSystem
from tests.helpers.plate import PLATE, dirichlet, mean
from tests.helpers.scene import CONFIGS, scene, scene_data

COMM = MPI.COMM_WORLD
BAR = (CONFIGS / "controlled_bar.toml").read_text(encoding="utf-8")
#: a 2 × 1 plate of 24 × 12 quads: a mean controlled by a load pattern, a linear relation of
#: overlapping terms (a node in both: one coefficient), a region's mean strain, and a maximum
#: of the strains of a box's cells controlled by the same pattern
PLATE_DATA = scene_data(
    PLATE, loads=[{**PLATE["loads"][0], "total_force": [1.0, 0.5]}],
    regions={"corner": {"point": [0.0, 0.0]}, "upper": {"box": [[0.0, 0.5], [2.0, 1.0]]},
             "mid": {"box": [[0.5, 0.25], [1.5, 0.75]]}},
    relations=[dirichlet("left_x", "left", "x"), mean("opening", "right", 1e-4, dual="pull"),
               {"name": "general", "type": "linear", "value": 0.0, "eliminate": False,
                "terms": [{"region": "top", "component": "y", "coefficient": 1.0, "mean": True},
                          {"region": "upper", "component": "y", "coefficient": -2.0}]},
               {"name": "mean_strain", "type": "strain", "region": "mid",
                "direction": [1.0, 1.0]},
               {"name": "cells", "type": "strain", "region": "mid", "component": "xx",
                "per_cell": True, "maximum": True, "sense": "<=", "value": 1.2e-3,
                "dual": "pull"}])
PLATE_TEXT = scene(PLATE_DATA)
SPREAD = ["opening", "general", "mean_strain", "cells"]
WHOLE = SPREAD[:3]   # (the cells' rows: per rank)


def entries(r: Relation) -> np.ndarray:
    """(row, DOF, coefficient) of the A entries held here, by row then DOF."""
    out = np.column_stack([r.a_rows, r.a_dofs, r.a_vals]).reshape(-1, 3)
    return out[np.lexsort((out[:, 1], out[:, 0]))]


def union(parts: list[np.ndarray]) -> np.ndarray:
    """Rows of (key, key, value) from every rank, by their keys, each pair of keys once."""
    out = np.concatenate(parts)
    out = out[np.lexsort((out[:, 1], out[:, 0]))]
    assert not np.any((np.diff(out[:, 0]) == 0) & (np.diff(out[:, 1]) == 0))
    return out


def model_of(text: str, comm):
    return build_model(parse_scene(tomllib.loads(text), "t.toml", text), comm)


def test_the_ranks_entries_are_the_one_process_build():
    model, alone = model_of(PLATE_TEXT, COMM), model_of(PLATE_TEXT, MPI.COMM_SELF)
    here = {r.name: r for r in model.relations}
    one = {r.name: r for r in alone.relations}
    mesh = model.mesh
    owned = mesh.global_nodes[:mesh.n_owned]
    # the sizes on one rank: the right side's 13 nodes; the top's 25 (mean) and the upper
    # half's 7 × 25 (sum) y, the top in both; the box's mean strain, a boundary integral: its
    # boundary's 36 nodes (direction (1, 1): x and y of each; the inner nodes' coefficients
    # cancel); its 12 × 6 cells' xx, 4 nodes each; the pattern on the right side's 13 nodes
    # (x and y)
    assert [one[n].a_vals.size for n in SPREAD] == [13, 175, 2 * 36, 72 * 4]
    assert [one[n].nrows for n in SPREAD] == [1, 1, 1, 72]
    assert one["opening"].shared_dual[0].size == 26
    for name in SPREAD:
        r, whole = here[name], one[name]
        if name in WHOLE:
            assert r.spread and r.whole and not r.complete and r.nrows == whole.nrows
            np.testing.assert_array_equal(r.values, whole.values)
            assert np.isin(r.a_dofs // 2, owned).all()   # each entry on its DOF's owner
            got = union(COMM.allgather(entries(r)))
        else:   # each row on the rank counting its cell, all its entries there
            assert not r.whole and r.total == whole.nrows and r.collapsed
            assert COMM.allreduce(r.nrows) == whole.nrows
            np.testing.assert_array_equal(r.values, whole.values[r.ids])
            mine = entries(r)
            mine[:, 0] = r.ids[mine[:, 0].astype(np.int64)]
            got = union(COMM.allgather(mine))
        np.testing.assert_array_equal(got[:, :2], entries(whole)[:, :2])
        np.testing.assert_allclose(got[:, 2], entries(whole)[:, 2], rtol=1e-13,
                                   atol=1e-13 * np.abs(got[:, 2]).max())
        if whole.shared_dual is not None:   # the pattern: each rank its owned DOFs'
            dofs, vals = r.shared_dual
            assert np.isin(dofs // 2, owned).all()
            got = union(COMM.allgather(np.column_stack([dofs, dofs, vals])))
            np.testing.assert_array_equal(got[:, 0], whole.shared_dual[0])
            np.testing.assert_allclose(got[:, 2], whole.shared_dual[1], rtol=1e-14)
    # the closed forms: a mean's coefficients 1 / 13; the linear row 1/25 − 2 on the top's
    # nodes, −2 on the others; the cells' rows ordered by cell id
    np.testing.assert_allclose(one["opening"].a_vals, 1 / 13, rtol=1e-15)
    top = np.isclose(alone.mesh.points[one["general"].a_dofs // 2, 1], 1.0)
    np.testing.assert_allclose(one["general"].a_vals, np.where(top, 1 / 25 - 2.0, -2.0),
                               rtol=1e-14)
    # the cells' rows: each rank the cells it counts, with their rows; over the ranks the
    # one-process cells in row order (by cell id), every cell once, told by ``row_cell``
    cells, rows = here["cells"].meta["cells"], here["cells"].meta["cell_rows"]
    assert cells.size == rows.size and COMM.allreduce(cells.size) == 72
    every = np.zeros(72, dtype=np.int64)
    every[rows] = cells
    every = COMM.allreduce(every)
    assert np.all(np.diff(every) > 0)
    np.testing.assert_array_equal(every[one["cells"].meta["cell_rows"]], one["cells"].meta["cells"])
    assert [row_cell(COMM, here["cells"], j) for j in (0, 71)] == [every[0], every[71]]
    assert row_cell(COMM, here["mean_strain"], 0) is None


def test_a_rows_entries_meet_at_its_owner():
    """In the stacking, each spread row's A entries reach the rank owning its multiplier row:
    every entry kept once, all of a row's on one rank (a maximum group's: those of the one row
    its multiplier row carries, its first until another is enforced); A q of the rows is the
    one-process value."""
    model = model_of(PLATE_TEXT, COMM)
    system = SaddleSystem(COMM, model)
    rs, dm = system.relation_set, system.dofmap
    _, _, l0, l1 = dm.owned()
    names = [r.name for r in rs.relations]
    for name in SPREAD:
        k = names.index(name)
        r = rs.relations[k]
        mult = np.unique(rs.mult_rows[k])
        here = np.isin(rs.a_rows, mult)
        assert np.all((rs.a_rows[here] >= l0) & (rs.a_rows[here] < l1))
        carried = np.ones(r.a_vals.size, dtype=bool) if r.whole else r.ids[r.a_rows] == 0
        assert COMM.allreduce(int(here.sum())) == COMM.allreduce(int(carried.sum())) > 0
        owners = COMM.allgather(np.unique(rs.a_rows[here]))
        every = np.concatenate(owners)
        assert every.size == np.unique(every).size   # a row's entries on one rank
    # A q with q the input DOF numbers, against the relations' own rows on every DOF
    local = dm.mesh
    q = ((local.global_nodes.astype(np.int64)[:, None] * dm.ncomp + np.arange(dm.ncomp))
         .ravel().astype(float))
    alone = {r.name: r for r in model_of(PLATE_TEXT, MPI.COMM_SELF).relations}
    every = np.arange(local.num_global_points * dm.ncomp, dtype=float)
    values = rs.primal_values(q)
    for name in SPREAD:
        k = names.index(name)
        expected = alone[name].primal(every)[rs.relations[k].row_ids()]
        np.testing.assert_allclose(values[rs.rows_of(k)], expected, rtol=1e-12)


#: the plate's rows over the whole mesh (the mean of x, the mean strain, every cell's strain
#: under a maximum), the pattern a load over the top: what the ranks share evenly
EVERYWHERE = scene(
    PLATE_DATA, loads=[{**PLATE_DATA["loads"][0], "region": "top"}],
    relations=[{**r, "region": "all"} if r["name"] in ("opening", "mean_strain", "cells") else r
               for r in PLATE_DATA["relations"]])


#: the entries on one rank alone: the mean's 325 nodes, the linear row's 175, the mean strain's
#: boundary's 72 nodes × 2, the 288 cells' rows × 4, the pattern's 25 top nodes × 2, twice
ONE_RANK = 1_896


def held(r: Relation) -> int:
    """Entries a rank holds of a relation: its A entries and its part of a pattern."""
    return r.a_vals.size + (0 if r.shared_dual is None else r.shared_dual[0].size)


def test_each_rank_holds_its_share_of_the_entries():
    """Each rank holds at most 1.4 / ranks of the rows' entries (0.35 at 4 ranks), the
    entries every rank holds together being the one-process build's. Measured at 1 / 2 / 3 /
    4 ranks: 1,896 / 986 / 678 / 530 entries on the largest rank (0.280 at 4 ranks)."""
    model = model_of(EVERYWHERE, COMM)
    rels = [r for r in model.relations if r.name in SPREAD]
    assert [r.name for r in rels] == SPREAD
    mine = sum(held(r) for r in rels)
    total, most = COMM.allreduce(mine), COMM.allreduce(mine, op=MPI.MAX)
    alone = sum(held(r) for r in model_of(EVERYWHERE, MPI.COMM_SELF).relations
                if r.name in SPREAD)
    assert total == alone == ONE_RANK
    assert most <= 1.4 / COMM.size * total + 4, (most, total)
    if COMM.size == 4:
        assert most <= 0.35 * total, (most, total)


#: the controlled bar's control relation's kind, region and component keys
CONTROL = 'report = true\ntype = "mean"\nregion = "right"\ncomponent = "x"'
#: the bar's control by one node's x (a Dirichlet row at the lower right corner: built per
#: rank, made one global row)
POINT = BAR.replace("[regions]", "[regions]\nend = { point = [1.0, 0.0] }").replace(
    CONTROL, 'type = "dirichlet"\nregion = "end"\ncomponents = ["x"]')


@pytest.mark.parametrize("kind", ["mean", "strain", "point"])
def test_a_controlled_bar_answers_its_closed_form(kind, run):
    """The controlled bar by its right end's mean displacement, by its mean strain or by one
    node's displacement (ν = 0: the same): the multiplier is the end force E H δ / L = E H ε =
    1e4 N at the last step, δ = 1e-4 (1e-4 × t at each step), at every rank count."""
    text = {"mean": BAR, "point": POINT,
            "strain": BAR.replace(CONTROL, 'type = "strain"\nregion = "all"\ncomponent = "xx"')
            }[kind]
    assert text != BAR or kind == "mean"
    res = run(text, name=f"bar_{kind}")
    assert res["attrs"]["status"] == "complete"
    t = res["steps/time"]
    np.testing.assert_allclose(res["relations/control/multiplier"][:, 0], 1e9 * 0.1 * 1e-4 * t,
                               rtol=1e-9)
    np.testing.assert_allclose(res["relations/control/primal"][:, 0], 1e-4 * t, rtol=1e-9)
    pts = res["mesh/points"]
    np.testing.assert_allclose(res["fields/displacement"][:, :, 0],
                               1e-4 * t[:, None] * pts[None, :, 0], rtol=0, atol=1e-12)


def test_a_point_control_is_one_row_on_every_rank():
    """A Dirichlet row controlled by a load pattern, built by the rank owning its node, is
    one global row: every rank holds that one row (its value from the holder), no more."""
    (r,) = [r for r in model_of(POINT, COMM).relations if r.name == "control"]
    assert r.whole and r.spread and r.nrows == 1 and r.values.tolist() == [1e-4]
    assert COMM.allreduce(r.a_rows.size) == 1   # (the node's owner holds its one entry)


@pytest.mark.parametrize("kind", ["dirichlet", "strain"])
def test_several_rows_sharing_one_load_are_refused(kind):
    """Several rows sharing one load pattern, without a maximum (the right end's x node by
    node, or each cell's strain), would leave all but their multipliers' sum undetermined: the
    scene is refused before any solve, on every rank, naming the file and the key."""
    from parsolve.errors import InputError

    rows = {"dirichlet": 'type = "dirichlet"\nregion = "right"\ncomponents = ["x"]',
            "strain": 'type = "strain"\nregion = "all"\ncomponent = "xx"\nper_cell = true'}
    text = BAR.replace(CONTROL, rows[kind])
    with pytest.raises(InputError) as caught:
        model_of(text, COMM)
    n = 4 if kind == "dirichlet" else 29 * 3
    assert caught.value.source == "t.toml" and caught.value.key == "relations[2].dual"
    assert f"'control' has {n} rows sharing the load pattern 'pull'" in str(caught.value)
