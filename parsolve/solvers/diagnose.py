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
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from mpi4py import MPI

from parsolve.contact import friction as fr
from parsolve.errors import SolverError
from parsolve.fem.materials.mazars import Mazars
from parsolve.solvers.linear import DoesNotFit


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
    row: int          # the enforced row (relation rows of the stacked set)
    sign: int         # +1 for "<=" and "=", -1 for ">="


def _controls(problem) -> list[Control]:
    """The control relations with a load as their dual: per maximum group its enforced row,
    per single-row equality its row."""
    rset, active = problem.rset, problem.active
    out = []
    for k, rel in enumerate(problem.ctx.multiplied):
        if not rel.meta.get("dual"):
            continue
        rows = np.arange(rset.rows_of(k).start, rset.rows_of(k).stop)
        if rel.maximum:
            enforced = rows[active.active[rows]]
            if enforced.size:
                out.append(Control(rel.name, True, int(enforced[0]), int(active.sign[enforced[0]])))
        elif rel.sense == "=" and rows.size == 1:
            out.append(Control(rel.name, False, int(rows[0]), 1))
    return out


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
        if closed.any() and (state[closed] == fr.SLIP).all() and (committed[0] == fr.SLIP).any():
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
    if isinstance(exc, GoingBack) and not _softens(problem.ctx.effects):
        return _no_turn_back(exc, problem, t, controls)
    if _softens(problem.ctx.effects):
        return _past_capacity(exc, problem, t, controls)
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


def _short_of(problem, t: float, controls: list[Control]) -> tuple | None:
    """The first control whose value at t lies beyond what the last converged state reached:
    (control, its kind in words, reached, target, control load), or None. Collective."""
    rset = problem.rset
    values = rset.primal_values(problem.q)
    targets = rset.targets(t)
    loads = rset.every_row(problem.lam)
    short = [c for c in controls if c.sign * (targets[c.row] - values[c.row]) > 0]
    if not short:
        return None
    c = short[0]
    kind = "maximum control" if c.maximum else "control"
    return c, kind, values[c.row], targets[c.row], loads[c.row]


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
    reached = rset.primal_values(problem.q)[c.row]
    target = rset.targets(t)[c.row]
    a, b = exc.rows
    return NamedFailure(
        f"maximum control {c.name!r} can no longer reach its value: {target:.6g} at t = {t:.6g} "
        f"(it reached {reached:.6g} at t = {problem.t_prev:.6g}); its rows {a} and {b} take "
        f"turns as the largest (the control load that brings one to the value takes the other "
        f"beyond it) and no material of the scene softens, so no control load gives that value: "
        f"the other loads already take the largest beyond it; raise the target or control "
        f"another quantity")


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
    ctx, rset = problem.ctx, problem.rset
    measured = [c for c in controls
                if ctx.multiplied[rset.locate(c.row)[0]].meta.get("cells") is not None]
    elastic = [c for c in measured if not _measures_softening(
        ctx, np.asarray(ctx.multiplied[rset.locate(c.row)[0]].meta["cells"], dtype=np.int64))]
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
