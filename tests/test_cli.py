"""The command line: exit statuses, one-line errors naming file and key, result files.

Most tests call ``parsolve.cli.main(argv)`` in this process (the ``cli`` fixture: its exit
status and what it printed, file descriptors included, so PETSc's own output too). A few run
``python -m parsolve`` as a process, for what only a process shows: PETSc options read at
PETSc's initialisation (-log_view, -options_left), mpirun, and the exit status as the shell
sees it."""

import os
import re
import subprocess
import sys
from typing import NamedTuple

import h5py
import numpy as np
import pytest

from conftest import CONFIGS, ROOT

pytestmark = pytest.mark.serial  # in-process runs on one rank; the mpirun runs start their own

GOOD = (CONFIGS / "controlled_bar.toml").read_text()


class Outcome(NamedTuple):
    returncode: int
    stdout: str
    stderr: str


@pytest.fixture
def cli(capfd, monkeypatch):
    """``cli(*args, cwd=None)``: parsolve's command line in this process, as ``parsolve(...)``
    returns it for a process (exit status, stdout, stderr)."""
    from parsolve.cli import main

    def call(*args, cwd=None) -> Outcome:
        if cwd is not None:
            monkeypatch.chdir(cwd)
        capfd.readouterr()          # what came before is not this command's
        try:
            code = main([str(a) for a in args])
        except SystemExit as exc:   # argparse's own exits
            code = exc.code
        out, err = capfd.readouterr()
        return Outcome(code, out, err)
    return call


def parsolve(*args, cwd=None, mpi: int | None = None):
    """``python -m parsolve ARGS`` as a process (under scripts/mpirun.sh with ``mpi`` ranks)."""
    cmd = [sys.executable, "-m", "parsolve", *map(str, args)]
    if mpi:
        cmd = ["bash", str(ROOT / "scripts" / "mpirun.sh"), "-n", str(mpi)] + cmd
    # this pytest process is itself an MPI singleton: keep its MPI variables from the child
    env = {k: v for k, v in os.environ.items() if not k.startswith(("OMPI_", "PMIX_", "OPAL_"))}
    return subprocess.run(cmd, capture_output=True, text=True, cwd=cwd, timeout=300, env=env)


