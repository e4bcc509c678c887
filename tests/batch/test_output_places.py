"""Outputs of batch, study and post in a place that refuses files (/proc, /sys, a read-only
mount): exit 2, one line naming the option and the place, nothing written, before any run
(in-process command lines; nothing here runs a solve). Root passes every permission check,
so the place is tried, not its permission bits read."""

import subprocess

import pytest
from mpi4py import MPI

from batch_helpers import BAR
from conftest import CONFIGS, run_scene
from helpers.disk import fill, mounted
from parsolve.batch.cli import main as batch
from parsolve.post.cli import main as post
from parsolve.study.cli import main as study

pytestmark = pytest.mark.serial

STUDY = f"""
title = "bar"
scene = "{CONFIGS / 'controlled_bar.toml'}"
ranks = 1
parallel = 1
[refine]
keys = ["mesh.nx", "mesh.ny"]
levels = [1, 2]
[[quantities]]
name = "force"
spec = "relation:control:multiplier"
reference = "1e4"
"""
CURVE = ["--x", "time", "--y", "relation:control:multiplier"]

# (command, arguments ({ro}: a read-only mount), message start after "PROG: ", fragment)
CASES = [
    ("batch", ["-o", "/proc/parsolve_runs"], "command line: -o: ",
     "cannot create /proc/parsolve_runs: folder /proc is not writable"),
    ("batch", ["-o", "/proc/sys/runs"], "command line: -o: ", "folder /proc/sys is read-only"),
    ("batch", ["-o", "{ro}/runs"], "command line: -o: ", "cannot create {ro}/runs: folder {ro} "),
    ("batch", ["-o", "{ro}"], "command line: -o: ", "folder {ro} "),
    ("study", ["--out", "/proc/parsolve_runs"], "command line: --out: ",
     "folder /proc is not writable"),
    ("study", ["--out", "{ro}/runs"], "command line: --out: ", "folder {ro} "),
    ("study", ["--save", "/proc/saved"], "command line: --save: ", "folder /proc is not writable"),
    ("study", ["--save", "{ro}/saved"], "command line: --save: ", "folder {ro} "),
    ("post", CURVE + ["--csv", "/proc/curve.csv"], "/proc/curve.csv: --csv: ",
     "folder /proc is not writable"),
    ("post", CURVE + ["--png", "{ro}/curve.png"], "{ro}/curve.png: --png: ", "folder {ro} "),
    ("post", ["--derive", "/proc/derived.h5"], "/proc/derived.h5: --derive: ",
     "folder /proc is not writable"),
    ("post", ["--derive", "{ro}/derived.h5"], "{ro}/derived.h5: --derive: ", "folder {ro} "),
]


@pytest.fixture(scope="module")
def result(tmp_path_factory):
    out = tmp_path_factory.mktemp("places") / "bar.h5"
    run_scene(BAR, out, MPI.COMM_SELF)
    return out


@pytest.fixture(scope="module")
def read_only(tmp_path_factory):
    """A read-only tmpfs (root writes in any folder whatever its mode), or None."""
    where = tmp_path_factory.mktemp("ro") / "mnt"
    where.mkdir()
    mount = subprocess.run(["mount", "-t", "tmpfs", "-o", "ro,size=64k", "tmpfs", str(where)],
                           capture_output=True, text=True)
    if mount.returncode != 0:
        yield None
        return
    yield where
    subprocess.run(["umount", "-l", str(where)], check=False)


@pytest.mark.parametrize("command, args, head, fragment", CASES)
def test_an_unwritable_place_is_one_line(command, args, head, fragment, tmp_path, capsys,
                                         result, read_only):
    if "{ro}" in " ".join(args) and read_only is None:
        pytest.skip("cannot mount a read-only tmpfs here (mount not permitted)")
    fill = (lambda text: text.replace("{ro}", str(read_only))) if read_only else (lambda t: t)
    args = [fill(a) for a in args]
    before = sorted(p.name for p in tmp_path.iterdir())
    if command == "batch":
        (tmp_path / "scene.toml").write_text(BAR.read_text())
        jobs = tmp_path / "jobs.toml"
        jobs.write_text('scene = "scene.toml"\noutput = "runs"\n[[runs]]\n"steps.count" = 2\n')
        before = sorted(p.name for p in tmp_path.iterdir())
        status, prog = batch([str(jobs)] + args), "parsolve"
    elif command == "study":
        path = tmp_path / "study.toml"
        path.write_text(STUDY)
        before = sorted(p.name for p in tmp_path.iterdir())
        out = [] if "--out" in args else ["--out", str(tmp_path / "runs")]
        status, prog = study([str(path)] + out + args), "parsolve study"
    else:
        status, prog = post([str(result)] + args), "parsolve post"
    assert status == 2
    captured = capsys.readouterr()
    err = captured.err.strip().splitlines()
    assert len(err) == 1 and "Traceback" not in captured.err, captured.err
    assert err[0].startswith(f"{prog}: {fill(head)}"), err[0]
    assert fill(fragment) in err[0], err[0]
    assert captured.out == ""
    assert sorted(p.name for p in tmp_path.iterdir()) == before       # nothing written
    if read_only is not None:
        assert list(read_only.iterdir()) == []


