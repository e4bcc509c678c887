"""Job files: grids × lists, names, and bad input (exit 2, one line naming the file and key,
nothing run or written)."""

import tomllib

import pytest

from batch_helpers import BAR, jobs_file, parsolve
from parsolve.batch.jobs import load_jobs

pytestmark = pytest.mark.serial  # subprocesses; the scene checks build meshes on one rank


def test_grid_times_list(tmp_path):
    path = jobs_file(tmp_path, 'ranks = 1\nargs = ["-ksp_rtol", "1e-12"]\n'
                     '[grid]\n"materials[0].E" = [1e9, 2e9, 3e9]\n"mesh.nx" = [4, 8]\n'
                     '[[runs]]\n"steps.count" = 2\n'
                     '[[runs]]\n"steps.count" = 3\nranks = 2\nargs = ["-pc_type", "lu"]\n')
    jobs = load_jobs(path)
    assert len(jobs.runs) == 2 * 3 * 2 and jobs.root == (tmp_path / "runs").resolve()
    names = [r.name for r in jobs.runs]
    assert len(set(names)) == 12 and names[0] == "count=2_E=1e+09_nx=4_ranks=1"
    base = tomllib.loads(BAR.read_text())
    for run in jobs.runs:
        scene = tomllib.loads(run.scene_text)
        p = run.params
        assert scene["materials"][0]["E"] == p["materials[0].E"] and scene["mesh"]["nx"] == p["mesh.nx"]
        assert scene["steps"]["count"] == p["steps.count"] and scene["mesh"]["ny"] == base["mesh"]["ny"]
        assert run.ranks == p["ranks"] == (2 if p["steps.count"] == 3 else 1)
        extra = ("-pc_type", "lu") if run.ranks == 2 else ()
        assert run.args == ("-ksp_rtol", "1e-12") + extra
    # every (E, nx, count) once
    assert len({(r.params["materials[0].E"], r.params["mesh.nx"], r.params["steps.count"])
                for r in jobs.runs}) == 12


def test_named_runs_and_defaults(tmp_path):
    path = jobs_file(tmp_path, '[[runs]]\nname = "coarse"\n"mesh.nx" = 4\n[[runs]]\nname = "fine"\n'
                     '"mesh.nx" = 40\n[slurm]\npartition = "debug"\nthrottle = 3\n')
    jobs = load_jobs(path)
    assert [r.name for r in jobs.runs] == ["coarse", "fine"]
    assert jobs.executor == "local" and jobs.parallel == 1
    assert jobs.slurm == {"partition": "debug", "throttle": 3}


def test_dry_run_lists_and_writes_nothing(tmp_path):
    path = jobs_file(tmp_path, '[grid]\n"mesh.nx" = [4, 8]\n')
    proc = parsolve("batch", path, "--dry-run")
    assert proc.returncode == 0, proc.stderr
    assert "2 runs" in proc.stdout and "nx=4" in proc.stdout and "nx=8" in proc.stdout
    assert not (tmp_path / "runs").exists()


BAD = {
    "unknown top key": ('sceen = "x"\n', "jobs.toml", "sceen"),
    "unknown slurm key": ('[slurm]\npartiton = "a"\n', "jobs.toml", "slurm.partiton"),
    "bad slurm value": ('[slurm]\nthrottle = 0\n', "jobs.toml", "slurm.throttle"),
    "no such table": ('[grid]\n"meshh.nx" = [1, 2]\n', "jobs.toml", 'grid."meshh.nx"'),
    "no such entry": ('[grid]\n"materials[3].E" = [1.0]\n', "jobs.toml", 'grid."materials[3].E"'),
    "unknown scene key": ('[grid]\n"mesh.nxx" = [4, 8]\n', "jobs.toml", 'grid."mesh.nxx"'),
    "malformed path": ('[grid]\n"mesh..nx" = [4]\n', "jobs.toml", 'grid."mesh..nx"'),
    "bad value type": ('[grid]\n"materials[0].nu" = [0.0, "zero"]\n', "jobs.toml",
                       'grid."materials[0].nu"'),
    "bad value in a list": ('[[runs]]\n"mesh.nx" = 4\n[[runs]]\n"model.hypothesis" = "plane"\n',
                            "jobs.toml", 'runs[1]."model.hypothesis"'),
    "region named by a run": ('[[runs]]\n"relations[2].region" = "rigth"\n', "jobs.toml",
                              'runs[0]."relations[2].region"'),
    "empty grid list": ('[grid]\n"mesh.nx" = []\n', "jobs.toml", 'grid."mesh.nx"'),
    "bad ranks": ('[[runs]]\nranks = 0\n', "jobs.toml", 'runs[0]."ranks"'),
    "bad args": ('args = ["ksp_rtol"]\n', "jobs.toml", "args"),
    "duplicate names": ('[[runs]]\nname = "a"\n[[runs]]\nname = "a"\n', "jobs.toml", 'runs[1]."name"'),
    "both grid and list": ('[grid]\n"mesh.nx" = [4]\n[[runs]]\n"mesh.nx" = 5\n', "jobs.toml",
                           'runs[0]."mesh.nx"'),
    "bad executor": ('executor = "pbs"\n', "jobs.toml", "executor"),
    "missing scene": ("", "nowhere.toml", ""),
}


@pytest.mark.parametrize("case", sorted(BAD))
def test_bad_input(case, tmp_path):
    body, source, key = BAD[case]
    path = jobs_file(tmp_path, body)
    if case == "missing scene":
        path.write_text('scene = "nowhere.toml"\n')
    proc = parsolve("batch", path, cwd=tmp_path)
    assert proc.returncode == 2, (proc.stdout, proc.stderr)
    lines = proc.stderr.strip().splitlines()
    assert len(lines) == 1 and "Traceback" not in proc.stderr, proc.stderr
    assert source in lines[0] and key in lines[0], lines[0]
    assert not (tmp_path / "runs").exists()