BAD = {
    "missing mesh file": (GOOD.replace('generator = "rectangle"\nlx = 1.0\nly = 0.1\nnx = 29\nny = 3\ncell = "quad"',
                                       'file = "nowhere.msh"'), "nowhere.msh", "mesh.file"),
    "unknown region": (GOOD.replace('region = "right"\ncomponent = "x"', 'region = "rigth"\ncomponent = "x"'),
                       "scene.toml", "relations[2].region"),
    "misspelt key": (GOOD.replace("hypothesis =", "hypothesys ="), "scene.toml", "model.hypothesys"),
    "wrong type": (GOOD.replace("nu = 0.0", 'nu = "zero"'), "scene.toml", "materials[0].nu"),
    "missing component": (GOOD.replace('components = ["y"]', 'components = ["z"]'), "scene.toml",
                          "relations[1].components[0]"),
    "dual names no pattern": (GOOD.replace('dual = "pull"', 'dual = "push"'), "scene.toml",
                              "relations[2].dual"),
    "bad selector": (GOOD.replace("[regions]", '[regions]\nodd = "__import__(1)"\n'), "scene.toml", "regions.odd"),
    "not TOML": ("[mesh\n", "scene.toml", ""),
    # issue 6 §2: numbers
    "nan E": (GOOD.replace("E = 1e9", "E = nan"), "scene.toml", "materials[0].E"),
    "inf thickness": (GOOD.replace("thickness = 1.0", "thickness = inf"), "scene.toml", "model.thickness"),
    "negative E": (GOOD.replace("E = 1e9", "E = -1e9"), "scene.toml", "materials[0].E"),
    "nu 0.5": (GOOD.replace("nu = 0.0", "nu = 0.5"), "scene.toml", "materials[0].nu"),
    "1e308 length": (GOOD.replace("lx = 1.0", "lx = 1e308"), "scene.toml", "mesh.lx"),
    "nan traction": (GOOD.replace("total_force = [1.0, 0.0]", "total_force = [1.0, nan]"),
                     "scene.toml", "loads[0].total_force[1]"),
    "inf end": (GOOD.replace("count = 10", "count = 10\nend = inf"), "scene.toml", "steps.end"),
    "nan value": (GOOD.replace("value = 1e-4", "value = nan"), "scene.toml", "relations[2].value"),
    "sqrt(-1-x) value": (GOOD.replace('components = ["x"]', 'components = ["x"]\nvalue = "sqrt(-1-x)"'),
                         "scene.toml", "relations[0].value"),
    "1/(x-x) selector": (GOOD.replace("[regions]", '[regions]\nodd = "1/(x-x) > 0"\n'),
                         "scene.toml", "regions.odd"),
    "power tower": (GOOD.replace('value = 1e-4', 'value = 1e-4').replace("[regions]", '[regions]\nodd = "x < 10**10**10"\n'),
                    "scene.toml", "regions.odd"),
    "huge step count": (GOOD.replace("count = 10", "count = 1000000000000"), "scene.toml", "steps.count"),
    # names
    "slash in name": (GOOD.replace('name = "control"', 'name = "a/b"'), "scene.toml", "relations[2].name"),
    "dot-dot name": (GOOD.replace('name = "pull"', 'name = ".."').replace('dual = "pull"', 'dual = ".."'),
                     "scene.toml", "loads[0].name"),
    "empty name": (GOOD.replace('name = "left_x"', 'name = ""'), "scene.toml", "relations[0].name"),
    # sizes
    "too large": (GOOD.replace("nx = 29\nny = 3", "nx = 20000\nny = 20000"), "scene.toml", "mesh.generator"),
    "bad generator count": (GOOD.replace("nx = 29", "nx = 2.5"), "scene.toml", "mesh.nx"),
    # PETSc options in the scene
    "unknown pc type": (GOOD + '\n[solver.petsc]\npc_type = "nosuch"\n', "scene.toml", "solver.petsc.pc_type"),
    "bad rtol": (GOOD + '\n[solver.petsc]\nksp_rtol = "abc"\n', "scene.toml", "solver.petsc.ksp_rtol"),
    # output paths (from the scene)
    "output is the scene": (GOOD + '\n[output]\nfile = "scene.toml"\n', "scene.toml", "output.file"),
}


@pytest.mark.parametrize("case", sorted(BAD))
@pytest.mark.parametrize("command", ["check", "run"])
def test_bad_input(case, command, tmp_path, cli):
    text, source, key = BAD[case]
    if case == "output is the scene" and command == "check":
        pytest.skip("check writes nothing")
    if case == "bad selector":  # make the bad region used (the others are checked unused)
        text = text.replace('region = "corner"', 'region = "odd"')
    (tmp_path / "scene.toml").write_text(text)
    before = (tmp_path / "scene.toml").read_bytes()
    out = tmp_path / "out.h5"
    own_output = case == "output is the scene"
    args = [command, "scene.toml"] + (["-o", out] if command == "run" and not own_output else [])
    proc = cli(*args, cwd=tmp_path)
    assert proc.returncode == 2, proc.stderr
    lines = proc.stderr.strip().splitlines()
    assert len(lines) == 1 and "Traceback" not in proc.stderr, proc.stderr
    assert source in lines[0] and key in lines[0], lines[0]
    assert not out.exists() and not list(tmp_path.glob("*.h5")) and not list(tmp_path.glob("*.xdmf"))
    assert (tmp_path / "scene.toml").read_bytes() == before


def test_bad_input_exit_2_from_the_process(tmp_path):
    """The exit status as the shell sees it (``python -m parsolve``): 2, one line naming the
    file and the key, no traceback, nothing written."""
    text, source, key = BAD["unknown region"]
    (tmp_path / "scene.toml").write_text(text)
    proc = parsolve("run", "scene.toml", "-o", "out.h5", cwd=tmp_path)
    assert proc.returncode == 2, proc.stderr
    line, = proc.stderr.strip().splitlines()
    assert source in line and key in line and "Traceback" not in proc.stderr, proc.stderr
    assert not list(tmp_path.glob("*.h5")) and not list(tmp_path.glob("*.xdmf"))


