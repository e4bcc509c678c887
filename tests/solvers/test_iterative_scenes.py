"""The iterative preset on every shipped scene: the direct preset's answers (1e-8 of the scale of
each kind of result) and the same global (Newton, active-set) iterations, at 1, 2 and 3 ranks;
its preconditioning matrix (solvers.augmented) entry by entry; right-hand sides of 0 and 1e-40.
"""

import numpy as np
import pytest
from mpi4py import MPI

from conftest import CONFIGS, dense, solve_in_process
from helpers.scene import scene, shipped

#: every shipped scene, at its own size unless coarsened here (CI runs this at 1, 2, 3 ranks)
COARSER = {
    "contact_mortar_sphere_3d.toml": {"mesh": {"n_fine": 8, "n_coarse": 4, "n_depth": 5}},
    "solubility_two_regions.toml": {"mesh": {"nx": 40}},
    "solubility_grow_shrink.toml": {"mesh": {"nx": 40}},
}
#: scenes whose run takes more than a few seconds: the nightly ("slow") run
SLOW = {"contact_ironing_3d.toml"}
SCENES = sorted(p.name for p in CONFIGS.glob("*.toml"))
#: rows chosen among equals: before the bar localizes every cell has the same strain, to
#: round-off, and the maximum control's enforced cell is any of them (the answers are the same;
#: the control force is then on another row: the rows' sum is compared)
TIES = {"localization_bar.toml": ("relations/max_strain/active",
                                  "relations/max_strain/multiplier")}
#: a flux is a gradient: the field's solver error ε shows in it as ε / h. The fin is one cell of
#: 0.01 across (1 / h = 100): measured at 2 ranks, T to 1e-8 of its scale, T_flux to 2.7e-8
GRADIENT = {"fin_convection.toml": 100.0}
#: Scenes solved by secant iterations (a linear rate), which end about their tolerance from
#: equilibrium: a solve's round-off may take one more iteration where the direct run's last
#: residual lay just under it (localization_bar at 3 ranks, step 13: 4 against 3), with
#: the same answers
SECANT = {"localization_bar.toml"}


def _params():
    for name in SCENES:
        marks = [pytest.mark.slow] if name in SLOW else []
        yield pytest.param(name, marks=marks, id=name.removesuffix(".toml"))


def _source(name: str):
    """The shipped file itself (a scene reading a mesh file), or its coarsened text."""
    if name in COARSER:
        return scene(shipped(name), **COARSER[name])
    return CONFIGS / name


def _scale(results: dict, key: str, family: dict, gradient: float = 1.0) -> float:
    """The scale a dataset is compared at: the largest value of its kind in the run (every
    relation's multipliers together, ...); a flux by its field's too (the flux of a uniform
    field is round-off, its scale the field's), times ``gradient`` (1 / the cells' smallest
    size where it amplifies the field's error)."""
    tail = key.rsplit("/", 1)[-1]
    scale = family[tail]
    if tail.endswith("_flux"):
        scale = gradient * max(scale, family.get(tail.removesuffix("_flux"), 0.0))
    return max(scale, 1e-300)


def assert_same_answers(a: dict, b: dict, tol: float = 1e-8, ignore: tuple = (),
                        gradient: float = 1.0) -> None:
    """``a`` (iterative) holds ``b``'s (direct) answers to ``tol`` of their scale, the same
    iterations and the same active rows (``ignore``: keys not compared; ``gradient``: see
    ``_scale``)."""
    assert a["attrs"]["status"] == b["attrs"]["status"] == "complete"
    keys = [k for k in b if k not in ("attrs", "steps/residual") + ignore
            and not k.startswith("timings")
            and not (k.startswith("balance") and k.endswith("error"))]
    assert sorted(keys) == sorted(k for k in a if k in keys)
    family: dict[str, float] = {}
    for k in keys:
        tail = k.rsplit("/", 1)[-1]
        family[tail] = max(family.get(tail, 0.0), float(np.abs(b[k]).max(initial=0.0)))
    for key in keys:
        if key.endswith("/active") or b[key].dtype.kind in "iub":
            assert np.array_equal(a[key], b[key]), key
        else:
            err = np.abs(a[key] - b[key]).max(initial=0.0)
            assert err <= tol * _scale(b, key, family, gradient) + 1e-13, (key, err)


