"""Failures named by their cause: what a step that failed for good says about the run.

A control relation (one whose dual is a load pattern: the load intensity is its multiplier)
can only reach values that some load gives. When the load cannot grow past a bound and the
controlled quantity stops growing with it, no step reaches the next target, however small:
the solve then fails at whatever breaks first (a singular operator once nothing holds the body,
a maximum group's enforced row going back and forth), and that says nothing of the cause.
Two bounds are named. Friction's: every closed node of a frictional contact slides, so the
tangential load is at the friction capacity μN and the body slides as a whole, which moves no
strain. The structure's capacity: a strain control measured on cells that do not soften, in a
model where others do, grows only with the load, which cannot pass the peak the softening
cells set. The controlled value reached, the target and the control load are the last converged
state's (the same on every rank: relation values and multipliers are reduced over ranks, the
contact states are the whole surface's).

A maximum group whose enforced row turns back, within a step, to a row it left is damage
localizing where a material softens (``ActiveSet``'s own message says so); where none does,
it is a target no control load gives, and the failure says that instead.

Two causes hold from the start, each probed with linear solves of the last converged state:
- a single-row control that its own load does not move (A K⁻¹ G = 0, e.g. a mean normal strain
  driven by a shear load, or a displacement the load does not reach): the controlled operator
  is singular; in a linear model no intensity of the load gives another value (the linear
  path's failure comes here too, ``name_linear_failure``);
- at the first step over a frictional contact that the failed attempt left sliding as a whole:
  with the contact stuck the model is linear, and the control load the target takes (a maximum
  group: the loads its rows allow) is one the contact cannot carry, beyond μN.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Callable

import numpy as np
from mpi4py import MPI

from parsolve.contact import friction as fr
from parsolve.errors import SolverError
from parsolve.fem.materials.mazars import Mazars
from parsolve.fem.materials.von_mises import VonMises
from parsolve.relation_kinds.strain import row_cell
from parsolve.solvers.linear import DoesNotFit

# a control's rate under its own load below this fraction of what the load's displacements
# could give through the control's coefficients (Σ|a| max|δq|) is round-off (1e-16 relative),
# not a small stiffness
UNMOVED = 1e-9


class NamedFailure(SolverError):
    """A solver failure whose message names its cause and the way out (no further hints)."""


class GoingBack(SolverError):
    """A maximum group's enforced row would go back, within a step, to a row it left
    (``ActiveSet``): ``relation`` and its rows ``rows`` = (enforced now, the one left)."""

    def __init__(self, message: str, relation: str, rows: tuple[int, int]):
        super().__init__(message)
        self.relation, self.rows = relation, rows


@dataclass
class Control:
    name: str
    maximum: bool
    row: int          # the enforced row (relation rows of the stacked set; -1: on another rank)
    sign: int         # +1 for "<=" and "=", -1 for ">="
    k: int = 0        # its relation (of the multiplied ones)
    number: int = 0   # the enforced row's number in its relation (the same on every rank)


def _controls(problem) -> list[Control]:
    """The control relations with a load as their dual: per maximum group its enforced row
    (held by one rank, the others knowing its number), per single-row equality its row.
    Collective."""
    rset, active = problem.rset, problem.active
    numbers = active.enforced_ids() if active.groups else np.zeros(0, dtype=np.int64)
    out = []
    for k, rel in enumerate(problem.ctx.multiplied):
        if not rel.meta.get("dual"):
            continue
        rows = np.arange(rset.rows_of(k).start, rset.rows_of(k).stop)
        if rel.maximum:
            number = int(numbers[active.group_relations.index(k)])
            if number >= 0:
                at = rows[rel.row_ids() == number]
                out.append(Control(rel.name, True, int(at[0]) if at.size else -1, rel.sign, k,
                                   number))
        elif rel.sense == "=" and rows.size == 1:
            out.append(Control(rel.name, False, int(rows[0]), 1, k, 0))
    return out


def _at_rows(problem, values: np.ndarray, controls: list[Control]) -> np.ndarray:
    """Per control, ``values`` (per relation row held here) at its row: a maximum group's
    from the rank holding its enforced row (one reduction of the controls' number).
    Collective."""
    out = np.array([values[c.row] if c.row >= 0 else 0.0 for c in controls])
    grouped = np.array([c.maximum for c in controls], dtype=bool)
    summed = np.where(grouped, out, 0.0)
    if problem.comm.size > 1:
        problem.comm.Allreduce(MPI.IN_PLACE, summed, op=MPI.SUM)
    return np.where(grouped, summed, out)


def _every(e, x):
    """A contact's sum (or any, of a decision) over its rows on every rank (rows built per
    rank: ``Contact.sum_ranks``); else x."""
    if not hasattr(e, "any_rank"):
        return x
    return e.any_rank(x) if isinstance(x, (bool, np.bool_)) else e.sum_ranks(x)


def _sliding_contacts(effects) -> list:
    """Frictional contacts whose closed nodes all slide at the failed attempt's last iterate,
    having begun to slide at the last converged state (some closed node sliding there): the
    load along the surface had reached the friction capacity, not jumped past it at once (a
    target out of reach from the first step on, which the load did not approach)."""
    out = []
    for e in effects:
        state = getattr(e, "node_state", None)
        committed = getattr(e, "committed", None)
        if state is None or committed is None or not getattr(e, "frictional", False):
            continue
        closed = state != fr.OPEN
        if _every(e, closed.any()) and not _every(e, (state == fr.STICK).any()) \
                and _every(e, (committed[0] == fr.SLIP).any()):
            out.append(e)
    return out


def name_failure(exc: SolverError, problem, t: float) -> SolverError:
    """The final failure of the step to ``t`` (``problem`` back at the last converged state),
    as a ``NamedFailure`` when a control can no longer reach its value; else ``exc``.
    Collective (every rank calls it with the same failure; the decisions before any reduction
    are taken from data every rank holds alike)."""
    if isinstance(exc, DoesNotFit):   # (memory: named already)
        return exc
    try:
        return _named(exc, problem, t)
    except Exception:   # (a diagnostic's own error: the solver's failure is the news)
        return exc


def _named(exc: SolverError, problem, t: float) -> SolverError:
    controls = _controls(problem)
    if not controls:
        return exc
    singles = [c for c in controls if not c.maximum]
    named = _unmoved(exc, problem, t, singles) if singles else None
    if named is not None:
        return named
    if isinstance(exc, GoingBack) and not _softens(problem.ctx.effects):
        return _no_turn_back(exc, problem, t, controls)
    if problem.t_prev > 0.0 and _perfectly_plastic(problem.ctx.effects):
        named = _at_limit_load(exc, problem, t, controls)
        if named is not None:
            return named
    if _softens(problem.ctx.effects):
        return _past_capacity(exc, problem, t, controls)
    if problem.t_prev == 0.0:
        named = _beyond_friction_from_start(exc, problem, t, controls)
        if named is not None:
            return named
    sliding = _sliding_contacts(problem.ctx.effects)
    if not sliding:
        return exc
    short = _short_of(problem, t, controls)
    if short is None:
        return exc
    (c, kind, reached, target, load), contact = short, sliding[0]
    return NamedFailure(
        f"{kind} {c.name!r} can no longer reach its value: {target:.6g} at t = {t:.6g}, where it "
        f"reached {reached:.6g} (t = {problem.t_prev:.6g}, control load {load:.6g}); every closed "
        f"node of contact {contact.spec.name!r} slides, so the control load cannot grow past the "
        f"friction capacity μN (μ = {contact.mu:g}) and the controlled quantity stops growing as "
        f"the body slides; reduce the target (it reached {reached:.6g}) or control a quantity "
        f"that grows as the body slides, such as a displacement (the last attempt: {exc})")


def short_control(problem, t: float) -> tuple | None:
    """``_short_of`` over every control of ``problem``, with the enforced row's cell where the
    relation measures cells row by row: (control, kind, reached, target, load, the enforced
    row in its relation, its cell or None), or None. Collective."""
    short = _short_of(problem, t, _controls(problem))
    if short is None:
        return None
    c = short[0]
    return short + (c.number, row_cell(problem.comm, problem.ctx.multiplied[c.k], c.number))


def _short_of(problem, t: float, controls: list[Control]) -> tuple | None:
    """The first control whose value at t lies beyond what the last converged state reached:
    (control, its kind in words, reached, target, control load), or None. Collective."""
    rset = problem.rset
    values = _at_rows(problem, rset.primal_values(problem.q), controls)
    targets = _at_rows(problem, rset.targets(t), controls)
    loads = _at_rows(problem, rset.every_row(problem.lam), controls)
    short = [j for j, c in enumerate(controls) if c.sign * (targets[j] - values[j]) > 0]
    if not short:
        return None
    j = short[0]
    c = controls[j]
    kind = "maximum control" if c.maximum else "control"
    return c, kind, values[j], targets[j], loads[j]


def _softens(effects) -> bool:
    """Whether a material of the model softens (damage), where a maximum group's enforced row
    may change back and forth as damage localizes."""
    return any(isinstance(m, Mazars) for e in effects for m in getattr(e, "models", []))


def _no_turn_back(exc: GoingBack, problem, t: float, controls: list[Control]) -> SolverError:
    """A maximum group turning back to a row it left, with nothing that softens: the largest
    of the rows, as a function of the control load, is then the upper envelope of rows that
    each grow or fall with it, and turning between two of them (the load that brings one to
    the value takes the other beyond it) is the envelope's lowest point lying above the
    target: no load gives the value."""
    c = next((c for c in controls if c.name == exc.relation), None)
    if c is None:
        return exc
    rset = problem.rset
    reached = float(_at_rows(problem, rset.primal_values(problem.q), [c])[0])
    target = float(_at_rows(problem, rset.targets(t), [c])[0])
    a, b = exc.rows
    return NamedFailure(
        f"maximum control {c.name!r} can no longer reach its value: {target:.6g} at t = {t:.6g} "
        f"(it reached {reached:.6g} at t = {problem.t_prev:.6g}); its rows {a} and {b} take "
        f"turns as the largest (the control load that brings one to the value takes the other "
        f"beyond it) and no material of the scene softens, so no control load gives that value: "
        f"the other loads already take the largest beyond it; raise the target or control "
        f"another quantity")


def _perfectly_plastic(effects) -> bool:
    """Whether a material of the model is perfectly plastic (von Mises, H = 0)."""
    return any(isinstance(m, VonMises) and m.H == 0.0
               for e in effects for m in getattr(e, "models", []))


def _at_limit_load(exc: SolverError, problem, t: float, controls: list[Control]
                   ) -> SolverError | None:
    """A control short of its value where, with the load the step's target takes (one solve
    from the last converged state), the perfectly plastic cells form a mechanism: the tangent
    there, the control released, is singular, while the converged state's is not. The body
    then flows at constant load and cannot carry more than its limit load, and a quantity
    that grows with the load only stops: the last converged control load is that limit, to
    within the last cut of the step. Collective."""
    short = _short_of(problem, t, controls)
    if short is None:
        return None
    c, kind, reached, target, load = short
    lin = problem.form()
    mask = problem.active.active
    try:
        _released(problem, lin.kmat, mask, c)   # (the converged state holds the body)
        dq, _ = _stuck_solve(problem, lin.kmat, mask,
                             lambda: problem.rhs(t, lin.f_int, problem.external(t)))
    except SolverError:
        return None
    system = problem.system
    kmat = system.composition.evaluate(problem.q + dq, problem.states, False, system.rate)[2]
    try:
        _released(problem, kmat, mask, c)
        return None   # (the target's load leaves the body a stiffness: no mechanism)
    except SolverError:
        pass
    return NamedFailure(
        f"{kind} {c.name!r} can no longer reach its value: {target:.6g} at t = {t:.6g}, where it "
        f"reached {reached:.6g} (t = {problem.t_prev:.6g}) with a control load of {load:.6g}; "
        f"with the load the target takes, the perfectly plastic cells (von Mises, H = 0) form a "
        f"mechanism (the tangent there, the control released, is singular): the body flows at "
        f"constant load and carries no more than its limit load, {load:.6g} (the last converged "
        f"control load, to within the last cut step), and the controlled quantity, which grows "
        f"only with the load, stops at {reached:.6g}; bring the target below that, control a "
        f"quantity that grows as the body flows (a displacement of the loaded part), or give the "
        f"material hardening (H > 0) (the last attempt: {exc})")


def _measures_softening(ctx, cells: np.ndarray) -> bool:
    """Whether any of these cells (input ids) has a softening material, on any rank.
    Collective."""
    local = False
    for e in ctx.effects:
        models, cell_model = getattr(e, "models", None), getattr(e, "cell_model", None)
        if models is None or cell_model is None:
            continue
        soft = [i for i, m in enumerate(models) if isinstance(m, Mazars)]
        mine = e.mesh.global_cells[np.isin(cell_model, soft)]
        local = local or bool(np.isin(cells, mine).any())
    return bool(ctx.comm.allreduce(local, op=MPI.LOR))


def _past_capacity(exc: SolverError, problem, t: float, controls: list[Control]) -> SolverError:
    """A strain control whose cells do not soften, in a model where other cells do: the
    measured strain grows only with the load, and the load cannot pass the peak the softening
    cells set (past it they take the deformation and the measured cells unload), so a target
    beyond the strain at the peak has no solution."""
    ctx = problem.ctx
    measured = [c for c in controls if ctx.multiplied[c.k].meta.get("cells") is not None]
    elastic = [c for c in measured if not _measures_softening(
        ctx, np.asarray(ctx.multiplied[c.k].meta["cells"], dtype=np.int64))]
    if not elastic:
        return exc
    short = _short_of(problem, t, elastic)
    if short is None:
        return exc
    c, kind, reached, target, load = short
    return NamedFailure(
        f"{kind} {c.name!r} can no longer reach its value: {target:.6g} at t = {t:.6g}, where it "
        f"reached {reached:.6g} (t = {problem.t_prev:.6g}, control load {load:.6g}); the cells "
        f"it measures do not soften, so their strain grows only with the load, and the load "
        f"cannot pass the structure's capacity, which the softening cells elsewhere set (past "
        f"the peak they take the deformation and the measured cells unload); reduce the target "
        f"(it reached {reached:.6g}) or control a quantity that includes the softening cells "
        f"(the last attempt: {exc})")


def _probe_rows(problem, first: bool) -> np.ndarray:
    """The rows a probe of the last converged state enforces: its active set; at the first
    step (nothing converged yet) the contact rows closed and stuck too, as the step's first
    solve starts them once open rows fail (``close_contact``)."""
    active = problem.active.active.copy()
    if first:
        for k, rel in enumerate(problem.ctx.multiplied):
            if rel.meta.get("type") == "contact":
                active[problem.rset.rows_of(k)] = True
    return active


def _released(problem, kmat, mask: np.ndarray, c: Control) -> np.ndarray:
    """δq under a unit of the control's own load, the control released and the rows
    ``mask`` enforced at zero. Collective."""
    pol = problem.policies
    mask = mask.copy()
    if c.row >= 0:
        mask[c.row] = False
    return problem.respond(kmat, pol.enforceable(mask), pol.dual_column(c.k, c.number))


def _response(problem, kmat, mask: np.ndarray, c: Control) -> tuple[float, float, float]:
    """How a single-row control's quantity answers a unit of its own load, the control
    released and the rows ``mask`` enforced at zero: ``_rate``'s. Collective."""
    dq = _released(problem, kmat, mask, c)
    return _rate(problem.ctx, problem.ctx.multiplied[c.k], 0, dq)