BAD_COMMAND_LINE = {  # arguments -> (exit 2) words in the one line
    "unknown PETSc type": (["-pc_type", "nosuch"], ["command line", "-pc_type", "unknown type"]),
    "unknown KSP type": (["-ksp_type", "foo"], ["command line", "-ksp_type", "unknown type"]),
    "missing value": (["-ksp_rtol"], ["command line", "-ksp_rtol", "missing value"]),
    "bad number": (["-ksp_rtol", "abc"], ["command line", "-ksp_rtol", "abc"]),
    "misspelt long flag": (["--outptu", "x.h5"], ["--outptu", "did you mean --output?"]),
    "prefix of a long flag": (["--out", "x.h5"], ["--out", "did you mean --output?"]),
}


@pytest.mark.parametrize("case", sorted(BAD_COMMAND_LINE))
@pytest.mark.parametrize("command", ["check", "run"])
def test_bad_command_line(case, command, tmp_path, cli):
    (tmp_path / "scene.toml").write_text(GOOD)
    extra, words = BAD_COMMAND_LINE[case]
    proc = cli(command, "scene.toml", *extra, cwd=tmp_path)
    assert proc.returncode == 2, proc.stderr
    lines = proc.stderr.strip().splitlines()
    assert len(lines) == 1 and "Traceback" not in proc.stderr, proc.stderr
    assert all(w in lines[0] for w in words), lines[0]
    assert not list(tmp_path.glob("*.h5"))


@pytest.mark.parametrize("what", ["folder", "binary", "latin-1"])
@pytest.mark.parametrize("command", ["check", "run"])
def test_scene_file_that_is_not_text(what, command, tmp_path, cli):
    scene = tmp_path / "scene.toml"
    if what == "folder":
        scene.mkdir()
    elif what == "binary":
        scene.write_bytes(b"\x7fELF\x02\x01\x00\x00")
    else:
        scene.write_bytes(b'title = "barre contr\xf4l\xe9e"\n')
    proc = cli(command, "scene.toml", cwd=tmp_path)
    assert proc.returncode == 2, proc.stderr
    line, = proc.stderr.strip().splitlines()
    assert line.startswith("parsolve: scene.toml: ") and "Traceback" not in proc.stderr
    assert {"folder": "folder", "binary": "binary", "latin-1": "not UTF-8"}[what] in line


def test_output_paths(tmp_path, cli):
    """Never an input; a folder, a parent that is a file, a missing folder: exit 2, the path."""
    (tmp_path / "scene.toml").write_text(GOOD)
    (tmp_path / "afile").write_text("x")
    (tmp_path / "adir").mkdir()
    for out, words in [("scene.toml", "overwrite the input"), ("scene.xdmf", "would overwrite"),
                       ("adir", "is a folder"), ("afile/r.h5", "is a file, not a folder"),
                       ("nowhere/r.h5", "does not exist")]:
        if out == "scene.xdmf":  # the XDMF beside the result would replace an input
            (tmp_path / "scene.toml").rename(tmp_path / "scene.xdmf")
            (tmp_path / "scene.xdmf").rename(tmp_path / "scene.toml")
            continue
        proc = cli("run", "scene.toml", "-o", out, cwd=tmp_path)
        assert proc.returncode == 2, (out, proc.stderr)
        line, = proc.stderr.strip().splitlines()
        assert "command line: -o:" in line and out.split("/")[0] in line and words in line, line
    assert (tmp_path / "scene.toml").read_text() == GOOD and (tmp_path / "afile").read_text() == "x"


def test_petsc_options_starting_with_o_reach_petsc(tmp_path):
    """-options_left and -on_error_abort are PETSc's, not '-o ptions_left'; -o is only -o."""
    out = tmp_path / "r.h5"
    proc = parsolve("run", CONFIGS / "controlled_bar.toml", "-o", out, "-options_left",
                    "-on_error_abort", "-ksp_rtol", "1e-3")
    assert proc.returncode == 0, proc.stderr
    assert out.exists() and not (tmp_path / "ptions_left").exists()
    # parsolve's report of the options no solver object used (preonly reads no tolerance)
    assert "parsolve: warning: PETSc option -parsolve_ksp_rtol was not used" in proc.stderr
    assert "options_left was not used" not in proc.stderr


