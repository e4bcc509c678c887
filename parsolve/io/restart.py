"""Restart: the whole state of the last finished step, kept beside the result, and a run that
continues from it.

The state (per rank: fields, multipliers, material history, active set, the step schedule,
the effects' own state) is written after every finished step into the folder
``RESULT.restart/`` beside ``RESULT.h5``: each rank its own file (``<rank>.<slot>``, pickled;
no rank gathers another's state), the steps alternating between two slots, each file
written under a temporary name and renamed. A run killed at any point thus leaves on every
rank the state of the last step all ranks finished saving (or of the one before), and that
step's number in each file tells which. The result file itself keeps DESIGN's layout.

A restarted run writes a new result file: the first ``steps`` steps of the old result copied
row for row, then its own. The root attributes ``restart_of`` (the old result's path) and
``restart_steps`` (the steps copied) record it. It needs the scene of the old result (only
``[steps]`` and ``[output]`` may differ, to extend the run) and as many ranks (the state is
per rank).
"""

from __future__ import annotations

import os
import pickle
import shutil
import tomllib
from dataclasses import dataclass
from pathlib import Path

import h5py
import numpy as np

from parsolve.errors import InputError
from parsolve.io.slabs import OwnedRows

KEY = "--restart"
PER_STEP = ("fields", "cell_fields", "relations")


def state_path(result: str | Path) -> Path:
    """The restart state's folder beside a result: RESULT.restart/."""
    result = Path(result)
    return result.with_name(result.stem + ".restart")


class Checkpoint:
    """Writes the state of each finished step, every rank its own (collective calls)."""

    def __init__(self, comm, result: str | Path, first_step: int = 0):
        self.comm, self.path = comm, state_path(result)
        self.steps = first_step
        if comm.rank == 0:   # a stale state never follows a new result
            if self.path.is_dir():
                shutil.rmtree(self.path)
            else:
                self.path.unlink(missing_ok=True)
            self.path.mkdir()
        comm.Barrier()

    def save(self, state: dict) -> None:
        """The state after one more finished step (the same call on every rank)."""
        self.steps += 1
        target = self.path / f"{self.comm.rank}.{self.steps % 2}"
        tmp = target.with_name(target.name + ".tmp")
        with open(tmp, "wb") as f:
            pickle.dump({"steps": self.steps, "nprocs": self.comm.size, "state": state}, f,
                        protocol=pickle.HIGHEST_PROTOCOL)
        os.replace(tmp, target)


@dataclass
class Restart:
    """A result to continue: its path, the steps to copy and this rank's state."""

    path: str
    steps: int
    time: float
    state: dict

    def copy_steps(self, writer, node_ids: np.ndarray, cell_ids: np.ndarray) -> None:
        """Write the first ``steps`` steps of the old result through ``writer`` (collective:
        every rank its owned rows, as a running step gives them)."""
        with h5py.File(self.path, "r", swmr=True) as f:
            for k in range(self.steps):
                row = _step_rows(f, k)
                fields = {n: OwnedRows(v[node_ids]) for n, v in row["fields"].items()}
                cells = {n: OwnedRows(v[cell_ids]) for n, v in row["cell_fields"].items()}
                writer.write_step(row["time"], row["iterations"], row["residual"], fields,
                                  cells, row["relations"], row["timings"], extra=row["extra"])


def _step_rows(f: h5py.File, k: int) -> dict:
    """Every per-step dataset's row k, as ``write_step`` takes them."""
    steps = f["steps"]
    row = {"time": float(steps["time"][k]), "iterations": int(steps["iterations"][k]),
           "residual": float(steps["residual"][k]), "extra": {}, "timings": {},
           "fields": {}, "cell_fields": {}, "relations": {}}
    for group in ("fields", "cell_fields"):
        for name, ds in f.get(group, {}).items():
            row[group][name] = ds[k]
    for name, rel in f.get("relations", {}).items():
        row["relations"][name] = {key: ds[k] for key, ds in rel.items()}
    for name, ds in f.get("timings", {}).items():
        row["timings"][name] = float(ds[k])

    def extra(name, obj):
        if isinstance(obj, h5py.Dataset) and obj.shape and obj.maxshape[0] is None:
            row["extra"][name] = obj[k]
    for group in f:
        if group not in ("mesh", "timings", "restart", *PER_STEP):
            f[group].visititems(lambda n, o, g=group: extra(f"{g}/{n}", o))
    for name in ("steps/time", "steps/iterations", "steps/residual"):
        row["extra"].pop(name, None)
    return row