def _rate(ctx, rel, local: int, dq: np.ndarray) -> tuple[float, float, float]:
    """(A δq of the row, max |δq|, Σ|a| max |δq|: what the row could measure of δq).
    Collective."""
    dofmap = ctx.relations.dofmap
    rate = float(dofmap.rows(rel.a_dofs, rel.a_rows, rel.a_vals, rel.nrows, dq)[local])
    largest = ctx.max_abs(dq)
    coefs = dofmap.rows(rel.a_dofs, rel.a_rows, np.abs(rel.a_vals), rel.nrows,
                        np.ones_like(dq))[local]
    return rate, largest, float(coefs) * largest


def _unmoved_message(dual: str, rate: float, largest: float) -> str:
    return (f"a unit of {dual!r} displaces the body by up to {largest:.3g} and changes the "
            f"controlled quantity by {rate:.3g} (round-off)")


def _frictional(effects) -> list:
    return [e for e in effects if getattr(e, "frictional", False)
            and getattr(e, "node_state", None) is not None]


def _unmoved(exc: SolverError, problem, t: float, controls: list[Control]) -> SolverError | None:
    """A single-row control whose quantity its own load does not move (A K⁻¹ G = 0: the
    saddle operator is singular with any tangent that holds the body, e.g. a mean normal
    strain driven by a shear load, which changes it by symmetry not at all, or a
    displacement the load does not reach): Newton from there cannot move it, and where the
    load acts linearly no intensity of it gives another value. Probed at the last converged
    state with one solve (its terms cancel to round-off)."""
    first = problem.t_prev == 0.0
    mask = _probe_rows(problem, first)
    kmat = problem.form().kmat
    stuck = first and _frictional(problem.ctx.effects)
    for c in controls:
        try:
            rate, largest, reach = _response(problem, kmat, mask, c)
        except SolverError:   # (nothing else holds the body: the probe cannot say)
            return None
        if abs(rate) > UNMOVED * reach:
            continue
        rset = problem.rset
        reached = rset.primal_values(problem.q)[c.row]
        target = rset.targets(t)[c.row]
        dual = problem.ctx.multiplied[c.k].meta["dual"]
        where = f"t = {problem.t_prev:.6g}" + (", the contact closed and stuck" if stuck else "")
        return NamedFailure(
            f"control {c.name!r} is not moved by its load {dual!r} at the step's start ({where}): "
            f"{_unmoved_message(dual, rate, largest)}, so the controlled system is singular "
            f"there and the value {target:.6g} at t = {t:.6g} (it is {reached:.6g}) is not "
            f"reached from it; control a quantity that {dual!r} moves, or drive this one with a "
            f"load that moves it (the control's 'dual') (the last attempt: {exc})")
    return None


