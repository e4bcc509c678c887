"""Discrete springs on the displacement: each node of a region to the ground, or each node of
a region to a partner node (of a target region), with a stiffness per global component.

A spring of stiffness K = diag(k_x, k_y(, k_z)) (force per unit displacement: N/m in 3D; in
2D the same, not per unit thickness) adds to the internal forces

    to ground        f_a = K u_a
    node to node     f_a = K (u_a - u_b),  f_b = K (u_b - u_a)

and its (constant, symmetric) blocks to the stiffness: the effect is linear and symmetric,
so an associated-only scene keeps its symmetric factorization.

The springs are one declared term (``Effect.terms``: a node to the ground, or a pair of nodes,
whether or not a cell holds them together): the system adds the tuples to its stiffness
pattern once and gives the term its slots; re-assembly stays a value update. Each rank
declares the springs whose nodes it holds and the rows it does not own fall out of its
pattern, so the ranks' sum is each spring once: the rank owning either node of a pair must
hold the other one too (owned or ghost: the nodes of its cells, always so for nodes of one
cell); a pair split otherwise is an input error (exit 2; e.g. run on fewer ranks).

Pairing (``target``): a target of one node takes every node of the region (a star, e.g. a
region hung from one point); otherwise each region node is paired with the target node at its
position + ``translation`` (default zero: coincident nodes), within the regions' tolerance.

Scene schema (one table per set of springs)::

    [[springs]]
    name = "support"             # optional (default springs0, springs1, ...): the output
    #                              /fields/<name>_force, the force the springs exert on
    #                              each node (zero elsewhere)
    region = "base"              # its nodes, each with its own spring
    stiffness = [0.0, 1e3]       # per component (x, y(, z)), >= 0, not all zero
    target = "pin"               # optional: node to node instead of to the ground
    translation = [0.0, 0.0]     # optional, with target: partner at x + translation
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from parsolve.effects.base import Effect
from parsolve.errors import InputError
from parsolve.fem.element_matrices import Term, TermMatrices
from parsolve.relation_kinds.periodic import partners


@dataclass
class SpringSpec:
    name: str
    region: str
    stiffness: list[float]
    key: str
    target: str | None = None
    translation: list[float] | None = None


def parse(t, dim: int) -> SpringSpec:
    """A ``[[springs]]`` table (a scene Table) → spec; raises the scene's InputError."""
    name = t.get("name", str, t.path.replace("[", "").replace("]", ""))   # springs0, ...
    if not name.isidentifier():
        raise t.error("name", f"a plain name (letters, digits, '_'), not {name!r}")
    region = t.get("region", str)
    stiffness = t.floats("stiffness", dim)
    if any(k < 0 for k in stiffness) or not any(k > 0 for k in stiffness):
        raise t.error("stiffness", "every component must be >= 0 and one at least > 0")
    target = t.get("target", str, None)
    translation = t.floats("translation", dim, None)
    if translation is not None and target is None:
        raise t.error("translation", "a translation pairs nodes with a 'target' region")
    t.done()
    return SpringSpec(name, region, stiffness, t.path, target, translation)


def regions(spec: SpringSpec) -> list[tuple[str, str]]:
    out = [(spec.region, spec.key + ".region")]
    return out + ([(spec.target, spec.key + ".target")] if spec.target is not None else [])