def test_unused_mesh_points_are_a_warning(tmp_path, cli):
    """A Gmsh-like file with a point no cell uses: check and run say so, on one line each."""
    import meshio

    pts = np.array([[0, 0], [1, 0], [1, 1], [0, 1], [5, 5]], float)
    meshio.write(tmp_path / "m.vtu", meshio.Mesh(pts, [("quad", np.array([[0, 1, 2, 3]]))]))
    (tmp_path / "scene.toml").write_text('''
[mesh]
file = "m.vtu"
[model]
hypothesis = "plane_stress"
[regions]
left = "x == 0"
[[materials]]
E = 1.0
nu = 0.3
[[relations]]
name = "clamp"
type = "dirichlet"
region = "left"
components = ["x", "y"]
''')
    proc = cli("check", "scene.toml", cwd=tmp_path)
    assert proc.returncode == 0, proc.stderr
    assert proc.stderr.strip() == ("parsolve: warning: m.vtu: mesh.file: 1 point(s) are used by no "
                                   "cell (points 4): they are left out of the system")
    # -q: the final line alone, the warning left out
    quiet = cli("run", "scene.toml", "-o", "out.h5", "-q", cwd=tmp_path)
    assert quiet.returncode == 0 and quiet.stderr == "" and quiet.stdout == "results: out.h5\n"


def test_check_good_scene(cli):
    proc = cli("check", CONFIGS / "kirsch.toml")
    assert proc.returncode == 0 and "ok" in proc.stdout


def test_run_result_file_layout(tmp_path, cli):
    out = tmp_path / "bar.h5"
    proc = cli("run", CONFIGS / "controlled_bar.toml", "-o", out)
    assert proc.returncode == 0, proc.stderr
    assert proc.stdout.count("step ") == 10  # one progress line per step
    with h5py.File(out) as f:
        assert f.attrs["status"] == "complete" and f.attrs["nprocs"] == 1
        assert f.attrs["scene"] == GOOD
        for key in ("parsolve_version", "petsc_version"):
            assert f.attrs[key]
        npts, ncells = f["mesh/points"].shape[0], f["mesh/cells/quad"].shape[0]
        assert f["mesh/points"].shape == (120, 2) and f["mesh/cells/quad"].shape == (87, 4)
        for name in ("time", "iterations", "residual"):
            assert f[f"steps/{name}"].shape == (10,)
        np.testing.assert_allclose(f["steps/time"][()], np.arange(1, 11) / 10)
        assert f["fields/displacement"].shape == (10, npts, 2)
        assert f["cell_fields/stress"].shape == (10, ncells, 3)
        assert f["relations/control/multiplier"].shape == (10, 1)
        assert f["relations/left_x/primal"].shape == (10, 4)
        for phase in ("assembly", "factorization", "solve", "output", "total"):
            assert f[f"timings/{phase}"].shape == (10,)
    xdmf = out.with_suffix(".xdmf").read_text()
    import xml.etree.ElementTree as ET

    grids = ET.fromstring(xdmf).findall(".//Grid[@GridType='Uniform']")
    assert len(grids) == 10 and "bar.h5:/mesh/points" in xdmf \
        and "bar.xdmf.h5:/fields/displacement/9" in xdmf


def test_petsc_options_from_command_line_win(tmp_path, cli):
    """-ksp_view goes to the solver (under its prefix); a scene option is overridden."""
    scene = tmp_path / "s.toml"
    scene.write_text(GOOD + '\n[solver.petsc]\nmat_mumps_icntl_7 = 0\n')
    proc = cli("run", scene, "-o", tmp_path / "o.h5", "-ksp_view", "-mat_mumps_icntl_7", "6")
    assert proc.returncode == 0, proc.stderr
    assert "INFOG(7) (ordering option effectively used after analysis): 6" in proc.stdout
    proc = cli("run", scene, "-o", tmp_path / "o.h5", "-ksp_view")
    assert "INFOG(7) (ordering option effectively used after analysis): 0" in proc.stdout


