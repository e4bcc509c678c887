"""PETSc options validation: unknown types, missing values, bad numbers, in the scene or on
the command line, found before anything is solved; options no object used. Any rank count."""

import numpy as np
import pytest
from mpi4py import MPI

from parsolve.errors import InputError
from parsolve.solvers import options as opt
from parsolve.solvers.linear import preset_options

PRESETS = [("direct", True, True), ("direct", False, True), ("iterative", True, True),
           ("iterative", True, False)]


@pytest.mark.parametrize("preset", PRESETS)
def test_presets_and_good_options_pass(preset):
    """Accepted, and PETSc sets up a solver with the layered options (the probe returns 0)."""
    scene, cli = {"ksp_monitor": "", "mat_mumps_icntl_14": "80"}, {"ksp_view": ""}
    assert opt.validate(MPI.COMM_WORLD, "parsolve_", preset_options(*preset), scene, cli,
                        "s.toml") is None
    merged = opt.merge(preset_options(*preset), scene, cli)
    assert merged["mat_mumps_icntl_14"] == "80" and merged["ksp_view"] == ""
    assert opt.probe(MPI.COMM_WORLD, "parsolve_", merged) == 0


@pytest.mark.parametrize("preset", PRESETS)
@pytest.mark.parametrize("scene, cli, source, key, words", [
    ({"pc_type": "nosuch"}, {}, "s.toml", "solver.petsc.pc_type", "unknown type ('nosuch')"),
    ({}, {"ksp_type": "foo"}, "command line", "-ksp_type", "unknown type ('foo')"),
    ({}, {"ksp_rtol": ""}, "command line", "-ksp_rtol", "missing value"),
    ({"ksp_rtol": "abc"}, {}, "s.toml", "solver.petsc.ksp_rtol", "not a valid number ('abc')"),
    ({"ksp_max_it": "1.5"}, {}, "s.toml", "solver.petsc.ksp_max_it", "not a valid integer"),
    ({"ksp_rtol": "1e-6"}, {"ksp_rtol": "nan"}, "command line", "-ksp_rtol", "must be finite"),
    ({"pc_type": "nosuch"}, {"ksp_type": "foo"}, "s.toml", "solver.petsc.pc_type", "unknown type"),
    # parsolve's own options, which no PETSc object of the probe reads
    ({"condensed_fine_sweeps": "abc"}, {}, "s.toml", "solver.petsc.condensed_fine_sweeps",
     "not a valid integer ('abc')"),
    ({"condensed_reuse_growth": "x"}, {}, "s.toml", "solver.petsc.condensed_reuse_growth",
     "not a valid number ('x')"),
    ({}, {"augmented_gamma": "inf"}, "command line", "-augmented_gamma", "must be finite"),
])
def test_bad_options_name_option_and_origin(preset, scene, cli, source, key, words):
    with pytest.raises(InputError) as info:
        opt.validate(MPI.COMM_WORLD, "parsolve_", preset_options(*preset), scene, cli, "s.toml")
    assert (info.value.source, info.value.key) == (source, key)
    assert words in info.value.message


def test_a_good_command_line_value_overrides_a_bad_scene_one():
    """The command line's value is the one PETSc sees (the scene's alone is refused)."""
    preset, scene, cli = preset_options("direct", True, True), {"pc_type": "nosuch"}, \
        {"pc_type": "lu"}
    assert opt.validate(MPI.COMM_WORLD, "parsolve_", preset, scene, cli, "s.toml") is None
    assert opt.merge(preset, scene, cli)["pc_type"] == "lu"
    assert opt.probe(MPI.COMM_WORLD, "parsolve_", opt.merge(preset, scene, cli)) == 0
    assert opt.probe(MPI.COMM_WORLD, "parsolve_", opt.merge(preset, scene)) != 0