def _stuck_solve(problem, kmat, mask: np.ndarray, rhs: Callable[[], np.ndarray]) -> tuple:
    """(Δq, λ per relation row) of one linear solve of the operator with the rows ``mask``
    enforced, from the last converged state; ``rhs`` made once the operator is assembled
    with those rows (its enforced rows and its lifting of the eliminated DOFs: an operator
    built anew, a maximum group moved, has none before). Collective."""
    system = problem.system
    system.set_active(problem.policies.enforceable(mask))
    mat = system.assemble(kmat)
    x = problem.solve(mat, rhs(), export=False)
    return x.q, problem.rset.every_row(problem.unscaled(x))


def _stuck_bounds(comm, values: np.ndarray, rates: np.ndarray, targets: np.ndarray,
                  sign: np.ndarray, ids: np.ndarray) -> tuple[int, float, int, float]:
    """The control loads that keep every row of a maximum group on its side of the value,
    the rows being values + load · rates (each rank its rows, numbered ``ids``): (the row
    setting the lowest, the lowest, the row setting the highest, the highest; the lowest
    row number among equal ends); -1 and ±inf where no row bounds that end. Collective."""
    room, slope = sign * (targets - values), sign * rates   # slope · load ≤ room, every row
    with np.errstate(divide="ignore", invalid="ignore"):
        ends = room / slope
    up, down = slope > 0, slope < 0
    big = int(np.iinfo(np.int64).max)
    # per rank: the lowest end of the rising rows, the highest of the falling ones, with
    # their rows' numbers, and whether a row beyond the value no load moves
    hi_end = ends[up].min(initial=np.inf)
    lo_end = ends[down].max(initial=-np.inf)
    mine = (float(hi_end), int(ids[up & (ends == hi_end)].min(initial=big)),
            float(lo_end), int(ids[down & (ends == lo_end)].min(initial=big)),
            bool(((slope == 0) & (room < 0)).any()))
    every = comm.allgather(mine) if comm.size > 1 else [mine]
    hi_end = min(e[0] for e in every)
    hi = min((e[1] for e in every if e[0] == hi_end and e[1] < big), default=-1)
    lo_end = max(e[2] for e in every)
    lo = min((e[3] for e in every if e[2] == lo_end and e[3] < big), default=-1)
    lo, hi = int(lo), int(hi)
    if any(e[4] for e in every):   # a row beyond the value that no load moves
        return lo, np.inf, hi, -np.inf
    return lo, (lo_end if lo >= 0 else -np.inf), hi, (hi_end if hi >= 0 else np.inf)