def test_solver_failure_exit_3_keeps_file(tmp_path):
    scene = tmp_path / "s.toml"
    scene.write_text(GOOD + '''
[[relations]]
name = "left_mean"
type = "mean"
region = "left"
component = "x"
''')
    out = tmp_path / "o.h5"
    proc = parsolve("run", scene, "-o", out)
    assert proc.returncode == 3, proc.stderr
    assert "singular" in proc.stderr and "Traceback" not in proc.stderr
    with h5py.File(out) as f:
        assert f.attrs["status"].startswith("failed") and f["steps/time"].shape == (0,)


def test_export_system_reproduces_the_solve(tmp_path, cli):
    """DIR/system.dat and DIR/fields.dat: a bare petsc4py MUMPS solve gives the same answer."""
    out = tmp_path / "bar.h5"
    proc = cli("run", CONFIGS / "controlled_bar.toml", "-o", out, "--export-system", tmp_path / "sys")
    assert proc.returncode == 0, proc.stderr
    from petsc4py import PETSc   # a bare solve of the exported system, in this process

    v = PETSc.Viewer().createBinary(str(tmp_path / "sys" / "system.dat"), "r", comm=PETSc.COMM_SELF)
    A, b, s = PETSc.Mat().load(v), PETSc.Vec().load(v), PETSc.Vec().load(v)
    w = PETSc.Viewer().createBinary(str(tmp_path / "sys" / "fields.dat"), "r", comm=PETSc.COMM_SELF)
    isq, isl = PETSc.IS().load(w), PETSc.IS().load(w)
    ksp = PETSc.KSP().create(comm=PETSc.COMM_SELF)
    ksp.setOperators(A)
    ksp.setType("preonly")
    ksp.getPC().setType("lu")
    ksp.getPC().setFactorSolverType("mumps")
    x = b.duplicate()
    ksp.solve(b, x)
    i = isl.getIndices()
    lam_scaled, lam_bare = x.getValues(i)[0], (x.getValues(i) * s.getValues(i))[0]
    nq, nl = isq.getSize(), isl.getSize()
    for obj in (ksp, x, A, b, s, isq, isl, v, w):
        obj.destroy()
    assert int(nq) == 240 and int(nl) == 1
    with h5py.File(out) as f:
        lam = f["relations/control/multiplier"][0, 0]
    assert abs(lam - 1000.0) < 1e-8  # E H δ / L at the first step
    assert float(lam_scaled) != lam      # the relation is scaled to the stiffness...
    assert abs(float(lam_bare) - lam) < 1e-8 * lam  # ...and s · x is the file's λ


@pytest.mark.parametrize("nranks", [2, 3])
def test_mpirun_results_match_one_rank(nranks, tmp_path, cli):
    """Under mpirun the result file keeps the input mesh order and matches 1 rank to round-off."""
    scene = tmp_path / "k.toml"
    scene.write_text((CONFIGS / "kirsch.toml").read_text().replace("n_radial = 48", "n_radial = 12")
                     .replace("n_angular = 64", "n_angular = 16"))
    one, many = tmp_path / "one.h5", tmp_path / "many.h5"
    assert cli("run", scene, "-o", one).returncode == 0
    proc = parsolve("run", scene, "-o", many, mpi=nranks)
    assert proc.returncode == 0, proc.stderr
    assert proc.stdout.count("step 1/1") == 1  # progress printed by rank 0 only
    with h5py.File(one) as a, h5py.File(many) as b:
        assert b.attrs["nprocs"] == nranks and b.attrs["status"] == "complete"
        np.testing.assert_array_equal(a["mesh/points"][()], b["mesh/points"][()])
        np.testing.assert_array_equal(a["mesh/cells/triangle6"][()], b["mesh/cells/triangle6"][()])
        for key in ("fields/displacement", "fields/stress", "cell_fields/stress",
                    "relations/symmetry_x/multiplier"):
            x, y = a[key][()], b[key][()]
            assert np.abs(x - y).max() <= 1e-10 * np.abs(x).max(), key


