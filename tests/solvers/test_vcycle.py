"""The condensed preconditioner's AMG V-cycle (solvers.vcycle): GAMG with SOR on its finest
level, its Galerkin product scoped to its set-up, and its coarse hierarchy kept across
set-ups while it serves — the finest level on the matrix's current values, the coarse
operators those of the set-up that made them."""

from contextlib import contextmanager

import numpy as np
from petsc4py import PETSc

from conftest import run_scene, solve_in_process
from helpers.scene import scene, shipped
from solvers.test_iterative_scenes import assert_same_answers
from parsolve.solvers import options as opt
from parsolve.solvers import vcycle
from parsolve.solvers.vcycle import (FINE_SWEEPS, REUSE_GROWTH, TIED_SWEEPS, VCycle,
                                     _products_freed)


def _friction(comm, petsc: dict | None = None):
    text = scene(shipped("contact_friction_3d.toml"), steps={"count": 1},
                 solver={"preset": "iterative", "petsc": petsc or {}})
    return solve_in_process(text, comm, options={})


def _laplacian(comm, n: int = 12) -> PETSc.Mat:
    """The 7-point Laplacian on an n³ grid (Dirichlet), rows split over the ranks."""
    N = n ** 3
    A = PETSc.Mat().createAIJ(size=((PETSc.DECIDE, N), (PETSc.DECIDE, N)), nnz=(7, 6),
                              comm=comm)
    r0, r1 = A.getOwnershipRange()
    rows = np.arange(r0, r1, dtype=np.int32)
    i, j, k = rows % n, (rows // n) % n, rows // n ** 2
    cols, vals = [rows], [np.full(rows.size, 6.0)]
    for d, (c, step) in enumerate(((i, 1), (j, n), (k, n * n))):
        for s in (-1, 1):
            ok = (c + s >= 0) & (c + s < n)
            cols.append(np.where(ok, rows + s * step, -1))
            vals.append(np.full(rows.size, -1.0))
    cols, vals = np.stack(cols, axis=1), np.stack(vals, axis=1)
    indptr = np.arange(0, 7 * rows.size + 1, 7, dtype=np.int32)
    A.setValuesCSR(indptr, cols.ravel().astype(np.int32), vals.ravel(), addv=False)
    A.assemble()
    return A


def _coarse(vc: VCycle) -> np.ndarray:
    """The next-to-finest level's operator (the first Galerkin product), dense on every rank."""
    pc = vc.pc
    C = pc.getMGSmoother(pc.getMGLevels() - 2).getOperators()[0]
    from conftest import dense
    return dense(C, C.getComm().tompi4py())


def _solve_with(vc: VCycle, A: PETSc.Mat, b: PETSc.Vec, its: int) -> None:
    """``its`` applications of the V-cycle (as a Krylov solve of ``its`` iterations would)."""
    y = b.duplicate()
    for _ in range(its):
        vc.apply(b, y)


def test_hierarchy_kept_while_it_serves(comm):
    """Kept: the same matrix, its values changed in place (S scaled by 2), the last solve
    within REUSE_GROWTH of the worst fresh one — the coarse operator stays the first set-up's
    to the bit. Made anew: after a solve of more iterations, the coarse operator is the
    Galerkin product of 2 S: twice the first (GAMG's aggregation and smoothed interpolation
    are invariant to S's scale)."""
    A = _laplacian(comm)
    b = A.createVecLeft()
    b.set(1.0)
    with opt.inserted("vc_", {"pc_type": "gamg", "pc_gamg_threshold": "0"}, record=False):
        vc = VCycle(comm, "vc_")
        vc.set_up(A)
        assert vc.pc.getMGLevels() >= 2 and (vc.made, vc.kept) == (1, 0)
        C0 = _coarse(vc)
        _solve_with(vc, A, b, 8)
        A.scale(2.0)
        vc.set_up(A)                                   # 8 applications ≤ 1.25 × 8: kept
        assert (vc.made, vc.kept) == (1, 1)
        assert np.array_equal(_coarse(vc), C0)
        _solve_with(vc, A, b, int(REUSE_GROWTH * 8))   # 10 ≤ 1.25 × 8: kept
        vc.set_up(A)
        assert (vc.made, vc.kept) == (1, 2)
        _solve_with(vc, A, b, int(REUSE_GROWTH * 8) + 1)   # 11 > 10: made anew
        vc.set_up(A)
        assert (vc.made, vc.kept) == (2, 2)
        assert np.abs(_coarse(vc) - 2 * C0).max() <= 1e-13 * np.abs(C0).max()
        fine = vc.pc.getMGSmoother(vc.pc.getMGLevels() - 1)
        assert fine.getOperators()[0].handle == A.handle   # (S's own values at every apply)


def test_hierarchy_made_anew_for_another_matrix_or_without_reuse(comm):
    """Another matrix (a new handle) makes the hierarchy anew; so does every set-up with
    -<prefix>reuse_growth 0. A kept hierarchy on unchanged values applies as a fresh one."""
    A = _laplacian(comm)
    b, y0, y1 = A.createVecLeft(), A.createVecLeft(), A.createVecLeft()
    b.setRandom()
    with opt.inserted("vc_", {"pc_type": "gamg", "pc_gamg_threshold": "0"}, record=False):
        vc = VCycle(comm, "vc_")
        vc.set_up(A)
        vc.apply(b, y0)
        vc.set_up(A)
        assert (vc.made, vc.kept) == (1, 1)
        vc.apply(b, y1)
        assert np.array_equal(y0.array, y1.array)
        vc.set_up(A.copy())
        assert (vc.made, vc.kept) == (2, 1)
    with opt.inserted("vc_", {"pc_type": "gamg", "reuse_growth": "0"}, record=False):
        vc = VCycle(comm, "vc_")
        for _ in range(3):
            vc.set_up(A)
            vc.apply(b, y0)
        assert (vc.made, vc.kept) == (3, 0)


def test_kept_hierarchy_gives_the_same_newton_run(comm, shared_tmp, monkeypatch):
    """The friction box's first two steps on the iterative preset: the V-cycle made at the
    first set-up and kept through the Newton iterations gives the run with the hierarchy made
    at every set-up (-condensed_reuse_growth 0): the same Newton iterations and active rows,
    the same answers to 1e-10 of their scale (GMRES runs on M itself)."""
    made: list[VCycle] = []
    init = VCycle.__init__

    def recorded(self, *args, **kwargs):
        init(self, *args, **kwargs)
        made.append(self)

    monkeypatch.setattr(VCycle, "__init__", recorded)
    text = scene(shipped("contact_friction_3d.toml"), steps={"count": 2, "end": 0.25})
    runs = {}
    for name, petsc in (("kept", {}), ("fresh", {"condensed_reuse_growth": "0"})):
        made.clear()
        runs[name] = run_scene(text, shared_tmp / f"{name}.h5", comm, options=petsc,
                               solver={"preset": "iterative"})
        counts = (sum(v.made for v in made), sum(v.kept for v in made))
        runs[name + " counts"] = counts
    solves = sum(runs["fresh counts"])
    assert runs["fresh counts"][1] == 0 and solves >= 10
    assert runs["kept counts"][0] < solves / 2 and sum(runs["kept counts"]) == solves
    assert_same_answers(runs["kept"], runs["fresh"], tol=1e-10)


def test_fine_level_smoothed_by_sor(comm):
    """The V-cycle on S is GAMG whose finest level takes FINE_SWEEPS SOR sweeps (Richardson),
    its coarser levels GAMG's Chebyshev; -condensed_fine_sweeps sets the sweeps."""
    for petsc, sweeps in (({}, FINE_SWEEPS), ({"condensed_fine_sweeps": "3"}, 3)):
        system, solver, mat, rhs, x = _friction(comm, petsc)
        amg = solver.condensed.amg.pc
        assert amg.getType() == "gamg" and amg.getMGLevels() >= 2
        fine = amg.getMGSmoother(amg.getMGLevels() - 1)
        assert (fine.getType(), fine.getPC().getType()) == ("richardson", "sor")
        assert fine.getTolerances()[3] == sweeps
        coarse = amg.getMGSmoother(amg.getMGLevels() - 2)
        assert amg.getMGLevels() == 2 or coarse.getType() == "chebyshev"


def test_preset_sweeps_give_the_direct_answers(comm, shared_tmp):
    """The friction box's first two steps on the iterative preset (FINE_SWEEPS on the finest
    level) and with twice the sweeps: the direct preset's Newton iterations and answers (1e-8
    of their scale): GMRES runs on M itself, the smoother changes its iterations only."""
    text = scene(shipped("contact_friction_3d.toml"), steps={"count": 2, "end": 0.25})
    direct = run_scene(text, shared_tmp / "direct.h5", comm, solver={"preset": "direct"})
    for sweeps in (FINE_SWEEPS, 2 * FINE_SWEEPS):
        run = run_scene(text, shared_tmp / f"sweeps{sweeps}.h5", comm,
                        options={"condensed_fine_sweeps": str(sweeps)},
                        solver={"preset": "iterative"})
        assert_same_answers(run, direct, tol=1e-8)


def test_tied_rows_take_more_fine_sweeps(comm):
    """S with tied rows (the coarsened mortar sphere's dual mortar rows: S = G K H) takes
    TIED_SWEEPS on its finest level, the nodal friction box FINE_SWEEPS;
    -condensed_fine_sweeps sets both."""
    assert TIED_SWEEPS > FINE_SWEEPS
    for petsc, tied, nodal in (({}, TIED_SWEEPS, FINE_SWEEPS),
                               ({"condensed_fine_sweeps": "5"}, 5, 5)):
        mortar = scene(shipped("contact_mortar_sphere_3d.toml"),
                       solver={"preset": "iterative", "petsc": petsc},
                       mesh={"n_fine": 4, "n_coarse": 2, "n_depth": 3})
        found = {}
        for name in ("tied", "nodal"):
            if name == "nodal":
                solver = _friction(comm, petsc)[1]
            else:
                solver = solve_in_process(mortar, comm, options={})[1]
            pre = solver.condensed
            assert solver.choice == "condensed" and (pre.G is not None) == (name == "tied")
            amg = pre.amg.pc
            found[name] = amg.getMGSmoother(amg.getMGLevels() - 1).getTolerances()[3]
        assert found == {"tied": tied, "nodal": nodal}


def test_galerkin_products_freed_in_scope(comm):
    """The V-cycle's set-up puts -mat_product_clear (and -matptap_via allatonce when asked)
    in PETSc's options only while it runs, and leaves a value the user gave as it is; the
    friction box's solve leaves none behind. One process's product takes no "allatonce"
    (its set-up would fail: solvers.options.DISTRIBUTED_PTAP): left out there."""
    options = PETSc.Options()
    with _products_freed(allatonce=True):
        assert options.getBool("mat_product_clear", False)
        if comm.size > 1:
            assert options.getString("matptap_via") == "allatonce"
        else:
            assert not options.hasName("matptap_via")
    assert not options.hasName("mat_product_clear") and not options.hasName("matptap_via")
    options["mat_product_clear"] = "false"
    options["matptap_via"] = "nonscalable"
    try:
        with _products_freed(allatonce=True):
            assert options.getString("mat_product_clear") == "false"
            assert options.getString("matptap_via") == "nonscalable"
        assert options.getString("mat_product_clear") == "false"
        assert opt.product_clear() is False
    finally:
        options.delValue("mat_product_clear")
        options.delValue("matptap_via")
    assert opt.product_clear() is None
    _friction(comm)
    assert not options.hasName("mat_product_clear") and not options.hasName("matptap_via")


def test_allatonce_products_from_a_size_reach_petsc(comm, monkeypatch):
    """From ALLATONCE_ROWS rows of S on several ranks, the set-up's Galerkin products are
    asked for "allatonce", and PETSc reads that option (PetscOptionsUsed while it is in);
    below, or on one rank, not. The hierarchy's V-cycle is the default product's to
    round-off."""
    A = _laplacian(comm)
    b = A.createVecLeft()
    b.setRandom()
    read: list[bool] = []
    freed = vcycle._products_freed

    @contextmanager
    def watched(allatonce: bool = False):
        with freed(allatonce):
            yield
            read.append(PETSc.Options().hasName("matptap_via") and opt._was_used("matptap_via"))

    monkeypatch.setattr(vcycle, "_products_freed", watched)
    ys = {}
    for name, rows in (("default", A.getSize()[0] + 1), ("allatonce", A.getSize()[0])):
        monkeypatch.setattr(vcycle, "ALLATONCE_ROWS", rows)
        with opt.inserted(name + "_", {"pc_type": "gamg", "pc_gamg_threshold": "0"},
                          record=False):
            vc = VCycle(comm, name + "_")
            vc.set_up(A)
            y = b.duplicate()
            vc.apply(b, y)
            ys[name] = y.array.copy()
    assert read == [False, comm.size > 1]
    np.testing.assert_allclose(ys["allatonce"], ys["default"], rtol=0,
                               atol=1e-12 * np.abs(ys["default"]).max())


def test_freed_products_give_the_same_hierarchy(comm):
    """The coarse operators made with the products' intermediates freed equal those made
    with them kept (-mat_product_clear false) and Pᵀ A P computed apart (dense), to
    round-off; so do the V-cycle's applications, on the first set-up and on one made anew on
    new values (S scaled by 3: a new product, not the freed one's reuse)."""
    from conftest import dense
    A = _laplacian(comm)
    b = A.createVecLeft()
    b.setRandom()
    out = {}
    for name, extra in (("freed", {}), ("kept", {"mat_product_clear": "false"})):
        B = A.copy()
        with opt.inserted(name + "_", {"pc_type": "gamg", "pc_gamg_threshold": "0",
                                       "reuse_growth": "0", **extra}, record=False):
            vc = VCycle(comm, name + "_")
            ys = []
            for scale in (1.0, 3.0):
                B.scale(scale)
                vc.set_up(B)
                y = b.duplicate()
                vc.apply(b, y)
                ys.append(y.array.copy())
            P = vc.pc.getMGInterpolation(vc.pc.getMGLevels() - 1)
            out[name] = (_coarse(vc), dense(P, comm), dense(B, comm), ys)
    C, P, B, ys = out["freed"]
    # (to round-off, not to the bit: on 3 ranks the product's sums of other ranks' parts
    # follow the messages' arrival, 1e-16 apart between two runs of the same options)
    scale = np.abs(C).max()
    np.testing.assert_allclose(C, out["kept"][0], rtol=0, atol=1e-14 * scale)
    for a, k in zip(ys, out["kept"][3]):
        np.testing.assert_allclose(a, k, rtol=0, atol=1e-13 * np.abs(k).max())
    np.testing.assert_allclose(C, P.T @ B @ P, rtol=0, atol=1e-12 * np.abs(C).max())
