"""The in-process API (parsolve.api): scenes from a file, a string or dicts give the command
line's result file; bad input raises InputError naming the key; callbacks once per step."""

import tomllib

import numpy as np
import pytest
from mpi4py import MPI

import parsolve
from conftest import CONFIGS, read_results
from parsolve.errors import InputError

BAR = CONFIGS / "controlled_bar.toml"


def _same_file(a, b) -> None:
    """Every dataset but the timings equal, bit for bit."""
    for name, value in a.items():
        if name == "attrs" or name.startswith("timings/"):
            continue
        assert np.array_equal(value, b[name]), name
    assert a["attrs"]["status"] == b["attrs"]["status"] == "complete"


def test_file_string_and_dict_give_the_command_line_result(shared_tmp):
    from parsolve.cli import main

    comm = MPI.COMM_WORLD
    assert main(["run", str(BAR), "-o", str(shared_tmp / "cli.h5")]) == 0
    text = BAR.read_text()
    scenes = {"file": parsolve.Scene.from_file(BAR),
              "string": parsolve.Scene.from_string(text, base=CONFIGS),
              "dict": parsolve.Scene.from_dict(tomllib.loads(text), base=CONFIGS)}
    cli = read_results(shared_tmp / "cli.h5")
    for name, scene in scenes.items():
        result = parsolve.run(scene, shared_tmp / f"{name}.h5", comm, log=None)
        comm.Barrier()
        _same_file(cli, read_results(shared_tmp / f"{name}.h5"))
        # the Result object holds the same numbers as the file
        assert np.array_equal(result.times, cli["steps/time"])
        assert np.array_equal(result.fields["displacement"], cli["fields/displacement"])
        assert np.array_equal(result.cell_fields["stress"], cli["cell_fields/stress"])
        for key in ("multiplier", "primal", "resultant"):
            assert np.array_equal(result.relations["control"][key],
                                  cli[f"relations/control/{key}"])
        assert result.status == "complete" and result.path == str(shared_tmp / f"{name}.h5")
    # the dict scene's stored text reads back as the same scene
    stored = tomllib.loads(read_results(shared_tmp / "dict.h5")["attrs"]["scene"])
    assert stored == tomllib.loads(text)


def test_bad_dict_key_raises_input_error_naming_it(shared_tmp):
    data = tomllib.loads(BAR.read_text())
    data["mesh"]["nxx"] = 4
    with pytest.raises(InputError) as info:
        parsolve.Scene.from_dict(data, base=CONFIGS)
    assert info.value.key == "mesh.nxx" and info.value.source == "<dict>"
    data = tomllib.loads(BAR.read_text())
    data["relations"][0]["region"] = "nowhere"
    with pytest.raises(InputError) as info:
        parsolve.Scene.from_dict(data, base=CONFIGS)
    assert info.value.key == "relations[0].region" and info.value.source == "<dict>"
    # what needs the model (PETSc options) fails at run, before anything is written
    scene = parsolve.Scene.from_dict(tomllib.loads(BAR.read_text()), base=CONFIGS)
    with pytest.raises(InputError):
        parsolve.run(scene, shared_tmp / "bad.h5", options={"ksp_type": "no_such_krylov"},
                     log=None)
    assert not (shared_tmp / "bad.h5").exists()


def test_callback_once_per_step_with_its_values(shared_tmp):
    comm = MPI.COMM_WORLD
    seen = []

    def on_step(step):
        seen.append((step.index, step.t, step.iterations, step.residual,
                     step.relations["control"]["multiplier"].copy(),
                     step.fields["displacement"].shape[0]))

    result = parsolve.run(parsolve.Scene.from_file(BAR), shared_tmp / "cb.h5", comm,
                          on_step=on_step, log=None)
    assert [s[0] for s in seen] == list(range(10))
    assert np.array_equal([s[1] for s in seen], result.times)
    assert np.allclose(result.times, np.arange(1, 11) / 10, rtol=1e-15)
    assert [s[2] for s in seen] == list(result.iterations)
    assert np.array_equal([s[3] for s in seen], result.residual)
    assert np.array_equal(np.array([s[4] for s in seen]), result.relations["control"]["multiplier"])
    # each rank sees its own nodes' rows; together, every node once
    assert comm.allreduce(seen[0][5]) == result.points.shape[0]


def test_check_and_options(shared_tmp):
    model = parsolve.check(BAR, options={"ksp_type": "preonly"})
    assert model.mesh.num_global_points > 0
    with pytest.raises(InputError) as info:
        parsolve.check(BAR, options=["-ksp_type", "no_such_krylov"])
    assert "ksp_type" in str(info.value)
