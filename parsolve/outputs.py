"""What a finished step writes: every field by its output name, each effect's own outputs
(stresses, fluxes, history variables), every relation's multiplier, primal value, active rows
and resultant, and for transient runs the balance of each conserved field.

Per-cell values stay on the rank that owns the cell, nodal averages on the rank that owns the
node (sums over its local cells, complete on its owned nodes, divided by the summed weights):
the result writer places every rank's rows (parsolve.io)."""

from __future__ import annotations

import numpy as np
from mpi4py import MPI

from parsolve.io.slabs import OwnedRows


def vector_field(fields):
    """The field whose components are the axes of space (the displacement: its reactions
    have moments), or None: known from the fields' own components, not from a name."""
    return next((f for f in fields if not f.scalar), None)


def resultant(relation, lam: np.ndarray, fields, points) -> np.ndarray:
    """Sum of the reactions D λ per node DOF column (every field's components), then, for a
    model with a displacement field, their moment about the origin (z in 2D; x, y, z in 3D).
    ``points``: the coordinates of the relation's nodes by id (an array, or a function of the
    ids)."""
    dofs, force = relation.reaction(lam)
    ncomp = fields.ncomp
    out = np.bincount(dofs % ncomp, weights=force, minlength=ncomp)
    mech = vector_field(fields)
    if mech is None:
        return out
    cols = fields.columns(mech.name)
    node, col = np.divmod(dofs, ncomp)
    dim = cols.size
    f = np.zeros((force.size, 3))
    x = np.zeros((force.size, 3))
    on_u = np.isin(col, cols)
    f[on_u, col[on_u] - cols[0]] = force[on_u]
    x[:, :dim] = points(node) if callable(points) else points[node]
    moment = np.cross(x, f).sum(axis=0)
    return np.concatenate([out, moment[2:] if dim == 2 else moment])


def resultant_labels(fields, dim: int) -> list[str]:
    """Names of the columns of /relations/<name>/resultant: the node DOF columns (x, y, z of
    the displacement; a scalar field by its name), then the moments."""
    labels = []
    for f in fields:
        labels += [f.name] * f.ncomp if f.scalar else list(f.components)
    if vector_field(fields) is not None:
        labels += ["mz"] if dim == 2 else ["mx", "my", "mz"]
    return labels


def labelled(labels: list[str], values) -> str:
    """``fx 10000  fy 0  mz -500``: a resultant's values by component (the displacement's
    forces fx, fy, fz and the moments mx, my, mz; a scalar field's reaction by its name)."""
    names = [f"f{c}" if c in ("x", "y", "z") else c for c in labels]
    return "  ".join(f"{n} {v:.6g}" for n, v in zip(names, values))


def resultant_line(name: str, labels: list[str], values) -> str:
    """A relation's resultant on the step's log line, with its components named."""
    about = " (moments about the origin)" if {"mx", "my", "mz"} & set(labels) else ""
    return f"{name}: resultant {labelled(labels, values)}{about}"


STATES = ("open", "stick", "slip")   # the values 0, 1, 2 of /fields/<contact>_state


def contact_totals(comm: MPI.Comm, name: str, fields: dict, rel_out: dict) -> dict:
    """One step's totals of contact ``name`` over the whole surface, the same on every rank
    (collective): ΣRn, ΣRt (the vector in the tangent basis), |ΣRt|/ΣRn and the counts of
    its open / stick / slip rows, from what the step writes (/relations/<name>_normal/
    normal_force and tangential_force where the relations form has them, else the sums of
    /fields/<name>_normal_reaction and _tangential_reaction; /fields/<name>_state)."""
    extras = rel_out.get(f"{name}_normal", {})
    state = fields[f"{name}_state"].values.ravel()
    counts = np.bincount(state[state >= 0].astype(np.int64), minlength=len(STATES))[:len(STATES)]
    local = [counts.astype(float)]
    if "normal_force" not in extras:
        local += [fields[f"{name}_normal_reaction"].values.sum(axis=0),
                  fields[f"{name}_tangential_reaction"].values.sum(axis=0)]
    total = comm.allreduce(np.concatenate(local), op=MPI.SUM)
    counts = total[:len(STATES)].astype(int)
    if "normal_force" in extras:
        rn, rt = float(extras["normal_force"][0]), np.atleast_1d(extras["tangential_force"])
    else:
        rn, rt = float(total[len(STATES)]), total[len(STATES) + 1:]
    norm_t = float(np.linalg.norm(rt))
    return {"normal": rn, "tangential": rt, "ratio": norm_t / rn if rn > 0 else float("nan"),
            **dict(zip(STATES, counts.tolist()))}


def contact_line(name: str, totals: dict) -> str:
    rt = totals["tangential"]
    return (f"{name}: ΣRn {totals['normal']:.6g}  ΣRt {' '.join(f'{v:.6g}' for v in rt)}  "
            f"|ΣRt|/ΣRn {totals['ratio']:.6g}  rows open {totals['open']}, stick "
            f"{totals['stick']}, slip {totals['slip']}")