def test_global_petsc_options_reach_petsc(tmp_path):
    """-log_view and -memory_view are read at PETSc's initialisation: nothing may initialise
    PETSc before the command line is handed to it."""
    scene = tmp_path / "bar.toml"
    scene.write_text(GOOD)
    proc = parsolve("run", scene, "-o", tmp_path / "bar.h5", "-log_view", "-memory_view", cwd=tmp_path)
    assert proc.returncode == 0, proc.stderr
    assert "Event" in proc.stdout and "Summary of Memory Usage in PETSc" in proc.stdout


def test_marked_relations_report_their_resultant(tmp_path, cli):
    """`report = true`: the resultant (Σ of the reactions per component, then the moment) is
    printed with each step's progress line; the controlled bar's end force E·H·δ/L = 1e4 N."""
    proc = cli("run", CONFIGS / "controlled_bar.toml", "-o", tmp_path / "bar.h5")
    assert proc.returncode == 0, proc.stderr
    lines = proc.stdout.splitlines()
    assert lines[-2].strip() == ("control: resultant fx 10000  fy 0  mz -500 (moments about the "
                                 "origin)")  # moment: -F · H/2


@pytest.mark.parametrize("mode", ["swmr", "parallel"])
@pytest.mark.parametrize("nranks", [2, 3])
def test_mpirun_distributed_mesh_matches_one_rank(nranks, mode, tmp_path):
    """Each rank holding its part of the mesh only: the result file (both output modes) is
    the one-rank file, in input order, to round-off."""
    scene = tmp_path / "k.toml"
    scene.write_text((CONFIGS / "kirsch.toml").read_text().replace("n_radial = 48", "n_radial = 12")
                     .replace("n_angular = 64", "n_angular = 16"))
    one, many = tmp_path / "one.h5", tmp_path / "many.h5"
    assert parsolve("run", scene, "-o", one).returncode == 0
    proc = parsolve("run", scene, "-o", many, "--output-mode", mode, mpi=nranks)
    assert proc.returncode == 0, proc.stderr
    with h5py.File(one) as a, h5py.File(many) as b:
        assert b.attrs["status"] == "complete" and b.attrs["dofs"] == a.attrs["dofs"]
        np.testing.assert_array_equal(a["mesh/points"][()], b["mesh/points"][()])
        np.testing.assert_array_equal(a["mesh/cells/triangle6"][()], b["mesh/cells/triangle6"][()])
        for key in ("fields/displacement", "fields/stress", "cell_fields/stress",
                    "relations/symmetry_x/multiplier", "relations/symmetry_x/resultant"):
            x, y = a[key][()], b[key][()]
            assert np.abs(x - y).max() <= 1e-10 * np.abs(x).max(), key


@pytest.mark.parametrize("case", ["missing mesh file", "unknown region", "bad selector",
                                  "not finite on one part", "no cell on any part"])
def test_distributed_input_errors_on_every_rank(case, tmp_path):
    """On a distributed mesh an input error found on one rank's part (or by rank 0 building
    the mesh) stops every rank with exit 2 and one line: no rank is left waiting."""
    if case == "not finite on one part":   # x = 1 is on one rank's part only
        text = GOOD.replace("[regions]", '[regions]\nodd = "1 / (x - 1) > 0"\n')
        source, key = "scene.toml", "regions.odd"
    elif case == "no cell on any part":
        text = GOOD.replace("[[materials]]", '[[materials]]\nregion = "beyond"', 1).replace(
            "[regions]", '[regions]\nbeyond = "x > 2"\n')
        source, key = "scene.toml", "regions.beyond"
    else:
        text, source, key = BAD[case]
    if case in ("bad selector", "not finite on one part"):
        text = text.replace('region = "corner"', 'region = "odd"')
    (tmp_path / "scene.toml").write_text(text)
    proc = parsolve("run", "scene.toml", "-o", tmp_path / "out.h5", cwd=tmp_path, mpi=2)
    assert proc.returncode == 2, proc.stderr
    lines = [line for line in proc.stderr.strip().splitlines() if line.startswith("parsolve")]
    assert len(lines) == 1 and "Traceback" not in proc.stderr, proc.stderr
    assert source in lines[0] and key in lines[0], lines[0]
    assert not list(tmp_path.glob("*.h5"))


# ---------------------------------------------------------------- the command line's surface

