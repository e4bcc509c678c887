"""Contact rows on a master region built per rank: on the shipped ironing scenes in small
sliding, node-to-face (2D with friction; 3D with friction along the slip increment, and
frictionless) and mortar (2D with friction, 3D frictionless), and on the shipped mortar
sphere (3D mortar, frictionless), each rank holds
only the rows of the slave nodes it owns, the union over the ranks is the one-rank relation
row by row (global ids, DOFs and coefficients, the dual's too), and so is its pairing. At 2
and 3 ranks some row reaches a master DOF another rank owns (the
case the fetched values and the sent D entries exist for)."""

import tomllib

import numpy as np
import pytest
from mpi4py import MPI

from parsolve.model import build_model
from parsolve.scene import parse_scene
from parsolve.solvers.system import SaddleSystem
from tests.helpers.contact import FOUNDATION, write_mesh
from tests.helpers.scene import CONFIGS

COMM = MPI.COMM_WORLD


def small_sliding(name: str, extra: str) -> str:
    """A shipped scene with its contact in small sliding (``extra``: more keys)."""
    text = (CONFIGS / name).read_text(encoding="utf-8")
    if "ironing" not in name:
        return text
    assert 'sliding = "finite"\n' in text
    mesh = name.replace(".toml", ".msh")
    text = text.replace(f'file = "{mesh}"', f'file = "{CONFIGS / mesh}"')
    return text.replace('sliding = "finite"\n', extra)


def contact_rows(text: str, source: str, comm) -> tuple[dict, object, object]:
    """Per contact relation: (global ids, per row its sorted (DOF, coefficient) entries, and
    its dual's), the contact effect and the system's DOF map."""
    model = build_model(parse_scene(tomllib.loads(text), source, text), comm)
    system = SaddleSystem(comm, model)
    out = {}
    for r in system.relation_set.relations:
        if r.meta.get("type") != "contact":
            continue
        dofs, rows, vals = r.dual_coo()
        out[r.name] = (r.row_ids(), r.total, _per_row(r.a_rows, r.a_dofs, r.a_vals, r.nrows),
                       _per_row(rows, dofs, vals, r.nrows))
    effect = next(e for e in model.effects if type(e).__name__ == "Contact")
    return out, effect, system.dofmap


def _per_row(rows, dofs, vals, n) -> list:
    """Per row, its (DOF, coefficient) entries sorted by DOF, a DOF's entries summed (mortar
    rows pad to their rank's widest row with zero weights on the row's first master node)."""
    keys, inverse = np.unique(np.column_stack([rows, dofs]), axis=0, return_inverse=True)
    summed = np.bincount(inverse.ravel(), weights=vals, minlength=keys.shape[0])
    split = np.cumsum(np.bincount(keys[:, 0], minlength=n))[:-1]
    return [np.column_stack([d, v]) for d, v in zip(np.split(keys[:, 1], split),
                                                    np.split(summed, split))]


#: (scene, keys added, whether its rows reach other ranks' DOFs at 2 and 3 ranks: the sphere
#: and the block mostly on different ranks; the ironing dies' contact and the base under
#: them may share a rank, as they do on today's partitions)
MORTAR = 'discretization = "mortar"\n'
CASES = [("contact_ironing_2d.toml", "", False),
         ("contact_ironing_3d.toml", 'direction = "displacement"\n', False),
         ("contact_ironing_3d.toml", "friction = 0.0\n", False),
         ("contact_ironing_2d.toml", MORTAR, False),
         ("contact_ironing_3d.toml", MORTAR + "friction = 0.0\n", False),
         ("contact_mortar_sphere_3d.toml", "", True)]


@pytest.mark.parametrize("name, extra, crosses", CASES)
def test_each_rank_holds_its_slave_rows_and_together_the_one_rank_rows(name, extra, crosses):
    text = small_sliding(name, extra)
    if "friction = 0.0" in extra:
        text = text.replace("friction = 0.3\n", "")
    frictional = "friction" not in extra and "sphere" not in name
    check_rows(text, str(CONFIGS / name), frictional, crosses)


@pytest.mark.parametrize("discretization", ["node_to_segment", "mortar"])
def test_rows_across_ranks_on_a_meshed_foundation(shared_tmp, discretization):
    """The block on a meshed rough foundation (test_contact_distributed): its slave and master
    nodes split over the ranks, frictional rows reaching master DOFs of other ranks."""
    mesh = shared_tmp / "foundation_rows.msh"
    write_mesh(mesh, 5, 8, ny_up=4, seed=4)
    text = FOUNDATION.format(mesh=mesh, discretization=discretization)
    check_rows(text, str(shared_tmp / "foundation_rows.toml"), True, True)


def check_rows(text: str, source: str, frictional: bool, crosses: bool) -> None:
    """Each rank's contact rows are those of its own slave nodes, and together the one-rank
    rows (ids, DOFs, coefficients of A and D), the pairing too."""
    here, effect, dofmap = contact_rows(text, source, COMM)
    alone, whole_effect, _ = contact_rows(text, source, MPI.COMM_SELF)
    assert effect.here and effect.ids is not None
    assert set(here) == set(alone) == {f"{effect.spec.name}_{k}" for k in
                                       (("normal", "tangent") if frictional else ("normal",))}
    # every slave node of the rows held here is owned here
    own, _ = dofmap.owned_nodes(effect.pairing.slave)
    assert own.all()
    reaches = 0
    for rel, (ids, total, a_rows, d_rows) in here.items():
        ids_1, total_1, a_1, d_1 = alone[rel]
        assert total == total_1 == ids_1.size
        assert np.array_equal(ids_1, np.arange(total_1))
        every = np.concatenate(COMM.allgather(ids))
        assert np.array_equal(np.sort(every), np.arange(total_1))   # each row on one rank
        for k, i in enumerate(ids):
            np.testing.assert_array_equal(a_rows[k][:, 0], a_1[i][:, 0])
            np.testing.assert_allclose(a_rows[k][:, 1], a_1[i][:, 1], rtol=0, atol=1e-14)
            np.testing.assert_array_equal(d_rows[k][:, 0], d_1[i][:, 0])
            np.testing.assert_allclose(d_rows[k][:, 1], d_1[i][:, 1], rtol=0, atol=1e-14)
        dofs = np.concatenate([r[:, 0] for r in a_rows]).astype(np.int64) if a_rows else \
            np.zeros(0, np.int64)
        owned, _ = dofmap.owned_nodes(dofs // dofmap.ncomp)
        reaches += int((~owned).sum())
    if COMM.size > 1 and crosses:   # a row on a master node of another rank
        assert COMM.allreduce(reaches) > 0
    np.testing.assert_array_equal(effect.pairing.slave,
                                  whole_effect.pairing.slave[effect.ids])
    np.testing.assert_allclose(effect.pairing.gap, whole_effect.pairing.gap[effect.ids],
                               rtol=0, atol=1e-14)
