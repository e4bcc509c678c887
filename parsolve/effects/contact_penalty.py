"""Baselines for frictional contact: the penalty method and an augmented Lagrangian (Uzawa,
Alart–Curnier type), selected by ``formulation`` in a ``[[contact]]`` section. They exist to
measure the paper's formulation (relations, ``parsolve.effects.contact``) against the classical
ones on the same scenes: same pairing, same rows, same linearised gap ``g = g0 + Dn·q``.

Per paired slave node i (against a rigid obstacle, or node-to-segment / node-to-face
against a deformable master's facet: its gap and tangential displacement are the rows'
``v·u_s − Σ_a N_a v·u_a``), with ε_i = penalty × A_i (A_i: the
node's tributary area, the consistent nodal force of a unit pressure on the slave facets; a
slave given as a node group has as facets those all of whose nodes it holds, so a group that
leaves out a neighbour, e.g. a wedge's apex, gives its end node half its area there):

* normal force (contact pressure force on the slave, along n):
  ``p_N = max(λ_N − ε_i g, 0)``;
* friction, return mapping on a tangential spring ε_T,i = penalty_tangential × A_i:
  trial ``t_tr = λ_T + ε_T,i (g_T − g_T,n)`` (g_T: tangential displacement in the tangent basis,
  g_T,n its value at the step's start), stick ``t = t_tr`` while ``|t_tr| ≤ μ p_N (1 + 1e-12)``,
  else slip ``t = μ p_N t_tr/|t_tr|`` (the tie rule: a node on the cone to round-off, as every
  node of a full slide at a step's start, sticks whatever its last bits); friction force on
  the slave ``Rt = −t`` (it opposes the slip);
* closed when ``λ_N − ε_i g ≥ 0``, or when the node starts within the relations form's
  ``closed`` tolerance g_c (× the mesh's size) and its gap stays ``≤ g_c``: a node touching to
  round-off counts as closed whatever the sign of its round-off gap (the V-wedge's inclined
  face: g0 = +3e-17..+6e-17; started open, the first iteration sank the block into that face
  and face 1's end node then flipped its slip sense at every iteration: a 2D return mapping
  whose tangential penalty is far stiffer than the body there cycles under Newton once it
  starts on the wrong side);
* internal force ``f = −p_N ∂g + ∂g_Tᵀ t`` on the pair's DOFs (∂g, ∂g_T: the rows'
  coefficients; on the slave n and the tangents T as columns, on master node a −N_a times
  them) and its consistent tangent: ``ε ∂g ∂gᵀ`` in contact, ``+ ε_T ∂g_Tᵀ ∂g_T`` in stick,
  and in slip ``− μ ε (∂g_Tᵀ ŝ) ∂gᵀ + μ p_N ε_T/|t_tr| ∂g_Tᵀ (I − ŝ ŝᵀ) ∂g_T``
  (ŝ = t_tr/|t_tr|): not symmetric.

**Penalty:** λ_N = 0; λ_T = the committed friction force t_n of the last converged step (an
elastic-plastic spring: the slip is what the return mapping takes out). The penetration is
p_N/ε: it falls as 1/ε.

**Augmented Lagrangian (Uzawa, not the semi-smooth Newton on (u, λ)):** the same forces with
multipliers λ_N ≥ 0 and λ_T, updated ``λ_N ← p_N``, ``λ_T ← t`` (the return-mapped force)
between Newton iterations (the effect's ``refresh`` hook) once the inner penalty problem is
solved: it is piecewise linear, so a Newton iteration after which no node changed status (nor,
in 3D, slip direction) has solved it exactly; after INNER_LIMIT iterations without settling it
augments anyway. It stops when an update would move the multipliers by less than
``augmentation_tolerance × max p_N``: that update is not applied and the step converges on the
penalty problem of the current multipliers. /steps/iterations counts every Newton iteration,
the augmentations' included. At the fixed point the gap is closed (λ_N = λ_N − ε g) and a
sticking node has not moved during the step (λ_T = λ_T + ε_T Δg_T): the constraints of the
relations form, to the tolerance. A step that needs more than ``max_augmentations`` fails (and
is cut like any failed step). The multipliers start each step from the last converged forces.

**Contact elements and the sparsity:** each pair is a node tuple, its slave node then its
master facet's nodes (an obstacle's: the slave alone), a term the effect declares
(``Effect.terms``, ``TermMatrices`` of its (m·dim)² blocks) in the partition's global node
numbers (``Term.global_ids``): the system derives the pattern's contact entries from them and
gives the term its slots once, so re-assembly stays a value update of that pattern. A
deformable master takes node-to-segment (2D) or node-to-face (3D) pairs (mortar rows are
refused, exit 2: the relations form has them), made once (``sliding = "small"``) or, by the
penalty, again on the current configuration at each step's start and Newton iteration
(``sliding = "finite"``, ``SlidingPenalty``: a tuple that moved is given anew, the effect
``restructured``, the pattern derived again; the augmented Lagrangian refuses it).

**On a distributed mesh** (each rank its part) each rank holds the pairs of the slave nodes
it owns (the relations form's pairing per rank: against the master facets near them, or its
own slaves projected on the obstacle): their areas A_i from its facets through them (a
facet's ghost nodes' pairing fetched from their owners), their gaps g and g_T from the
displacement of its pairs' nodes, each fetched from its owner (one plan). A pair's tuple is
declared by the pair's rank alone: the system sends the entries of its rows another rank
owns to that owner, summed per (row, column) over the rank's pairs (``la.tuple_rows``), and
the pair's rank sends the forces on those nodes (one exchange an evaluation). A rank owning
the whole master surface then declares its own slaves' pairs only. Finite sliding
against a master region (``SlidingPenalty``) pairs each rank's slaves again against the
master facets near them on the current configuration, those that came near sent to it
(``contact.distributed.update_near``, as the relations form's finite sliding). The
augmented Lagrangian's decisions (settled, the augmentation's change and stop) are one
reduction: the ranks agree. Outputs are each rank's owned rows.

Scene keys (besides those of ``parsolve.effects.contact``)::

    formulation = "penalty"          # "relations" (default) | "penalty" | "augmented_lagrangian"
    penalty = 1e5                    # per unit area (pressure per unit penetration, E/length);
                                     # default 100 E_max / h (h: mean slave facet size)
    penalty_tangential = 1e5         # default: penalty
    augmentation_tolerance = 1e-6    # AL: max |Δλ| / max λ_N to stop augmenting
    max_augmentations = 25           # AL: per step
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass

import numpy as np
from mpi4py import MPI

from parsolve.contact.distributed import facet_extent, facet_index, update_near
from parsolve.contact.friction import OPEN, SLIP, STICK
from parsolve.contact.pairing import pair_nodes, pair_on
from parsolve.contact.surfaces import Surfaces
from parsolve.la.dofmap import DofMap
from parsolve.la.fetch import Fetch
from parsolve.mesh.blocks import exchange
from parsolve.effects import contact
from parsolve.effects.base import Effect
from parsolve.effects.contact_sliding import KEEP_TOL
from parsolve.fem.element_matrices import NodeForces, Term, TermMatrices
from parsolve.errors import InputError, SolverError
from parsolve.fem.integrals import facet_rule
from parsolve.mesh.topology import facets_from_nodes

FORMULATIONS = ("relations", "penalty", "augmented_lagrangian")
BASELINE_KEYS = ("penalty", "penalty_tangential")
AL_KEYS = ("augmentation_tolerance", "max_augmentations")
DEFAULT_FACTOR = 100.0     # default penalty: DEFAULT_FACTOR × E / h
CONE_TIE = 1e-12           # a node slides once |t_tr| > μ p_N (1 + CONE_TIE): see forces
INNER_LIMIT = 4            # AL: Newton iterations on one penalty problem before augmenting anyway


@dataclass
class BaselineSpec(contact.ContactSpec):
    formulation: str = "penalty"
    penalty: float | None = None
    penalty_tangential: float | None = None
    augmentation_tolerance: float = 1e-6
    max_augmentations: int = 25


def read_formulation(t) -> dict:
    """Consume ``formulation`` and the baseline keys from a [[contact]] table (before
    ``contact.parse`` checks that no key is left); {} for the relations form."""
    formulation = t.get("formulation", str, "relations", choices=FORMULATIONS)
    keys = BASELINE_KEYS + AL_KEYS
    if formulation == "relations":
        for k in keys:
            if t.has(k):
                raise t.error(k, "applies only with formulation = \"penalty\" or "
                                 "\"augmented_lagrangian\"")
        return {}
    if formulation == "penalty":
        for k in AL_KEYS:
            if t.has(k):
                raise t.error(k, "applies only with formulation = \"augmented_lagrangian\"")
    out = {"formulation": formulation}
    for k in BASELINE_KEYS:
        value = t.get(k, float, None)
        if value is not None and not value > 0:
            raise t.error(k, f"must be positive, got {value!r}")
        out[k] = value
    if formulation == "augmented_lagrangian":
        tol = t.get("augmentation_tolerance", float, 1e-6)
        if not 0 < tol < 1:
            raise t.error("augmentation_tolerance", f"must lie in (0, 1), got {tol!r}")
        count = t.get("max_augmentations", int, 25)
        if count < 1:
            raise t.error("max_augmentations", f"must be at least 1, got {count!r}")
        out.update(augmentation_tolerance=tol, max_augmentations=count)
    return out


def with_baseline(spec: contact.ContactSpec, baseline: dict) -> contact.ContactSpec:
    """The relations form's spec as is ({} from read_formulation), else a BaselineSpec."""
    return BaselineSpec(**dataclasses.asdict(spec), **baseline) if baseline else spec