def test_help_lists_every_command_and_usage_lines(cli):
    top = cli("--help")
    assert top.returncode == 0
    for command in ("run", "check", "study", "batch", "post", "mesh"):
        assert f"\n  {command} " in top.stdout, top.stdout
    assert "--version" in top.stdout and "PETSc options" in top.stdout
    run = cli("run", "--help")
    assert run.returncode == 0
    assert run.stdout.startswith("usage: parsolve run SCENE [-o OUT.h5]"), run.stdout
    assert "-q, --quiet" in run.stdout and "-v, --verbose" in run.stdout
    check = cli("check", "--help")
    assert check.stdout.startswith("usage: parsolve check SCENE [-q | -v] [PETSc options]\n")
    post = cli("post", "--help")
    assert post.stdout.startswith("usage: parsolve post RESULT.h5")
    assert "see parsolve/post/spec.py" not in post.stdout
    for form in ("relation:NAME:multiplier[:SEL]", "field:NAME:COMP@X,Y[,Z]", "max:field:NAME",
                 "examples:", "--line 0,1 0,10 50"):
        assert form in post.stdout, form


def test_version_names_parsolve_petsc_and_mpi():
    from petsc4py import PETSc

    import parsolve

    proc = parsolve_process("--version")
    assert proc.returncode == 0, proc.stderr
    line, = proc.stdout.strip().splitlines()
    petsc = ".".join(map(str, PETSc.Sys.getVersion()))
    assert line.startswith(f"parsolve {parsolve.__version__}; PETSc {petsc} (petsc4py "), line
    assert "; MPI 3." in line or "; MPI 4." in line, line


def parsolve_process(*args, **kw):
    return parsolve(*args, **kw)


def test_split_args_keeps_quiet_and_verbose_ours():
    from parsolve.cli import split_args

    ours, petsc = split_args(["run", "s.toml", "-q", "-ksp_monitor", "-v", "-vec_type", "mpi",
                              "--verbose", "-o", "x.h5", "-options_left"])
    assert ours == ["run", "s.toml", "-q", "-v", "--verbose", "-o", "x.h5"]
    assert petsc == ["-ksp_monitor", "-vec_type", "mpi", "-options_left"]


PHASES = ["mesh read", "checks", "partition", "effects", "relations", "numbering", "pattern",
          "operator", "result file", "assembly", "analysis+factorization"]


def test_progress_phases_quiet_and_verbose(tmp_path, cli):
    """Before step 1: one line per set-up phase with its time, in order; -q: the final line
    alone; -v: each linear solve's Krylov iterations."""
    normal = cli("run", CONFIGS / "controlled_bar.toml", "-o", tmp_path / "a.h5")
    assert normal.returncode == 0, normal.stderr
    lines = normal.stdout.splitlines()
    first = next(i for i, line in enumerate(lines) if line.startswith("step 1/10"))
    # the factorization (one long C call) announces itself when it starts
    assert lines[:first].count("  analysis+factorization ...") == 1
    # its two parts from PETSc's event log, within the phase's own time
    parts = re.fullmatch(r"    analysis (\d+\.\d{3}) s, numeric factorization (\d+\.\d{3}) s",
                         lines[first - 1])
    assert parts, lines[first - 1]
    whole = float(lines[first - 2].split()[-2])
    assert sum(float(p) for p in parts.groups()) <= whole + 2e-3
    # the preset "auto" resolved to, said once among the phases
    said = [line for line in lines[:first] if line.startswith("solver: ")]
    assert said == ["solver: direct preset (auto: 2D, 240 DOFs: MUMPS)"], said
    timed = [line for line in lines[:first - 1]
             if not line.endswith(" ...") and not line.startswith("solver: ")]
    names = [re.fullmatch(r"  (\S.*?)\s+(\d+\.\d{3}) s", line) for line in timed]
    assert all(names), lines[:first]
    assert [m.group(1) for m in names] == PHASES
    quiet = cli("run", CONFIGS / "controlled_bar.toml", "-o", tmp_path / "b.h5", "-q")
    assert quiet.returncode == 0 and quiet.stdout == f"results: {tmp_path / 'b.h5'}\n", quiet.stdout
    verbose = cli("run", CONFIGS / "controlled_bar.toml", "-o", tmp_path / "c.h5", "-v")
    krylov = [line for line in verbose.stdout.splitlines() if "Krylov iterations" in line]
    assert len(krylov) == 10 and krylov[0].strip().startswith("linear solve: 1 Krylov iterations")
    check = cli("check", CONFIGS / "controlled_bar.toml", "-q")
    assert check.returncode == 0 and check.stdout.startswith(f"{CONFIGS / 'controlled_bar.toml'}: ok")


