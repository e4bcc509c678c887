"""What a Newton iteration holds: one linearization at a time (an iterate's tangent and states
go before the next are formed), and an elastic material's tangent not copied to every
quadrature point. Counted in objects and bytes, not seconds; at 1, 2 and 3 ranks."""

import tracemalloc
import weakref

import numpy as np
from mpi4py import MPI

from conftest import dense
from helpers.scene import scene, shipped
from parsolve.model import build_model
from parsolve.scene import parse_scene
from parsolve.solvers import problem as problem_module
from parsolve.solvers.system import SaddleSystem

#: the shipped 3D friction box (held only by contact, Coulomb friction), its first step
FRICTION = scene(shipped("contact_friction_3d.toml"), steps={"count": 1, "end": 0.125},
                 solver={"preset": "iterative"})


def _model(text: str, comm=MPI.COMM_WORLD):
    import tomllib

    return build_model(parse_scene(tomllib.loads(text), "test.toml", text), comm)


def test_one_linearization_alive_per_iteration(run, monkeypatch):
    form = problem_module.SaddleProblem.form
    made, alive_at_form = [], []

    def counted(self):
        alive_at_form.append(sum(ref() is not None for ref in made))
        lin = form(self)
        made.append(weakref.ref(lin))
        return lin

    monkeypatch.setattr(problem_module.SaddleProblem, "form", counted)
    res = run(FRICTION)
    iterations = int(res["steps/iterations"][0])
    assert iterations >= 4                         # Newton went through several iterates
    assert len(alive_at_form) == iterations + 1    # one form per iterate, the converged one too
    assert alive_at_form == [0] * len(alive_at_form)


def test_elastic_tangent_not_copied_per_point():
    model = _model(FRICTION)
    effect = model.effects[0]
    system = SaddleSystem(MPI.COMM_WORLD, model)
    comp = system.composition   # this rank's cells
    cells = comp.cells
    q = np.random.default_rng(0).normal(scale=1e-3, size=comp.ndof)
    u = comp.values(q)["u"]
    states = effect.init_state(cells)
    tracemalloc.start()
    before = tracemalloc.get_traced_memory()[0]
    fe, tangent, trial, sig = effect.evaluate_u(cells, u, states)
    held = tracemalloc.get_traced_memory()[0] - before
    tracemalloc.stop()
    nq, nv = sig.shape[1], sig.shape[2]
    full_tangent = len(cells) * nq * nv * nv * 8
    # what the evaluation keeps: forces, stresses (and their strains' size) at most, no tangent
    assert held < fe.nbytes + 2 * sig.nbytes + 0.1 * full_tangent, (held, full_tangent)
    # the tangent assembles into the elastic stiffness's operator
    want = dense(system.assemble())
    got = dense(system.assemble(tangent))
    assert np.abs(got - want).max() <= 1e-12 * np.abs(want).max()
