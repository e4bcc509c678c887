"""Gas solubility on the distributed mesh (each rank its part): the same relation, the same
results as one rank alone, mass conserved on the parts; an input error of one part is raised
on every rank. Runs on 1, 2 and 3 ranks."""

import tomllib

import numpy as np
import pytest
from mpi4py import MPI

from conftest import assert_same_results, run_scene
from helpers.scene import scene
from parsolve.errors import InputError
from parsolve.model import build_model
from parsolve.relations import keep_rows
from parsolve.scene import parse_scene

N, SOURCE, FILL_END, DT = 12, 3.0, 0.5, 0.05
FILL_END_STEP = round(FILL_END / DT) - 1       # the last step of the source

# A closed unit square (walls of no flux), a uniform source of the dissolved phase until
# t = 0.5, a mobile gas, c_sat growing with x (an expression, evaluated per node) and lower on
# a box in the middle (a region's override): the gas appears first in the box, fronts move.
BASE = {
    "mesh": {"generator": "rectangle", "lx": 1.0, "ly": 1.0, "nx": N, "ny": N, "cell": "quad"},
    "model": {"dimension": 2},
    "regions": {"core": {"box": [[0.3, 0.3], [0.6, 0.7]]}},
    "evolutions": {"fill": {"times": [0.0, FILL_END, FILL_END + DT], "values": [1.0, 1.0, 0.0]}},
    "diffusion": [{"field": "c_s", "materials": [{"conductivity": 0.05, "capacity": 1.0}]},
                  {"field": "c_g", "materials": [{"conductivity": 0.01, "capacity": 1.0}]}],
    "solubility": {"regions": [{"region": "core", "saturation": 0.3}]},   # + saturation: square()
    "loads": [{"name": "fill", "field": "c_s", "source": SOURCE, "evolution": "fill"}],
    "time": {"mass": "lumped"},
    "steps": {"count": 30, "end": 30 * DT},
}
CSAT = "0.6 + 0.8 * x"
# a drain of the dissolved phase on the right side: the gas re-dissolves and leaves
DRAIN = [{"name": "drain", "type": "dirichlet", "field": "c_s", "region": "right", "value": 0.0}]


def square(csat: str = CSAT, **overrides) -> str:
    """The square with c_sat = ``csat`` (an expression) outside the core."""
    return scene(BASE, solubility={"saturation": csat}, **overrides)


def model_of(text: str, comm):
    scene = parse_scene(tomllib.loads(text), "test.toml", text)
    return build_model(scene, comm)


def solubility(model):
    return next(e for e in model.effects if e.name == "solubility")