def build(spec: BaselineSpec, mesh, regions, fields, scene) -> Effect:
    cls = AugmentedContact if spec.formulation == "augmented_lagrangian" else \
        SlidingPenalty if spec.master is not None and spec.sliding == "finite" else PenaltyContact
    return cls(spec, mesh, regions, fields, scene)


def slave_areas(values: DofMap, mesh, slave: np.ndarray, thickness,
                region_nodes: np.ndarray) -> np.ndarray:
    """``nodal_areas`` of this rank's paired slave nodes (input ids, all owned): every cell
    through an owned node is local, so a boundary facet through it is one of the whole mesh
    and all of them are here; a facet counts when all its nodes are paired (its ghost nodes'
    pairing fetched from their owners among ``region_nodes``, the slave region's local
    nodes). Collective."""
    local = values.local_nodes(slave)
    paired = np.zeros(values.n_owned_nodes)
    paired[local] = 1.0
    ghosts = region_nodes[region_nodes >= values.n_owned_nodes]
    got = Fetch(values.comm, np.asarray(mesh.node_new)[ghosts].astype(np.int64),
                values.node_ranges, 1)(paired)
    flagged = np.concatenate([local, ghosts[got > 0.5]])
    area = np.zeros(mesh.num_points)
    area[flagged] = nodal_areas(mesh, flagged, thickness)
    return area[local]