def _beyond_friction_from_start(exc: SolverError, problem, t: float,
                                controls: list[Control]) -> SolverError | None:
    """The first step of a control (a maximum group: all its rows) over a frictional
    contact whose closed nodes all slide at the failed attempt's last iterate. With the
    contact closed and stuck the model is linear: the controlled rows are their values under
    the other loads plus the control load times their rates (two solves), which gives the
    control load the target takes and the contact reactions with it. Their tangential sum
    beyond the friction capacity μN is a load the contact cannot carry (no state carries
    more than μN along the surface: |Σ rt| ≤ Σ μ rn), and sliding as a whole the body takes
    no more: the target is out of reach from the start."""
    sliding = [e for e in _frictional(problem.ctx.effects)
               if _every(e, (e.node_state != fr.OPEN).any())
               and not _every(e, (e.node_state == fr.STICK).any())]
    if not sliding:
        return None
    rset, mult = problem.rset, problem.ctx.multiplied
    c = controls[0]
    k = c.k
    rows = np.arange(rset.rows_of(k).start, rset.rows_of(k).stop) if c.maximum \
        else np.array([c.row])
    mask = _probe_rows(problem, True)
    mask[rows] = False
    lin = problem.form()
    unit = problem.policies.dual_column(k, c.number)
    dq1, lam1 = _stuck_solve(problem, lin.kmat, mask, lambda: problem.rhs_of(unit))
    dq0, lam0 = _stuck_solve(problem, lin.kmat, mask,
                             lambda: problem.rhs(t, lin.f_int, problem.external(t)))
    values = rset.primal_values(problem.q + dq0)[rows]
    rates = rset.primal_values(dq1)[rows]
    targets, sign = rset.targets(t)[rows], problem.active.sign[rows]
    if c.maximum:
        lo, low, hi, high = _stuck_bounds(problem.comm, values, rates, targets, sign,
                                          mult[k].row_ids())
        if low > high:
            return _stuck_apart(exc, problem, t, c, sliding[0], lam0, (lo, low, hi, high))
        load = float(high if abs(high) < abs(low) else low)
    else:
        load = float((targets[0] - values[0]) / rates[0])
    if not np.isfinite(load):
        return None
    total = lam0 + load * lam1
    lam = {rel.name: total[rset.rows_of(j)] for j, rel in enumerate(mult)}
    for e in sliding:
        rn, rt = e.forces(lam)
        normal = float(_every(e, rn.sum()))
        tangential = float(np.linalg.norm(_every(e, rt.sum(axis=0))))
        capacity = e.mu * normal
        if normal <= 0.0 or tangential <= capacity * (1 + 1e-9):
            continue
        target = float(_at_rows(problem, rset.targets(t), [c])[0])
        kind = "maximum control" if c.maximum else "control"
        nearer = values[0] if not c.maximum else problem.comm.allreduce(
            float(values.max(initial=-np.inf)), op=MPI.MAX)
        return NamedFailure(
            f"{kind} {c.name!r} cannot reach its value from the first step: {target:.6g} at "
            f"t = {t:.6g}; with contact {e.spec.name!r} closed and stuck, that value takes a "
            f"control load of {load:.6g} and a tangential reaction of {tangential:.6g}, "
            f"beyond the friction capacity μN = {capacity:.6g} (μ = {e.mu:g}, N = "
            f"{normal:.6g}): every closed node slides and the body slides as a whole, which "
            f"the control load cannot pass, so the value lies beyond what the load gives; "
            f"bring the target nearer {nearer:.6g} (the "
            f"other loads alone) or raise the friction (the last attempt: {exc})")
    return None


