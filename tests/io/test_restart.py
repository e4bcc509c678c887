"""Restart (parsolve.io.restart): a run stopped at step k and continued from its result gives
the uninterrupted run's result (bit for bit on one rank, to round-off on several), and a
finished run is extended by a later end of [steps]."""

import os
import shutil
import signal
import subprocess
import sys
import time
import tomllib

import h5py
import numpy as np
import pytest
from mpi4py import MPI

import parsolve
from conftest import CONFIGS, read_results
from parsolve.errors import InputError
from parsolve.batch.toml_write import dumps as to_toml
from parsolve.io.restart import state_path


def _times_scene(name: str, times: list[float]) -> parsolve.Scene:
    """A shipped scene with explicit step times (the same numbers in both runs) and no
    [output] file."""
    data = tomllib.loads((CONFIGS / name).read_text())
    data.pop("output", None)
    data["steps"] = {"times": times}
    return parsolve.Scene.from_dict(data, source=name, base=CONFIGS)


def assert_continued(full: dict, restarted: dict, steps_copied: int,
                     tol: float = 1e-12) -> None:
    """Every per-step dataset of the restarted result equals the uninterrupted run's: bit for
    bit on one rank. On several, the direct solver's parallel analysis, made on another
    step's matrix, changes the round-off of the steps after the first restarted one, and
    MUMPS' parallel factorization is not bitwise reproducible (it sums contributions in the
    order they arrive: two identical runs may differ in their last bits): each value then
    within ``tol`` of its scale (a field's largest value; for reactions, the largest
    reaction in the file, for relation values the largest relation value or displacement — a
    reaction or a held value that is zero up to round-off has no scale of its own;
    damage: within 1e-10 at least, a softening law amplifies round-off near its threshold),
    and the residuals (round-off themselves) below the convergence tolerance alike."""
    assert restarted["attrs"]["restart_steps"] == steps_copied
    assert restarted["attrs"]["status"] == full["attrs"]["status"] == "complete"
    names = [n for n in full if n != "attrs" and not n.startswith(("timings/", "mesh/"))]
    assert any(n.startswith("fields/") for n in names)

    def largest(*ends) -> float:
        return max([float(np.abs(full[n]).max(initial=0.0)) for n in names if n.endswith(ends)]
                   + [0.0])
    force, motion = largest("/multiplier", "/resultant"), largest("/primal", "/displacement")
    for name in names:
        a, b = np.asarray(full[name]), np.asarray(restarted[name])
        assert a.shape == b.shape, name
        if MPI.COMM_WORLD.size == 1 or a.dtype.kind in "iub":
            assert np.array_equal(a, b), name
        elif name == "steps/residual":
            assert b.max() < 1e-6, name
        else:
            scale = force if name.endswith(("/multiplier", "/resultant")) else \
                motion if name.endswith("/primal") else float(np.abs(a).max(initial=0.0))
            bound = max(tol, 1e-10) if name.endswith("/damage") else tol
            assert np.abs(a - b).max(initial=0.0) <= bound * max(scale, 1e-300), name


def _stop_and_restart(shared_tmp, name: str, count: int, k: int, mode: str = "swmr",
                      tol: float = 1e-12) -> None:
    """The scene's ``count`` steps at once, and its first ``k`` then the rest by restart."""
    times = [(i + 1) / count for i in range(count)]
    comm = MPI.COMM_WORLD
    parsolve.run(_times_scene(name, times), shared_tmp / "full.h5", comm, log=None,
                 output_mode=mode)
    first = parsolve.run(_times_scene(name, times[:k]), shared_tmp / "first.h5", comm,
                         log=None, output_mode=mode)
    assert len(first.times) == k
    rest = parsolve.run(_times_scene(name, times), shared_tmp / "rest.h5", comm,
                        restart=shared_tmp / "first.h5", log=None, output_mode=mode)
    assert np.array_equal(rest.times, times)
    assert_continued(read_results(shared_tmp / "full.h5"), read_results(shared_tmp / "rest.h5"),
                     k, tol)


@pytest.mark.parametrize("name, count, k, tol", [
    ("thermal_expansion.toml", 4, 2, 1e-12),      # linear: one factorization, back-substitutions
    # Newton, damage history, maximum control. Runs whose solves differ in their last bits
    # stop Newton at iterates apart by the convergence tolerance, and the damage history
    # carries that through the softening steps (x5 per step, then back): two identical runs
    # at 3 ranks differed by up to 9e-12 of scale, at 4 by 4.3e-10 (the same operator and
    # right-hand side on every rank gave solutions differing in their last bits: MUMPS'
    # parallel scheduling), one rank's runs with the maximum group's row built two ways by
    # 1.4e-9 (2026-12-06)
    ("localization_bar.toml", 24, 10, 1e-8),
    ("contact_block_friction.toml", 10, 4, 1e-12),   # Coulomb friction: stick / slip states
    ("contact_ironing_2d.toml", 10, 4, 1e-12),       # finite sliding: pairing and spans
])
def test_restart_continues_the_run(shared_tmp, name, count, k, tol):
    _stop_and_restart(shared_tmp, name, count, k, tol=tol)


def test_restart_in_parallel_output_mode(shared_tmp):
    """Every rank writes its own rows (MPI-IO), the copied steps' as the new ones."""
    _stop_and_restart(shared_tmp, "contact_block_friction.toml", 10, 4, mode="parallel")


class Stop(Exception):
    pass


