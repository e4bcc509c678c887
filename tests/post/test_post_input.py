"""Bad post input: exit 2, one line naming the file (or option) and the key, nothing written
(in-process command line on the controlled bar's result)."""

import pytest

from mpi4py import MPI

from conftest import CONFIGS, run_scene
from parsolve.post.cli import main

pytestmark = pytest.mark.serial

CURVE = ["--x", "time", "--y", "relation:control:multiplier"]

# (arguments after the result file, source of the message, key, fragment); {dir}: a folder,
# {file}: a plain file, {result}: the result file itself
CASES = [
    (CURVE + ["--csv", "{dir}"], "{dir}", "--csv", "is a folder, not a file"),
    (CURVE + ["--csv", "{dir}/missing/curve.csv"], "{dir}/missing/curve.csv", "--csv",
     "folder {dir}/missing does not exist"),
    (CURVE + ["--csv", "{file}/curve.csv"], "{file}/curve.csv", "--csv", "is a file, not a folder"),
    (CURVE + ["--csv", "{result}"], "{result}", "--csv", "the input is never overwritten"),
    (CURVE + ["--png", "{dir}"], "{dir}", "--png", "is a folder, not a file"),
    (["--derive", "{dir}/missing/derived.h5"], "{dir}/missing/derived.h5", "--derive",
     "folder {dir}/missing does not exist"),
    (["--derive", "{dir}"], "{dir}", "--derive", "is a folder, not a file"),
    (["--derive", "{dir}/sub.h5"], "{dir}/sub.h5", "--derive", "sub.xdmf is a folder, not a file"),
    (["--derive", "{result}"], "{result}", "--derive", "writes a copy: the input is never"),
    (["--x", "field:displacement:x@9**9**9,0", "--y", "time"], "--x", "field:displacement:x@9**9**9,0",
     "no expressions"),
    (["--x", "field:displacement:x@1e999,0", "--y", "time"], "--x", "field:displacement:x@1e999,0",
     "finite numbers"),
    (["--x", "field:displacement:x@0.5", "--y", "time"], "--x", "field:displacement:x@0.5",
     "2 or 3 finite numbers"),
    (["--x", "time" * 100, "--y", "time"], "--x", "timetime", "longer than 300"),
    (["--x", "time", "--y", "(" * 200], "--y", "(((", "unknown form"),
]


@pytest.fixture(scope="module")
def result(tmp_path_factory):
    out = tmp_path_factory.mktemp("post_input") / "bar.h5"
    run_scene(CONFIGS / "controlled_bar.toml", out, MPI.COMM_SELF)
    return out


@pytest.mark.parametrize("args, source, key, fragment", CASES)
def test_bad_post_input(tmp_path, capsys, result, args, source, key, fragment):
    folder = tmp_path / "work"
    folder.mkdir()
    (folder / "sub.xdmf").mkdir()
    afile = tmp_path / "a_file"
    afile.write_text("not a folder")

    def fill(text: str) -> str:
        return text.replace("{dir}", str(folder)).replace("{file}", str(afile)).replace(
            "{result}", str(result))

    before = sorted(str(p) for p in tmp_path.rglob("*")) + sorted(str(p) for p in result.parent.iterdir())
    assert main([str(result)] + [fill(a) for a in args]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1, err
    assert err[0].startswith(f"parsolve post: {fill(source)}: {fill(key)}"), err[0]
    assert fill(fragment) in err[0], err[0]
    after = sorted(str(p) for p in tmp_path.rglob("*")) + sorted(str(p) for p in result.parent.iterdir())
    assert after == before   # nothing written
