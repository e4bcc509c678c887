"""Gas solubility (the paper's fourth use): a species dissolved (c_s) and gaseous (c_g), two
scalar fields declared by their own diffusion effects, and a saturation limit c_sat.

At every node exactly one of two relations holds: below saturation c_g = 0, at saturation
c_s = c_sat. Both are non-associated with the same dual, equal and opposite reactions on the
two fields' equations (−r on c_s, +r on c_g: r is the rate at which dissolved matter turns
into gas), so a reaction never changes c_s + c_g and mass is conserved exactly. Written as
one relation of two unilateral rows per node forming a group of which exactly one row is
enforced (the active-set machinery's maximum group, as for maximum control):

    row 2k:     −c_g ≤ 0          (enforced: dissolved state, c_g = 0)
    row 2k + 1:  c_s ≤ c_sat      (enforced: saturated state, c_s = c_sat)

the enforced row is the one with the larger left-hand side minus value, i.e. the group
enforces max(−c_g, c_s − c_sat) = 0, which is the complementarity min(c_g, c_sat − c_s) = 0.
The switch on loading (saturation reached: the gas appears) and on unloading (gas exhausted:
c_s is free again) is the active set's, not special code.

Scene schema::

    [solubility]
    dissolved = "c_s"         # a diffusion field
    gas = "c_g"               # another diffusion field (conductivity 0: immobile gas)
    saturation = 1.0          # c_sat: a number or an expression of x, y, z
    evolution = "constant"    # how c_sat follows t (default constant)
    [[solubility.regions]]    # optional: c_sat per region (later entries override)
    region = "zone"
    saturation = 0.5
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from parsolve.collective import agree
from parsolve.effects.base import Effect
from parsolve.errors import InputError
from parsolve.io.slabs import OwnedRows
from parsolve.mesh import selectors
from parsolve.relation_kinds.spread import places
from parsolve.relations import Relation, rows_here


@dataclass
class SolubilitySpec:
    dissolved: str
    gas: str
    saturation: list[tuple[str, float | str, str]]   # (region, value or expression, key)
    evolution: str
    key: str


def parse(t) -> SolubilitySpec:
    dissolved = t.get("dissolved", str, "c_s")
    gas = t.get("gas", str, "c_g")
    if dissolved == gas:
        raise t.error("gas", "the gas and the dissolved phase must be two fields")
    levels = [("all", _saturation(t), t.key("saturation"))]
    for sub in t.tables("regions"):
        levels.append((sub.get("region", str), _saturation(sub), sub.key("saturation")))
        sub.done()
    evolution = t.get("evolution", str, "constant")
    t.done()
    return SolubilitySpec(dissolved, gas, levels, evolution, t.path)


def _saturation(t) -> float | str:
    value = t.get("saturation", (float, str))
    if isinstance(value, float) and not value > 0:
        raise t.error("saturation", "c_sat must be positive")
    return value


class Solubility(Effect):
    """Each rank (its ``LocalMesh``) knows c_sat on its owned nodes only and builds those
    nodes' rows alone (``Relation.ids``): a node's two rows are rows 2p and 2p + 1 of the
    whole relation, p its place among every node with a c_sat in input order, so that
    outputs and answers keep the one-rank order; its group and dual are the rank's own."""

    name = "solubility"
    symmetric = False

    def __init__(self, spec: SolubilitySpec, mesh, regions, fields, evolutions, source: str):
        self.spec, self.mesh, self.fields_, self.source = spec, mesh, fields, source
        for key, name in (("dissolved", spec.dissolved), ("gas", spec.gas)):
            if name not in fields or not fields[name].scalar:
                raise InputError(f"names no scalar diffusion field: {name!r} (fields: "
                                 f"{', '.join(fields.names())})", source, f"{spec.key}.{key}")
        self.comm = regions.comm
        self.c_sat = self._levels(regions)
        self.nodes, self.saturation = self._relation_nodes()
        self.evolution = evolutions[spec.evolution]

    @property
    def n_nodes(self) -> int:
        """The nodes this rank gives c_sat: its owned nodes."""
        return self.mesh.n_owned

    def _levels(self, regions) -> np.ndarray:
        """c_sat at every node of ``n_nodes`` (later region entries override earlier ones)."""
        n = self.n_nodes
        # every region first (collective on a part), then the values (this rank's points alone)
        nodes = [regions(region, key.rsplit(".", 1)[0] + ".region").nodes
                 for region, _, key in self.spec.saturation]
        nodes = [k[k < n] for k in nodes]
        return agree(self.comm, self._fill, nodes)   # an error on one part: on every rank

    def _fill(self, nodes: list[np.ndarray]) -> np.ndarray:
        c_sat = np.full(self.n_nodes, np.nan)
        for at, (_, value, key) in zip(nodes, self.spec.saturation):
            if isinstance(value, str):
                value = selectors.evaluate_value(value, self.mesh.points[at], self.source, key)
                if not np.all(np.isfinite(value) & (value > 0)):
                    raise InputError("c_sat must be finite and positive at every node", self.source, key)
            c_sat[at] = value
        return c_sat

    def _relation_nodes(self) -> tuple[np.ndarray, np.ndarray]:
        """(input ids of this rank's owned nodes with a c_sat, increasing; their c_sat)."""
        has = np.flatnonzero(np.isfinite(self.c_sat))
        ids = self.mesh.global_nodes[has].astype(np.int64)
        order = np.argsort(ids)
        return ids[order], self.c_sat[has][order]

    def relations(self) -> list[Relation]:
        nodes = self.nodes
        n = nodes.size
        f = self.fields_
        # input DOFs: DOF numbers of input node ids (fields.dofs is node · ncomp + column)
        gas, dis = f.dofs(self.spec.gas, nodes)[:, 0], f.dofs(self.spec.dissolved, nodes)[:, 0]
        rows = np.arange(2 * n)
        a_dofs = np.stack([gas, dis], 1).ravel()
        a_vals = np.tile([-1.0, 1.0], n)
        values = np.stack([np.zeros(n), self.saturation], 1).ravel()
        # both rows of a node share the dual: -1 on c_s, +1 on c_g
        d_dofs = np.stack([dis, gas, dis, gas], 1).ravel()
        d_rows = np.repeat(rows, 2)
        d_vals = np.tile([-1.0, 1.0], 2 * n)
        rel = Relation("solubility", 2 * n, rows, a_dofs, a_vals, values, self.evolution, "<=",
                       (d_dofs, d_rows, d_vals), eliminate=False)
        rel.groups = np.repeat(np.arange(n), 2)
        rel.meta = {"type": "solubility", "key": self.spec.key, "dual": None, "nodes": nodes}
        # the node's place among every rank's (one exchange): its rows' global numbers
        place = places(self.comm, nodes, int(self.mesh.num_global_points))
        total = self.comm.allreduce(n) if self.comm.size > 1 else n
        return [rows_here(rel, (2 * place[:, None] + np.arange(2)).ravel(), 2 * total)]

    def output_names(self) -> list[str]:
        return ["solubility_state"]

    def step_outputs(self, q: np.ndarray, lam: dict, active: dict) -> tuple[dict, dict]:
        """/fields/solubility_state per node: 0 dissolved, 1 saturated (no c_sat: -1). On a
        part: its owned nodes' rows (its relation rows, in increasing input id), for the
        writer to place."""
        out = np.full(self.n_nodes, -1, dtype=np.int8)
        has = np.flatnonzero(np.isfinite(self.c_sat))
        saturated = active["solubility"].reshape(-1, 2)[:, 1]   # per relation node
        out[has] = saturated[np.searchsorted(self.nodes, self.mesh.global_nodes[has])]
        return {"solubility_state": OwnedRows(out[:, None])}, {}
