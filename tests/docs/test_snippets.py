"""Every ```toml block of the docs is a complete scene, and `parsolve check` accepts it; so
are the scenes of tests/docs/scenes/ (keys no shipped scene uses: the 3D baselines, arc length).

The convention (docs/guide.md's header): a ```toml fence holds a whole scene; excerpts, study
and job files are plain text blocks. Each scene is written to its own folder and checked in
process through ``parsolve.cli.main`` (the command line's own entry: same validation, same
exit status, no subprocess). A scene naming ``bracket.msh`` gets the guide's Gmsh part: a 2 × 1
plate with the physical groups body, clamp and load, written by meshio in MSH 2.2.
"""
import re
from pathlib import Path

import numpy as np
import pytest

ROOT = Path(__file__).resolve().parents[2]
FENCE = re.compile(r"^```toml\n(.*?)^```", re.S | re.M)


def snippets() -> list[tuple[str, str]]:
    out = []
    for md in sorted((ROOT / "docs").rglob("*.md")):
        for i, m in enumerate(FENCE.finditer(md.read_text())):
            out.append((f"{md.relative_to(ROOT)}#{i + 1}", m.group(1)))
    return out


def write_bracket(path: Path) -> None:
    """The guide's bracket.geo meshed by hand: 20 × 10 quads, groups as Gmsh names them."""
    import meshio

    nx, ny = 20, 10
    x, y = np.meshgrid(np.linspace(0.0, 2.0, nx + 1), np.linspace(0.0, 1.0, ny + 1))
    points = np.column_stack([x.ravel(), y.ravel()])
    ids = np.arange((nx + 1) * (ny + 1)).reshape(ny + 1, nx + 1)
    quads = np.column_stack([ids[:-1, :-1].ravel(), ids[:-1, 1:].ravel(),
                             ids[1:, 1:].ravel(), ids[1:, :-1].ravel()])
    left = np.column_stack([ids[:-1, 0], ids[1:, 0]])
    right = np.column_stack([ids[:-1, -1], ids[1:, -1]])
    lines = np.vstack([left, right])
    tags = [np.full(len(quads), 1), np.concatenate([np.full(ny, 2), np.full(ny, 3)])]
    mesh = meshio.Mesh(points, [("quad", quads), ("line", lines)],
                       cell_data={"gmsh:physical": tags, "gmsh:geometrical": tags},
                       field_data={"body": np.array([1, 2]), "clamp": np.array([2, 1]),
                                   "load": np.array([3, 1])})
    meshio.write(str(path), mesh, file_format="gmsh22", binary=False)


ALL = snippets() + [(str(p.relative_to(ROOT)), p.read_text())
                    for p in sorted((Path(__file__).parent / "scenes").glob("*.toml"))]


def test_the_docs_hold_scenes():
    assert len(snippets()) >= 5, [name for name, _ in ALL]


@pytest.mark.parametrize("text", [t for _, t in ALL], ids=[n for n, _ in ALL])
def test_snippet_passes_check(text, tmp_path, capsys):
    from parsolve.cli import main

    if "bracket.msh" in text:
        write_bracket(tmp_path / "bracket.msh")
    scene = tmp_path / "scene.toml"
    scene.write_text(text)
    status = main(["check", str(scene)])
    out = capsys.readouterr()
    assert status == 0, out.err
    assert f"{scene}: ok (" in out.out or not out.out  # rank 0 prints, the others do not
    assert not list(tmp_path.glob("*.h5"))             # check writes nothing


CHECKED = re.compile(r"^<!-- check: (study|jobs) -->\n```\w*\n(.*?)^```", re.S | re.M)


def files() -> list[tuple[str, str, str]]:
    """(name, kind, text) of every study and job file the docs mark as checked."""
    out = []
    for md in sorted((ROOT / "docs").rglob("*.md")):
        for i, m in enumerate(CHECKED.finditer(md.read_text())):
            out.append((f"{md.relative_to(ROOT)}#{m.group(1)}{i + 1}", m.group(1), m.group(2)))
    return out


FILES = files()


def test_the_docs_hold_a_study_and_a_job_file():
    assert sorted({kind for _, kind, _ in FILES}) == ["jobs", "study"]


@pytest.mark.parametrize("kind,text", [(k, t) for _, k, t in FILES], ids=[n for n, _, _ in FILES])
def test_study_or_job_file_is_valid(kind, text, tmp_path):
    """Loaded as `parsolve study` / `parsolve batch` load them, every effective scene
    validated; the shipped scene they name sits one folder up, as in configs/."""
    import shutil

    for scene in (ROOT / "configs").glob("*.toml"):
        shutil.copyfile(scene, tmp_path / scene.name)
    (tmp_path / kind).mkdir()
    path = tmp_path / kind / "file.toml"
    path.write_text(text)
    if kind == "study":
        from parsolve.study.config import load_study

        study = load_study(path)
        assert study.families and study.quantities
    else:
        from parsolve.batch.jobs import load_jobs

        jobs = load_jobs(path, validate=True)
        assert len(jobs.runs) == 4    # the grid's 2 values × the 2 [[runs]] entries
    assert sorted(p.name for p in (tmp_path / kind).iterdir()) == ["file.toml"]  # nothing written


PYTHON = re.compile(r"^<!-- check: python -->\n```python\n(.*?)^```", re.S | re.M)


@pytest.mark.serial
def test_python_reading_snippet_runs_on_the_first_run_result(tmp_path, monkeypatch, capsys):
    """The guide's h5py snippet, on the result of the README's first run (configs/kirsch.toml,
    run in process: one linear step)."""
    from parsolve.cli import main

    blocks = [m.group(1) for m in PYTHON.finditer((ROOT / "docs" / "guide.md").read_text())]
    assert len(blocks) == 1
    monkeypatch.chdir(tmp_path)
    assert main(["run", str(ROOT / "configs" / "kirsch.toml"), "-o", "kirsch.h5"]) == 0
    capsys.readouterr()
    exec(compile(blocks[0], "docs/guide.md", "exec"), {})
    status, sizes = capsys.readouterr().out.splitlines()
    assert status == "complete"
    assert sizes == "1 (12513, 2) (1, 97)"    # 1 step; P2 quarter plate; 97 nodes on x = 0
