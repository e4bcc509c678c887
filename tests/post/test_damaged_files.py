"""post on damaged result files: a truncated, overwritten, deleted or partly garbled file, or one
holding a non-finite or out-of-scale value, under every command (curve, --summary, --derive,
--line, --recover) is exit 2 with one line naming the file — never a traceback, never a number — and
nothing is left behind (in-process command line, results of both output modes)."""

import os
import shutil

import h5py
import numpy as np
import pytest
from mpi4py import MPI

from conftest import run_scene
from helpers.xdmf import SCENE_2D
from parsolve.io.lock import OutputLock
from parsolve.post.cli import main

pytestmark = pytest.mark.serial

GARBAGE = 256 << 10
# 60 × 30 cells, 12 steps: /fields/displacement holds 12 × 1891 × 2 doubles (363 kB)
SCENE = SCENE_2D.replace("nx = 8", "nx = 60").replace("ny = 4", "ny = 30").replace(
    "count = 3", "count = 12")
COMMANDS = {
    "curve": ["--x", "time", "--y", "field:displacement:x@1.5,0.5"],
    "summary": ["--summary"],
    "derive": ["--derive", "{dir}/derived.h5"],
    "line": ["--line", "0,0.5", "2,0.5", "5", "--y", "field:displacement:x", "--y",
             "field:displacement:y", "--step", "all"],
}


def _chunk_offset(path, name: str, index: int) -> int:
    with h5py.File(path, "r") as f:
        return f[name].id.get_chunk_info(index).byte_offset


