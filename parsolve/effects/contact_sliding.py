"""Finite sliding of a contact (``sliding = "finite"``): the methods of ``effects.contact.Contact``
that pair its slaves again on the current configuration and keep its rows, over spans made
again as the slaves leave them, the exact linearisation of the current geometry; and the
geometric stiffness of those rows.

The slaves are paired again on the current (displaced) configuration at each step's start
and after each solve, until the rows stop changing (their fixed point: the gap and the slip
of the current geometry, exact at convergence); a slave keeps its facet while it stays in it
(no flip at a kink), else takes the closest (ties: the canonical facet order of
``surfaces``). Each row spans the master nodes of every facet within ``search_radius`` of
the slave when its span was made (``pairing.facet_spans``), zeros where a facet is not the
current one: re-pairing is a value update of the same entries. When at a step's start a
facet within half the radius of a slave is not in its span (``sliding.near_edge``), or a
slave has left its span at an iterate, the spans are made again around the current
configuration (``sliding.respan``) and the system builds its operator again on the new
pattern (``restructured``: preallocated as at the start; MUMPS analyses it again). A slave
that no facet faces at the start but that is within the search radius of one (a die's
overhang) is kept, uncovered: a zero row (its gap inf in the outputs) until a facet faces it
(mortar: until the rows hold it). The stick rows hold the master's material point faced at
the step's start, on whatever facet it now is; the slip
output is the total over the steps. Small strain: the bodies' stiffness is the initial one,
the contact geometry the current one. In 3D (node-to-face: triangle, quad, triangle6 faces)
the two stick rows per slave run along the slip direction s and across it over the span, and
hold both components of the slip since the step's start; the tangent basis (t1, t2 = n × t1)
is not the facet's own but the initial t1 projected on the current tangent plane, so that the
slip direction, written in it, does not jump when a slave crosses to a facet numbered from
another corner (``reference_frame``). A 3D slave that passed its facet's edge into a concave
crease of the deformed master (and so entered the next facet) goes to that facet; one that
went back and forth between the crease's two facets twice in the step (a slave on the crease
itself, e.g. on a line of master face edges, which its own force presses into a crease) is held
there with the two facets' mean normal (``_hold_at_creases``). Mortar
rows (``contact.sliding``): integrated again on the current configuration, on the slaves
paired at the start, each over the master nodes within the search radius plus its slave
facets' reach (a slave no facet covers any more keeps its last row). Limits: in 2D a
node-to-segment slave at a concave kink (an indentation's rim), held to one segment, may
cross it into the next by ~1e-6 of the press (the 3D rule makes a 2D slave cycle between the
two segments); mortar enforces weighted gaps, not the nodes' (a die's corner node enters a
bent rim by a few % of the press). Against a rigid obstacle the slaves are projected again on
it (rows on the slave alone, empty spans); the stick rows hold the obstacle's point faced at
the step's start.

The geometric stiffness (``contact.geometry``, docs/contact.md §4.3): the force a slave passes
to its facet (or receives from a curved obstacle) turns with the facet and slides along it;
that dependence enters the Newton matrix as a term on each slave's tuple (its node and its
span's: ``row_terms``), so that a sliding step converges quadratically.
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np
from mpi4py import MPI

from parsolve.contact.distributed import facet_index, update_near
from parsolve.contact.geometry import facet_terms, local_terms
from parsolve.contact.mortar import master_half
from parsolve.contact.pairing import in_spans, pair_nodes, pair_on
from parsolve.contact.rows import normal_values, repeated, rows_differ, span_combination
from parsolve.contact.sliding import fit_mortar, frame_of, make_spans, merged, \
    mortar_waiting, near_edge, outside_spans, pad, reference_frame, respan
from parsolve.contact.surfaces import Surfaces
from parsolve.errors import SolverError

# finite sliding: the rows' fixed point: their coefficients to TOL_ROWS, their gaps to TOL_GAP ×
# the largest master facet (the span's radius would make the iterations depend on it)
TOL_ROWS, TOL_GAP = 1e-12, 1e-11
# finite sliding: a slave keeps its facet while its projection is within this of the facet (in
# reference coordinates, pair_nodes' own tolerance), clipped to the facet's end: at a kink of
# the master (the corner of an indentation) the slave would otherwise flip between the two
# facets, each solve sending it back over the vertex to the other
KEEP_TOL = 1e-2
# finite sliding: the gap of a slave no facet has faced yet, × the largest master facet (its row is
# zero, so any positive value keeps it open; not a large one, which would widen the active
# set's gap tolerance, scaled to the largest |A q − b|)
UNCOVERED_GAP = 1.0
# 3D node-to-face: a slave held at a concave crease (``_hold_at_creases``) once it went back this
# many times within the step to the facet it left
CREASE_RETURNS = 2
# a node-to-segment slave named in a failure: it went back to the facet it left within this
# many re-pairings of the failed attempt's end (``failure_hints``)
RECENT = 3


class FiniteSliding:
    """The finite-sliding part of a contact effect (mixed into ``Contact``, whose state it
    reads: ``span``, ``pairing``, the rows and relations, ``values``, ``fields_``)."""

    def _current_points(self, q: np.ndarray) -> np.ndarray:
        """This rank's surfaces (its slaves, the master facets near them) in the current
        configuration X + u, made again first when master facets came near (``_follow``).
        Collective."""
        if self.spec.obstacle is None:
            self._follow(q)
        return self.span.surf.points + self._surface_u(q)

    def _surface_u(self, q: np.ndarray) -> np.ndarray:
        """u at this rank's surface nodes, from their owners (one plan per surface)."""
        ids, f, dim = self.span.surf.ids, self.fields_, self.mesh.dim
        if "surface" not in self._fetches:
            dofs = (ids[:, None] * f.ncomp + f.offset[self.u] + np.arange(dim)).ravel()
            self._fetches["surface"] = self._fetch(dofs)
        return self._fetches["surface"](q).reshape(ids.size, dim)

    def _follow(self, q: np.ndarray) -> None:
        """The master facets that came within reach of this rank's slaves on the current
        configuration sent to it (``dist.update_near``: every rank's box gathered, a facet
        sent once to a rank), and the local surfaces made again with them (``_resurface``).
        Collective."""
        f, dim, ids, pts = self.fields_, self.mesh.dim, self._mine[0], self._mine[1]
        if "mine" not in self._fetches:   # (this rank's own master facets)
            dofs = (ids.reshape(-1, 1) * f.ncomp + f.offset[self.u] + np.arange(dim)).ravel()
            self._fetches["mine"] = self._fetch(dofs)
        self._mine_x = pts + self._fetches["mine"](q).reshape(pts.shape)
        # its own slaves' u from its own rows of q (the surface's fetch is ``_current_points``')
        at = f.offset[self.u] + np.arange(dim)
        own = self.values.local_nodes(self._own_ids)
        slave_x = (self.span.surf.points[self.span.surf.compact(self._own_ids)]
                   + q.reshape(-1, f.ncomp)[own[:, None], at])
        near, new = update_near(self.values.comm, self._near, slave_x, self._mine,
                                self._mine_x, self._reach)
        if new:
            self._resurface(near)

    def _resurface(self, near) -> None:
        """This rank's surfaces made again with the master facets ``near`` (those it had and
        more, in the canonical order): every compact node number and facet index of its state
        renumbered (facets keep their relative order, nodes their input-id order)."""
        sp, old = self.span, self.span.surf
        parts = [(old.ids, old.points), (near.ids, near.pts)]
        surf = Surfaces.of(parts)
        old_facets = old.ids[sp.facets]

        def node(c):
            return None if c is None else _mapped(c, lambda v: surf.compact(old.ids[v]))

        def facet(i):
            return None if i is None else _mapped(i, lambda v: facet_index(near.ids,
                                                                           old_facets[v]))

        def pairing(p):
            if p is None:
                return None
            p = p.subset(np.arange(len(p)))
            p.slave, p.master, p.facet = node(p.slave), node(p.master), facet(p.facet)
            return p
        self.span = replace(sp, surf=surf, slave=node(sp.slave), facets=surf.compact(near.ids),
                            facet_ids=facet(sp.facet_ids), slave_facets=node(sp.slave_facets),
                            _repeated={})
        self._facet_now, self._facet_committed = facet(self._facet_now), \
            facet(self._facet_committed)
        self._left = facet(self._left)
        self._compact, self._compact_committed, self._hold = \
            pairing(self._compact), pairing(self._compact_committed), pairing(self._hold)
        if getattr(self, "_start_point", None) is not None:
            master0, weights0, point0 = self._start_point
            self._start_point = (node(master0), weights0, point0)
        self.set_near(near)
        self._fetches.pop("surface", None)

    def _repair(self, q: np.ndarray, start: bool = False):
        """Finite sliding: the slaves paired on the current configuration X + u (compact
        numbering): the closest facet of the master (ties: the canonical facet order), except
        that a slave keeps its current facet while its projection stays in it (within
        ``KEEP_TOL``) and is as close (to 1e-9 of the largest master facet): a slave on a kink of the
        master must not flip between its two facets from one iteration to the next; a slave
        that no facet faces any more (past the master's free end) stays on its last facet,
        clipped to the facet's end (as small sliding keeps its first pairing). The spans are
        made again when a slave leaves its span, or (``start``: a step's start) nears its edge
        (``_respan_if``)."""
        x = self._current_points(q)   # (first: it may make the surfaces again)
        sp, ft = self.span, self.mesh.facet_type
        if self.spec.obstacle is not None:   # projected again on the obstacle
            p = self._project(x, sp.slave)
            if sp.reference is not None:
                reference_frame(p, sp.reference)
            return p, x
        if sp.slave_facets is not None:
            return self._repair_mortar(x, start), x
        p = pair_nodes(x, sp.slave, sp.facets, ft, sp.radius)
        facing = p.paired.copy()
        if self._facet_now is not None:
            cur, inside = pair_on(x, sp.slave, sp.facets, self._facet_now, ft, KEEP_TOL)
            dist = np.abs(cur.gap)
            best = np.where(p.paired, np.abs(p.gap), np.inf)
            # ... but a slave past its facet's edge (its point clipped: farther than its normal
            # gap) that has entered the closest facet (a concave crease of the deformed master)
            # goes there: on its facet's plane it would stay inside the next one. 3D only: in
            # 2D (the die placed on an indented slab, frictionless) a slave then cycles
            # between the two segments of a kink
            past = np.linalg.norm(x[sp.slave] - cur.point, axis=1) > dist + 1e-9 * sp.length
            entered = p.paired & (p.gap < -1e-9 * sp.length) & (p.facet != cur.facet) \
                & (self.mesh.dim == 3)
            # ... and a slave beyond the master's free end stays on its last facet, at the end
            keep = inside & (dist <= best + 1e-9 * sp.length) & ~(past & entered) | ~p.paired
            for name in p.__dataclass_fields__:
                getattr(p, name)[keep] = getattr(cur, name)[keep]
            if not start:   # (the counts are the last step's until _count_returns resets them)
                self._hold_at_creases(x, p, cur, inside)
        if sp.reference is not None:
            reference_frame(p, sp.reference)
        self._cover(p, facing)   # (after the frame: an uncovered slave's tangents stay zero)
        outside = ~in_spans(p.facet, sp.facet_ptr, sp.facet_ids) & (p.facet >= 0)
        self._respan_if(x, p, outside, start)
        return p, x

    def _hold_at_creases(self, x: np.ndarray, p, cur, inside: np.ndarray) -> None:
        """3D node-to-face: a slave that went back to the facet it left ``CREASE_RETURNS``
        times in the step (``_count_returns``) and lies in both facets (within ``KEEP_TOL``)
        sits on a concave crease of the master: held by one facet, the force along that
        facet's normal pushes it over the crease into the other, whose normal pushes it back,
        at every solve (a slave on a line of master nodes, pressed: Newton never converges).
        Such a slave is held on its facet now (``cur``), its row's normal the mean of the two
        facets' (the bisector, to which the two facets' reactions sum on a symmetric crease),
        set in p in place; it stays there for the rest of the step."""
        if self.mesh.dim != 3 or self._returns is None or self._returns.size != len(p):
            return
        sp = self.span
        other = self._left
        maybe = np.flatnonzero((self._returns >= CREASE_RETURNS) & (other >= 0) & inside
                               & (other != cur.facet))
        if maybe.size == 0:   # (local: no collective)
            return
        two, in_two = pair_on(x, sp.slave[maybe], sp.facets, other[maybe],
                              self.mesh.facet_type, KEEP_TOL)
        at = maybe[in_two]
        normal = cur.normal[at] + two.normal[in_two]
        normal /= np.linalg.norm(normal, axis=1)[:, None]
        for name in p.__dataclass_fields__:
            getattr(p, name)[at] = getattr(cur, name)[at]
        p.normal[at] = normal
        p.gap[at] = np.einsum("mx,mx->m", normal, x[sp.slave[at]] - cur.point[at])

    def _with_uncovered(self, surf, p, facets: np.ndarray, length: float):
        """Finite sliding, node-to-segment, at the start: p (this rank's slaves, compact) with
        the slaves that no facet faces yet but that are within the search radius of one kept
        too, *uncovered* (``_uncover``: no row until a facet faces them, e.g. a die's overhang
        dragged onto the slab); the spans set (``make_spans``; ``length``: the largest master
        facet)."""
        near = pair_nodes(surf.points, p.slave, facets, self.mesh.facet_type,
                          self._radius, tol=np.inf)   # the nearest, clipped
        keep = p.paired | near.paired
        p, near = p.subset(keep), near.subset(keep)
        self._covered = p.paired.copy()
        for name in p.__dataclass_fields__:
            getattr(p, name)[~self._covered] = getattr(near, name)[~self._covered]
        self._hold = p.subset(np.arange(len(p)))   # (a copy) where the uncovered wait
        self.span = make_spans(surf, p, facets, self._radius, length)
        self._uncover(p)
        return p

    def _mortar_with_uncovered(self, surf, p, facets: np.ndarray, slave_facets: np.ndarray,
                               slaves: np.ndarray, slave_reach: float, length: float):
        """Finite sliding, mortar, at the start: the rows p (compact) and, uncovered, the
        nodes ``slaves`` (this rank's) that no row holds yet but whose span is not empty
        (``sliding.mortar_waiting``); the spans set (the whole surfaces' ``slave_reach`` and
        ``length``)."""
        waiting = mortar_waiting(surf, p, facets, self.mesh.facet_type,
                                 self._radius + slave_reach, slaves)
        p = merged(p, waiting)
        self._covered = ~np.isin(p.slave, waiting.slave)
        self._hold = p.subset(np.arange(len(p)))
        self.span = make_spans(surf, p, facets, self._radius, length, slave_facets,
                               slave_reach)
        self._uncover(p)
        self._compact = p
        return p

    def _cover(self, p, facing: np.ndarray) -> None:
        """The entries of the current rows p (compact) that a facet faces now (``facing``)
        are covered from now on; those never faced yet get their placeholder (``_uncover``). A
        slave faced for the first time counts its slip in the step from there."""
        new = facing & ~self._covered
        if new.any() and getattr(self, "_start_point", None) is not None:
            master0, weights0, point0 = self._start_point
            width = max(master0.shape[1], p.master.shape[1])
            master0, weights0 = pad(master0, weights0, width)
            master, weights = pad(p.master, p.weights, width)
            master0[new], weights0[new], point0[new] = master[new], weights[new], p.point[new]
            self._start_point = (master0, weights0, point0)
        self._covered = self._covered | facing
        self._uncover(p)

    def _uncover(self, p) -> None:
        """The entries of p (compact) that no facet has faced yet: on their nearest facet at
        the start (inside their span), with no row (normal, tangents and weights zero) and a
        gap of ``UNCOVERED_GAP`` × the largest master facet (never closed)."""
        if self._covered is None or self._covered.all():
            return
        out = ~self._covered
        hold = self._hold
        for name in p.__dataclass_fields__:
            if name not in ("master", "weights"):
                getattr(p, name)[out] = getattr(hold, name)[out]
        master, _ = pad(hold.master, hold.weights, p.master.shape[1])   # (mortar: wider now)
        p.master[out] = master[out]
        p.normal[out], p.tangents[out], p.weights[out] = 0.0, 0.0, 0.0
        p.gap[out] = UNCOVERED_GAP * self.span.length

    def _repair_mortar(self, x: np.ndarray, start: bool = False):
        """Finite sliding, mortar: the rows made again on the current configuration x, on the
        fixed set of slaves (``sliding.fit_mortar``: a slave no master facet covers any more
        keeps its last row)."""
        sp = self.span
        # the whole surfaces' largest master half-extent per axis and slave facet extent on x
        # (one reduction): the candidates' bounds and the default search radius
        slave_facets = x[sp.slave_facets]
        reach = np.append(master_half(self._mine_x),
                          np.max(np.ptp(slave_facets, axis=1), initial=0.0))
        self.values.comm.Allreduce(MPI.IN_PLACE, reach, op=MPI.MAX)
        half, radius = reach[:-1], self.spec.search_radius
        if radius is None:   # (the largest facet: a master's extent is twice its half)
            radius = max(2.0 * half.max(), reach[-1])
        new = self._mortar(x, sp.slave_facets, sp.facets, radius, half).pairing
        if self.values.comm.allreduce(len(new)) == 0:
            raise SolverError("no mortar row left: the Newton iterate carried every slave of "
                              "the contact off the master (the iterates diverged)")
        p, found = fit_mortar(new, self._compact, x)
        if sp.reference is not None:
            reference_frame(p, sp.reference)
        self._cover(p, found)
        compact_nodes = sp.surf.compact(sp.nodes)
        self._respan_if(x, p, outside_spans(p, sp.node_ptr, compact_nodes), start)
        self._compact = p
        return p

    def _count_returns(self, facet: np.ndarray, start: bool) -> None:
        """Node-to-segment/face: per slave, how often it went back, within the step, to the
        facet it left last (A → B → A), and at which re-pairing it last did: a slave still
        cycling between two facets at the end (a concave crease of the master) is what keeps
        Newton from converging (``failure_hints``)."""
        if self.spec.obstacle is not None or self.span.slave_facets is not None:
            return
        if start or self._returns is None or self._facet_now is None:
            self._returns = np.zeros(facet.size, dtype=np.int64)
            self._left = np.full(facet.size, -1, dtype=np.int64)
            self._last_return = np.full(facet.size, -RECENT - 1, dtype=np.int64)
            self._repairings = 0
            return
        self._repairings += 1
        moved = (facet != self._facet_now) & (facet >= 0) & (self._facet_now >= 0)
        back = moved & (facet == self._left)
        self._returns += back
        self._last_return[back] = self._repairings
        self._left[moved] = self._facet_now[moved]

    def failure_hints(self) -> list[str]:
        """The slaves that went back and forth between two master facets at least twice in
        the failed attempt and still did in its last ``RECENT`` re-pairings: node-to-segment
        holds each on one facet, and it slides off into the other at each solve."""
        if self.any_rank(self._returns is None):
            return []
        still = self._repairings - self._last_return <= RECENT
        cycling = np.flatnonzero((self._returns >= 2) & still)
        mine = np.column_stack([self.span.surf.ids[self.span.slave[cycling]],
                                self._returns[cycling]])
        every = np.concatenate(self.values.comm.allgather(mine))   # (a few nodes per rank)
        if every.shape[0] == 0:
            return []
        every = every[np.argsort(every[:, 0], kind="stable")]
        nodes = every[:, 0]
        listed = ", ".join(f"{int(n)} ({int(k)} times)" for n, k in every[:5])
        listed += ", ..." * (nodes.size > 5)
        return [f"{self.source}: {self.spec.key}: slave node(s) {listed}"
                " went back and forth between two master facets until the end, as at a "
                "concave crease of the deformed master (node-to-segment holds a slave on one "
                'facet); discretization = "mortar" handles it']

    def _respan_if(self, x: np.ndarray, p, outside: np.ndarray, start: bool) -> None:
        """The spans made again around x (``sliding.respan``, p the current rows, compact)
        when a slave's row reaches outside its span, or at a step's start when a facet within
        half the radius of a slave now is not in its span (``near_edge``, on the current
        positions of both bodies: so that a step seldom leaves it); ``restructured`` then
        tells the solver."""
        if outside.any() or start and near_edge(self.span, x):
            self.span = respan(self.span, x, p)
            self._restructuring = True

    def _tangential_offset(self, x: np.ndarray, p) -> np.ndarray:
        """t_j · (x_s − x_m0): the slave's tangential distance, on the current configuration
        x, from the master's material point it faced at the step's start (``_start_point``: its
        master nodes and weights, a facet's shape functions or a mortar row's):
        its slip in the step, whatever facets it crossed; (n, dim − 1), in the tangent basis
        of the current pairing p."""
        master0, weights0, point0 = self._start_point
        # (a rigid obstacle: the point faced at the start, fixed in space)
        xm0 = np.einsum("mk,mkx->mx", weights0, x[master0]) if master0.shape[1] else point0
        return np.einsum("mjx,mx->mj", p.tangents, x[self.span.slave] - xm0)

    def _slide(self, q: np.ndarray, start: bool) -> bool:
        """Finite sliding: pair again on the current configuration and rewrite the rows'
        values in place over the spans (the same entries). The normal rows: the gap
        linearised at q, g = g_q + Dn·(q' − q) (the entry's gap is g_q − Dn·q); the stick
        rows: the slip since the step's start, s_q + Dt·(q' − q) = 0, measured from the
        master's material point faced at the step's start (``start``: that point is set
        here). Both are exact at the fixed point the iterations reach (True while the rows
        still change). Small strain: the bodies' stiffness is the initial one.

        3D (node-to-face): two stick rows per slave, along the slip direction s and across
        it (``_tangent_coefs``, over the span), holding both components of the slip since
        the step's start (``_stick_values``)."""
        p, x = self._repair(q, start)
        sp = self.span
        if start:
            self._start_point = (p.master.copy(), p.weights.copy(), p.point.copy())
        self._count_returns(p.facet, start)
        self._facet_now = p.facet.copy()
        self.du = self._tangential_offset(x, p)
        self._geo = (x, p.slave.copy(), p.master.copy())   # compact ids (geometric stiffness)
        p = self.span.surf.to_input(p)
        nrows, trows = self._rows(p.normal, p), self._span_tangent_rows(p)
        # the rows' new entries (values: set below and by the hooks), on every rank when
        # one made its spans again (its relations and terms are laid out together)
        if self.any_rank(self._restructuring):
            self.restructured = True
            self._set_entries(p, nrows, trows)
        p.gap = p.gap - self._read_rows(self.n_dofs, nrows.row, nrows.coef, nrows.nrows, q)
        old = (self.nrows, self.pairing.gap, self.trows)
        self.pairing, self.nrows, self.trows = p, nrows, trows
        self.normal.a_vals[:] = nrows.coef
        self.normal.values[:] = normal_values(p)
        if self.frictional and self.mesh.dim == 2:
            self.tangent.a_vals[:] = trows.coef
            self.tangent.values[:] = self._slip(q) - self.du[:, 0]
        elif self.frictional:
            self._q_slide = q.copy()
            self.tangent.a_vals[:] = self._tangent_coefs()
            self.tangent.values[:] = self._stick_values()
        # (compared whatever their layout: spans made again change the entries, not the rows)
        return (rows_differ(old[0], nrows, TOL_ROWS) or rows_differ(old[2], trows, TOL_ROWS)
                or not np.allclose(old[1], p.gap, rtol=0, atol=TOL_GAP * sp.length))

    def _span_tangent_rows(self, p):
        """Finite sliding: the rows along the tangents over the spans (2D: one per slave, along
        t; 3D: two, along t1 and t2, the slip measure and the tangential relation's layout)."""
        if self.mesh.dim == 2:
            return self._rows(p.tangents[:, 0], p)
        return self._rows(p.tangents.reshape(-1, 3), repeated(p, 2))

    def _stick_values(self) -> np.ndarray:
        """Values of the tangential rows (3D: along s and across it) that hold the slip at its
        value at the step's start. Small sliding: the rows' values at that start. Finite
        sliding: the rows at the last re-pairing's q less the slip since the start, measured
        on the geometry (``_tangential_offset``: du in (t1, t2), whose components along s and
        n × s are s·du and (−s₂, s₁)·du), so that a row linearised at q reads zero slip."""
        if self.span is None:
            return self._relation_values(self.tangent, self.q_start)
        s, du = self.direction, self.du
        slip = np.column_stack([np.einsum("mj,mj->m", s, du),
                                s[:, 0] * du[:, 1] - s[:, 1] * du[:, 0]]).ravel()
        return self._relation_values(self.tangent, self._q_slide) - slip

    def _set_entries(self, p, nrows, trows) -> None:
        """The relations' entries (A's and D's rows and DOFs) over spans made again (p the
        current pairing, input ids; nrows, trows its normal and tangential rows over them);
        their values zero until ``_slide`` and the hooks set them."""
        self._restructuring = False
        for key in [k for k in self._fetches if not isinstance(k, str)]:
            del self._fetches[key]   # (the plans of the rows' old entries)
        self.n_dofs, self.t_dofs = self._row_dofs(nrows), self._row_dofs(trows)
        zero_dual = self.normal.dual is not None
        self.normal.set_entries(nrows.row, self.n_dofs, zero_dual)
        if self.frictional:
            self.tangent.set_entries(trows.row, self.t_dofs, False)
        self._lay_terms(p, trows)   # (their tuples moved with the spans)

    def _geometry_layout(self, p):
        """The geometric rows' layout over the spans (``geometric_rank`` rows per slave, values
        zero): the tuples of the geometric stiffness's term."""
        dim, m = self.mesh.dim, self.geometric_rank * len(p)
        return span_combination(self._repeated(p), np.zeros((m, dim)),
                                np.zeros((m, p.master.shape[1], dim)), *self.span.ptr_for(m))

    def _repeated(self, p):
        """p's entries each ``geometric_rank`` times (the geometric rows of a slave)."""
        return repeated(p, self.geometric_rank)

    def _set_geometry(self, active: dict) -> None:
        """The geometric stiffness −Σ u wᵀ at the current pairing, from the last iterate's
        multipliers (the force on the slave as a function of its facet's frame:
        ``_force_of``), where the normal row is enforced; its rows' coefficients (w, u) in
        the layout of the term's tuples (``evaluate`` makes the term's values)."""
        if not self.geometric:
            return
        x, slave, master = self._geo
        p, dim = self.pairing, self.mesh.dim
        closed = np.flatnonzero(active[self.normal.name])   # (the others: no force)
        r, k = self.geometric_rank, master.shape[1]
        w, u = np.zeros((2, len(p), r, 1 + k, dim))
        force_of = self._force_of(closed, active)
        if k:
            w[closed], u[closed] = facet_terms(x[slave[closed]], x[master[closed]],
                                               self.mesh.facet_type, force_of)
        else:   # the force turns with the obstacle's normal at the slave's projection
            def forces(y, entries):
                o = self._project(y[:, 0], np.arange(y.shape[0]))
                return force_of(o.normal, o.tangents, entries)[:, None, :]
            h = np.full(closed.size, 1e-6 * self.span.length)
            w[closed], u[closed] = local_terms(x[slave[closed]][:, None], forces, r, h)
        m = len(p) * r
        p_rows, ptr = self._repeated(p), self.span.ptr_for(m)
        w, u = w.reshape(m, 1 + k, dim), u.reshape(m, 1 + k, dim)
        self._geo_rows = (span_combination(p_rows, u[:, 0], u[:, 1:], *ptr).coef,
                          span_combination(p_rows, w[:, 0], w[:, 1:], *ptr).coef)

    def _force_of(self, slaves: np.ndarray, active: dict):
        """v(n, tangents, entries): the force D λ on the slaves ``slaves[entries]`` (λ the
        last iterate's) in a facet frame:
        −λn (n − μ s·t) from the normal row and its friction dual; from the stick rows −λt t
        (2D) or −λs s·t − λc n × (s·t) (3D: rows along s and across it, in the reference
        tangents projected on the facet, ``reference_frame``)."""
        dm1 = self.mesh.dim - 1
        lam_n = self._lam_now[0][slaves]
        if self.frictional:   # the stick rows that the next solve enforces (released: no force)
            held = active[self.tangent.name].reshape(-1, dm1)[slaves]
            lam_t = np.where(held, self._lam_now[1].reshape(-1, dm1)[slaves], 0.0)
        mu, s, reference = self.mu, self.direction[slaves], self.span.reference

        def force_of(normal, tangents, entries):
            ln = lam_n[entries, None]
            v = -ln * normal
            if not self.frictional:
                return v
            if reference is not None:
                tangents = frame_of(normal, reference[slaves][entries])
            sv = np.einsum("mj,mjx->mx", s[entries], tangents)
            lt = lam_t[entries]
            if dm1 == 1:
                return v + mu * ln * sv - lt * tangents[:, 0]
            return v + (mu * ln - lt[:, :1]) * sv - lt[:, 1:] * np.cross(normal, sv)
        return force_of


def _mapped(values: np.ndarray, f) -> np.ndarray:
    """values with f applied to its entries ≥ 0 (−1: none, kept)."""
    out = np.array(values, dtype=np.int64, copy=True)
    ok = out >= 0
    out[ok] = f(out[ok])
    return out
