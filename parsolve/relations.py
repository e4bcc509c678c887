"""The relation: the one abstraction behind Dirichlet conditions, control, contact and solubility.

A relation of ``m`` rows couples the primal unknowns ``q`` (all DOFs, numbered
``node * ncomp + component`` in the input mesh's node order) through

    primal part   A q  (sense)  b(t)        sense is "=", ">=" or "<="
    dual part     the reaction force  D λ  added to the external forces: K q = F + D λ

Sign convention (the paper's): an *associated* relation has ``D = -Aᵀ``, so the assembled
operator ``[[K, -D], [A, 0]] = [[K, Aᵀ], [A, 0]]`` is symmetric and, for a Dirichlet condition,
λ is minus the reaction force. A *non-associated* relation carries its own ``D`` (for control,
a load pattern): λ is then the intensity of that load.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Callable

import numpy as np

from parsolve.evolution import RAMP, Evolution

SENSES = ("=", ">=", "<=")


@dataclass
class Relation:
    """``m`` rows of ``A q (sense) b(t)`` with reaction ``D λ``; ``dual is None`` means associated.

    A is given as COO triplets (row, dof, coefficient); ``dual`` likewise as (dof, row, value).
    ``values`` are the row values at the reference level, scaled by ``evolution(t)``.
    """

    name: str
    nrows: int
    a_rows: np.ndarray
    a_dofs: np.ndarray
    a_vals: np.ndarray
    values: np.ndarray
    evolution: Evolution = RAMP
    sense: str = "="
    dual: tuple[np.ndarray, np.ndarray, np.ndarray] | None = None
    eliminate: bool | None = None  # None: let the solver decide (single-DOF rows are eliminated)
    maximum: bool = False          # unilateral rows of which only the extreme one is enforced
    shared_dual: tuple[np.ndarray, np.ndarray] | None = None  # every row's reaction along one
    #                                   vector (dofs, values): a load pattern, stored once
    groups: np.ndarray | None = None  # per row: rows with one id form a group of which exactly
    #                                   one row, the extreme one, is enforced (contiguous rows)
    meta: dict = field(default_factory=dict)
    # a zone of these rows may form from nothing (a contact): the active set closes the most
    # violated first (solvers/active_set.py, ``_forming``)
    forming: bool = False
    # a relation built per rank (``rows_here``): the global number of each of its rows this
    # rank holds (increasing; all owned here), and ``size`` its rows over every rank. None: a
    # whole relation, every row on every rank (its row k is global row k)
    ids: np.ndarray | None = None
    size: int | None = None
    # a whole relation whose entries are spread (``spread_rows``): every row on every rank,
    # each A entry (and a load pattern's, ``shared_dual``) held by the rank owning its DOF
    # alone, so that A q is the sum of every rank's part; its rows' A entries reach their
    # multiplier row's owner in the stacking (``la.relation_set``)
    spread: bool = False
    # the ranks a relation built per rank spans (its rows' sums over them: ``reaction``)
    comm: object = field(default=None, repr=False, compare=False)

    def __post_init__(self) -> None:
        if self.sense not in SENSES:
            raise ValueError(f"relation {self.name}: sense must be one of {SENSES}")
        self.a_rows = np.asarray(self.a_rows, dtype=np.int64)
        self.a_dofs = np.asarray(self.a_dofs, dtype=np.int64)
        self.a_vals = np.asarray(self.a_vals, dtype=float)
        self.values = np.broadcast_to(np.asarray(self.values, dtype=float), (self.nrows,)).copy()

    def set_entries(self, a_rows: np.ndarray, a_dofs: np.ndarray, dual: bool) -> None:
        """New entries for A (its rows and DOFs, values zero) and, with ``dual``, a dual of
        the same layout (values zero): the same rows, another sparsity (finite sliding's
        spans made again). The system must then build its operator again (``restructure``)."""
        self.a_rows = np.asarray(a_rows, dtype=np.int64)
        self.a_dofs = np.asarray(a_dofs, dtype=np.int64)
        self.a_vals = np.zeros(self.a_rows.size)
        if dual:
            self.dual = (self.a_dofs, self.a_rows, np.zeros(self.a_rows.size))

    @property
    def whole(self) -> bool:
        """Every row on every rank (else: this rank's rows only, ``ids``)."""
        return self.ids is None

    @property
    def complete(self) -> bool:
        """Every row and every A and D entry on every rank (a whole relation neither spread
        nor with a load pattern, which each rank holds its owned part of): sums over its
        entries, such as its reactions' resultant, are then the same on every rank."""
        return self.whole and not self.spread and self.shared_dual is None

    @property
    def total(self) -> int:
        """Rows over every rank."""
        return self.nrows if self.ids is None else int(self.size)

    def row_ids(self) -> np.ndarray:
        """Global number of each row held here."""
        return np.arange(self.nrows, dtype=np.int64) if self.ids is None else self.ids

    @property
    def associated(self) -> bool:
        return self.dual is None and self.shared_dual is None

    @property
    def collapsed(self) -> bool:
        """A maximum group whose rows share one dual vector: one multiplier (one control
        column) whatever its number of rows, carrying the enforced row's coefficients."""
        return self.maximum and self.shared_dual is not None

    def rhs(self, t: float) -> np.ndarray:
        """b(t), one value per row."""
        return self.values * self.evolution(t)

    def empty_rows(self) -> np.ndarray:
        """Rows with no nonzero A entry (a finite-sliding contact slave that no facet faces
        yet): never enforced while so."""
        return np.bincount(self.a_rows, weights=np.abs(self.a_vals), minlength=self.nrows) == 0.0

    def single_dof(self) -> bool:
        """True when every row constrains one DOF alone (a Dirichlet-like relation)."""
        counts = np.bincount(self.a_rows, minlength=self.nrows)
        return bool(np.all(counts == 1)) and bool(np.all(self.a_vals != 0.0))

    def eliminable(self) -> bool:
        """Can be eliminated instead of multiplied: associated, equality, single-DOF rows (a
        spread relation never: its rows' entries are over the ranks)."""
        return self.associated and self.sense == "=" and not self.spread and self.single_dof() \
            and self.eliminate is not False

    @property
    def sign(self) -> int:
        """+1 for "<=", -1 for ">=", 0 for "=": s (A q - b) <= 0 is the admissible side."""
        return {"=": 0, "<=": 1, ">=": -1}[self.sense]

    def dual_coo(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """D as (dof, row, value); for an associated relation D = -Aᵀ."""
        if self.shared_dual is not None:
            dofs, vals = self.shared_dual
            return (np.tile(dofs, self.nrows), np.repeat(np.arange(self.nrows), dofs.size),
                    np.tile(vals, self.nrows))
        if self.dual is None:
            return self.a_dofs, self.a_rows, -self.a_vals
        return self.dual

    def reaction(self, lam: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """The reaction D λ as (dof, force) entries (a shared dual: one vector, this rank's
        part, times Σ λ over every row: a relation built per rank sums its rows' over the
        ranks, collective)."""
        if self.shared_dual is not None:
            dofs, vals = self.shared_dual
            total = float(lam.sum())
            if not self.whole:   # (its rows' λ are over the ranks: a partial sum is wrong)
                if self.comm is None:
                    raise ValueError(f"relation {self.name!r} is built per rank: its "
                                     "communicator is needed to sum its rows' reactions")
                total = self.comm.allreduce(total)
            return dofs, vals * total
        dofs, rows, vals = self.dual_coo()
        return dofs, vals * lam[rows]

    def primal(self, q: np.ndarray) -> np.ndarray:
        """A q for a full primal vector q (input numbering)."""
        return np.bincount(self.a_rows, weights=self.a_vals * q[self.a_dofs], minlength=self.nrows)


# ---------------------------------------------------------------- builders


def dirichlet(name: str, nodes: np.ndarray, components: list[int], ncomp: int,
              value: float | np.ndarray = 0.0, evolution: Evolution = RAMP) -> Relation:
    """u_c(node) = value for every node and listed component (one row each)."""
    nodes = np.asarray(nodes, dtype=np.int64)
    comps = np.asarray(components, dtype=np.int64)
    dofs = (nodes[:, None] * ncomp + comps[None, :]).ravel()
    vals = np.broadcast_to(np.asarray(value, dtype=float), (len(nodes), len(comps))).ravel()
    m = dofs.size
    return Relation(name, m, np.arange(m), dofs, np.ones(m), vals, evolution)


def equal(name: str, nodes: np.ndarray, component: int, ncomp: int) -> Relation:
    """u_c is the same at every node: u_c(n_k) - u_c(n_0) = 0 for k >= 1."""
    nodes = np.asarray(nodes, dtype=np.int64)
    m = len(nodes) - 1
    rows = np.repeat(np.arange(m), 2)
    dofs = np.stack([nodes[1:] * ncomp + component, np.full(m, nodes[0] * ncomp + component)], 1).ravel()
    coefs = np.tile([1.0, -1.0], m)
    return Relation(name, m, rows, dofs, coefs, np.zeros(m), RAMP)


def combination(name: str, terms: list[tuple], ncomp: int,
                value: float = 0.0, evolution: Evolution = RAMP, sense: str = "=") -> Relation:
    """One row: sum over terms of coefficient × (mean or sum of u_c over the term's nodes) = value.

    ``terms``: (nodes, component, coefficient, mean[, count]): ``count`` the term's nodes a
    mean divides by (default: those given; a spread row's part gives the whole region's).
    """
    dofs, coefs = [], []
    for nodes, comp, coef, mean, *count in terms:
        nodes = np.asarray(nodes, dtype=np.int64)
        dofs.append(nodes * ncomp + comp)
        n = count[0] if count else len(nodes)
        coefs.append(np.full(len(nodes), coef / n if mean else coef))
    dofs_all, coefs_all = np.concatenate(dofs), np.concatenate(coefs)
    # a node listed in two terms is one coefficient: sum duplicates
    udofs, inv = np.unique(dofs_all, return_inverse=True)
    ucoefs = np.bincount(inv, weights=coefs_all)
    keep = ucoefs != 0.0
    udofs, ucoefs = udofs[keep], ucoefs[keep]
    return Relation(name, 1, np.zeros(udofs.size), udofs, ucoefs, np.array([value]), evolution,
                    sense)


def rows(name: str, row_dofs: np.ndarray, row_coefs: np.ndarray, value: float = 0.0,
         evolution: Evolution = RAMP, sense: str = "=") -> Relation:
    """One row per line of (row_dofs, row_coefs) (m, k): Σ coef · u[dof] (sense) value."""
    m, k = row_dofs.shape
    r = np.repeat(np.arange(m), k)
    dofs, coefs = row_dofs.ravel(), row_coefs.ravel()
    # merge repeated DOFs of a row (a node shared by several cells of a region)
    key = r * (dofs.max() + 1 if dofs.size else 1) + dofs
    _, first, inv = np.unique(key, return_index=True, return_inverse=True)
    ucoef = np.bincount(inv, weights=coefs)
    urow, udof = r[first], dofs[first]
    keep = ucoef != 0.0
    return Relation(name, m, urow[keep], udof[keep], ucoef[keep], np.full(m, value), evolution, sense)


def spread_rows(relation: Relation) -> Relation:
    """A whole relation whose entries this rank holds are those on the DOFs it owns
    (``Relation.spread``)."""
    relation.spread = True
    return relation


def rows_here(relation: Relation, ids: np.ndarray, size: int) -> Relation:
    """A relation built per rank: its rows are the global rows ``ids`` (increasing) of a
    relation of ``size`` rows over every rank, all owned by this rank (``Relation.ids``)."""
    relation.ids, relation.size = np.asarray(ids, dtype=np.int64), int(size)
    return relation


def lead_dofs(relation: Relation) -> np.ndarray:
    """Per row, the DOF it constrains: its first entry of positive coefficient (a Dirichlet
    row's DOF, a tie's u_a of u_a − u_b), else its first entry; -1 for a row with none."""
    out = np.full(relation.nrows, -1, dtype=np.int64)
    n = relation.a_rows.size
    order = np.lexsort((np.arange(n), relation.a_vals <= 0.0, relation.a_rows))
    rows = relation.a_rows[order]
    first = np.flatnonzero(np.concatenate([[True], rows[1:] != rows[:-1]])) if n else order
    out[rows[first]] = relation.a_dofs[order[first]]
    return out


def keep_rows(relation: Relation, keep: np.ndarray) -> Relation:
    """The relation restricted to the rows ``keep`` (a mask), renumbered."""
    new = np.cumsum(keep) - 1
    on = keep[relation.a_rows]
    dual = relation.dual
    if dual is not None:
        dofs, rows, vals = dual
        d_on = keep[rows]
        dual = (dofs[d_on], new[rows[d_on]], vals[d_on])
    out = Relation(relation.name, int(keep.sum()), new[relation.a_rows[on]], relation.a_dofs[on],
                   relation.a_vals[on], relation.values[keep], relation.evolution,
                   relation.sense, dual, relation.eliminate, relation.maximum,
                   shared_dual=relation.shared_dual,
                   groups=None if relation.groups is None else relation.groups[keep],
                   spread=relation.spread)
    out.meta, out.comm = relation.meta, relation.comm
    return out


RelationBuilder = Callable[..., Relation]