def step_outputs(comm: MPI.Comm, ctx, q: np.ndarray, multipliers: dict, newton=None):
    """(fields, cell fields, relations) of a step; ``ctx``: the step context
    (``parsolve.solvers.context``); ``newton`` carries the material states."""
    values = ctx.values(q)
    # owned nodes first: this rank's rows, in increasing input id
    n_owned = ctx.mesh.n_owned
    fields = {f.output: OwnedRows(values[f.name][:n_owned]) for f in ctx.fields}
    # every local cell: the sums on owned nodes are then complete, no exchange
    computed, keep = ctx.cells, ctx.reported
    cell_fields = {}
    for k, effect in enumerate(ctx.effects):
        extra = None
        if newton is not None and newton.extras[k] is not None:
            extra = (newton.extras[k], newton.states[k])
        nodal, cells = effect.outputs(computed, values, extra, ctx.cells)
        for name, (sums, weights) in nodal.items():  # each rank its owned nodes' averages
            sums, weights = sums[:n_owned], weights[:n_owned]
            fields[name] = OwnedRows(sums / np.maximum(weights, 1e-300)[:, None])
        for name, value in cells.items():  # owned cells, in increasing id: the writer places them
            value = np.asarray(value, dtype=float)
            cell_fields[name] = OwnedRows(value[keep])
    rel_out = {}
    active = newton.enforced if newton is not None else None
    for r in ctx.all_relations:   # (a relation built per rank: every row gathered, collective)
        lam = multipliers[r.name]
        total = resultant(r, lam, ctx.fields, ctx.dofs.input_points)
        rel_out[r.name] = {"multiplier": every_row(comm, r, lam),
                           "primal": every_row(comm, r, ctx.relation_primal(r, q)),
                           "resultant": total if r.complete else comm.allreduce(total, op=MPI.SUM)}
    views = ctx.views(active) if active is not None else {}
    for r in ctx.all_relations:
        if r.sense != "=":
            rel_out[r.name]["active"] = every_row(comm, r, views[r.name]).astype(np.int8)
    if active is not None:  # switched relations' outputs: solubility states, contact
        for effect in ctx.effects:
            nodal, per_relation = effect.step_outputs(q, multipliers, views)
            fields.update(nodal)
            for name, values in per_relation.items():
                rel_out[name].update(values)
    return fields, cell_fields, rel_out


def every_row(comm: MPI.Comm, relation, values: np.ndarray) -> np.ndarray:
    """A relation's per-row values over every row from the rows held here: a relation built
    per rank's gathered from each row's rank (one reduction of its size: the written
    steps' outputs only); a whole relation's as they are. Collective."""
    if relation.whole:
        return values
    out = np.zeros(relation.total)
    out[relation.ids] = values
    comm.Allreduce(MPI.IN_PLACE, out, op=MPI.SUM)
    return out


class Balance:
    """Conservation of every field that has a capacity (transient runs): storage ∫ c, and the
    supply since the start from the known loads (sources, boundary fluxes) and from the
    relations' reactions; error = storage − initial storage − supplied, per field and in all."""

    def __init__(self, comm, ctx, q0: np.ndarray):
        self.comm, self.ctx, self.q0 = comm, ctx, q0
        fields = ctx.fields
        self.names = sorted(ctx.composition.rate_fields())
        self.owned = {n: ctx.dofs.field_dofs(fields.columns(n)) for n in self.names}
        self.ncomp = fields.ncomp
        self.cols = {n: fields.columns(n) for n in self.names}
        self.initial = None
        self.supplied = {n: 0.0 for n in self.names}

    def storage(self, q: np.ndarray) -> dict[str, float]:
        m = self.ctx.composition.product(self.ctx.composition.mass_parts(), q)
        return {n: self.comm.allreduce(float(m[self.owned[n]].sum())) for n in self.names}

    def step(self, q: np.ndarray, dt: float, f_known: np.ndarray, multipliers: dict) -> dict:
        """Datasets of one step: /balance/<field>/{storage, sources, reactions, supplied,
        error} (sources and reactions: what came in since the start through the known loads
        and through the relations' reactions — boundary fluxes, phase exchange)."""
        if self.initial is None:
            self.initial = self.storage(self.q0)
            self.previous = dict(self.initial)
            self.sources = {n: 0.0 for n in self.names}
            self.reacted = {n: 0.0 for n in self.names}
        stored = self.storage(q)
        out = {}
        step_total = 0.0
        for n in self.names:
            step_sources = dt * self.comm.allreduce(float(f_known[self.owned[n]].sum()))
            step_reactions = dt * self._reactions(n, multipliers)
            self.sources[n] += step_sources
            self.reacted[n] += step_reactions
            self.supplied[n] = self.sources[n] + self.reacted[n]
            # this step's own closure (the error above accumulates the steps' round-off)
            step_error = stored[n] - self.previous[n] - step_sources - step_reactions
            out[f"balance/{n}/step_error"] = step_error
            step_total += step_error
            out[f"balance/{n}/storage"] = stored[n]
            out[f"balance/{n}/sources"] = self.sources[n]
            out[f"balance/{n}/reactions"] = self.reacted[n]
            out[f"balance/{n}/supplied"] = self.supplied[n]
            out[f"balance/{n}/error"] = stored[n] - self.initial[n] - self.supplied[n]
        self.previous = stored
        total = sum(stored.values())
        out["balance/total/step_error"] = step_total
        out["balance/total/storage"] = total
        out["balance/total/error"] = total - sum(self.initial.values()) - sum(self.supplied.values())
        return out

    def _reactions(self, name: str, multipliers: dict) -> float:
        """Σ of the reactions D λ of every relation on a field's equations."""
        total, own = 0.0, 0.0   # (a relation built per rank: its rows' sum over the ranks)
        for r in self.ctx.all_relations:
            dofs, force = r.reaction(multipliers[r.name])
            part = float(force[np.isin(dofs % self.ncomp, self.cols[name])].sum())
            if r.complete:
                total += part
            else:
                own += part
        if any(not r.complete for r in self.ctx.all_relations):
            total += self.comm.allreduce(own)
        return total


def progress(log, comm, step: int, total, t: float, iterations: int, residual: float,
             seconds: float, extra: str = "") -> None:
    if comm.rank == 0:
        log(f"step {step}/{total}  t={t:.6g}  iterations={iterations}  residual={residual:.2e}  "
            f"{seconds:.3f} s{extra}")