# (command, arguments ({full}: a full disk), exit status, message start after "PROG: ",
# fragment): a full disk is one line naming the output, and no file cut or left behind
NO_SPACE = "cannot write (No space left on device)"
FULL_CASES = [
    ("batch", ["-o", "{full}/runs"], 4, "{full}/runs/runs.json: ", NO_SPACE),
    ("study", ["--out", "{full}/runs"], 4, "{full}/runs/runs.json: ", NO_SPACE),
    ("study", ["--save", "{full}/saved"], 4, "{full}/saved.md: ", NO_SPACE),
    ("post", CURVE + ["--csv", "{full}/curve.csv"], 2, "{full}/curve.csv: --csv: ",
     NO_SPACE + ": nothing written"),
    ("post", CURVE + ["--png", "{full}/curve.png"], 2, "{full}/curve.png: --png: ",
     NO_SPACE + ": nothing written"),
    ("post", ["--line", "0,0.05", "1,0.05", "4", "--y", "field:displacement:x", "--csv",
              "{full}/line.csv"], 2, "{full}/line.csv: --csv: ", NO_SPACE),
    ("post", ["--line", "0,0.05", "1,0.05", "4", "--y", "field:displacement:x", "--png",
              "{full}/line.png"], 2, "{full}/line.png: --png: ", NO_SPACE),
    ("post", ["--derive", "{full}/derived.h5"], 2, "{full}/derived.h5: --derive: ",
     "cannot write ([Errno 28] No space left on device"),
]


@pytest.fixture
def full_disk(tmp_path):
    """A 64 kB tmpfs filled to the last byte."""
    with mounted(tmp_path / "full", "64k", full=True) as where:
        yield where


@pytest.mark.parametrize("command, args, status, head, fragment", FULL_CASES)
def test_a_full_disk_is_one_line_and_nothing_cut(command, args, status, head, fragment,
                                                  tmp_path, capsys, result, full_disk):
    fill = (lambda text: text.replace("{full}", str(full_disk)))
    args = [fill(a) for a in args]
    if command == "batch":
        (tmp_path / "scene.toml").write_text(BAR.read_text())
        jobs = tmp_path / "jobs.toml"
        jobs.write_text('scene = "scene.toml"\noutput = "runs"\n[[runs]]\n"steps.count" = 2\n')
        code, prog = batch([str(jobs)] + args), "parsolve batch"
    elif command == "study":
        path = tmp_path / "study.toml"
        path.write_text(STUDY)
        out = [] if "--out" in args else ["--out", str(tmp_path / "runs")]
        code, prog = study([str(path)] + out + args), "parsolve study"
    else:
        code, prog = post([str(result)] + args), "parsolve post"
    captured = capsys.readouterr()
    err = captured.err.strip().splitlines()
    assert code == status, captured.err
    assert len(err) == 1 and "Traceback" not in captured.err, captured.err
    assert err[0].startswith(f"{prog}: {fill(head)}{fragment}"), err[0]
    assert [p.name for p in full_disk.rglob("*") if not p.is_dir()] == ["fill"]   # nothing cut


def test_collect_on_a_full_disk_is_one_line(tmp_path, capsys):
    """--collect rewrites the manifest of a batch whose disk has filled since: one line naming
    the manifest (exit 4), the old manifest kept whole."""
    (tmp_path / "scene.toml").write_text(BAR.read_text())
    (tmp_path / "jobs.toml").write_text('scene = "scene.toml"\noutput = "runs"\n[[runs]]\n'
                                        '"steps.count" = 2\n')
    with mounted(tmp_path / "disk", "64k") as disk:
        root = disk / "runs"
        root.mkdir()
        (root / "runs.json").write_text('[{"name": "a", "ranks": 1, "params": {}}]')
        (root / "manifest.csv").write_text("old\n")
        fill(disk)
        assert batch([str(tmp_path / "jobs.toml"), "--collect", "-o", str(root)]) == 4
        err = capsys.readouterr().err.strip().splitlines()
        assert len(err) == 1 and err[0].startswith(
            f"parsolve batch: {root / 'manifest.csv'}: cannot write (No space left on device)"), err
        assert (root / "manifest.csv").read_text() == "old\n"
        assert sorted(p.name for p in root.iterdir()) == ["manifest.csv", "runs.json"]