def _stuck_apart(exc: SolverError, problem, t: float, c: Control, contact, lam0: np.ndarray,
                 bounds: tuple) -> SolverError:
    """A maximum group whose rows, the contact stuck, ask for control loads that exclude
    each other; sliding, the contact carries no more than μN."""
    rset = problem.rset
    lo, low, hi, high = bounds
    rn, _ = contact.forces({rel.name: lam0[rset.rows_of(j)]
                            for j, rel in enumerate(problem.ctx.multiplied)})
    normal = float(_every(contact, rn.sum()))
    target = float(_at_rows(problem, rset.targets(t), [c])[0])
    return NamedFailure(
        f"maximum control {c.name!r} cannot reach its value from the first step: {target:.6g} "
        f"at t = {t:.6g}; with contact {contact.spec.name!r} closed and stuck, its row {lo} "
        f"stays on its side of that value only for control loads of at least {low:.6g} and "
        f"its row {hi} only for at most {high:.6g} (the load that brings one there takes the "
        f"other beyond it), and sliding the contact carries no more than μN = "
        f"{contact.mu * normal:.6g} (μ = {contact.mu:g}); raise the target or control "
        f"another quantity (the last attempt: {exc})")


def name_linear_failure(exc: SolverError, system, solver, t: float) -> SolverError:
    """A linear run's failed solve at ``t`` (``system`` and its linear ``solver``), as a
    ``NamedFailure`` when a single-row control is not moved by its own load; else ``exc``.
    Collective."""
    if isinstance(exc, DoesNotFit):
        return exc
    try:
        return _linear_unmoved(exc, system, solver, t) or exc
    except Exception:   # (a diagnostic's own error: the solver's failure is the news)
        return exc