def test_verbose_shows_each_newton_residual(tmp_path, cli):
    """The block on a rough plane: the Newton residuals of every step, the last one of a step
    being the residual its progress line reports."""
    proc = cli("run", CONFIGS / "contact_block_friction.toml", "-o", tmp_path / "b.h5", "-v")
    assert proc.returncode == 0, proc.stderr
    step_lines = [i for i, line in enumerate(proc.stdout.splitlines()) if line.startswith("step ")]
    lines = proc.stdout.splitlines()
    with h5py.File(tmp_path / "b.h5", "r") as f:
        iterations, residual = f["steps/iterations"][()], f["steps/residual"][()]
    start = 0
    for k, i in enumerate(step_lines):
        newton = [float(line.split("residual ")[1]) for line in lines[start:i]
                  if line.strip().startswith("newton ")]
        assert len(newton) >= 1
        np.testing.assert_allclose(newton[-1], residual[k], rtol=1e-3)
        start = i + 1


@pytest.mark.parametrize("formulation", ["relations", "penalty"])
@pytest.mark.parametrize("nranks", [1, 2, 3])
def test_contact_report_on_screen_matches_the_file(nranks, formulation, tmp_path):
    """``report = true`` on a contact: each step's ΣRn, ΣRt, |ΣRt|/ΣRn and open / stick / slip
    counts, the same on any number of ranks as the file's states and forces (the relations
    form's surface totals; the penalty form's nodal reactions summed)."""
    scene = (CONFIGS / "contact_block_friction.toml").read_text().replace(
        "friction = 0.3", f"friction = 0.3\nreport = true\nformulation = \"{formulation}\"")
    (tmp_path / "block.toml").write_text(scene)
    proc = parsolve("run", "block.toml", "-o", "block.h5", cwd=tmp_path, mpi=nranks)
    assert proc.returncode == 0, proc.stderr
    found = re.findall(r"^    base: ΣRn (\S+)  ΣRt (\S+)  \|ΣRt\|/ΣRn (\S+)  rows open (\d+), "
                       r"stick (\d+), slip (\d+)$", proc.stdout, re.M)
    with h5py.File(tmp_path / "block.h5", "r") as f:
        state = f["fields/base_state"][()][..., 0]
        if formulation == "relations":
            rn = f["relations/base_normal/normal_force"][()][:, 0]
            rt = f["relations/base_normal/tangential_force"][()][:, 0]
        else:
            rn = f["fields/base_normal_reaction"][()][..., 0].sum(axis=1)
            rt = f["fields/base_tangential_reaction"][()][..., 0].sum(axis=1)
    assert len(found) == len(state) == 10
    for k, (n, t, ratio, *counts) in enumerate(found):
        np.testing.assert_allclose([float(n), float(t), float(ratio)],
                                   [rn[k], rt[k], abs(rt[k]) / rn[k]], rtol=1e-5)
        assert [int(c) for c in counts] == [int((state[k] == s).sum()) for s in range(3)]
    assert found[-1][2] == "0.3" and float(found[-1][0]) == pytest.approx(10.0)


def test_resultant_lines_name_their_components():
    from parsolve.outputs import resultant_line

    assert resultant_line("clamp", ["x", "y", "z", "mx", "my", "mz"], [1.5, -2, 0, 3, 4e-7, 5]) == \
        "clamp: resultant fx 1.5  fy -2  fz 0  mx 3  my 4e-07  mz 5 (moments about the origin)"
    # a scalar field's reaction by its name; no moment without a displacement
    assert resultant_line("inlet", ["h"], [0.25]) == "inlet: resultant h 0.25"
    assert resultant_line("both", ["x", "y", "T", "mz"], [1, 2, 3, 4]) == \
        "both: resultant fx 1  fy 2  T 3  mz 4 (moments about the origin)"