def read_restart(comm, path: str, scene) -> Restart:
    """The state to continue ``path`` from, for ``scene`` (collective; InputError naming
    ``--restart`` on every rank when the result cannot be continued)."""
    verdict, times = None, None
    if comm.rank == 0:
        try:
            times = _check_result(path, scene, comm.size)
        except InputError as exc:
            verdict = exc.message
    verdict = comm.bcast(verdict, root=0)
    if verdict is not None:
        raise InputError(verdict, path, KEY)
    times = comm.bcast(times, root=0)
    mine = _saved_states(state_path(path), comm.rank)
    # the last step every rank saved (a kill may have caught some ranks a step ahead)
    common = set.intersection(*map(set, comm.allgather(sorted(mine))))
    steps = max(common, default=0)
    if steps < 1 or steps > len(times):
        raise InputError(f"its restart state ({state_path(path)}) holds no step that every "
                         f"rank saved and the result has", path, KEY)
    return Restart(path, steps, float(times[steps - 1]), mine[steps])


def _check_result(path: str, scene, nprocs: int) -> np.ndarray:
    """The result's step times, once it is known to be a result of this scene whose state
    is there for this many ranks."""
    try:
        with h5py.File(path, "r", swmr=True) as f:   # (also a killed run's file)
            times = f["steps/time"][()]
            text = str(f.attrs.get("scene", ""))
    except (OSError, KeyError) as exc:
        raise InputError(f"cannot read the result to restart ({exc})") from None
    folder = state_path(path)
    if not folder.is_dir():
        raise InputError(f"no restart state beside it ({folder} is missing)")
    ranks = len({p.name.split(".")[0] for p in folder.iterdir() if not p.name.endswith(".tmp")})
    if ranks != nprocs:
        raise InputError(f"its restart state is for {ranks} ranks; run on {ranks} ranks "
                         f"(this run has {nprocs})")
    if _without_steps(text) != _without_steps(scene.text):
        raise InputError("the scene differs from the result's beyond [steps] (a restart "
                         "continues the same problem)")
    return times


def _saved_states(folder: Path, rank: int) -> dict[int, dict]:
    """This rank's saved states by step (up to two)."""
    out = {}
    for slot in (0, 1):
        try:
            with open(folder / f"{rank}.{slot}", "rb") as f:
                saved = pickle.load(f)
        except (OSError, EOFError, pickle.UnpicklingError):
            continue
        out[saved["steps"]] = saved["state"]
    return out


def _without_steps(text: str) -> dict:
    try:
        data = tomllib.loads(text)
    except tomllib.TOMLDecodeError:
        return {"unreadable": text}
    data.pop("steps", None)
    data.pop("output", None)   # where results go is no part of the problem
    return data


# ------------------------------------------------------------------ reading results

def read_result(path: str, groups=("fields", "cell_fields", "relations")) -> dict:
    """A result's data of its finished steps as numpy arrays: times, iterations, residual,
    status, attrs, points, and the per-step ``groups`` asked for (fields and cell_fields:
    {name: array}; relations: {name: {key: array}})."""
    with h5py.File(path, "r", swmr=True) as f:
        n = len(f["steps/time"])
        data = {"times": f["steps/time"][:n], "iterations": f["steps/iterations"][:n],
                "residual": f["steps/residual"][:n], "attrs": dict(f.attrs),
                "status": str(f.attrs.get("status", "")), "points": f["mesh/points"][()]}
        for group in groups:
            if group == "relations":
                data[group] = {name: {key: ds[:n] for key, ds in rel.items()}
                               for name, rel in f.get(group, {}).items()}
            else:
                data[group] = {name: ds[:n] for name, ds in f.get(group, {}).items()}
    return data
