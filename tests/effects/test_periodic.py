"""The periodic relation: each node of a region tied to the node of a target region at its
position + a translation (u_a - u_b = 0 per component, associated). The shipped laminate
cell in simple shear gives the laminate's exact answer (the tie is what makes it
homogeneous along x) on the parts as alone; a node without a partner is an input error
naming the file and the key. Run at 1, 2 and 3 ranks."""

from __future__ import annotations

import numpy as np
import pytest
from mpi4py import MPI

from conftest import CONFIGS, assert_same_results
from test_configs import U, check_laminate, laminate_ux
from parsolve.errors import InputError
from parsolve.model import build_model
from parsolve.scene import load_scene

def test_laminate_cell_on_parts_and_alone(run):
    parts = run(CONFIGS / "periodic_shear_laminate.toml", name="laminate_parts",
                solver={"mesh": "distributed"})
    check_laminate(parts)
    alone = run(CONFIGS / "periodic_shear_laminate.toml", name="laminate_alone",
                comm=MPI.COMM_SELF)
    assert_same_results(parts, alone, tol=1e-10)


def test_without_the_tie_the_cell_is_not_homogeneous(run):
    """The control: the same cell without the periodic relation is far from the laminate."""
    text = (CONFIGS / "periodic_shear_laminate.toml").read_text()
    text = text[:text.index('name = "cell"')].rsplit("[[relations]]", 1)[0] + "[steps]\ncount = 1\n"
    res = run(text, name="laminate_untied")
    y = res["mesh/points"][:, 1]
    assert np.abs(res["fields/displacement"][-1][:, 0] - laminate_ux(y)).max() > 1e-2 * U


def test_a_node_without_partner_is_an_input_error(shared_tmp):
    text = (CONFIGS / "periodic_shear_laminate.toml").read_text().replace(
        "translation = [1.0, 0.0]", "translation = [1.0, 0.03]")
    path = shared_tmp / "periodic_lost.toml"
    if MPI.COMM_WORLD.rank == 0:
        path.write_text(text)
    MPI.COMM_WORLD.Barrier()
    with pytest.raises(InputError) as exc:
        build_model(load_scene(path), MPI.COMM_WORLD)
    assert exc.value.source == str(path) and exc.value.key == "relations[3].target"
    assert "has no node of region 'right_side'" in exc.value.message


@pytest.mark.parametrize("key, value, message", [
    ("translation", "translation = [1.0]", "expected 2 numbers"),
    ("value", 'value = 1.0', "has no value"),
    ("target", None, "missing required key"),
])
def test_scene_keys(shared_tmp, key, value, message):
    text = (CONFIGS / "periodic_shear_laminate.toml").read_text()
    old = 'target = "right_side"' if key == "target" else "translation = [1.0, 0.0]"
    text = text.replace(old, "" if value is None else
                        (old + "\n" + value if key == "value" else value))
    path = shared_tmp / f"periodic_{key}.toml"
    if MPI.COMM_WORLD.rank == 0:
        path.write_text(text)
    MPI.COMM_WORLD.Barrier()
    with pytest.raises(InputError) as exc:
        load_scene(path)
    assert exc.value.key == f"relations[3].{key}" and message in exc.value.message