def truncate(path):
    os.truncate(path, path.stat().st_size // 2)


def overwrite(path):
    path.write_bytes(np.random.default_rng(1).bytes(path.stat().st_size))


def delete(path):
    path.unlink()


def garble(path):
    """256 KB of random bytes from the displacement's second step on (its later steps, and
    whatever lies between them)."""
    offset = _chunk_offset(path, "fields/displacement", 1)
    assert offset + GARBAGE < path.stat().st_size
    with open(path, "r+b") as fh:
        fh.seek(offset)
        fh.write(np.random.default_rng(2).bytes(GARBAGE))


def flip(path):
    """A few bytes of one displacement chunk changed: only the checksum can tell."""
    offset = _chunk_offset(path, "fields/displacement", 5) + 100
    with open(path, "r+b") as fh:
        fh.seek(offset)
        data = bytearray(fh.read(8))
        fh.seek(offset)
        fh.write(bytes(b ^ 0x01 for b in data))


def _flip_chunk(path, name: str, index: int) -> None:
    """A few bytes of a dataset's chunk changed: only the checksum can tell."""
    offset = _chunk_offset(path, name, index) + 16
    with open(path, "r+b") as fh:
        fh.seek(offset)
        data = bytearray(fh.read(8))
        fh.seek(offset)
        fh.write(bytes(b ^ 0x01 for b in data))


def flip_points(path):
    """The mesh's coordinates changed by a bit in a few bytes (no value goes out of scale)."""
    _flip_chunk(path, "mesh/points", 0)


def flip_cells(path):
    """The mesh's connectivity changed by a bit in a few bytes (integers: only the checksum
    can tell)."""
    _flip_chunk(path, "mesh/cells/triangle", 0)


def nan(path):
    with h5py.File(path, "r+") as f:
        f["fields/displacement"][3, 7, 0] = np.nan


def huge(path):
    with h5py.File(path, "r+") as f:
        f["fields/displacement"][4, 2, 1] = 1e200


# damage, what the message says (after "parsolve post: FILE")
DAMAGES = [
    (truncate, "cannot open result file"),
    (overwrite, "cannot open result file"),
    (delete, "cannot open result file"),
    (garble, ""),      # where the bytes land (data, or the chunk index) decides the words
    (flip, "/fields/displacement: damaged data"),
    (flip_points, "/mesh/points: damaged data"),
    (flip_cells, "/mesh/cells/triangle: damaged data"),
    (nan, "/fields/displacement: damaged data (1 non-finite or out-of-scale value(s), e.g. nan)"),
    (huge, "/fields/displacement: damaged data (1 non-finite or out-of-scale value(s), e.g. 1e+200)"),
]


@pytest.fixture(scope="module", params=["swmr", "parallel"])
def result(request, tmp_path_factory):
    out = tmp_path_factory.mktemp(f"damaged_{request.param}") / "whole.h5"
    run_scene(SCENE + f'\n[output]\nmode = "{request.param}"\n', out, MPI.COMM_SELF)
    return out


def test_the_whole_file_reads(result, capsys, tmp_path):
    """The undamaged file under the same commands: exit 0 (the cases below test damage)."""
    for args in COMMANDS.values():
        args = [a.replace("{dir}", str(tmp_path)) for a in args]
        assert main([str(result)] + args) == 0, capsys.readouterr().err
    out = capsys.readouterr().out
    assert f"{result}: status complete, 12 steps" in out
    assert (tmp_path / "derived.h5").is_file()


@pytest.mark.parametrize("command", sorted(COMMANDS))
@pytest.mark.parametrize("damage, fragment", DAMAGES, ids=[d.__name__ for d, _ in DAMAGES])
def test_damage_is_one_line_and_exit_2(result, damage, fragment, command, capsys, tmp_path):
    path = tmp_path / "r.h5"
    shutil.copyfile(result, path)
    damage(path)
    before = sorted(p.name for p in tmp_path.iterdir())
    args = [a.replace("{dir}", str(tmp_path)) for a in COMMANDS[command]]
    assert main([str(path)] + args) == 2
    captured = capsys.readouterr()
    err = captured.err.strip().splitlines()
    assert len(err) == 1 and "Traceback" not in captured.err, captured.err
    assert err[0].startswith(f"parsolve post: {path}: {fragment}"), err[0]
    assert captured.out == ""
    assert sorted(p.name for p in tmp_path.iterdir()) == before   # no copy, no XDMF, no temp


@pytest.mark.parametrize("damage", [truncate, overwrite])
def test_recover_of_a_damaged_file_says_so(result, damage, capsys, tmp_path):
    path = tmp_path / "r.h5"
    shutil.copyfile(result, path)
    damage(path)
    size = path.stat().st_size
    assert main([str(path), "--recover"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert err == [f"parsolve post: {path}: --recover: cannot recover: the file is damaged or "
                   f"truncated ({err[0].split('truncated (', 1)[1]}"]
    assert path.stat().st_size == size and sorted(tmp_path.iterdir()) == [path]


@pytest.mark.parametrize("command", ["summary", "curve", "line"])
def test_every_input_is_checked_before_anything_is_printed(result, command, capsys, tmp_path):
    """A good file, then a missing one, then a damaged one: nothing printed for the first."""
    missing = tmp_path / "missing.h5"
    assert main([str(result), str(missing)] + COMMANDS[command]) == 2
    captured = capsys.readouterr()
    assert captured.out == ""
    assert captured.err.startswith(f"parsolve post: {missing}: cannot open result file")
    damaged = tmp_path / "nan.h5"
    shutil.copyfile(result, damaged)
    nan(damaged)
    assert main([str(result), str(damaged)] + COMMANDS[command]) == 2
    captured = capsys.readouterr()
    assert captured.out == "" and captured.err.startswith(f"parsolve post: {damaged}: "), \
        captured.err
    assert sorted(p.name for p in tmp_path.iterdir()) == ["nan.h5"]


def test_derive_refuses_a_file_being_written(result, capsys, tmp_path):
    """A run holds the lock beside its result (parsolve.io.lock) until it ends: a parallel-output
    file opens between two steps, but --derive refuses it; once the lock is free it works."""
    path = tmp_path / "live.h5"
    shutil.copyfile(result, path)
    lock = OutputLock(path)
    assert lock.acquire()
    try:
        assert main([str(path), "--derive", str(tmp_path / "d.h5")]) == 2
    finally:
        lock.release()
    err = capsys.readouterr().err.strip().splitlines()
    assert err == [f"parsolve post: {path}: --derive: a run is writing it now (lock held on "
                   f"{path}.lock): --derive reads a finished result; derive once the run has "
                   "ended"]
    assert sorted(p.name for p in tmp_path.iterdir()) == ["live.h5"]
    assert main([str(path), "--derive", str(tmp_path / "d.h5")]) == 0
