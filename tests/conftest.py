"""Shared fixtures. Every test runs unchanged on 1, 2 or 3 MPI ranks unless marked ``serial``."""

from __future__ import annotations

import sys
from pathlib import Path

import h5py
import numpy as np
import pytest
from mpi4py import MPI

ROOT = Path(__file__).resolve().parents[1]
CONFIGS = ROOT / "configs"


def pytest_sessionstart(session):
    """PETSc's event log on for the session, before any PETSc object: the tests marked
    ``petsc_events`` count factorizations with its events."""
    from petsc4py import PETSc

    PETSc.Log.begin()


def pytest_collection_modifyitems(config, items):
    # the tests that count PETSc events first: an error inside PETSc (a MUMPS factorization
    # out of workspace, redone with a larger margin by design) leaves its events begun and
    # never ended, and PETSc's log counts them no more for the rest of the process
    items.sort(key=lambda item: "petsc_events" not in item.keywords)
    if MPI.COMM_WORLD.size > 1:
        skip = pytest.mark.skip(reason="serial test (runs on 1 rank only)")
        for item in items:
            if "serial" in item.keywords:
                item.add_marker(skip)


@pytest.hookimpl(hookwrapper=True)
def pytest_runtest_makereport(item, call):
    """Under mpirun a failure on one rank would leave the others waiting in a collective call:
    report it and abort the whole job (mpi4py's rule) instead of hanging."""
    outcome = yield
    report = outcome.get_result()
    if report.failed and MPI.COMM_WORLD.size > 1:
        sys.stderr.write(f"\n[rank {MPI.COMM_WORLD.rank}] {item.nodeid} FAILED\n{report.longreprtext}\n")
        sys.stderr.flush()
        MPI.COMM_WORLD.Abort(1)


@pytest.fixture
def comm() -> MPI.Comm:
    return MPI.COMM_WORLD


@pytest.fixture
def shared_tmp(tmp_path) -> Path:
    """A temporary directory that is the same on every rank (rank 0's)."""
    return Path(MPI.COMM_WORLD.bcast(str(tmp_path), root=0))


def read_results(path: Path) -> dict:
    """Every dataset of a result file as numpy arrays, plus the root attributes under 'attrs'."""
    out = {}
    with h5py.File(path, "r") as f:
        out["attrs"] = dict(f.attrs)
        f.visititems(lambda name, obj: out.__setitem__(name, obj[()])
                     if isinstance(obj, h5py.Dataset) else None)
    return out


def run_scene(scene, out: Path, comm=MPI.COMM_WORLD, options: dict | None = None,
              export: str | None = None, solver: dict | None = None) -> dict:
    """Run a scene (path, or TOML text written beside ``out``) and read its results on every
    rank; ``solver``: [solver] keys to set."""
    from parsolve.driver import run
    from parsolve.model import build_model
    from parsolve.scene import load_scene

    if not isinstance(scene, Path):
        src = out.with_suffix(".toml")
        if comm.rank == 0:
            src.write_text(scene)
        comm.Barrier()
        scene = src
    scene = load_scene(scene)
    for key, value in (solver or {}).items():
        setattr(scene.solver, key, value)
    model = build_model(scene, comm)
    try:
        run(comm, model, str(out), options or {}, export, log=lambda *a: None)
    finally:
        comm.Barrier()  # rank 0 has closed the file, whatever happened
    return read_results(out)


@pytest.fixture
def run(shared_tmp):
    """run(scene, name='result', comm=..., options=...) -> results dict (see run_scene)."""
    counter = iter(range(1000))

    def _run(scene, name: str | None = None, comm=MPI.COMM_WORLD, **kw):
        name = name or f"result{next(counter)}"
        if comm is MPI.COMM_SELF:
            name += f"_self{MPI.COMM_WORLD.rank}"
        _run.last = shared_tmp / f"{name}.h5"
        return run_scene(scene, _run.last, comm, **kw)

    return _run