def test_restart_of_automatic_steps(shared_tmp):
    """Adaptive steps (the step size is state too): a run stopped by its callback after its
    5th step (that step's state is not saved: the restart copies 4 and redoes the 5th)."""
    data = tomllib.loads((CONFIGS / "plate_hole_control.toml").read_text())
    data.pop("output", None)
    data["steps"]["automatic"] = {"strain_increment": 8e-5, "max_steps": 60}
    scene = parsolve.Scene.from_dict(data, base=CONFIGS)
    parsolve.run(scene, shared_tmp / "full.h5", log=None)

    def stop(step):
        if step.index == 4:
            raise Stop()
    with pytest.raises(Stop):
        parsolve.run(scene, shared_tmp / "first.h5", on_step=stop, log=None)
    MPI.COMM_WORLD.Barrier()
    parsolve.run(scene, shared_tmp / "rest.h5", restart=shared_tmp / "first.h5", log=None)
    full = read_results(shared_tmp / "full.h5")
    assert len(full["steps/time"]) > 8
    assert_continued(full, read_results(shared_tmp / "rest.h5"), 4)


def test_callbacks_of_a_restart_are_the_new_steps(shared_tmp):
    times = [0.25, 0.5, 0.75, 1.0]
    parsolve.run(_times_scene("controlled_bar.toml", times[:2]), shared_tmp / "a.h5", log=None)
    seen = []
    parsolve.run(_times_scene("controlled_bar.toml", times), shared_tmp / "b.h5",
                 restart=shared_tmp / "a.h5", on_step=lambda s: seen.append((s.index, s.t)),
                 log=None)
    assert seen == [(2, 0.75), (3, 1.0)]


def test_restart_refuses_another_scene_and_its_own_input(shared_tmp):
    comm = MPI.COMM_WORLD
    parsolve.run(_times_scene("controlled_bar.toml", [0.5]), shared_tmp / "a.h5", log=None)
    other = tomllib.loads((CONFIGS / "controlled_bar.toml").read_text())
    other.pop("output", None)
    other["mesh"]["nx"] = other["mesh"]["nx"] + 1
    with pytest.raises(InputError) as info:
        parsolve.run(parsolve.Scene.from_dict(other, base=CONFIGS), shared_tmp / "b.h5",
                     restart=shared_tmp / "a.h5", log=None)
    assert info.value.key == "--restart" and "differs" in info.value.message
    with pytest.raises(InputError) as info:   # the restarted result is an input
        parsolve.run(_times_scene("controlled_bar.toml", [0.5, 1.0]), shared_tmp / "a.h5",
                     restart=shared_tmp / "a.h5", log=None)
    assert "overwrite the input" in info.value.message
    comm.Barrier()
    assert not (shared_tmp / "b.h5").exists()
    with h5py.File(shared_tmp / "a.h5", "r") as f:
        assert f.attrs["status"] == "complete" and len(f["steps/time"]) == 1


def test_restart_needs_its_state(shared_tmp):
    comm = MPI.COMM_WORLD
    parsolve.run(_times_scene("controlled_bar.toml", [0.5]), shared_tmp / "a.h5", log=None)
    comm.Barrier()
    if comm.rank == 0:
        shutil.rmtree(state_path(shared_tmp / "a.h5"))
    comm.Barrier()
    with pytest.raises(InputError) as info:
        parsolve.run(_times_scene("controlled_bar.toml", [0.5, 1.0]), shared_tmp / "b.h5",
                     restart=shared_tmp / "a.h5", log=None)
    assert "restart state" in info.value.message and info.value.source == str(shared_tmp / "a.h5")


@pytest.mark.serial   # spawns a run and signals it
@pytest.mark.parametrize("sig", [signal.SIGTERM, signal.SIGKILL])
def test_a_stopped_run_restarted_from_the_command_line(tmp_path, sig):
    """A run stopped by SIGTERM (status "interrupted") or killed (-9: the file as it was),
    then `parsolve run SCENE --restart RESULT.h5`: the uninterrupted run's result, bit for
    bit (a transient scene with switched relations: its history is the state)."""
    from parsolve.cli import main

    data = tomllib.loads((CONFIGS / "solubility_grow_shrink.toml").read_text())
    data.pop("output", None)
    data["steps"] = {"count": 200, "end": 4.0}
    scene = tmp_path / "long.toml"
    scene.write_text(to_toml(data))
    stopped = tmp_path / "stopped.h5"
    env = {k: v for k, v in os.environ.items() if not k.startswith(("OMPI_", "PMIX_", "OPAL_"))}
    proc = subprocess.Popen([sys.executable, "-m", "parsolve", "run", str(scene), "-o",
                             str(stopped)], stdout=subprocess.DEVNULL,
                            stderr=subprocess.DEVNULL, env=env)
    deadline = time.time() + 120
    while time.time() < deadline:   # a few finished steps, then the signal
        time.sleep(0.2)
        try:
            with h5py.File(stopped, "r", swmr=True) as f:
                if len(f["steps/time"]) >= 5:
                    break
        except (OSError, KeyError):
            pass
    proc.send_signal(sig)
    proc.wait(timeout=300)
    assert proc.returncode == (143 if sig == signal.SIGTERM else -9)
    with h5py.File(stopped, "r", swmr=True) as f:
        finished = len(f["steps/time"])
    assert 5 <= finished < 200
    assert main(["run", str(scene), "-o", str(tmp_path / "continued.h5"),
                 "--restart", str(stopped)]) == 0
    assert main(["run", str(scene), "-o", str(tmp_path / "full.h5")]) == 0
    continued = read_results(tmp_path / "continued.h5")
    # the steps kept: all the finished ones, or (killed between the step and its state) one less
    assert continued["attrs"]["restart_steps"] in (finished, finished - 1)
    assert continued["attrs"]["restart_of"] == str(stopped)
    assert_continued(read_results(tmp_path / "full.h5"), continued,
                     continued["attrs"]["restart_steps"])
