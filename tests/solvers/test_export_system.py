"""--export-system DIR on every path: the first system a Newton or an arc-length run solves is
written, and it is the system an independent linear run of the same elastic scene writes (a
damage material's tangent at zero damage is the elastic stiffness; Newton's first right-hand
side from q = 0 is the linear one). A contact run's (Newton with an active set) holds the
elastic stiffness of the same body and one row per contact row and node."""

import numpy as np
import pytest
from mpi4py import MPI
from petsc4py import PETSc

from conftest import CONFIGS, ROOT

from parsolve.cli import main

MAZARS = 'model = "mazars"\neps_d0 = 1e-4\nAt = 1.0\nBt = 1e4\nAc = 1.2\nBc = 1500.0\nbeta = 1.06\n'
LINEAR = (CONFIGS / "controlled_bar.toml").read_text().replace("count = 10", "count = 2").replace(
    "value = 1e-4", "value = 2e-6")
NEWTON = LINEAR.replace("E = 1e9\nnu = 0.0", "E = 1e9\nnu = 0.0\n" + MAZARS)
ARC = (ROOT / "tests/docs/scenes/nonlinear_arc_length.toml").read_text().replace(
    "automatic = { strain_increment = 8e-5, max_steps = 60 }\n", "").replace("count = 10", "count = 2")
ARC_ELASTIC = ARC.replace(MAZARS.split("\n", 1)[1], "").replace('model = "mazars"\n', "").split(
    "[nonlinear]")[0]


def _export(tmp, name: str, text: str, code: int = 0, sets: bool = False):
    """(operator, right-hand side[, the index sets of q and λ]) that ``parsolve run
    --export-system`` wrote; ``code``: the run's exit status."""
    comm = MPI.COMM_WORLD
    if comm.rank == 0:
        (tmp / f"{name}.toml").write_text(text)
    comm.Barrier()
    status = main(["run", str(tmp / f"{name}.toml"), "-o", str(tmp / f"{name}.h5"),
                 "--export-system", str(tmp / name)])
    assert status == code
    viewer = PETSc.Viewer().createBinary(str(tmp / name / "system.dat"), "r", comm=comm)
    A, b = PETSc.Mat().load(viewer), PETSc.Vec().load(viewer)
    viewer.destroy()
    if not sets:
        return A, b
    viewer = PETSc.Viewer().createBinary(str(tmp / name / "fields.dat"), "r", comm=comm)
    q, lam = PETSc.IS().load(viewer), PETSc.IS().load(viewer)
    viewer.destroy()
    return A, b, q, lam


@pytest.mark.parametrize("path, text, reference", [("newton", NEWTON, LINEAR),
                                                   ("arc_length", ARC, ARC_ELASTIC)],
                         ids=["newton", "arc_length"])
def test_nonlinear_runs_export_their_first_system(path, text, reference, shared_tmp):
    A, b = _export(shared_tmp, path, text)
    A0, b0 = _export(shared_tmp, "linear", reference)
    assert A.getSize() == A0.getSize() and A.getSize()[0] > 60
    A.axpy(-1.0, A0, PETSc.Mat.Structure.DIFFERENT_NONZERO_PATTERN)
    assert A.norm(PETSc.NormType.FROBENIUS) <= 1e-12 * A0.norm(PETSc.NormType.FROBENIUS)
    if path == "newton":   # the first right-hand side: the loads and relations' values of step 1
        b.axpy(-1.0, b0)
        assert b0.norm() > 0 and b.norm() <= 1e-12 * b0.norm()


CONTACT = (CONFIGS / "contact_block_friction.toml").read_text().replace(
    "count = 10", "count = 1").replace('file = "contact_block_friction.h5"', "")
# the same body without its contact: free along y, a singular system (exit 3), but the linear
# path writes it before its solve
FLOATING = CONTACT.split("[[contact]]")[0] + "[steps]" + CONTACT.split("[steps]")[1]


def test_contact_run_exports_its_first_system(shared_tmp):
    """The block of configs/contact_block_friction.toml (9 bottom nodes on a rough plane, 2
    rows each): the exported system's q-block is the elastic stiffness a linear run of the body
    alone writes, and its 18 relation rows each hold one entry of q (a node's u_y or u_x)."""
    A, _, q, lam = _export(shared_tmp, "contact", CONTACT, sets=True)
    A0, _, q0, lam0 = _export(shared_tmp, "floating", FLOATING, code=3, sets=True)
    assert (q.getSize(), lam.getSize(), lam0.getSize()) == (q0.getSize(), 18, 0)
    K, K0 = A.createSubMatrix(q, q), A0.createSubMatrix(q0, q0)
    K.axpy(-1.0, K0, PETSc.Mat.Structure.DIFFERENT_NONZERO_PATTERN)
    assert K.norm(PETSc.NormType.FROBENIUS) <= 1e-12 * K0.norm(PETSc.NormType.FROBENIUS)
    B = A.createSubMatrix(lam, q)
    counts = [np.count_nonzero(B.getRow(i)[1]) for i in range(*B.getOwnershipRange())]
    assert MPI.COMM_WORLD.allreduce(counts) == [1] * 18
