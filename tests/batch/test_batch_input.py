"""Bad job files: exit 2, one line naming the file and the key, nothing written, before the
first run (in-process command line; nothing here runs a solve)."""

import pytest

from batch_helpers import BAR
from parsolve.batch.cli import main

pytestmark = pytest.mark.serial

BASE = 'scene = "scene.toml"\noutput = "runs"\n'
SECOND_BAD = '[[runs]]\n"steps.count" = 2\n[[runs]]\n"steps.count" = 3\nargs = ["-pc_type", "nosuch"]\n'

# (job file body after scene/output, extra command-line arguments, source, key, fragment)
CASES = [
    ('args = ["-ksp_type", "nosuch"]\n', [], "jobs", "args", "-ksp_type: unknown type ('nosuch')"),
    ('args = ["-pc_type", "nosuch"]\n', [], "jobs", "args", "-pc_type: unknown type ('nosuch')"),
    ('args = ["-o", "x.h5", "--output-mode", "serial", "-pc_type", "nosuch"]\n', [], "jobs", "args",
     "-pc_type: unknown type"),
    ('args = ["-ksp_rtol", "abc"]\n', [], "jobs", "args", "-ksp_rtol"),
    (SECOND_BAD, [], "jobs", 'runs[1]."args"', "-pc_type: unknown type ('nosuch') (run "),
    ('[grid]\n"steps.count" = [2, 3]\n[[runs]]\nargs = ["-ksp_type", "nosuch"]\n', [], "jobs",
     'runs[0]."args"', "unknown type"),
    ('[grid]\n"solver.petsc.ksp_type" = ["gmres", "nosuch"]\n', [], "jobs", 'grid."solver.petsc.ksp_type"',
     "unknown type ('nosuch') (PETSc option -parsolve_ksp_type) (run "),
    ('output = "a_file"\n', [], "jobs", "output", "is a file, not a folder"),
    ('output = "a_file/runs"\n', [], "jobs", "output", "a_file is a file, not a folder"),
    ("", ["-o", "{file}"], "command line", "-o", "is a file, not a folder"),
    ("", ["-o", "{file}/deeper/runs"], "command line", "-o", "is a file, not a folder"),
    ("", ["--parallel", "0"], "command line", "--parallel", "at least 1"),
]


@pytest.mark.parametrize("body, extra, source, key, fragment", CASES)
def test_bad_job_input(tmp_path, capsys, body, extra, source, key, fragment):
    afile = tmp_path / "a_file"
    afile.write_text("not a folder")
    (tmp_path / "scene.toml").write_text(BAR.read_text() + '\n[solver.petsc]\nksp_rtol = 1e-10\n')
    path = tmp_path / "jobs.toml"
    text = BASE + body
    if body.startswith("output"):
        text = text.replace('output = "runs"\n', "")
    path.write_text(text)
    before = sorted(p.name for p in tmp_path.iterdir())
    argv = [str(path)] + [a.replace("{file}", str(afile)) for a in extra]
    assert main(argv) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1, err
    where = str(path) if source == "jobs" else source
    assert err[0].startswith(f"parsolve: {where}: {key}: "), err[0]
    assert fragment in err[0], err[0]
    assert sorted(p.name for p in tmp_path.iterdir()) == before   # nothing written
    assert afile.read_text() == "not a folder"