@pytest.mark.parametrize("name", _params())
def test_iterative_preset_gives_the_direct_answers(name, run):
    source = _source(name)
    direct = run(source, name=f"{name}_direct", solver={"preset": "direct"})
    iterative = run(source, name=f"{name}_iterative", solver={"preset": "iterative"})
    extra = iterative["steps/iterations"] - direct["steps/iterations"]
    if name in SECANT:
        assert extra.min() >= 0 and extra.max() <= 1 and extra.sum() <= 1, extra
    else:
        np.testing.assert_array_equal(extra, 0)
    counted = ("steps/iterations",) if name in SECANT else ()   # (compared just above)
    assert_same_answers(iterative, direct, ignore=TIES.get(name, ()) + counted,
                        gradient=GRADIENT.get(name, 1.0))
    for key in (k for k in TIES.get(name, ()) if k.endswith("/multiplier")):
        total = direct[key].sum(axis=1)
        err = np.abs(iterative[key].sum(axis=1) - total).max()
        assert err <= 1e-8 * np.abs(total).max(), (key, err)


@pytest.mark.parametrize("preset", ["direct", "iterative"])
def test_step_unloaded_to_zero_converges_at_once(run, preset):
    """seepage_overflow at t = 3: the pump stops (no flux, no relation active), the head is 0.
    Every force of that step is round-off of the state it started from; measured against
    that state's round-off (not |q|, which the solves shrink to 0 by their accuracy per
    iteration: 12-13 iterations down to right-hand sides of 1e-162, where GMRES failed at 3
    ranks and the step was cut) it converges in one iteration on both presets."""
    res = run(CONFIGS / "seepage_overflow.toml", name=f"seepage_{preset}",
              solver={"preset": preset})
    np.testing.assert_allclose(res["steps/time"], np.arange(1, 9) * 0.5)
    assert res["steps/iterations"][5] == 1
    assert not res["steps/cuts"].any()
    assert np.abs(res["fields/h"][5]).max() <= 1e-13   # h = 0 to round-off of h ~ 1
    # the other steps: the exact line h0 (1 - x/L), h0 = clip(q L / k, -0.5, 1)
    x = res["mesh/points"][:, 0]
    flux = np.interp(res["steps/time"], [0.0, 2.0, 4.0], [0.0, 3.0, -3.0])
    h0 = np.clip(flux / 2.0, -0.5, 1.0)
    np.testing.assert_allclose(res["fields/h"][:, :, 0], h0[:, None] * (1 - x), atol=1e-10)


def test_frictional_contact_of_a_body_held_only_by_contact(run):
    """The 3D friction box: K alone is singular (the top free in z, pressed on the plane), the
    operator is not (contact holds it): the iterative preset converges and slides as the
    direct one does, at every rank count (CI's contact scene on the iterative preset)."""
    text = scene(shipped("contact_friction_3d.toml"), steps={"count": 4})
    direct = run(text, name="friction_direct", solver={"preset": "direct"})
    iterative = run(text, name="friction_iterative", solver={"preset": "iterative"})
    np.testing.assert_array_equal(iterative["steps/iterations"], direct["steps/iterations"])
    assert_same_answers(iterative, direct)
    # the plane carries the whole pressure (p = 10 on 1 x 1), the friction at most mu N
    normal = iterative["relations/base_normal/resultant"]
    tangent = iterative["relations/base_tangent/resultant"]
    np.testing.assert_allclose(normal[:, 2], 10.0, rtol=1e-10)
    friction = np.hypot(*(normal + tangent)[:, :2].T)
    assert np.all(friction <= 0.3 * 10.0 * (1 + 1e-9)) and friction[-1] > 2.5


from parsolve.solvers.augmented import GAMMA_COUPLED  # noqa: E402