class Springs(Effect):
    name = "springs"
    linear = True
    symmetric = True

    def __init__(self, spec: SpringSpec, mesh, regions, scene):
        if not scene.materials:
            raise InputError("springs act on the displacement: the scene needs [[materials]]",
                             scene.source, spec.key)
        self.spec, self.mesh, self.source = spec, mesh, scene.source
        self.u = scene.primary   # the displacement (the field springs act on)
        self.k = np.asarray(spec.stiffness, dtype=float)
        self.pairs = self._pairs(regions)   # (n, 2) local nodes (-1: not on this part; b to
        #                                     the ground: -1 throughout)
        self._check_split(regions)
        self.term, self.matrices = self._term()

    # ------------------------------------------------------------------ pairing

    def _pairs(self, regions) -> np.ndarray:
        spec = self.spec
        a = regions.relation_nodes(spec.region, spec.key + ".region")   # input ids, whole
        if spec.target is None:
            return np.stack([self._local(a), np.full(a.size, -1)], axis=1)
        b_all = regions.relation_nodes(spec.target, spec.key + ".target")
        if b_all.size == 1:
            b = np.repeat(b_all, a.size)
        else:
            b = partners(regions.points_of(a), b_all, regions.points_of(b_all),
                         spec.translation or [0.0] * self.mesh.dim, regions.tol)
            if np.any(b < 0):
                lost = int(a[np.flatnonzero(b < 0)[0]])
                raise InputError(f"node {lost} of region {spec.region!r} has no node of region "
                                 f"{spec.target!r} at its position + translation (within "
                                 f"{regions.tol:.3g})", self.source, spec.key + ".target")
        if np.any(a == b):
            raise InputError("a spring would tie a node to itself", self.source,
                             spec.key + ".target")
        # a pair of which this rank holds a node but not the other cannot be in its cells
        return np.stack([self._local(a), self._local(b)], axis=1)

    def _local(self, ids: np.ndarray) -> np.ndarray:
        """Local node of each input id (-1: not on this rank's part)."""
        glob = getattr(self.mesh, "global_nodes", None)
        if glob is None:
            return np.asarray(ids, dtype=np.int64)
        order = np.argsort(glob)
        pos = np.minimum(np.searchsorted(glob[order], ids), max(glob.size - 1, 0))
        hit = glob[order][pos] == ids if glob.size else np.zeros(ids.size, dtype=bool)
        return np.where(hit, order[pos] if glob.size else -1, -1)

    def _check_split(self, regions) -> None:
        """The rank owning either node of a pair holds the other (owned or ghost: the nodes
        of its cells), so that the row's owner adds the spring whole; a pair split otherwise
        (nodes far apart that share no cell, on different ranks' parts) is an input error."""
        if self.spec.target is None:
            return
        a, b = self.pairs[:, 0], self.pairs[:, 1]
        owned = getattr(self.mesh, "n_owned", self.mesh.num_points)
        split = ((a >= 0) & (a < owned) & (b < 0)) | ((b >= 0) & (b < owned) & (a < 0))
        comm = getattr(regions, "comm", None)
        nsplit = int(split.sum()) if comm is None else comm.allreduce(int(split.sum()))
        if nsplit:
            raise InputError(f"{nsplit} spring pairs join nodes that share no cell and lie on "
                             "different ranks' parts (the rank owning one node must hold the "
                             "other; run on fewer ranks)", self.source, self.spec.key + ".target")

    # ------------------------------------------------------------------ the Effect interface

    def _term(self) -> tuple[Term, TermMatrices]:
        """The declared term on this rank's springs (both nodes local) and its constant
        values: K on a node to the ground; [[K, −K], [−K, K]] on a pair."""
        K = np.diag(self.k).ravel()[:, None, None, None]          # (d², 1, 1, 1), (i, j)
        if self.spec.target is None:
            nodes = self.pairs[self.pairs[:, 0] >= 0, :1]
            values = np.repeat(K, len(nodes), axis=3)
        else:
            nodes = self.pairs[(self.pairs >= 0).all(axis=1)]
            sign = np.array([[1.0, -1.0], [-1.0, 1.0]])[None, :, :, None]
            values = np.repeat(K * sign, len(nodes), axis=3)
        term = Term(self.u, self.u, nodes)
        return term, TermMatrices(term, values)

    def terms(self) -> list[Term]:
        return [self.term]

    def term_values(self, term: Term, cells: np.ndarray) -> TermMatrices:
        return self.matrices

    def output_names(self) -> list[str]:
        return [f"{self.spec.name}_force"]

    def outputs(self, owned, values, extra, local_cells):
        """The force the springs exert on each node, -K (u_a - u_b) on a and its opposite on
        b, complete on every node this rank holds with its partner (all the owned ones);
        weight 1 there, so that the ranks' contributions average to it."""
        npts, d = self.mesh.num_points, self.mesh.dim
        a, b = self.pairs[:, 0], self.pairs[:, 1]
        u = values[self.u]
        ground = self.spec.target is None
        on = (a >= 0) if ground else (a >= 0) & (b >= 0)
        a, b = a[on], b[on]
        f = -self.k * (u[a] - (0.0 if ground else u[b]))
        force, weight = np.zeros((npts, d)), np.zeros(npts)
        np.add.at(force, a, f)
        weight[a] = 1.0
        if not ground:
            np.add.at(force, b, -f)
            weight[b] = 1.0
        return {f"{self.spec.name}_force": (force * weight[:, None], weight)}, {}