def saddle_of_input_dofs(comm, system) -> np.ndarray:
    """The saddle index of every input DOF of the whole mesh (each from its owner; a rank's
    ``system.dofmap.saddle_of_local`` covers its local DOFs only)."""
    from parsolve.mesh.regions import allgather_rows

    mesh, nc = system.model.mesh, system.model.ncomp
    own = system.dofmap.owned_dofs
    node, comp = np.divmod(own, nc)
    pairs = allgather_rows(comm, np.column_stack([mesh.global_nodes[node].astype(np.int64) * nc
                                                  + comp, system.dofmap.saddle_of_local[own]]))
    out = np.empty(mesh.num_global_points * nc, dtype=np.int64)
    out[pairs[:, 0]] = pairs[:, 1]
    return out


def stiffness_block(comm, system) -> np.ndarray:
    """The assembled K block of a system in input DOF numbering, whole on every rank."""
    rows = system.assemble().convert("dense").getDenseArray().copy()
    whole = np.concatenate(comm.allgather(rows), axis=0)
    iq = saddle_of_input_dofs(comm, system)
    return whole[np.ix_(iq, iq)]


def whole_points(comm, mesh) -> np.ndarray:
    """The whole mesh's points in input order, from every rank's owned ones."""
    from parsolve.mesh.regions import allgather_rows

    ids = allgather_rows(comm, mesh.global_nodes[:mesh.n_owned].astype(np.int64))
    pts = allgather_rows(comm, np.ascontiguousarray(mesh.points[:mesh.n_owned]))
    out = np.empty((mesh.num_global_points, mesh.dim))
    out[ids] = pts
    return out


def rel_err(a, b) -> float:
    a, b = np.asarray(a, float), np.asarray(b, float)   # (empty: a relation with no row here)
    return float(np.abs(a - b).max(initial=0.0) / max(np.abs(b).max(initial=0.0), 1e-300))


def solve_in_process(text: str, comm=MPI.COMM_WORLD, t: float = 1.0, options: dict | None = None):
    """Build and solve a scene's first system in memory: (system, solver, mat, rhs, x)."""
    from parsolve.driver import make_solver
    from parsolve.model import build_model
    from parsolve.scene import parse_scene
    from parsolve.solvers.system import SaddleSystem
    import tomllib

    model = build_model(parse_scene(tomllib.loads(text), "test.toml", text), comm)
    system = SaddleSystem(comm, model)
    mat = system.assemble()
    solver = make_solver(comm, system, options or {})
    solver.set_operator(mat)
    x, rhs = mat.createVecs()
    rhs.array[:] = system.rhs(t)[0]
    solver.solve(rhs, x)
    return system, solver, mat, rhs, x


def dense(mat, comm=MPI.COMM_WORLD) -> np.ndarray:
    """The whole matrix on every rank (small systems only); converted into a new Mat: the
    assembled one works on the operator's own arrays and must stay as it is."""
    from petsc4py import PETSc

    rows = mat.convert("dense", PETSc.Mat()).getDenseArray().copy()
    return np.concatenate(comm.allgather(rows), axis=0)



def assert_same_results(a: dict, b: dict, tol: float = 1e-10, ignore: tuple = ()) -> None:
    """Two result files hold the same datasets, equal to ``tol`` of the largest value of each
    kind of dataset (``stress``, ``multiplier``, ...), integers and active rows exactly; the
    residuals (round-off over round-off), timings and the ``ignore`` keys apart."""
    assert a["attrs"]["status"] == b["attrs"]["status"] == "complete"
    keys = [k for k in b if k not in ("attrs", "steps/residual") + tuple(ignore)
            and not (k.startswith("balance") and k.endswith("error"))
            and not k.startswith("timings")]
    assert sorted(keys) == sorted(k for k in a if k in keys)
    family = {}
    for k in keys:
        tail = k.rsplit("/", 1)[-1]
        family[tail] = max(family.get(tail, 0.0), float(np.abs(b[k]).max(initial=0.0)))
    for key in keys:
        if key.endswith("/active") or b[key].dtype.kind in "iub":
            assert np.array_equal(a[key], b[key]), key
        else:
            scale = max(family[key.rsplit("/", 1)[-1]], 1e-300)
            assert np.abs(a[key] - b[key]).max() <= tol * scale + 1e-13, key