def test_missing_value_of_a_type_found_by_petsc():
    """-pc_type with no value is not a flag: PETSc refuses a type 'true', so it was missing."""
    with pytest.raises(InputError, match="missing value") as info:
        opt.validate(MPI.COMM_WORLD, "parsolve_", preset_options("iterative", True, False),
                     {}, {"pc_type": ""}, "s.toml")
    assert info.value.key == "-pc_type"


def test_unused_options():
    """What -options_left would report: options no object read while they were inserted."""
    from petsc4py import PETSc

    comm = MPI.COMM_WORLD
    settings = {"ksp_type": "cg", "ksp_rtol": "1e-6", "nosuch_option": "1"}
    ksp = PETSc.KSP().create(comm)
    ksp.setOptionsPrefix("unusedtest_")
    with opt.inserted("unusedtest_", settings):
        ksp.setFromOptions()
    ksp.destroy()
    assert opt.unused_options("unusedtest_", settings) == ["-unusedtest_nosuch_option"]
    # the validation's probe does not count as a use
    opt.probe(comm, "unusedtest2_", {"nosuch": "1", "ksp_type": "gmres"})
    assert opt.unused_options("unusedtest2_", {"ksp_type": "gmres"}) == ["-unusedtest2_ksp_type"]


def test_iterative_preset_takes_gmres_for_an_unsymmetric_operator():
    # CG on an unsymmetric operator (thermal expansion's (u, T) block) converges to a wrong
    # answer (1e-6 off on configs/thermal_expansion.toml): the preset must not use it
    assert preset_options("iterative", True, False)["ksp_type"] == "cg"
    assert preset_options("iterative", False, False)["ksp_type"] == "gmres"
    # with multipliers: GMRES on the saddle operator (indefinite even when symmetric), one
    # V-cycle on the q block (no inner Krylov method, whatever K's symmetry)
    for symmetric in (True, False):
        saddle = preset_options("iterative", symmetric, True)
        assert saddle["ksp_type"] == "gmres" and saddle["ksp_pc_side"] == "right"
        assert saddle["fieldsplit_q_ksp_type"] == "preonly"


def _laplacian_ksp(comm, prefix: str):
    """CG + GAMG on a 1D Laplacian of 400 rows per rank (coarse levels made by P^T A P)."""
    from petsc4py import PETSc

    n = 400
    A = PETSc.Mat().createAIJ(((n, None), (n, None)), nnz=(3, 2), comm=comm)
    lo, hi = A.getOwnershipRange()
    N = A.getSize()[0]
    for i in range(lo, hi):
        A.setValue(i, i, 2.0)
        for j in (i - 1, i + 1):
            if 0 <= j < N:
                A.setValue(i, j, -1.0)
    A.assemble()
    ksp = PETSc.KSP().create(comm)
    ksp.setOptionsPrefix(prefix)
    ksp.setOperators(A)
    return ksp, A


def _solves_laplacian(comm, prefix: str) -> None:
    """A Laplacian solved with the options under ``prefix``, to 1e-9 of the right-hand side."""
    ksp, A = _laplacian_ksp(comm, prefix)
    ksp.setFromOptions()
    b, x = A.createVecs()
    b.set(1.0)
    ksp.solve(b, x)
    r = b.duplicate()
    A.mult(x, r)
    r.axpy(-1.0, b)
    assert ksp.getConvergedReason() > 0 and r.norm() <= 1e-9 * b.norm()
    ksp.destroy()
    A.destroy()


