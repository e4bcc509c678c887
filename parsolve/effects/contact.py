"""Contact and Coulomb friction (the paper's third use) as relations only.

Per paired slave node (``parsolve.contact``: node-to-segment/face pairing or a rigid obstacle):

* frictionless (μ = 0): one unilateral associated row ``Dn·q ≥ −g0`` (relation
  ``<name>_normal``): the active set closes and opens it;
* Coulomb (μ > 0): the same normal row with the non-associated dual ``D = −(Dn − μ Dt·s)``
  (the normal reaction carries the friction force of a sliding node, ``Rt = −μ Rn s``), and a
  tangential associated equality row per tangent, ``Dt·q = Dt·q_n`` (relation
  ``<name>_tangent``: no slip during the step). The tangential row is *switched*, not
  unilateral: enforced in STICK, released in SLIP and OPEN. Its switch and the slip sense s
  are decided between Newton iterations by ``parsolve.contact.friction.friction_update``
  (``refresh``): a sticking node whose force leaves the cone slides with s = −Rt/|Rt|, a
  sliding node that moves against s sticks again, a node that closes sticks. The sense s is
  written in place into the normal row's dual, whose sparsity is that of ``Dn``: re-assembly
  stays a value update. The normal rows stay with the active set (closing on penetration,
  opening on tension, orientation o = −sign(A·D) = +1 since n·t = 0).

In stick the normal dual still carries μ s (whatever s was last): the tangential multiplier
absorbs it, the friction force is ``Rt = −λt − μ Rn s`` (``friction.reactions``).

The tangential rows: in 2D one row along t per node (s = ±1 only flips the dual). In 3D two
rows per node along s and n × s (same entries as Dt₁, Dt₂: a direction change is a value
update of A, D and the stick values). With ``direction = "reaction"`` (the default) the
directions follow a generalised Newton step (``friction.SlipNewton``, docs/contact.md §4.1):
a node that starts sliding is held (its row across s blocked) until it has a slip, then free
(both rows released) with s along its slip and, in the Newton matrix only, the cross
stiffness κ = mu Rn / γ that linearises the dual's dependence on s: κ (n × s)(n × s)ᵀ on the
relative slip across s, slave and master nodes alike, a term on the tuple of the row across s
(``row_terms``: what that row, enforced with compliance 1/κ and its multiplier discarded,
would add to the stiffness; the row itself is released) (4–13
iterations per step in the 3D tests, obstacles and master bodies, finite sliding and mortar;
not growing with the surface; the same on any number of ranks). ``"displacement"``
releases both rows and takes s along the slip increment (the plain update): it does not
converge in partial slip (kept for study).
A node that closes while moving along the surface starts sliding that way (sticking it at
the step's starting point would pull it back, open it again, and cycle).

On a distributed mesh (each rank its part) the rows stay in input DOFs. Each rank pairs the
slave nodes it owns and builds their rows alone (``Relation.ids``: each entry's place among
the paired slaves in input-id order, the same on any partition). On a master region (node-to-
face, mortar) against the master facets near its slaves (``contact.distributed``: each rank's
slave box gathered, the facets that meet it sent; never the whole surface; finite sliding:
again on the current configuration, the facets new to a rank sent as they come near); a
row's values on a master node another rank owns are fetched from it (``_read_rows``), its D
entries there sent to it (``la.relation_set``), and the Newton-matrix terms on its nodes (3D
friction's cross stiffness, finite sliding's geometric stiffness) declared by the rank alone,
their entries in rows another rank owns sent there (``effects.row_terms``, ``la.tuple_rows``).
Against a rigid obstacle the rank projects its own slave nodes. Node states, slip directions
and decisions are the rank's own; only a change (any rank's) and the resultants cross the
ranks.

Held, tied and shared nodes: a contact node that a Dirichlet condition also holds, a periodic
tie between contact nodes, a node in two surfaces along one normal make the enforced rows
dependent; the solver leaves the dependent contact rows out of each solve (exactly, by
``parsolve.contact.dependent``: the same displacements as with the node out of the surface,
its reaction taken by the rows it depends on) and fails, naming the row, if those rows push it
through the obstacle. A body held only by contact (nothing, or a soft support, in the contact
direction) starts with its rows open and a singular first operator: the first solve is then
retried with every contact row closed, and the active set opens those that pull (no
``closed`` tolerance to guess).

Refused input (exit 2, file and key): a name that is not a plain name (it names relations,
fields and HDF5 groups), μ < 0, not finite or above ``friction.MU_MAX``, an obstacle that no
facet of the slave surface faces or that every slave node starts inside. An obstacle farther
than the mesh's size from every slave node is legitimate (a body lowered onto it over the
steps) and said in a warning; ``search_radius`` bounds an obstacle's initial gaps too.

Scene schema::

    [[contact]]
    name = "base"                  # relations base_normal (and base_tangent); a plain name
    slave = "bottom"               # boundary region (nodes) of the slave body
    master = "top_of_foundation"   # boundary region (facets) of the master body, or:
    # obstacle = { plane = { origin = [0, 0], normal = [0, 1] } }
    #            { cylinder = { centre = [..], radius = R, axis = [..] (3D), inside = false } }
    #            { sphere = { centre = [..], radius = R, inside = false } }
    friction = 0.3                 # 0 ≤ μ ≤ 10; 0 or absent: frictionless
    direction = "reaction"         # 3D slip direction update: "reaction" (default) or
    #                                "displacement" (see below; 2D: the sense needs neither)
    search_radius = 0.1            # largest initial gap paired (default: one facet extent;
    #                                obstacles: any gap); finite sliding: the size of each
    #                                slave's span of facets, made again (a new operator
    #                                pattern) when it nears the span's edge
    discretization = "mortar"      # "node_to_segment" (default) or "mortar" (master region
    #                                only: dual mortar rows, parsolve.contact.mortar in 2D,
    #                                mortar3d on triangle, quad, triangle6 faces in 3D)
    closed = 1e-9                  # initial gaps ≤ this (relative to the mesh size) start closed
    #                                (a floating body needs no larger one: see above)
    sliding = "finite"             # "small" (default: paired once) or "finite" (paired again
    #                                each iteration; any master or obstacle, 2D and 3D:
    #                                effects/contact_sliding.py)
    report = true                  # each step's line: ΣRn, ΣRt, |ΣRt|/ΣRn, open/stick/slip rows
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from mpi4py import MPI

from parsolve.contact import distributed as dist
from parsolve.contact import friction as fr
from parsolve.contact import obstacles
from parsolve.contact.mortar import master_half, mortar_pairing
from parsolve.contact.mortar3d import mortar_pairing_3d
from parsolve.contact.pairing import pair_nodes
from parsolve.contact.rows import friction_dual, node_rows, normal_rows, normal_values, \
    repeated, slip_vectors, span_rows, tangent_rows
from parsolve.contact.sliding import Spans, obstacle_spans
from parsolve.contact.surfaces import Surfaces, canonical_facets
from parsolve.effects.base import Effect, displacement_field
from parsolve.effects.contact_sliding import FiniteSliding
from parsolve.effects.row_terms import RowTerm
from parsolve.fem.element_matrices import Term
from parsolve.errors import InputError
from parsolve.la.dofmap import DofMap
from parsolve.la.fetch import Fetch
from parsolve.evolution import CONSTANT
from parsolve.mesh.topology import FACETS, boundary_facets
from parsolve.relations import Relation, rows_here
from parsolve.schema import NAME_PATTERN
from parsolve.collective import agree

OBSTACLES = ("plane", "cylinder", "sphere")
DISCRETIZATIONS = ("node_to_segment", "mortar")
SLIDINGS = ("small", "finite")
# finite sliding: the round-off of a slip measured on the geometry, × ε × the largest coordinate
# (``Contact._angle_tolerance``)
SLIP_ROUNDOFF = 16.0


@dataclass
class ContactSpec:
    name: str
    slave: str
    master: str | None
    obstacle: tuple[str, dict] | None    # (kind, parameters)
    mu: float
    direction: str
    search_radius: float | None
    closed: float
    key: str
    discretization: str = "node_to_segment"
    sliding: str = "small"
    report: bool = False        # ΣRn, ΣRt, |ΣRt|/ΣRn, open / stick / slip with each step's line


def parse(t, dim: int) -> ContactSpec:
    name = t.get("name", str)
    if not NAME_PATTERN.fullmatch(name):   # it names relations and HDF5 groups and fields
        raise t.error("name", f"{name!r} is not a plain name (a letter or '_', then letters, "
                              "digits, '_' or '-'; at most 64 characters)")
    slave = t.get("slave", str)
    master = t.get("master", str, None)
    obs = t.table("obstacle", None)
    if (master is None) == (obs is None):
        raise t.error("master", "give exactly one of master (a region) and obstacle")
    obstacle = _obstacle(obs, dim) if obs is not None else None
    mu = fr.check_mu(t.get("friction", (float, int), 0.0), t.source, t.key("friction"))
    direction = t.get("direction", str, "reaction", choices=fr.DIRECTION_MODES)
    radius = t.get("search_radius", float, None)
    if radius is not None and not radius > 0:
        raise t.error("search_radius", "must be positive")
    closed = t.get("closed", float, 1e-9)
    if closed < 0:
        raise t.error("closed", "must be >= 0")
    discretization = t.get("discretization", str, "node_to_segment", choices=DISCRETIZATIONS)
    if discretization == "mortar" and master is None:
        raise t.error("discretization", "mortar needs a master region (not an obstacle)")
    sliding = t.get("sliding", str, "small", choices=SLIDINGS)
    report = t.get("report", bool, False)
    t.done()
    return ContactSpec(name, slave, master, obstacle, mu, direction, radius, closed, t.path,
                       discretization, sliding, report)


def _obstacle(t, dim: int) -> tuple[str, dict]:
    kinds = [k for k in OBSTACLES if t.has(k)]
    if len(kinds) != 1:
        raise t.error(OBSTACLES[0], f"give exactly one of {', '.join(OBSTACLES)}")
    sub = t.table(kinds[0])
    t.done()
    if kinds[0] == "plane":
        params = {"origin": sub.floats("origin", dim), "normal": sub.floats("normal", dim)}
    else:
        params = {"centre": sub.floats("centre", dim), "radius": sub.get("radius", float),
                  "inside": sub.get("inside", bool, False)}
        if kinds[0] == "cylinder" and dim == 3:
            params["axis"] = sub.floats("axis", 3)
    sub.done()
    return kinds[0], params


class Contact(FiniteSliding, Effect):
    """One contact surface (slave nodes against a master surface or a rigid obstacle)."""

    symmetric = True

    # slave-surface nodes that rows hold besides their own slave node (3D mortar on triangle6:
    # a midside's row holds its edge's corners); the resultants count each row's slave share
    side_nodes = np.zeros(0, dtype=np.int64)

    def __init__(self, spec: ContactSpec, mesh, regions, fields, source: str,
                 radial: bool = False):
        self.spec, self.mesh, self.fields_, self.source = spec, mesh, fields, source
        self.radial = radial    # axisymmetric: mortar integrals over the surface of revolution
        # rows on a master region (node-to-face, mortar) built per rank (``_pair_here``)
        self.here = spec.master is not None
        self._fetches: dict = {}            # plans of the values read on other ranks' DOFs
        self.name = f"contact {spec.name}"
        key = spec.key
        self.u = displacement_field(fields)
        if self.u is None:
            raise InputError("contact needs a displacement field (a [[materials]] section)",
                             source, key)
        # rows over input DOFs; their values from this rank's vector (the DOF map's owned
        # reductions)
        self.values = DofMap(getattr(regions, "comm", None), mesh, fields.ncomp)
        self.span: Spans | None = None     # finite sliding (set by _pair)
        self._facet_now = None              # finite sliding: the facets faced now (compact)
        self._facet_committed = None        # ... at the last converged step
        self._committed_slip = False
        self._compact = None                # finite sliding, mortar: the rows now (compact)
        self._covered = None                # finite sliding on a master region: a facet (mortar:
        #                                     a row) has held the slave (``_with_uncovered``)
        self._covered_committed = None
        self._restructuring = False         # finite sliding: spans made again, rows not yet
        self._returns = None                # node-to-segment finite sliding: per slave, its
        self._left = self._last_return = None   # returns to a facet it left within the step
        self._repairings = 0
        self._x_reach = None                # finite sliding: the mesh's largest coordinate
        self._check_slave(regions)
        # rows built per rank (``_pair_here``, ``_pair_obstacle``): the global number of each
        # entry held here (``ids``) among ``entries``
        self._known = np.zeros((2, 0), dtype=np.int64)   # (master ids near, their numbers)
        self.pairing = self._pair(regions)
        self._compact_committed = self._compact
        self._covered_committed = self._covered
        if self.entries == 0:
            raise InputError("no slave node faces the master surface within the search radius",
                             source, f"{key}.slave")
        p = self.pairing
        # finite sliding against a deformable master's facets (node-to-segment / face) or a
        # curved obstacle: the force's dependence on the geometry in the Newton matrix
        # (``contact.geometry``), in rows per slave: the facet's turns and the projection's
        # slides, or the obstacle normal's turns
        curved = spec.obstacle is not None and spec.obstacle[0] != "plane"
        self.geometric = self.span is not None and (
            curved or spec.master is not None and spec.discretization == "node_to_segment")
        self.geometric_rank = (mesh.dim - 1) * (1 if curved else 2)
        self.symmetric = spec.mu == 0.0 and not self.geometric   # (its rows are not)
        # finite sliding on a master region: its spans may be made again (a rigid obstacle's
        # rows hold the slave alone)
        self.restructures = self.span is not None and spec.master is not None
        self.turning = fr.SlipNewton()
        # the Newton matrix's terms (``row_terms``), laid on their rows' tuples by ``relations``
        cross = self.frictional and mesh.dim == 3 and spec.direction == "reaction"
        self.cross = RowTerm(self.u, True, self.new_of) if cross else None
        self.geo = RowTerm(self.u, False, self.new_of) if self.geometric else None
        self._kappa = self._geo_rows = None
        self._start_entries()

    def _start_entries(self) -> None:
        """The pairing's entries' starting state and rows."""
        p, spec, mesh = self.pairing, self.spec, self.mesh
        n, dm1 = len(p), mesh.dim - 1
        size = float(np.max(mesh.extent))   # the whole mesh's (a part's own would differ)
        closed = p.gap <= spec.closed * size
        # per node: state, slip direction (tangent basis); the committed ones and the trial ones
        self.node_state = np.where(closed, fr.STICK, fr.OPEN).astype(np.int8)
        self.direction = np.ones((n, dm1)) / np.sqrt(dm1)
        self.committed = (self.node_state.copy(), self.direction.copy())
        # finite sliding: the total slip of the converged steps (the output adds the step's)
        self.slip_base = np.zeros(n * dm1)
        # the multipliers (normal, tangential) of the last iterate and of the last converged
        # step, for the geometric stiffness
        self._lam_now = self._lam_committed = (np.zeros(n), np.zeros(n * dm1))
        self._build_rows()

    # ------------------------------------------------------------------ geometry

    def _check_slave(self, regions) -> None:
        """The slave region lies on the boundary. On a distributed mesh each rank checks its
        owned nodes (all their cells are local: a local boundary facet through an owned node
        is a boundary facet of the whole mesh) and the counts are summed: every rank agrees."""
        key = self.spec.key
        slave = regions(self.spec.slave, f"{key}.slave").nodes
        slave = slave[slave < self.mesh.n_owned]
        boundary = np.unique(boundary_facets(self.mesh)[0])
        counts = np.array([np.setdiff1d(slave, boundary).size, slave.size])
        counts = self.values.comm.allreduce(counts)
        off, total = (int(c) for c in counts)
        if total == 0 or off:
            raise InputError(f"the slave region {self.spec.slave!r} must lie on the boundary "
                             f"({off} of its {total} nodes are inside the mesh)",
                             self.source, f"{key}.slave")

    def _pair(self, regions):
        """The paired slave nodes this rank owns, in input ids (``_pair_here``,
        ``_pair_obstacle``)."""
        return self._pair_here(regions) if self.here else self._pair_obstacle(regions)

    def _pair_obstacle(self, regions):
        """The slave nodes this rank owns projected on the rigid obstacle, in input ids; their
        rows are this rank's own (they hold the slave alone: ``ids``, each entry's place among
        the paired slaves in input-id order). The checks are reductions: every rank agrees.
        Collective."""
        spec, comm = self.spec, self.values.comm
        okey = f"{spec.key}.obstacle.{spec.obstacle[0]}"
        slave, slave_pts = self._own_slaves(regions)
        surf = Surfaces.of([(slave, slave_pts)])

        def project():
            try:
                return self._project(surf.points, np.arange(slave.size))
            except ValueError as exc:
                raise InputError(str(exc), self.source, okey) from None
        p = agree(comm, project)
        self._check_reach(p, okey)
        self._check_facing(regions, okey)
        if spec.search_radius is not None:
            p.paired &= p.gap <= spec.search_radius
        p = p.only_paired()
        if spec.sliding == "finite":   # rows on the slave alone: the spans are empty
            self.span = obstacle_spans(surf, p, float(np.max(self.mesh.extent)))
        p = surf.to_input(p)
        self.ids, self.entries = dist.global_positions(comm, p.slave)
        return p

    def _own_slaves(self, regions) -> tuple[np.ndarray, np.ndarray]:
        """The slave nodes this rank owns: increasing input ids and their coordinates."""
        nodes = regions(self.spec.slave, f"{self.spec.key}.slave").nodes
        nodes = nodes[nodes < self.mesh.n_owned]
        ids = self.mesh.global_nodes[nodes].astype(np.int64)
        order = np.argsort(ids)
        return ids[order], self.mesh.points[nodes[order]]

    def _pair_here(self, regions):
        """The rows of the slave nodes this rank owns against the master facets near them (a
        bounded exchange: ``contact.distributed``), in input ids: node-to-face pairs or
        mortar rows (from this rank's slave facets: every facet through an owned node is
        here); finite sliding: with the slaves a facet (a row) will hold later, and their
        spans. ``ids``: each entry's place in the whole pairing (paired slaves in input-id
        order: the same on any partition). The lengths (search radius, largest facets) are
        the whole surfaces', the checks summed over the ranks: every rank agrees.
        Collective."""
        spec, mesh, key, comm = self.spec, self.mesh, self.spec.key, self.values.comm
        mine = self._local_facets(regions(spec.master, f"{key}.master"))
        if comm.allreduce(mine[0].shape[0]) == 0:
            raise InputError(f"the master region {spec.master!r} has no boundary facet",
                             self.source, f"{key}.master")
        slave, slave_pts = self._own_slaves(regions)
        mortar, finite = spec.discretization == "mortar", spec.sliding == "finite"
        sides = [(slave, slave_pts)]
        length = dist.facet_extent(comm, mine[1])      # the largest master facet
        radius = length if spec.search_radius is None else spec.search_radius
        box, reach = slave_pts, radius
        if mortar:   # the rows integrate over the slave facets: their nodes span the box
            sfacets, sfacet_pts, _ = self._local_facets(regions(spec.slave, f"{key}.slave"))
            sides.append((sfacets, sfacet_pts))
            slave_reach = dist.facet_extent(comm, sfacet_pts)
            row_radius = max(length, slave_reach) if spec.search_radius is None else radius
            box = sfacet_pts.reshape(-1, mesh.dim)
            if finite:   # (spans: within the radius plus the slave facets' reach)
                box, reach = slave_pts, radius + slave_reach
            else:
                reach = row_radius
        self._mine, self._reach, self._radius, self._own_ids = mine, reach, radius, slave
        near, _ = dist.update_near(comm, dist.start_near(*mine[0].shape[1:], mesh.dim), box,
                                   mine, mine[1], reach)
        self.set_near(near)
        facets = self._near.ids
        self._check_shared(slave, facets)
        surf = Surfaces.of(sides + [(facets, self._near.pts)])
        cf, own = surf.compact(facets), surf.compact(slave)
        if mortar:
            half = self._master_half(mine[1])
            try:
                p = self._mortar(surf.points, surf.compact(sfacets), cf, row_radius, half)
            except ValueError as exc:   # 3D faces that are not triangle, quad, triangle6
                raise InputError(str(exc), self.source, f"{key}.discretization") from None
            self.side_nodes = np.unique(sfacets)
            p = p.pairing.only_paired()
            p = p.subset(np.flatnonzero(np.isin(p.slave, own)))   # its owned slaves' rows
            if finite:   # (with the slaves rows will hold later)
                p = self._mortar_with_uncovered(surf, p, cf, surf.compact(sfacets), own,
                                                slave_reach, length)
        else:
            p = pair_nodes(surf.points, own, cf, mesh.facet_type, radius)
            # (finite: with the slaves a facet will face later)
            p = self._with_uncovered(surf, p, cf, length) if finite else p.only_paired()
        p = surf.to_input(p)
        self.ids, self.entries = dist.global_positions(comm, p.slave)
        return p

    @property
    def master_facets(self) -> tuple:
        """This rank's own master facets (input ids, points, global numbers): ``_pair_here``."""
        return self._mine

    @property
    def near(self):
        """The master facets near this rank's slaves (``dist.NearFacets``)."""
        return self._near

    def set_near(self, near) -> None:
        """Hold the master facets ``near`` and learn the global numbers of their nodes (those
        of its rows' tuples: ``new_of``)."""
        self._near = near
        self._known = np.unique(np.column_stack([near.ids.ravel(), near.new.ravel()]),
                                axis=0).reshape(-1, 2).T

    def _master_half(self, mine_pts: np.ndarray) -> np.ndarray:
        """The whole master surface's largest half-extent per axis (mortar candidates), from
        every rank's own facets (``mine_pts``: their points). Collective."""
        half = np.empty(self.mesh.dim)
        self.values.comm.Allreduce(master_half(mine_pts), half, op=MPI.MAX)
        return half

    def _local_facets(self, region) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """A region's boundary facets on this rank (those with an owned node): input ids,
        coordinates and the nodes' global numbers, in the canonical order (``surfaces``: as
        the whole surface's)."""
        nfn = len(FACETS[self.mesh.cell_type][0])
        local = np.asarray(region.facets, dtype=np.int64).reshape(-1, nfn)
        return canonical_facets(self.mesh.global_nodes[local].astype(np.int64),
                                self.mesh.points[local],
                                np.asarray(self.mesh.node_new)[local].astype(np.int64))

    def new_of(self, ids: np.ndarray) -> np.ndarray:
        """The global numbers of input node ids: this rank's nodes' from its mesh, the master
        nodes near its slaves' from their facets' exchange (``_pair_here``)."""
        ids = np.asarray(ids, dtype=np.int64)
        local = self.values.local_nodes(ids)
        out = np.asarray(self.mesh.node_new)[np.maximum(local, 0)].astype(np.int64)
        far = local < 0
        if far.any():
            known, new = self._known
            out[far] = new[np.searchsorted(known, ids[far])]
        return out

    def _fetch(self, dofs: np.ndarray) -> Fetch:
        """The plan of q's values at input DOFs of nodes this rank knows (``new_of``).
        Collective."""
        ncomp = self.fields_.ncomp
        node, comp = np.divmod(np.asarray(dofs, dtype=np.int64), ncomp)
        return Fetch(self.values.comm, self.new_of(node) * ncomp + comp,
                          self.values.node_ranges, ncomp)

    def _check_shared(self, slave: np.ndarray, facets: np.ndarray) -> None:
        """Slave nodes (this rank's) in master facets (those near them: a slave node in a
        master facet lies in its box), counted over the ranks. Collective."""
        comm = self.values.comm
        shared = np.intersect1d(slave, facets.ravel())
        count = comm.allreduce(shared.size)
        if count:
            first = comm.allreduce(int(shared[0]) if shared.size else np.iinfo(np.int64).max,
                                   op=MPI.MIN)
            raise InputError(f"master and slave surfaces share {count} node(s) (first: "
                             f"{first})", self.source, f"{self.spec.key}.master")

    def _read_rows(self, dofs: np.ndarray, rows: np.ndarray, coefs: np.ndarray, nrows: int,
                   q: np.ndarray) -> np.ndarray:
        """A q of this rank's rows over input DOFs, their entries on other ranks' DOFs (a
        master node) fetched from the owners (planned once per DOF array, until the rows'
        entries change). Collective."""
        values = self.values
        sel, local = values.owned_dof_entries(dofs)
        part = values.owned_part(sel, local, rows, coefs, nrows, q)
        if values.comm.size == 1 or not self.here:   # (an obstacle's: the slave's alone)
            return part
        key = id(dofs)
        if key not in self._fetches:   # (the array kept: its id is not reused meanwhile)
            at = np.setdiff1d(np.arange(dofs.size), sel)
            self._fetches[key] = (at, self._fetch(dofs[at]), dofs)
        at, plan, _ = self._fetches[key]
        got = plan(q)
        return part + np.bincount(rows[at], weights=coefs[at] * got, minlength=nrows)

    def _relation_values(self, r: Relation, q: np.ndarray) -> np.ndarray:
        """A q of a relation's rows held here (``_read_rows``). Collective."""
        return self._read_rows(r.a_dofs, r.a_rows, r.a_vals, r.nrows, q)

    def sum_ranks(self, x):
        """Σ over the ranks of a sum over this rank's rows (rows built per rank)."""
        return self.values.comm.allreduce(x, op=MPI.SUM)

    def any_rank(self, x: bool) -> bool:
        """The same, of a decision."""
        return self.values.comm.allreduce(bool(x), op=MPI.LOR)

    def _project(self, points: np.ndarray, nodes: np.ndarray):
        """The nodes (compact ids) projected on the rigid obstacle (``contact.obstacles``)."""
        kind, params = self.spec.obstacle
        src, okey = self.source, f"{self.spec.key}.obstacle.{kind}"
        if kind == "plane":
            return obstacles.plane(points, nodes, params["origin"], params["normal"], src, okey)
        if kind == "cylinder":
            return obstacles.cylinder(points, nodes, params["centre"], params["radius"],
                                      params.get("axis"), params["inside"], src, okey)
        return obstacles.sphere(points, nodes, params["centre"], params["radius"],
                                params["inside"], src, okey)

    def _rows(self, vectors: np.ndarray, pairing=None):
        """Rows along one vector per entry: node_rows, or (finite sliding) over the spans."""
        p = self.pairing if pairing is None else pairing
        if self.span is None:
            return node_rows(p, vectors)
        return span_rows(p, vectors, *self.span.ptr_for(len(p)))

    def _dual_coef(self) -> np.ndarray:
        """Coefficients of Dn − μ Dt·s (the normal rows' dual is their negation)."""
        p = self.pairing
        if self.span is None:
            return friction_dual(p, self.mu, self.direction).coef
        return self._rows(p.normal - self.mu * slip_vectors(p, self.direction)).coef

    def _mortar(self, points: np.ndarray, slave_facets: np.ndarray, facets: np.ndarray,
                radius: float | None = None, half: np.ndarray | None = None):
        """The mortar rows of the surfaces (compact numbering) on the configuration points
        (``radius``, ``half``: the whole surfaces' search radius and largest master
        half-extent when these are a rank's part; default: the scene's radius, theirs)."""
        ft = self.mesh.facet_type
        radius = self.spec.search_radius if radius is None else radius
        if self.mesh.dim == 3:
            return mortar_pairing_3d(points, slave_facets, facets, ft, radius, half=half)
        return mortar_pairing(points, slave_facets, facets, ft, radius, radial=self.radial,
                              half=half)

    def _check_facing(self, regions, key: str) -> None:
        """Refuse an obstacle that no facet of the slave surface faces (outward normal of the
        slave body against the obstacle's normal at the facet's first node: n_s · n < 0
        somewhere): its normal points into the slave body, which would then be pushed through
        it. Each rank's facets through an owned node; one reduction. Collective."""
        comm = self.values.comm
        facets, pts, _ = self._local_facets(regions(self.spec.slave, f"{self.spec.key}.slave"))
        if comm.allreduce(facets.shape[0]) == 0:
            return
        if self.mesh.dim == 2:
            d = pts[:, 1] - pts[:, 0]
            normal = np.column_stack([d[:, 1], -d[:, 0]])   # outward (FACETS orientation)
        else:
            normal = np.cross(pts[:, 1] - pts[:, 0], pts[:, 2] - pts[:, 0])
        facing = False
        if facets.shape[0]:   # (its first nodes are slave nodes: projected by their owner)
            o = self._project(pts[:, 0], np.arange(facets.shape[0])).normal
            facing = bool(np.any(np.einsum("fx,fx->f", normal, o)
                                 < -1e-6 * np.linalg.norm(normal, axis=1)))
        if not comm.allreduce(facing, op=MPI.LOR):
            raise InputError("no facet of the slave surface faces the obstacle (its normal "
                             "points into the slave body: is its sign right?)", self.source, key)

    def _check_reach(self, p, key: str) -> None:
        """An obstacle the slave surface cannot meet as written: every slave node behind its
        surface (its normal points into the slave body, or the body starts inside it) is
        refused; an obstacle farther than the mesh's size from every slave node is legitimate
        (a body lowered onto it over the steps) but said in a warning: a misplaced origin
        would otherwise give a run without contact and no message. p: this rank's slaves
        (the extreme gaps: reductions; collective)."""
        comm = self.values.comm
        size = float(np.max(self.mesh.extent))   # the whole mesh's, on every rank
        lo = comm.allreduce(float(p.gap.min(initial=np.inf)), op=MPI.MIN)
        hi = comm.allreduce(float(p.gap.max(initial=-np.inf)), op=MPI.MAX)
        if hi < -1e-9 * size:
            raise InputError(f"every slave node starts inside the obstacle (gaps from "
                             f"{lo:.3g} to {hi:.3g}): does its normal point "
                             "into the slave body?", self.source, key)
        if lo > size and hasattr(self.mesh, "warnings"):
            self.mesh.warnings.append(
                f"{self.source}: {key}: no slave node is within the mesh's size ({size:.3g}) of "
                f"the obstacle (smallest gap {lo:.3g}): contact only if the body "
                "travels that far")

    def _build_rows(self) -> None:
        p = self.pairing
        if self.span is None:
            self.nrows = normal_rows(p)
            self.trows = tangent_rows(p)    # along the fixed tangents (slip measure, outputs)
        else:                               # finite sliding: over the spans
            self.nrows = self._rows(p.normal)
            self.trows = self._span_tangent_rows(p)
        self.n_dofs, self.t_dofs = self._row_dofs(self.nrows), self._row_dofs(self.trows)

    def _row_dofs(self, rows) -> np.ndarray:
        """The displacement DOFs (input numbering) of rows' entries."""
        return rows.node * self.fields_.ncomp + self.fields_.offset[self.u] + rows.comp

    def _tangent_coefs(self) -> np.ndarray:
        """Coefficients of the tangential relation's rows: 2D, along t; 3D, along the slip
        direction s and across it (n × s), per node (same entries as the fixed tangents)."""
        p = self.pairing
        if self.mesh.dim == 2:
            return self.trows.coef
        sv = slip_vectors(p, self.direction)
        vectors = np.stack([sv, np.cross(p.normal, sv)], axis=1).reshape(-1, 3)
        return self._rows(vectors, repeated(p, 2)).coef

    def _slip(self, q: np.ndarray) -> np.ndarray:
        """Tangential displacement of the slave relative to the master (rows of ``trows``)."""
        t = self.trows
        return self._read_rows(self.t_dofs, t.row, t.coef, t.nrows, q)

    @property
    def mu(self) -> float:
        return self.spec.mu

    @property
    def frictional(self) -> bool:
        return self.spec.mu > 0.0

    def failure_hints(self) -> list[str]:
        """Besides finite sliding's: every closed node sliding at the failed attempt's last
        iterate, with nothing else holding the body along the surface, is a tangential load
        above what friction can carry (μ N): no equilibrium exists, the operator is singular
        along the slide. (The node states are the whole surface's: the same on every rank.)"""
        hints = super().failure_hints()
        closed = self.node_state != fr.OPEN
        sticking = (self.node_state == fr.STICK).any()
        if self.frictional and self.any_rank(closed.any()) and not self.any_rank(sticking):
            hints.append(f"{self.source}: {self.spec.key}: every closed node of {self.spec.name!r} "
                         f"slides at the last iterate: with nothing else holding the body along the "
                         f"surface, the tangential load exceeds the friction capacity μN (μ = "
                         f"{self.mu:g}); hold it, lower the tangential load or raise the friction")
        return hints

    # ------------------------------------------------------------------ relations

    def relations(self) -> list[Relation]:
        """The relations form's relations (this rank's rows when built per rank: ``ids``)."""
        p, name = self.pairing, self.spec.name
        r = self.nrows
        dual = None
        if self.frictional:
            dual = (self.n_dofs, r.row, -self._dual_coef())
        normal = Relation(f"{name}_normal", r.nrows, r.row, self.n_dofs, r.coef,
                          normal_values(p), CONSTANT, ">=", dual, eliminate=False, forming=True)
        finite = self.span is not None    # its rows' values change at each step
        normal.meta = {"type": "contact", "key": self.spec.key,
                       "refresh": self.frictional or finite}
        self.normal = normal
        rows_here(normal, self.ids, self.entries)
        out = [normal]
        if self.frictional:
            t = self.trows
            tangent = Relation(f"{name}_tangent", t.nrows, t.row, self.t_dofs,
                               self._tangent_coefs(), np.zeros(t.nrows), CONSTANT, "=", None,
                               eliminate=False, forming=True)
            tangent.meta = {"type": "contact", "key": self.spec.key,
                            "refresh": self.mesh.dim == 3 or finite}
            self.tangent = tangent
            out.append(tangent)
            dm1 = self.mesh.dim - 1
            rows_here(tangent, (self.ids[:, None] * dm1 + np.arange(dm1)).ravel(),
                      self.entries * dm1)
        self._lay_terms(self.pairing)
        return out

    def _lay_terms(self, p, trows=None) -> None:
        """The tuples of its Newton-matrix terms (``row_terms``) from their rows' layout (p:
        the pairing, input ids; ``trows``: its tangential rows, if new): the cross stiffness's on the tangential rows (two per
        slave), the geometric stiffness's on the geometric rows; declared where this rank
        owns a node (rows per rank: every tuple its own slave). Collective unless the rows
        are this rank's own."""
        dim = self.mesh.dim
        if self.cross is not None:
            self.cross.lay(self.trows if trows is None else trows, 2, dim, self.values)
        if self.geometric:
            self.geo.lay(self._geometry_layout(p), self.geometric_rank, dim, self.values)

    def _set_dual(self) -> None:
        """The slip direction s into the normal row's dual and (3D) the tangential rows, in
        place (same entries); the stick rows keep the step's starting position."""
        self.normal.dual[2][:] = -self._dual_coef()
        if self.mesh.dim == 3:
            self.tangent.a_vals[:] = self._tangent_coefs()
            self.tangent.values[:] = self._stick_values()

    def _tangent_active(self, active: dict) -> None:
        """Tangential rows enforced where the node sticks; in 3D with the "reaction" mode a
        sliding node that is held (``SlipNewton.held``) keeps its row across s; a free one
        releases both, and the cross term carries, in the Newton matrix only, the stiffness
        κ (n × s)(n × s)ᵀ on the relative slip (the dual's dependence on s, linearised) over
        the tuple of its row across s: the slave and the master nodes the row holds."""
        stick = self.node_state == fr.STICK
        if self.mesh.dim == 2:
            active[self.tangent.name][:] = stick
            return
        sliding = (self.node_state == fr.SLIP) & (self.spec.direction == "reaction")
        kappa = self.turning.kappa
        free = sliding & ~self.turning.held & (kappa > 0.0)
        across = stick | sliding & self.turning.held
        active[self.tangent.name][:] = np.stack([stick, across], axis=1).ravel()
        self._kappa = np.where(free, kappa, 0.0)

    # ------------------------------------------------------------------ Newton hooks

    def attach(self, ctx) -> None:
        """The system's DOF map from now on (the same numbers as the one built with the
        effect: its lookups and reductions, shared)."""
        self.values = ctx.dofs

    def begin_step(self, q: np.ndarray, active: dict, at) -> bool:
        """Start a step from the committed state: stick rows hold the tangential displacement
        of the step's start; True when the dual changed (values to copy into the system)."""
        self.node_state, self.direction = (a.copy() for a in self.committed)
        if self.span is not None:
            if self._committed_slip:   # the last step converged (its last refresh at this q)
                self.slip_base += self.du.ravel()
                self._committed_slip = False
            self._facet_now = self._facet_committed   # a retried step starts from there too
            self._compact = self._compact_committed
            self._covered = self._covered_committed
            self._slide(q, start=True)
        # the normal rows in contact at the last converged step (initially: the closed gaps);
        # the same as the active set's after a converged step, and right after a failed one
        active[self.normal.name][:] = self.node_state != fr.OPEN
        self._lam_now = self._lam_committed
        self._set_geometry(active)
        if not self.frictional:
            return self.span is not None
        self.q_start = q.copy()
        self.turning.start(self.node_state)
        self.u_start = self._slip(q)
        self._set_dual()
        if self.span is None:
            self.tangent.values[:] = self._relation_values(self.tangent, q)
        self._tangent_active(active)
        return True

    def forces(self, lam: dict) -> tuple[np.ndarray, np.ndarray]:
        """(Rn (n,), Rt (n, dim-1)) on the slave nodes from the multipliers."""
        dm1 = self.mesh.dim - 1
        lam_t, direction = None, None
        if self.frictional:
            lam_t = lam[self.tangent.name].reshape(-1, dm1)
            direction = self.direction
            if dm1 == 2:  # rows along (s, n × s): back to the tangent basis (t1, t2)
                s, c = self.direction, lam_t
                lam_t = c[:, :1] * s + c[:, 1:] * np.column_stack([-s[:, 1], s[:, 0]])
        rn, rt = fr.reactions(lam[self.normal.name], lam_t, self.mu, direction)
        if rt.shape[1] != dm1:   # frictionless 3D: no tangential force, two components
            rt = np.zeros((rn.size, dm1))
        return rn, rt

    def slip_increment(self, q: np.ndarray) -> np.ndarray:
        """Tangential displacement of the slave relative to the master since the step's start."""
        dm1 = self.mesh.dim - 1
        if self.span is not None:   # measured on the geometry (``_slide``)
            return self.du
        return (self._slip(q) - self.u_start).reshape(-1, dm1)

    def refresh(self, q: np.ndarray, lam: dict, active: dict) -> bool:
        """One friction update between iterations (``active``: the normal rows' new set);
        True when a state or a slip direction changed (the dual and the tangential switches
        are then updated in place)."""
        # (rows per rank: any rank's rows moved, as on one rank)
        moved = self.span is not None and self.any_rank(self._slide(q, start=False))
        self.rows_moved = moved   # (the active set's history is of other rows)
        if self.geometric:
            self._lam_now = (lam[self.normal.name].copy(), lam[self.tangent.name].copy()
                             if self.frictional else self._lam_now[1])
        if not self.frictional:
            self.node_state = np.where(active[self.normal.name], fr.STICK, fr.OPEN).astype(np.int8)
            self._set_geometry(active)
            return moved
        rn, rt = self.forces(lam)
        closed = active[self.normal.name].astype(bool)
        du = self.slip_increment(q)
        closing = closed & (self.node_state == fr.OPEN)
        turning = self.mesh.dim == 3 and self.spec.direction == "reaction"
        state, direction, changed = fr.friction_update(
            self.node_state, self.direction, closed, rn, rt, du, self.mu, self.spec.direction,
            tol_angle=np.inf if turning else fr.TOL_ANGLE,   # (turning: settled by _turn)
            rn_max=self.values.max_abs(rn))
        # a node that closes while it moves along the surface slides that way: sticking it
        # at the step's starting point would pull it back (and may open it again: a cycle)
        norm = np.linalg.norm(du, axis=1)
        motion = max(self.values.max_abs(q - self.q_start), 1e-300)   # the step's, so far
        moving = closing & (norm > 1e-8 * motion)
        state[moving] = fr.SLIP
        direction[moving] = du[moving] / norm[moving, None]
        if turning:
            changed = self._turn(state, direction, lam, rn, rt, du, motion) or changed
        changed = self.any_rank(changed)   # (rows per rank: any rank's change, as on one rank)
        self.node_state, self.direction = state, direction
        if changed or moved or self.restructured:   # (spans made again: the dual's new entries)
            self._set_dual()
        if changed or moved or self.mesh.dim == 3:   # 3D: the cross rows' κ at this q
            self._tangent_active(active)
        self._set_geometry(active)
        return changed or moved

    def _turn(self, state, direction, lam, rn, rt, du, motion: float) -> bool:
        """Newton's update of the directions of the nodes that slide before and after this
        update (``fr.SlipNewton``: s along the slip, the cross stiffness of the next solve);
        True when one is not settled yet or changes mode. A settled update leaves s as solved
        (the outputs are those of the relations solved)."""
        sliding = (self.node_state == fr.SLIP) & (state == fr.SLIP)
        murn = self.mu * np.maximum(rn, 0.0)
        # a slip below 1e-6 of the step's motion has no direction: such a node stays held
        s, residual, switched = self.turning.turn(
            sliding, self.direction, du, rt, murn, 1e-6 * motion,
            self.values.comm)
        starting = (self.node_state == fr.STICK) & (state == fr.SLIP)
        excess = np.linalg.norm(rt, axis=1) - murn
        self.turning.begin_slip(starting & (excess > 0.0), excess, murn)
        free = sliding & ~self.turning.held   # (the nodes whose s is their slip's)
        unsettled = residual > self._angle_tolerance(np.linalg.norm(du, axis=1), free)
        unsettled = self.any_rank(bool(np.any(unsettled) or np.any(switched)))
        if unsettled:
            direction[sliding] = s[sliding]
        return unsettled

    def _angle_tolerance(self, gamma: np.ndarray, free: np.ndarray) -> np.ndarray:
        """Per node, the slip direction's settled angle: ``fr.TOL_ANGLE``, or under finite
        sliding, for a node whose s is its slip's (``free``), the angle the slip's round-off
        gives: measured on the geometry, t · (x_s − x_m0), the slip γ carries an error of a
        few ε |x| (|x| the mesh's largest coordinate), so its direction is known to
        ``SLIP_ROUNDOFF`` ε |x| / γ at best (a node of a refined die slipping 4e-8 in a press
        step: 1e-9 rad, which TOL_ANGLE never reached: Newton went on at its residual's
        floor). Collective the first time (the coordinates' largest over the ranks)."""
        tol = np.full(gamma.shape, fr.TOL_ANGLE)
        if self.span is None:   # (small sliding: the slip from q alone, no coordinates in it)
            return tol
        if self._x_reach is None:   # (the mesh's owned nodes: the same on any partition,
            # where a rank's surfaces, its slaves and the master facets near them, are not)
            owned = self.mesh.points[:self.mesh.n_owned]
            self._x_reach = max(self.values.max_abs(owned), 1e-300)
        floor = SLIP_ROUNDOFF * np.finfo(float).eps * self._x_reach
        tol[free] = np.maximum(fr.TOL_ANGLE, floor / np.maximum(gamma[free], 1e-300))
        return tol

    def evaluate(self, cells: np.ndarray, values: dict, state, secant: bool, at):
        """No forces of its own (the contact acts through its relations); in the Newton
        matrix, its terms: 3D friction's cross stiffness κ a aᵀ (a: the free nodes' rows
        across s) and finite sliding's geometric stiffness −Σ u wᵀ (``row_terms``)."""
        tangent = []
        if self.cross is not None and self._kappa is not None:
            a = self.cross.layout.dense(self.tangent.a_vals)[:, 1:]
            tangent.append(self.cross.matrices(self._kappa[:, None, None, None] * a, a))
        if self.geometric and self._geo_rows is not None:
            u, w = (self.geo.layout.dense(c) for c in self._geo_rows)
            tangent.append(self.geo.matrices(-u, w))
        return {}, tangent, state, None

    def terms(self) -> list[Term]:
        return [t.term for t in (self.cross, self.geo) if t is not None]

    # what the model builds (not the state between steps a restart restores)
    _BUILT = ("spec", "mesh", "fields_", "source", "radial", "name", "values", "_fetches")
    _ROW_VALUES = ("a_vals", "values")   # a relation's values the hooks change

    def restart_state(self) -> dict:
        """Everything but what the model builds: the committed node states and slip
        directions, the slip Newton's, the slip so far, finite sliding's pairing and spans;
        of its relations (shared with the system), the values the hooks change."""
        state = {k: v for k, v in vars(self).items()
                 if k not in self._BUILT and not isinstance(v, (Relation, RowTerm))}
        state["relation_values"] = {
            k: ({a: getattr(r, a) for a in self._ROW_VALUES}, r.dual[2] if r.dual else None)
            for k, r in vars(self).items() if isinstance(r, Relation)}
        return state

    def load_restart_state(self, state: dict) -> None:
        # spans made again since the start: the relations' entries and the operator anew
        # (the same spans: the operator as built, for the same round-off)
        state = dict(state)
        respanned = self.any_rank(self.restructures and not _equal(self.span, state["span"]))
        self._fetches.clear()   # (plans of the surfaces and rows now held)
        for k, (values, dual) in state.pop("relation_values").items():
            r = getattr(self, k)
            for a, v in values.items():
                if v is not None and getattr(r, a).shape == v.shape:
                    getattr(r, a)[...] = v   # in place: the relation set holds these arrays
            if dual is not None and r.dual[2].shape == dual.shape:
                r.dual[2][...] = dual
        vars(self).update(state)
        if respanned:
            self._restructuring = self.restructured = True

    def end_step(self) -> None:
        self.turning.commit()
        self._lam_committed = self._lam_now
        self._committed_slip = self.span is not None
        self._facet_committed = self._facet_now
        self._compact_committed = self._compact
        self._covered_committed = self._covered
        self.committed = (self.node_state.copy(), self.direction.copy())

    # ------------------------------------------------------------------ outputs

    def step_outputs(self, q: np.ndarray, lam: dict, active: dict) -> tuple[dict, dict]:
        """Per slave node (fields over all nodes, 0 elsewhere; state −1 elsewhere): normal and
        tangential reaction, gap (0 where the row is enforced), slip (total tangential
        displacement relative to the master, in the tangent basis), state; per surface: the
        resultant normal and tangential forces (Σ Rn, Σ Rt in the tangent basis). A finite-
        sliding slave that no facet has faced yet has the gap inf."""
        p, name = self.pairing, self.spec.name
        rn, rt = self.forces(lam)
        if self.frictional:
            state = np.where(active[self.normal.name], self.node_state, fr.OPEN)
        else:
            state = np.where(active[self.normal.name], fr.STICK, fr.OPEN)
        # an enforced row's gap is zero (its computed value is round-off, which depends on
        # the partition); an open node's is g0 + Dn·q
        closed = active[self.normal.name].astype(bool)
        # a row's slave share: 1, or 1 − 2α for a 3D mortar row of a triangle6 midside (its
        # row is scaled by it: its gap, its slip, its multiplier's share of the resultants)
        share = 1.0 - np.where(np.isin(p.master, self.side_nodes), p.weights, 0.0).sum(axis=1)
        gap = np.where(closed, 0.0, (p.gap + self._relation_values(self.normal, q)) / share)
        if self._covered is not None:   # no facet has faced it yet: no gap
            gap[~self._covered] = np.inf
        slip = self._slip(q) if self.span is None else self.slip_base + self.du.ravel()
        dm1 = self.mesh.dim - 1   # (a rank may hold no row: no -1 in the shape)
        slip = slip.reshape(share.size, dm1) / share[:, None]
        # over every node (0 elsewhere; state -1), or this rank's owned rows on a part
        nodal = self.values.nodal
        fields = {f"{name}_normal_reaction": nodal(p.slave, rn),
                  f"{name}_tangential_reaction": nodal(p.slave, rt),
                  f"{name}_gap": nodal(p.slave, gap), f"{name}_slip": nodal(p.slave, slip),
                  f"{name}_state": nodal(p.slave, state, fill=-1.0)}
        extras = {"normal_force": np.array([self.sum_ranks((rn * share).sum())]),
                  "tangential_force": self.sum_ranks((rt * share[:, None]).sum(axis=0))}
        return fields, {self.normal.name: extras}


def _equal(a, b) -> bool:
    """Equal values: arrays element for element, objects attribute for attribute."""
    if isinstance(a, np.ndarray) or isinstance(b, np.ndarray):
        return isinstance(a, np.ndarray) and isinstance(b, np.ndarray) and np.array_equal(a, b)
    if isinstance(a, dict) or hasattr(a, "__dict__"):
        if type(a) is not type(b):
            return False
        a, b = (a, b) if isinstance(a, dict) else (vars(a), vars(b))
        return a.keys() == b.keys() and all(_equal(a[k], b[k]) for k in a)
    if isinstance(a, (list, tuple)):
        return type(a) is type(b) and len(a) == len(b) and all(map(_equal, a, b))
    return bool(a == b)
