"""The preset of a scene that names none: MUMPS or the iterative preset by size and kind
(solvers.choice), said in one line on rank 0, and the run as the chosen preset's."""

import numpy as np
import pytest
from mpi4py import MPI

from conftest import read_results
from helpers.scene import DROP, scene, shipped
from parsolve.solvers import choice


def test_choice_by_dimension_and_size():
    n = choice.CROSSOVER_3D
    assert choice.choose(10 * n, 2)[0] == "direct"
    assert choice.choose(n - 1, 3)[0] == "direct"
    assert choice.choose(n, 3)[0] == "iterative"
    preset, why = choice.choose(n, 3)
    assert f"{n:,}" in why and "3D" in why


def _run(text: str, out, comm=MPI.COMM_WORLD):
    """Run a scene text, its log lines kept; (results, log lines, the preset run)."""
    from parsolve.driver import run
    from parsolve.model import build_model
    from parsolve.scene import parse_scene
    import tomllib

    model = build_model(parse_scene(tomllib.loads(text), str(out) + ".toml", text), comm)
    lines: list[str] = []
    run(comm, model, str(out), {}, log=lines.append)
    comm.Barrier()
    return read_results(out), lines, model.scene.solver.preset


@pytest.mark.parametrize("crossover, expected", [(10**9, "direct"), (100, "iterative")])
def test_default_preset_is_chosen_and_said(shared_tmp, monkeypatch, crossover, expected):
    """The 3D friction box (441 DOFs) without a preset: MUMPS below the crossover, the
    iterative preset above it (the crossover moved to 100 DOFs here); one line on rank 0 says
    which and why; the answers are the same either way."""
    monkeypatch.setattr(choice, "CROSSOVER_3D", crossover)
    base = shipped("contact_friction_3d.toml")
    base["steps"]["count"] = 2
    base["steps"]["end"] = 0.25
    text = scene(base, solver=DROP)
    res, lines, preset = _run(text, shared_tmp / f"auto_{expected}.h5")
    assert preset == expected
    said = [ln for ln in lines if ln.startswith("solver:")]
    if MPI.COMM_WORLD.rank == 0:
        assert said == [f"solver: {expected} preset ({choice.choose(441, 3)[1]})"]
    else:
        assert said == []
    direct, _, _ = _run(scene(base, solver={"preset": "direct"}), shared_tmp / "auto_ref.h5")
    np.testing.assert_array_equal(res["steps/iterations"], direct["steps/iterations"])
    scale = np.abs(direct["fields/displacement"]).max()
    assert np.abs(res["fields/displacement"] - direct["fields/displacement"]).max() <= 1e-8 * scale


def test_a_given_preset_is_kept_and_not_said(shared_tmp):
    text = scene(shipped("contact_block_friction.toml"), solver={"preset": "iterative"})
    _, lines, preset = _run(text, shared_tmp / "given.h5")
    assert preset == "iterative" and not [ln for ln in lines if ln.startswith("solver:")]