def _linear_solve(system, solver, mask: np.ndarray, f: np.ndarray, t: float | None):
    """q of the linear system with the rows ``mask`` enforced, loaded by ``f``, the
    relations' values and eliminated DOFs' at t (homogeneous without t). Collective."""
    rset = system.context.relations
    system.set_active(mask)
    mat = system.assemble()
    solver.set_operator(mat)
    x, b = mat.createVecs()
    target = np.zeros(rset.n_owned) if t is None else rset.rhs(t)
    elim = np.zeros(system.elim_dofs.size) if t is None else system.elim_values(t)
    b.array[:] = system.rhs_from(f, target, elim)[0]
    solver.solve(b, x)
    return system.gather(x.array).q


def _linear_unmoved(exc: SolverError, system, solver, t: float) -> SolverError | None:
    """In a linear model a control's quantity is A q = A q₀ + λ A K⁻¹ G (q₀: the other loads'
    answer): when A K⁻¹ G = 0 its load does not move it, the saddle operator is singular, and
    no intensity gives a value other than A q₀. (Not for a transient run, whose q₀ carries
    the step's rate terms.)"""
    ctx = system.context
    rset = ctx.relations
    if ctx.transient:
        return None
    for k, rel in enumerate(ctx.multiplied):
        if not rel.meta.get("dual") or rel.maximum or rel.sense != "=" or rel.nrows != 1:
            continue
        row = rset.rows_of(k).start
        mask = np.ones(rset.nrelrows, dtype=bool)
        mask[row] = False
        # (its load pattern: one row, spread when built per rank, ``relation_kinds.build``)
        dq = _linear_solve(system, solver, mask, ctx.local_vector(*rel.shared_dual), None)
        rate, largest, reach = _rate(ctx, rel, 0, dq)
        if abs(rate) > UNMOVED * reach:
            continue
        q0 = _linear_solve(system, solver, mask, ctx.composition.known_loads(t, 0.0, None), t)
        alone = float(rset.primal_values(q0)[row])
        target = float(rset.targets(t)[row])
        dual = rel.meta["dual"]
        return NamedFailure(
            f"control {rel.name!r} is not moved by its load {dual!r}: "
            f"{_unmoved_message(dual, rate, largest)}; the model is linear, so the quantity is "
            f"{alone:.6g} whatever the intensity of {dual!r} (the other loads' answer) and its "
            f"value {target:.6g} at t = {t:.6g} is out of reach; control a quantity that "
            f"{dual!r} moves, or drive this one with a load that moves it (the control's "
            f"'dual') (the solve: {exc})")
    return None