def _augmented_expected(system, mat, gamma: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """From the dense operator M: T (the hard rows' equations, times γ/k Aₕᵀ, added to the
    force balance), T M, and P = T M with -k on the diagonal of a row with no sparse Schur
    diagonal."""
    comm = system.comm
    M = dense(mat, comm)
    dm = system.dofmap
    offsets = dm.offsets
    ranks = range(comm.size)
    q = np.concatenate([np.arange(offsets[r], offsets[r] + dm.owned(r)[1] - dm.owned(r)[0])
                        for r in ranks])
    lam = np.setdiff1d(np.arange(M.shape[0]), q)
    active = system.op.active.astype(bool)
    # multiplier rows in saddle order: each rank's owned rows (first among those it holds)
    hard = np.concatenate(comm.allgather(active[:system.relation_set.n_owned]))
    rows = M[np.ix_(lam, q)]
    # a row of one node (at most 3 entries) enters T at γ; one tying several nodes P alone
    nodal = np.count_nonzero(rows, axis=1) <= 3
    T = np.eye(M.shape[0])
    T[np.ix_(q, lam)] = (gamma / system.kscale * (hard & nodal))[None, :] * rows.T
    TM = T @ M   # (C's hard rows included: nothing to add when they are 0, as they must be)
    P = TM.copy()
    coupled = rows * (hard & ~nodal)[:, None]
    P[np.ix_(q, q)] += min(gamma, GAMMA_COUPLED) / system.kscale * coupled.T @ coupled
    schur = np.diag(P)[lam] - np.einsum("ki,ik->k", M[np.ix_(lam, q)] / np.diag(P)[q],
                                        M[np.ix_(q, lam)])
    empty = np.abs(schur) <= 1e-8 * system.kscale
    P[lam[empty], lam[empty]] += -system.kscale
    return T, TM, P


def check_augmented_form(system, mat):
    """The system's augmented form of ``mat`` against the dense products: its operator is T M
    and its preconditioning matrix P, entry by entry. Returns (form, T, TM, P)."""
    from parsolve.solvers.augmented import GAMMA

    form = system.preconditioner(mat, GAMMA)
    T, TM, P = _augmented_expected(system, mat, GAMMA)
    scale = np.abs(TM).max()
    assert np.abs(dense(form.operator, system.comm) - TM).max() <= 1e-12 * scale
    assert np.abs(dense(form.pmat, system.comm) - P).max() <= 1e-12 * scale
    return form, T, TM, P


def test_augmented_form_entry_by_entry(comm):
    """The friction box after a solve with some rows inactive: the KSP's operator is T M (the
    operator plus γ/k Aₕᵀ Aₕ of the enforced hard rows, nothing else), its right-hand side
    T b, from dense products; the KSP's answer solves M x = b."""
    text = scene(shipped("contact_friction_3d.toml"), steps={"count": 1},
                 solver={"preset": "iterative"})
    system, solver, mat, rhs, x = solve_in_process(text, comm, options={})
    active = system.op.active.copy()   # (per held multiplier row: owned, then ghosts)
    active[system.dofmap.l_held % 3 == 0] = False   # some rows switched off, as an active set does
    system.op.active = active
    mat = system.assemble()
    form, T, TM, _ = check_augmented_form(system, mat)
    scale = np.abs(TM).max()
    # the augmentation is there (not the operator alone)
    assert np.abs(TM - dense(mat, comm)).max() > 1e-3 * scale
    b = comm.allgather(rhs.array.copy())
    transformed = rhs.copy()
    form.transform(transformed)
    b, tb = np.concatenate(b), np.concatenate(comm.allgather(transformed.array))
    assert np.abs(tb - T @ b).max() <= 1e-12 * np.abs(T @ b).max()
    # T M x = T b has M x = b's answer
    solver.solve(rhs, x)
    xs = np.concatenate(comm.allgather(x.array))
    reference = np.linalg.solve(dense(mat, comm), b)
    assert np.abs(xs - reference).max() <= 1e-9 * np.abs(reference).max()


@pytest.mark.parametrize("factor", [0.0, 1e-40, 1e-54])
def test_tiny_right_hand_side_is_a_tiny_solution(comm, factor):
    """A Krylov solve of b · 1e-40 is x · 1e-40 (not 0 from GMRES' absolute floors, not a
    failure of the residual check); b = 0 is x = 0."""
    text = scene(shipped("contact_friction_3d.toml"), solver={"preset": "iterative"})
    system, solver, mat, rhs, x = solve_in_process(text, comm)
    reference = x.array.copy()
    rhs.scale(factor)
    y = x.duplicate()
    solver.solve(rhs, y)
    scale = comm.allreduce(np.abs(reference).max(), op=MPI.MAX)
    err = comm.allreduce(np.abs(y.array - factor * reference).max(initial=0.0), op=MPI.MAX)
    assert err <= 1e-9 * factor * scale or (factor == 0.0 and err == 0.0)
    assert solver.residual <= 1e-8