def test_product_options_reach_the_amg_unprefixed():
    """-matptap_via is read by the AMG's Galerkin products under no prefix: inserted under a
    solver's prefix it would be ignored. A bad value inserted so makes GAMG's set-up fail (so
    PETSc read it); a good one solves, and is recorded as used under the prefixed name."""
    from petsc4py import PETSc

    comm = MPI.COMM_WORLD
    settings = {"ksp_type": "cg", "pc_type": "gamg", "pc_gamg_coarse_eq_limit": "10",
                "ksp_rtol": "1e-10", "ksp_norm_type": "unpreconditioned"}
    db = PETSc.Options()
    with opt.inserted("ptaptest_", {**settings, "matptap_via": "nosuch"}):
        assert db.getString("matptap_via") == "nosuch" and not db.hasName("ptaptest_matptap_via")
        ksp, A = _laplacian_ksp(comm, "ptaptest_")
        ksp.setFromOptions()
        with pytest.raises(PETSc.Error):
            ksp.setUp()
        ksp.destroy()
        A.destroy()
    assert not db.hasName("matptap_via")
    good = "allatonce" if comm.size > 1 else "scalable"   # (no all-at-once on one rank)
    with opt.inserted("ptaptest2_", {**settings, "matptap_via": good}):
        _solves_laplacian(comm, "ptaptest2_")
    assert "-ptaptest2_matptap_via" not in opt.unused_options(
        "ptaptest2_", {**settings, "matptap_via": good})


def test_a_distributed_product_option_on_one_rank_is_left_out():
    """-matptap_via allatonce (the memory-saving choice at several ranks) names no algorithm
    of one process's product: there it is left out, the solve goes on, and it is reported
    unused; at several ranks it is used."""
    comm = MPI.COMM_WORLD
    settings = {"ksp_type": "cg", "pc_type": "gamg", "pc_gamg_coarse_eq_limit": "10",
                "ksp_rtol": "1e-10", "ksp_norm_type": "unpreconditioned",
                "matptap_via": "allatonce"}
    with opt.inserted("ptaptest3_", settings):
        _solves_laplacian(comm, "ptaptest3_")
    unused = "-ptaptest3_matptap_via" in opt.unused_options("ptaptest3_", settings)
    assert unused == (comm.size == 1)



def _laplacian_solution(comm, prefix: str, settings: dict, scale: float = 1.0):
    """x of scale · A x = 1 (the 1D Laplacian) with ``settings`` inserted under ``prefix``, set
    up once on A and again after its values change (a Newton iteration's new tangent)."""
    with opt.inserted(prefix, settings):
        ksp, A = _laplacian_ksp(comm, prefix)
        ksp.setFromOptions()
        b, x = A.createVecs()
        b.set(1.0)
        ksp.solve(b, x)
        first = x.copy()
        A.scale(scale)   # the same pattern, new values: GAMG's hierarchy made again
        ksp.setOperators(A)
        ksp.solve(b, x)
        reasons = (ksp.getConvergedReason(), ksp.getIterationNumber())
    out = first.getArray().copy(), x.getArray().copy(), reasons
    ksp.destroy()
    A.destroy()
    return out


def test_plain_amg_preset_frees_its_galerkin_products():
    """The iterative preset without multipliers frees each coarse operator's P^T A P
    intermediates once it is computed (-mat_product_clear, read under no prefix): the AMG is
    set up, then set up again on new values (its hierarchy made anew, not reused from the
    cleared product), and both solves give what the same options without it give, to
    round-off, in as many iterations."""
    comm = MPI.COMM_WORLD
    preset = preset_options("iterative", True, False)
    assert preset["mat_product_clear"] == "" and "mat_product_clear" in opt.UNPREFIXED
    settings = {**preset, "pc_gamg_coarse_eq_limit": "10"}   # (coarse levels on 400 rows/rank)
    kept = {k: v for k, v in settings.items() if k != "mat_product_clear"}
    x1, x2, (reason, its) = _laplacian_solution(comm, "cleartest_", settings, scale=4.0)
    y1, y2, (reason_kept, its_kept) = _laplacian_solution(comm, "keeptest_", kept, scale=4.0)
    assert reason > 0 and (reason, its) == (reason_kept, its_kept)
    np.testing.assert_allclose(x1, y1, rtol=1e-12, atol=1e-12 * np.abs(y1).max())
    # 4 A x = b: a quarter of the first answer, to the solver's tolerance
    np.testing.assert_allclose(x2, x1 / 4, atol=1e-8 * np.abs(x1).max())
    assert "-cleartest_mat_product_clear" not in opt.unused_options("cleartest_", settings)
