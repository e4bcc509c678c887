"""The localization bar and the scenes of tests/solvers/test_control.py that other tests of the
control and arc-length methods reuse, with the bar's closed form."""

import tomllib

import numpy as np
from mpi4py import MPI

from conftest import CONFIGS

BAR = (CONFIGS / "localization_bar.toml").read_text()


E, H, L, N = 1e9, 0.1, 1.0, 29


def closed_form(eps_d: np.ndarray):
    """1D localization bar: the damaged column at strain ε_d sets the stress, the rest unloads
    elastically. Mazars with At = 1 in uniaxial tension (ν = 0): D = 1 - exp(-Bt (κ - εd0))."""
    kappa = np.maximum.accumulate(np.maximum(eps_d, 1e-4))
    sigma = E * eps_d * np.exp(-1e4 * (kappa - 1e-4))
    force = sigma * H
    delta = eps_d * L / N + sigma / E * L * (N - 1) / N
    return delta, force


def end_delta(res):
    pts = res["mesh/points"]
    return res["fields/displacement"][:, np.isclose(pts[:, 0], L), 0].mean(axis=1)


def without_control(text: str) -> str:
    i = text.index('[[relations]]\nname = "max_strain"')
    return text[:i] + text[text.index("[steps]"):]


def displacement_control() -> str:
    """The bar pulled by a prescribed end displacement instead of a controlled load."""
    text = without_control(BAR).replace('[[loads]]\nname = "pull"\nregion = "right"\n'
                                        'total_force = [1.0, 0.0]\n', "")
    return text.replace("[regions]\n", "[regions]\nend = { point = [1.0, 0.0] }\n") + """
[[relations]]
name = "end_displacement"
type = "dirichlet"
region = "end"
components = ["x"]
value = 2.4e-4
"""


VON_MISES = """
[mesh]
generator = "box"
lx = 1.0
ly = 0.2
nz = 2
lz = 0.2
nx = 5
ny = 2
cell = "hexahedron"
[model]
hypothesis = "3d"
[[materials]]
model = "von_mises"
E = 200e3
nu = 0.3
sigma_y = 250.0
H = 2e3
[[relations]]
name = "sym_x"
type = "dirichlet"
region = "xmin"
components = ["x"]
[[relations]]
name = "sym_y"
type = "dirichlet"
region = "ymin"
components = ["y"]
[[relations]]
name = "sym_z"
type = "dirichlet"
region = "zmin"
components = ["z"]
[[relations]]
name = "pull"
type = "dirichlet"
region = "xmax"
components = ["x"]
value = 4e-3
[steps]
count = 8
"""


ARC_BAR = """
[mesh]
generator = "rectangle"
lx = 1.0
ly = 0.1
nx = 10
ny = 2
cell = "quad"
[model]
hypothesis = "plane_stress"
[regions]
corner = { point = [0.0, 0.0] }
[[materials]]
E = 1e3
nu = 0.0
[[loads]]
name = "pull"
region = "right"
total_force = [1.0, 0.0]
[[relations]]
name = "clamp"
type = "dirichlet"
region = "left"
components = ["x"]
[[relations]]
name = "corner"
type = "dirichlet"
region = "corner"
components = ["y"]
[nonlinear]
method = "arc_length"
arc_length = { pattern = "pull", length = 1e-3 }
[steps]
count = 3
"""


# the refined control plate of tests/solvers/test_max_control_*.py
def plate(level: int, steps: int) -> str:
    text = (CONFIGS / "plate_hole_control.toml").read_text()
    text = text.replace("n_radial = 8", f"n_radial = {8 * level}")
    text = text.replace("n_angular = 12", f"n_angular = {12 * level}")
    return text.replace("count = 30", f"count = {steps}\nend = {steps / 30}")


def newton_of(text: str, comm=MPI.COMM_WORLD) -> tuple:
    """(scene, model, system, problem, Newton solver) of a scene's text, as the driver builds
    them (the system assembled once, which scales its relations), ready for its first step."""
    from parsolve.driver import make_solver
    from parsolve.model import build_model
    from parsolve.scene import parse_scene
    from parsolve.solvers.newton import NewtonSolver
    from parsolve.solvers.problem import SaddleProblem
    from parsolve.solvers.system import SaddleSystem

    scene = parse_scene(tomllib.loads(text), "scene.toml", text)
    model = build_model(scene, comm)
    system = SaddleSystem(comm, model)
    system.assemble()
    problem = SaddleProblem(comm, system, make_solver(comm, system, {}), scene.nonlinear)
    return scene, model, system, problem, NewtonSolver(problem, scene.nonlinear)


def plate_newton(refine: int, steps: int):
    """The refined plate's (scene, model, system, Newton solver, maximum relation, mask of
    the DOFs not eliminated), ready for its first step."""
    scene, model, system, _, newton = newton_of(plate(refine, steps))
    (rel,) = [r for r in system.multiplied if r.maximum]
    free = np.ones(model.mesh.num_points * model.ncomp, dtype=bool)
    free[system.elim_local[system.elim_local >= 0]] = False   # (local DOFs of this rank)
    return scene, model, system, newton, rel, free