def test_each_rank_builds_its_nodes_rows_of_the_one_rank_relation(comm):
    """Each rank holds the rows of its owned nodes alone (``Relation.ids``), numbered by the
    node's place in input order: rows, DOFs, values, dual and groups equal to one rank's
    rows at those numbers, from c_sat known on the owned nodes only; the ranks' rows are
    the whole relation's once each, and no rank holds them all when the square splits."""
    text = square()
    whole = model_of(text, MPI.COMM_SELF)
    parts = model_of(text, comm)
    a = next(r for r in whole.relations if r.name == "solubility")
    b = next(r for r in parts.relations if r.name == "solubility")
    assert a.nrows == b.total == 2 * (N + 1) ** 2
    every = np.sort(np.concatenate(comm.allgather(b.ids)))
    assert np.array_equal(every, np.arange(b.total))            # each row on one rank
    assert comm.allreduce(b.nrows) == b.total
    if comm.size > 1:
        assert b.nrows < b.total                               # (2, 3 ranks: none holds all)
    assert np.array_equal(b.ids[::2] + 1, b.ids[1::2]) and np.all(b.ids[::2] % 2 == 0)
    keep = np.zeros(a.nrows, dtype=bool)
    keep[b.ids] = True
    mine = keep_rows(a, keep)
    for name in ("a_rows", "a_dofs", "a_vals", "values"):
        assert np.array_equal(getattr(mine, name), getattr(b, name)), name
    for x, y in zip(mine.dual, b.dual):
        assert np.array_equal(x, y)
    assert np.array_equal(b.groups, np.repeat(np.arange(b.nrows // 2), 2))   # its own groups
    assert np.array_equal(a.groups[b.ids], b.ids // 2)
    assert np.array_equal(b.meta["nodes"], a.meta["nodes"][b.ids[::2] // 2])
    # the known levels: the core's nodes at 0.3, the others at 0.6 + 0.8 x
    x, y = whole.mesh.points[:, 0], whole.mesh.points[:, 1]
    core = (x >= 0.3 - 1e-9) & (x <= 0.6 + 1e-9) & (y >= 0.3 - 1e-9) & (y <= 0.7 + 1e-9)
    np.testing.assert_allclose(a.values[1::2], np.where(core, 0.3, 0.6 + 0.8 * x), rtol=1e-15)
    assert np.all(a.values[::2] == 0.0)
    mesh = parts.mesh   # c_sat on the owned nodes only, the rows on the owned nodes only
    assert solubility(parts).c_sat.shape == (mesh.n_owned,)
    assert np.all(np.isin(b.meta["nodes"], mesh.global_nodes[:mesh.n_owned]))


@pytest.mark.parametrize("drain, mode", [(False, "swmr"), (True, "parallel")],
                         ids=["closed", "drained"])
def test_parts_give_the_one_rank_results(drain, mode, shared_tmp, comm):
    """Every dataset (fields, states, multipliers, active rows, balance) to 1e-10, integer
    states and active rows exactly, in both output modes (the parts written by rank 0, or
    each rank its owned rows); the states switch both ways during the run."""
    text = square(relations=DRAIN) if drain else square()
    name = "drained" if drain else "closed"
    whole = run_scene(text, shared_tmp / f"{name}_whole{comm.rank}.h5", MPI.COMM_SELF)
    text = square(output={"mode": mode}, **({"relations": DRAIN} if drain else {}))
    parts = run_scene(text, shared_tmp / f"{name}_parts.h5", comm)
    assert_same_results(parts, whole, 1e-10)
    state = parts["fields/solubility_state"][..., 0]
    assert state.dtype.kind == "i" and set(np.unique(state)) == {0, 1}
    mixed = [(s == 1).any() and (s == 0).any() for s in state]
    assert any(mixed)                                   # a front: both states in one step
    assert np.array_equal(parts["relations/solubility/active"][:, 1::2], state)
    # the gas appears while the source fills (most nodes saturated at its last step), then
    # redissolves where diffusion or the drain lowers c_s below c_sat
    saturated = state.sum(axis=1)
    assert saturated[0] == 0 and saturated.argmax() == FILL_END_STEP
    assert saturated[-1] < 0.75 * saturated.max()          # (measured: 0.68, 0.70)


def test_mass_is_conserved_on_the_parts(shared_tmp, comm):
    """Closed walls: c_s + c_g integrates to what the source put in (3 · t until t = 0.5, then
    1.5) at every step, from the parts' fields with the lumped nodal areas (h²/4 per cell
    touching a node) and in the balance the parts reduce; each node obeys the
    complementarity (c_g = 0 dissolved, c_s = c_sat saturated)."""
    text = square()
    res = run_scene(text, shared_tmp / "mass.h5", comm)
    t = res["steps/time"]
    injected = SOURCE * 1.0 * np.minimum(t, FILL_END)
    cells = res["mesh/cells/quad"]
    area = np.bincount(cells.ravel(), minlength=res["mesh/points"].shape[0]) / (4.0 * N * N)
    cs, cg = res["fields/c_s"][..., 0], res["fields/c_g"][..., 0]
    np.testing.assert_allclose((cs + cg) @ area, injected, rtol=1e-12, atol=1e-14)
    np.testing.assert_allclose(res["balance/total/storage"], injected, rtol=1e-12, atol=1e-14)
    assert injected[-1] == pytest.approx(1.5)
    assert (cg @ area)[-1] > 0.1                        # a good part of it is gas
    x, y = res["mesh/points"][:, 0], res["mesh/points"][:, 1]
    core = (x >= 0.3 - 1e-9) & (x <= 0.6 + 1e-9) & (y >= 0.3 - 1e-9) & (y <= 0.7 + 1e-9)
    c_sat = np.where(core, 0.3, 0.6 + 0.8 * x)
    state = res["fields/solubility_state"][..., 0]
    assert np.all(cs <= c_sat + 1e-12) and np.all(cg >= -1e-12)
    np.testing.assert_allclose(np.where(state == 1, cs - c_sat, cg), 0.0, atol=1e-12)


def test_a_level_invalid_on_one_part_fails_on_every_rank(comm):
    """c_sat = 1 - x is 0 on the right side only (one rank's nodes on a part): every rank
    raises the same input error, none is left waiting."""
    text = square("1 - x")
    with pytest.raises(InputError) as err:
        model_of(text, comm)
    assert err.value.key == "solubility.saturation"
    assert "finite and positive" in err.value.message