def nodal_areas(mesh, nodes: np.ndarray, thickness) -> np.ndarray:
    """Tributary area of each node (n,): the consistent nodal force of a unit pressure on the
    boundary facets all of whose nodes are in ``nodes`` (2D: length × thickness, or × 2π r
    for the axisymmetric measure: the ring's area)."""
    mask = np.zeros(mesh.num_points, dtype=bool)
    mask[nodes] = True
    facets = facets_from_nodes(mesh, mask)[0]
    area = np.zeros(mesh.num_points)
    if facets.size:
        rule = facet_rule(mesh.points[facets], mesh.facet_type, thickness)
        area = np.bincount(facets.ravel(), weights=(rule.weights @ rule.N).ravel(),
                           minlength=mesh.num_points)
    return area[nodes]


def check_master(spec: BaselineSpec, source: str) -> None:
    """A baseline against a master region takes node-to-segment pairs; finite sliding by the
    penalty only (the augmented Lagrangian's multipliers would have to follow the pairs)."""
    if spec.discretization != "node_to_segment":
        raise InputError(f"formulation = {spec.formulation!r} on a master region takes "
                         "node_to_segment pairs (node-to-face in 3D); mortar rows are the "
                         "relations form's", source, f"{spec.key}.discretization")
    if spec.sliding != "small" and spec.formulation != "penalty":
        raise InputError(f"formulation = {spec.formulation!r} on a master region takes "
                         "pairs made once (sliding = \"small\"); finite sliding: the "
                         "penalty or the relations form", source, f"{spec.key}.sliding")


def gap_gradients(p) -> tuple[np.ndarray, np.ndarray]:
    """(∂g (n, m·dim), ∂g_T (n, m·dim, dim-1)) of each pair's gap and tangential displacement
    on its tuple's DOFs (slave, then master facet nodes, node-major): the rows' coefficients
    (``contact.rows``: v on the slave, −N_a v on master node a; an obstacle's: v alone)."""
    n, dm1, dim = p.tangents.shape
    w = np.concatenate([np.ones((n, 1)), -p.weights], axis=1)               # (n, m)
    md = w.shape[1] * dim   # (a rank may hold no pair)
    bn = (w[:, :, None] * p.normal[:, None, :]).reshape(n, md)
    bt = (w[:, None, :, None] * p.tangents[:, :, None, :]).reshape(n, dm1, md)
    return bn, np.swapaxes(bt, 1, 2)




