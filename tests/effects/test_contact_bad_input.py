"""Bad contact sections (issue 18): each refused with the file and the key, in process (any
number of ranks) and from the command line (exit 2, one line, nothing written)."""

from __future__ import annotations

import os
import subprocess
import sys

import pytest
from mpi4py import MPI

from conftest import ROOT
from parsolve.errors import InputError
from parsolve.model import build_model
from parsolve.scene import load_scene

SCENE = """
[mesh]
generator = "rectangle"
lx = 1.0
ly = 0.5
nx = 4
ny = 2
[model]
hypothesis = "plane_strain"
[[materials]]
E = 1000.0
nu = 0.3
[[relations]]
name = "down"
type = "dirichlet"
region = "top"
components = ["x", "y"]
value = -0.01
[[contact]]
{contact}
"""


def plane(origin: str = "[0.0, 0.0]", normal: str = "[0.0, 1.0]") -> str:
    return f"obstacle = {{ plane = {{ origin = {origin}, normal = {normal} }} }}"


OK = f'slave = "bottom"\n{plane()}'
BAD = {
    "name with a slash": (f'name = "a/b"\n{OK}', "contact[0].name", "plain name"),
    "empty name": (f'name = ""\n{OK}', "contact[0].name", "plain name"),
    "name with a space": (f'name = "a b"\n{OK}', "contact[0].name", "plain name"),
    "absurd friction": (f'name = "c"\n{OK}\nfriction = 1e30', "contact[0].friction", "beyond"),
    "negative friction": (f'name = "c"\n{OK}\nfriction = -0.5', "contact[0].friction", ">= 0"),
    "infinite friction": (f'name = "c"\n{OK}\nfriction = inf', "contact[0].friction", "finite"),
    "nan friction": (f'name = "c"\n{OK}\nfriction = nan', "contact[0].friction", "not a number"),
    "obstacle facing away": (f'name = "c"\nslave = "bottom"\n{plane(normal="[0.0, -1.0]")}',
                             "contact[0].obstacle.plane", "faces the obstacle"),
    "body inside the obstacle": (f'name = "c"\nslave = "bottom"\n{plane(origin="[0.0, 0.1]")}',
                                 "contact[0].obstacle.plane", "inside the obstacle"),
    "obstacle beyond the search radius": (
        f'name = "c"\nslave = "bottom"\n{plane(origin="[0.0, -1.0]")}\nsearch_radius = 0.5',
        "contact[0].slave", "search radius"),
}


def _write(path, text: str):
    if MPI.COMM_WORLD.rank == 0:
        path.write_text(text)
    MPI.COMM_WORLD.Barrier()
    return path


@pytest.mark.parametrize("case", list(BAD))
def test_bad_contact_is_refused_with_file_and_key(shared_tmp, case):
    contact, key, words = BAD[case]
    path = _write(shared_tmp / "bad_contact.toml", SCENE.format(contact=contact))
    with pytest.raises(InputError) as err:
        build_model(load_scene(path), MPI.COMM_WORLD)
    assert err.value.key == key, str(err.value)
    assert words in str(err.value) and str(path) in str(err.value)


def test_far_obstacle_is_a_warning(shared_tmp):
    """A plane 100 below the body: legitimate (a body may be lowered onto it over the steps),
    so not refused, but the run says so."""
    path = _write(shared_tmp / "far_contact.toml",
                  SCENE.format(contact=f'name = "c"\nslave = "bottom"\n'
                                       f'{plane(origin="[0.0, -100.0]")}'))
    model = build_model(load_scene(path), MPI.COMM_WORLD)
    warned = [w for w in model.mesh.warnings if "contact[0].obstacle.plane" in w]
    assert len(warned) == 1 and "smallest gap 100" in warned[0] and str(path) in warned[0]


@pytest.mark.serial
@pytest.mark.parametrize("case", list(BAD))
def test_bad_contact_exits_2_with_one_line(tmp_path, case):
    contact, key, _ = BAD[case]
    path = tmp_path / "bad.toml"
    path.write_text(SCENE.format(contact=contact))
    out = tmp_path / "out.h5"
    env = {k: v for k, v in os.environ.items() if not k.startswith(("OMPI_", "PMIX_", "OPAL_"))}
    res = subprocess.run([sys.executable, "-m", "parsolve", "run", str(path), "-o", str(out)],
                         capture_output=True, text=True, timeout=120, env=env, cwd=ROOT)
    lines = res.stderr.strip().splitlines()
    assert res.returncode == 2 and len(lines) == 1, res.stderr
    assert str(path) in lines[0] and key in lines[0]
    assert not any(tmp_path.glob("out*"))