class PenaltyContact(Effect):
    """One contact surface against a rigid obstacle, by penalty (see the module docstring)."""

    linear = False

    def __init__(self, spec: BaselineSpec, mesh, regions, fields, scene):
        key = spec.key
        if spec.master is not None:
            check_master(spec, scene.source)
        # the relations form's set-up does the checks, the pairing and the rows, per rank:
        # reused as is (finite sliding: its pairs at the start made as small sliding's, then
        # again at each step's start and iteration: ``SlidingPenalty``)
        geo = contact.Contact(dataclasses.replace(spec, sliding="small"), mesh, regions,
                              fields, scene.source)
        self.geo = geo
        self.spec, self.mesh, self.fields_ = spec, mesh, fields
        self.u = geo.u
        self.name = f"contact {spec.name} ({spec.formulation})"
        self.pairing = geo.pairing
        self.values = geo.values
        self.symmetric = spec.mu == 0.0
        p = self.pairing
        dim = mesh.dim
        thickness = scene.thickness if dim == 2 else 1.0
        region = regions(spec.slave, f"{key}.slave").nodes
        area = self._positive(slave_areas(self.values, mesh, p.slave, thickness, region))
        # the facets' size, from their plane measure (the axisymmetric areas are rings')
        plane = self._positive(slave_areas(self.values, mesh, p.slave, 1.0, region))
        total, count = geo.sum_ranks(np.array([plane.sum(), plane.size]))
        self.h = float(total / max(count, 1)) ** (1.0 / (dim - 1))
        if spec.penalty is None:
            emax = max((m.params.get("E", 0.0) for m in scene.materials), default=0.0)
            if emax <= 0:
                raise InputError("no Young's modulus to size the default penalty: give penalty",
                                 scene.source, f"{key}.penalty")
            self.penalty = DEFAULT_FACTOR * emax / self.h
        else:
            self.penalty = spec.penalty
        self.penalty_t = self.penalty if spec.penalty_tangential is None else spec.penalty_tangential
        self.eps_n = self.penalty * area           # per node (force per unit penetration)
        self.eps_t = self.penalty_t * area
        # the relations form's ``closed`` rule (initial gaps ≤ spec.closed × the mesh's size
        # start closed): such a node counts as closed while its gap stays within that tolerance
        # (its stiffness in the tangent; its force max(λ_N − ε g, 0), zero there). A gap of
        # round-off's size (a slave face lying on an inclined obstacle: g0 = ±1e-17) then
        # starts closed whatever its sign, as in the relations form. Only the nodes that start
        # touching: elsewhere (a contact edge's open neighbours) the plain test stays
        self.touch = spec.closed * float(np.max(mesh.extent))   # the whole mesh's size, as there
        self.touching = p.gap <= self.touch
        self._last = None
        self.term = Term(self.u, self.u, np.zeros((0, 1), dtype=np.int64),
                         symmetric=self.symmetric, linear=False, global_ids=True)
        self._surfaces(geo)
        self._declare(p)

    def _positive(self, area: np.ndarray) -> np.ndarray:
        """Zero areas (a node no whole slave facet holds) replaced by the mean of the others
        (every rank's). Collective."""
        count, total = self.geo.sum_ranks(np.array([np.count_nonzero(area > 0),
                                                    area[area > 0].sum()]))
        mean = total / count if count else 1.0
        return np.where(area > 0, area, mean)

    def _surfaces(self, geo: contact.Contact) -> None:
        """The nodes whose displacement the gaps read: its pairs' tuples' (fixed)."""
        p = self.pairing
        self._plan(np.unique(np.concatenate([p.slave, p.master.ravel()])))

    def _plan(self, surface: np.ndarray) -> None:
        """The plan of u (this rank's nodes, (n, dim)) at the input node ids ``surface`` (this
        rank's slaves and the master nodes their pairs may hold), from their owners: one
        ``Fetch`` a surface. Collective."""
        dim = self.mesh.dim
        new = self.geo.new_of(surface)
        self.surface = surface
        self.fetch = Fetch(self.values.comm, (new[:, None] * dim + np.arange(dim)).ravel(),
                           self.values.node_ranges, dim)

    def surface_u(self, u: np.ndarray) -> np.ndarray:
        """u at the surface nodes (m, dim) from this rank's u (its nodes, owned first).
        Collective."""
        return self.fetch(np.ascontiguousarray(u).ravel()).reshape(-1, self.mesh.dim)

    def _declare(self, p) -> None:
        """The contact elements: one node tuple per pair (its slave node, then its master
        facet's nodes; an obstacle's pair is its slave alone), in the partition's global node
        numbers, declared by this rank alone, the rank of its slave node (the system sends the
        entries of the rows another rank owns there: ``la.tuple_rows``). Also (tuple, place
        in it, local node) of the tuple nodes this rank owns, where its forces go, and the
        plan of the forces on the others, sent to their owners; the pairs' gradients ∂g, ∂g_T
        and their tuples' places among the surface nodes. Collective."""
        ids = np.concatenate([p.slave[:, None], p.master], axis=1)          # (n, m) input ids
        self.gradients(p)
        values = self.values
        self.tuple_ids = ids
        nodes = self.term.nodes = self.geo.new_of(ids).reshape(ids.shape).astype(np.int64)
        lo, hi = values.node_ranges[values.rank], values.node_ranges[values.rank + 1]
        mine = (nodes >= lo) & (nodes < hi)
        pair, place = np.nonzero(mine)
        self.force_at = (pair, place, nodes[pair, place] - lo)   # (owned: new = lo + local)
        pair, place = np.nonzero(~mine)
        owner = np.searchsorted(values.node_ranges, nodes[pair, place], side="right") - 1
        order = np.argsort(owner, kind="stable")
        self.away = (pair[order], place[order], owner[order])
        got, _ = exchange(values.comm, nodes[pair, place][order], owner[order])
        self.away_local = got - lo

    def gradients(self, p) -> None:
        """The pairs' ∂g, ∂g_T and their tuples' places among the surface nodes."""
        self.bn, self.bt = gap_gradients(p)
        ids = np.concatenate([p.slave[:, None], p.master], axis=1)
        self.tuple_at = np.searchsorted(self.surface, ids)

    # ------------------------------------------------------------------ kinematics

    def _u(self, values: dict) -> np.ndarray:
        return values[self.u]

    def rows_at(self, us: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """(∂g·u (n,), ∂g_Tᵀ u (n, dim-1)): the pairs' rows at the surface nodes' u ``us``
        (m, dim)."""
        ut = us[self.tuple_at].reshape(self.bn.shape)               # (n, m·dim)
        return (np.einsum("nk,nk->n", self.bn, ut), np.einsum("nkj,nk->nj", self.bt, ut))

    def gaps(self, u: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """(g (n,), g_T (n, dim-1)): linearised gap g0 + Dn·q and tangential displacement at
        this rank's paired nodes (u: this rank's nodes; a master node's value fetched from its
        owner: one plan). Collective."""
        gn, gt = self.rows_at(self.surface_u(u))
        return self.pairing.gap + gn, gt

    def forces(self, u: np.ndarray, state: dict, lam_n: np.ndarray, lam_t: np.ndarray) -> dict:
        """Normal and friction forces at the displacement u (this rank's pairs)."""
        g, gT = self.gaps(u)
        trial = lam_n - self.eps_n * g
        pN = np.maximum(trial, 0.0)
        # touching (g = 0, or a node that starts within the closed tolerance and stays there)
        # counts: its stiffness holds a body laid on it
        closed = (trial >= 0.0) | (self.touching & (g <= self.touch))
        mu = self.spec.mu
        t_tr = lam_t + self.eps_t[:, None] * (gT - state["gT"])
        norm = np.linalg.norm(t_tr, axis=1)
        # frictionless: closed nodes "stick". The tie rule on the cone: a node slides only
        # beyond μ p_N (1 + CONE_TIE). In full sliding the committed (or augmented) friction
        # sits on the cone at a step's start, |t_tr| = μ p_N to round-off, and a strict test
        # decided stick or slip by the last bits, which differ between runs on 2+ ranks. The
        # tie goes to stick, the elastic predictor: started sliding, a 2D node without its
        # tangential stiffness can overshoot and flip its slip sense at every iteration (the
        # block's trailing corner did). The margin is far above round-off and far below any
        # accuracy asked of a baseline (a cone violation of CONE_TIE at most). Decided by the
        # pair's rank alone
        slip = closed & (norm > mu * pN * (1.0 + CONE_TIE)) & (mu > 0)
        scale = np.where(slip, mu * pN / np.maximum(norm, 1e-300), 1.0)
        t = np.where(closed[:, None] & (mu > 0), t_tr * scale[:, None], 0.0)
        status = np.where(closed, np.where(slip, SLIP, STICK), OPEN).astype(np.int8)
        return {"g": g, "gT": gT, "pN": pN, "t": t, "t_tr": t_tr, "norm": norm, "state": status}

    def node_tangents(self, f: dict) -> np.ndarray:
        """Consistent tangent (n, m·dim, m·dim) of each pair's contact forces on its tuple's
        DOFs (slave first, then its master facet's nodes; an obstacle's: (n, dim, dim))."""
        mu = self.spec.mu
        n_vec, T = self.bn, self.bt                   # ∂g (n, m·dim), ∂g_T (n, m·dim, dim-1)
        closed, slip = f["state"] != OPEN, f["state"] == SLIP
        k = (self.eps_n * closed)[:, None, None] * np.einsum("mi,mj->mij", n_vec, n_vec)
        if mu == 0.0:
            return k
        stick = f["state"] == STICK
        k += (self.eps_t * stick)[:, None, None] * np.einsum("mik,mjk->mij", T, T)
        s = f["t_tr"] / np.maximum(f["norm"], 1e-300)[:, None]       # (n, dim-1)
        ts = np.einsum("mik,mk->mi", T, s)                           # T ŝ
        k -= (mu * self.eps_n * slip)[:, None, None] * np.einsum("mi,mj->mij", ts, n_vec)
        dm1 = s.shape[1]
        if dm1 > 1:  # the direction turns with the trial force (3D only)
            proj = np.eye(dm1)[None] - np.einsum("mk,ml->mkl", s, s)
            c = mu * f["pN"] * self.eps_t / np.maximum(f["norm"], 1e-300) * slip
            k += c[:, None, None] * np.einsum("mik,mkl,mjl->mij", T, proj, T)
        return k

    def tuple_forces(self, f: dict) -> np.ndarray:
        """Each pair's internal forces on its tuple's nodes (n, m, dim): ``−p_N ∂g + ∂g_Tᵀ t``
        (on the slave −p_N n + T t, on a master node −N_a of it)."""
        n, md = self.bn.shape
        force = -f["pN"][:, None] * self.bn + np.einsum("mxj,mj->mx", self.bt, f["t"])
        return force.reshape(n, md // self.mesh.dim, self.mesh.dim)

    # ------------------------------------------------------------------ the Effect interface

    def output_names(self) -> list[str]:
        name = self.spec.name
        return [f"{name}_{k}" for k in ("normal_reaction", "tangential_reaction", "gap", "slip",
                                        "state")]

    def init_state(self, cells: np.ndarray) -> dict:
        """Per paired slave node (this rank's): the normal force, the friction
        force and the tangential displacement of the last converged step."""
        n, dm1 = len(self.pairing), self.mesh.dim - 1
        return {"pN": np.zeros(n), "t": np.zeros((n, dm1)), "gT": np.zeros((n, dm1))}

    def multipliers(self, state: dict) -> tuple[np.ndarray, np.ndarray]:
        """(λ_N, λ_T): penalty, none normal, and the committed friction force."""
        return np.zeros(len(self.pairing)), state["t"]

    def step_state(self, state: dict) -> dict:
        """The committed state the step starts from (finite sliding: on its new pairs)."""
        return state

    def evaluate(self, cells: np.ndarray, values: dict, state, secant: bool, at):
        u = self._u(values)
        state = self.step_state(state)
        lam_n, lam_t = self.multipliers(state)
        f = self.forces(u, state, lam_n, lam_t)
        self._last, self._state = f, state
        trial = {"pN": f["pN"], "t": f["t"], "gT": f["gT"]}
        pair, place, local = self.force_at
        tuple_forces, k = self.tuple_forces(f), self.node_tangents(f)
        m, d = tuple_forces.shape[1:]
        # the forces on nodes another rank owns sent there (one exchange)
        away, _, owner = self.away
        got, _ = exchange(self.values.comm, tuple_forces[away, self.away[1]], owner)
        forces = NodeForces(np.concatenate([local, self.away_local])[:, None],
                            np.concatenate([tuple_forces[pair, place],
                                            got.reshape(-1, d)])[:, None, :])
        # (n, m·d, m·d) → (d·d, m, m, n): entry (i, j) of node pair (a, b) at [i d + j, a, b]
        blocks = k.reshape(len(k), m, d, m, d).transpose(2, 4, 1, 3, 0).reshape(d * d, m, m, -1)
        return {self.u: forces}, [(self.term, TermMatrices(self.term, blocks))], trial, None

    def terms(self) -> list[Term]:
        return [self.term]

    # ------------------------------------------------------------------ outputs

    def step_outputs(self, q: np.ndarray, lam: dict, active: dict) -> tuple[dict, dict]:
        """Per slave node, as the relations form: normal force Rn = p_N, friction Rt = −t in the
        tangent basis, gap (the actual one: negative where it penetrates), slip (tangential
        displacement), state (−1 not a contact node, 0 open, 1 stick, 2 slip)."""
        f, p, name = self._last, self.pairing, self.spec.name
        # over every node (0 elsewhere; state -1), or this rank's owned rows on a part
        nodal = self.values.nodal
        return {f"{name}_normal_reaction": nodal(p.slave, f["pN"]),
                f"{name}_tangential_reaction": nodal(p.slave, -f["t"]),
                f"{name}_gap": nodal(p.slave, f["g"]), f"{name}_slip": nodal(p.slave, f["gT"]),
                f"{name}_state": nodal(p.slave, f["state"], fill=-1.0)}, {}


class AugmentedContact(PenaltyContact):
    """The same forces with Uzawa-augmented multipliers (see the module docstring)."""

    augmentations, total_augmentations, _fresh, _inner = 0, 0, True, 0

    def multipliers(self, state: dict) -> tuple[np.ndarray, np.ndarray]:
        """The current multipliers; at a step's first evaluation, the last converged forces."""
        if self._fresh:
            self.lam_n, self.lam_t = state["pN"].copy(), state["t"].copy()
            self._fresh = False
        return self.lam_n, self.lam_t

    def begin_step(self, q: np.ndarray, active: dict, at) -> bool:
        self.augmentations, self._fresh, self._inner = 0, True, 0
        return False

    def end_step(self) -> None:
        self.total_augmentations += self.augmentations

    def refresh(self, q: np.ndarray, lam: dict, active: dict) -> bool:
        """Between Newton iterations: while the inner penalty problem is not solved (the status
        of a node, or a 3D slip direction, changed since the tangent was made), True and
        nothing else; once it is, one augmentation λ_N ← p_N, λ_T ← t, True while it moves
        them by more than the tolerance."""
        u = q.reshape(self.mesh.num_points, -1)[:, self.fields_.columns(self.u)]
        f = self.forces(u, self._state, self.lam_n, self.lam_t)
        self._inner += 1
        # every rank's pairs settled, the largest change and force: one reduction
        local = np.array([not self._settled(f, self._last),
                          np.abs(f["pN"] - self.lam_n).max(initial=0.0),
                          np.abs(f["t"] - self.lam_t).max(initial=0.0),
                          f["pN"].max(initial=0.0)])
        self.values.comm.Allreduce(MPI.IN_PLACE, local, op=MPI.MAX)
        unsettled, change_n, change_t, scale = local
        if unsettled and self._inner < INNER_LIMIT:
            return True
        self._inner = 0
        change, scale = max(change_n, change_t), max(scale, 1e-300)
        if change <= self.spec.augmentation_tolerance * scale:
            return False
        if self.augmentations >= self.spec.max_augmentations:
            raise SolverError(f"contact {self.spec.name!r}: the augmented Lagrangian did not "
                              f"converge in {self.spec.max_augmentations} augmentations "
                              f"(last change {change / scale:.1e} of the largest force)")
        self.augmentations += 1
        self.lam_n, self.lam_t = f["pN"], f["t"]
        return True

    @staticmethod
    def _settled(new: dict, old: dict, tol_angle: float = 1e-8) -> bool:
        """The last Newton step solved the inner (piecewise linear) problem: same status at
        every node and, in 3D, the same slip directions."""
        if not np.array_equal(new["state"], old["state"]):
            return False
        if new["t_tr"].shape[1] == 1:
            slip = new["state"] == SLIP
            return bool(np.all(np.sign(new["t_tr"][slip]) == np.sign(old["t_tr"][slip])))
        slip = new["state"] == SLIP
        a = new["t_tr"][slip] / np.maximum(new["norm"][slip], 1e-300)[:, None]
        b = old["t_tr"][slip] / np.maximum(old["norm"][slip], 1e-300)[:, None]
        return bool(np.all(np.linalg.norm(a - b, axis=1) <= tol_angle))


class SlidingPenalty(PenaltyContact):
    """The penalty against a master region with finite sliding: each rank's slaves paired
    again with the master's facets near them on the current configuration X + u at each
    step's start and after each Newton iteration (the facets that came within the search
    radius of its slaves sent to it: ``dist.update_near``, as the relations form's finite
    sliding; a slave keeps its facet while it stays in it and as close, or when no facet
    faces it), their rows linearised there (``g = g(x) + Dn·(q − q(x))``: at convergence the
    gap is the actual one), the committed friction force turned onto the new tangents and
    the tangential displacement counted from the step's start q_n on the new rows. When a
    tuple changed on some rank (a slave onto another facet) the tuples are given anew and
    the effect ``restructured``: the system derives its pattern again; the iteration does
    not count as converged. No geometric stiffness (the relations form's finite sliding has
    it)."""

    restructures = True

    def __init__(self, spec: BaselineSpec, mesh, regions, fields, scene):
        super().__init__(spec, mesh, regions, fields, scene)
        self.reference = None   # (tangential displacement at q_n, committed → new tangents)
        self.committed_tangents = self.pairing.tangents
        self.q_start = None
        self._start_u = None    # the surface nodes' u at q_start (until the surface changes)
        self.repairs = 0        # pairings that moved a tuple (each a new pattern)

    def _surfaces(self, geo: contact.Contact) -> None:
        """This rank's surfaces: its paired slaves and the master facets near them (the
        relations form's exchange: ``geo.near``); the plan of its own master facets' u; the
        largest master facet (every rank's own: the whole surface's), the closeness
        tolerance's length. Collective."""
        p, dim, comm = self.pairing, self.mesh.dim, self.values.comm
        local = self.values.local_nodes(p.slave)           # (its own: owned)
        self.slaves = (local, self.mesh.points[local])
        _, pts, new = geo.master_facets
        self.mine = Fetch(comm, (new.reshape(-1, 1) * dim + np.arange(dim)).ravel(),
                          self.values.node_ranges, dim)
        size = float(np.linalg.norm(np.ptp(pts, axis=1), axis=1).max(initial=0.0))
        self.length = comm.allreduce(size, op=MPI.MAX)
        self._resurface(geo.near)

    def _resurface(self, near) -> None:
        """The surfaces made again with the master facets ``near`` (the relations form's
        numbers learnt) and the plan of their u. Collective."""
        self.geo.set_near(near)
        self.surf = Surfaces.of([(self.pairing.slave, self.slaves[1]), (near.ids, near.pts)])
        self._plan(self.surf.ids)
        self._start_u = None

    def _follow(self, u: np.ndarray) -> float:
        """The master facets that came within the search radius of this rank's slaves on the
        current configuration sent to it (``update_near``) and its surfaces made again with
        them (the pairs' facets renumbered); the search radius: the scene's, or the largest
        master facet's extent on the current configuration (``pair_nodes``' default on the
        whole master). Collective."""
        geo, dim = self.geo, self.mesh.dim
        _, pts, _ = geo.master_facets
        mine_x = pts + self.mine(np.ascontiguousarray(u).ravel()).reshape(pts.shape)
        radius = self.spec.search_radius
        if radius is None:
            radius = facet_extent(self.values.comm, mine_x)
        local, slave_pts = self.slaves
        near, new = update_near(self.values.comm, geo.near, slave_pts + u[local, :dim],
                                geo.master_facets, mine_x, radius)
        if new:   # (facets keep their relative order: the pairs' facets renumbered)
            p = self.pairing.subset(np.arange(len(self.pairing)))
            p.facet = facet_index(near.ids, geo.near.ids[p.facet])
            self.pairing = p
            self._resurface(near)
        return radius

    def _displacement(self, q: np.ndarray) -> np.ndarray:
        return q.reshape(self.mesh.num_points, -1)[:, self.fields_.columns(self.u)]

    def _repair(self, q: np.ndarray, start: bool = False) -> bool:
        """Pairs made again at q (collective); True when some rank's tuple moved."""
        u = self._displacement(q)
        radius = self._follow(u)   # (first: it may make the surfaces again)
        us = self.surface_u(u)
        surf, ft = self.surf, self.mesh.facet_type
        x = surf.points + us
        slave, facets = surf.compact(self.pairing.slave), surf.compact(self.geo.near.ids)
        new = pair_nodes(x, slave, facets, ft, radius)
        # a slave keeps its facet while its projection stays in it and is as close (on a kink
        # of the master it would flip between two facets from one iteration to the next), and
        # when no facet faces it (past the master's end: clipped to its facet), as the
        # relations form's finite sliding does
        cur, inside = pair_on(x, slave, facets, self.pairing.facet, ft, KEEP_TOL)
        best = np.where(new.paired, np.abs(new.gap), np.inf)
        keep = inside & (np.abs(cur.gap) <= best + 1e-9 * self.length) | ~new.paired
        for name in new.__dataclass_fields__:
            getattr(new, name)[keep] = getattr(cur, name)[keep]
        new = surf.to_input(new)
        ids = np.concatenate([new.slave[:, None], new.master], axis=1)
        moved = self.geo.any_rank(not np.array_equal(ids, self.tuple_ids))
        self.pairing = new
        if moved:
            self._declare(new)
            self.restructured = True
            self.repairs += 1
        else:
            self.gradients(new)
        actual = new.gap   # at x; the rows' offset: g = actual + Dn·(q' − q)
        new.gap = actual - self.rows_at(us)[0]
        if start:
            self.touching = actual <= self.touch
            self._start_u = us
        if self._start_u is None:   # (the surface made again since the step's start)
            self._start_u = self.surface_u(self._displacement(self.q_start))
        gT = self.rows_at(self._start_u)[1]
        turn = np.einsum("mkx,mjx->mjk", self.committed_tangents, new.tangents)
        self.reference = (gT, turn)
        return moved

    def begin_step(self, q: np.ndarray, active: dict, at) -> bool:
        self.q_start = q.copy()
        self._repair(q, start=True)
        return False

    def refresh(self, q: np.ndarray, lam: dict, active: dict) -> bool:
        return self._repair(q)

    def step_state(self, state: dict) -> dict:
        """The committed friction force on the current tangents, the tangential displacement
        from the step's start on the current rows."""
        if self.reference is None:
            return state
        gT, turn = self.reference
        return {**state, "gT": gT, "t": np.einsum("mjk,mk->mj", turn, state["t"])}

    def end_step(self) -> None:
        self.committed_tangents = self.pairing.tangents

    def restart_state(self) -> dict:
        """The pairs of the last converged step and their tangents (those of a slave no facet
        faces any more, and the committed friction force's basis), the master facets near
        (the pairs' facets index them)."""
        return {"pairing": self.pairing, "committed_tangents": self.committed_tangents,
                "near": self.geo.near}

    def load_restart_state(self, state: dict) -> None:
        # the tuples stay the pattern's: the next step's pairing moves them (restructured)
        self.pairing = state["pairing"]
        self.committed_tangents = state["committed_tangents"]
        self._resurface(state["near"])
        self.gradients(self.pairing)
