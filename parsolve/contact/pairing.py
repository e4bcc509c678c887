"""Closest-point pairing of slave nodes with a master surface (node-to-segment, node-to-face).

The master surface is a set of boundary facets of the master body, each given by its nodes in
the outward orientation of ``parsolve.mesh.topology.FACETS`` (as returned by ``boundary_facets``,
``facets_from_nodes`` or ``match_facets``): the facet normal computed from that orientation
points out of the master body, i.e. towards the slave. Facet types: line, line3 (2D);
triangle, triangle6, quad (3D).

Frame at the projection (see docs/contact.md):

* 2D: ``t = dx/dxi / |dx/dxi|`` and ``n = (t_y, -t_x)`` (outward for the facet (a, b));
  so ``t = (-n_y, n_x)``.
* 3D: ``n = (dx/dxi1 x dx/dxi2) / |...|``, ``t1 = dx/dxi1 / |dx/dxi1|``, ``t2 = n x t1``;
  ``(t1, t2, n)`` is right-handed and orthonormal.

Signed initial gap ``g0 = n . (x_s - x_m)``: positive open, negative penetration.

Everything is vectorised over nodes and candidate pairs; the candidates come from a uniform
bucket grid (cell size = largest facet extent + search radius), so the work grows linearly
with the number of slave nodes and facets.
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import lru_cache

import numpy as np

from parsolve.fem.elements import element

FACET_DIM = {"line": 1, "line3": 1, "triangle": 2, "triangle6": 2, "quad": 2}


@dataclass
class Pairing:
    """Per slave node (n = number of slave nodes), for 2D (dim=2) or 3D (dim=3) surfaces.

    slave     (n,)            slave node ids (into the points array given to the pairing)
    paired    (n,) bool       a projection was found (on a facet or on an obstacle)
    facet     (n,) int64      master facet index (row of ``master_facets``), -1 if unpaired
                              or for a rigid obstacle
    xi        (n, dim-1)      local coordinates of the projection on the facet (reference cell
                              of ``parsolve.fem.elements``); 0 when unpaired
    master    (n, k) int64    master node ids of the facet (k = nodes per facet; k = 0 for an
                              obstacle); -1 when unpaired
    weights   (n, k)          master shape functions at the projection N_a(xi); 0 when unpaired
    point     (n, dim)        projected point x_m
    normal    (n, dim)        unit master normal at x_m, pointing towards the slave
    tangents  (n, dim-1, dim) orthonormal tangent(s) (see the module docstring)
    gap       (n,)            signed initial gap g0 = normal . (x_s - x_m); +inf when unpaired
    """

    slave: np.ndarray
    paired: np.ndarray
    facet: np.ndarray
    xi: np.ndarray
    master: np.ndarray
    weights: np.ndarray
    point: np.ndarray
    normal: np.ndarray
    tangents: np.ndarray
    gap: np.ndarray

    @property
    def dim(self) -> int:
        return self.normal.shape[1]

    def __len__(self) -> int:
        return self.slave.shape[0]

    def subset(self, mask: np.ndarray) -> "Pairing":
        """The pairing restricted to the entries selected by ``mask`` (bool (n,) or indices)."""
        return Pairing(*(getattr(self, f)[mask] for f in self.__dataclass_fields__))

    def only_paired(self) -> "Pairing":
        return self.subset(self.paired)


# ----------------------------------------------------------------------------- facet geometry


@lru_cache(maxsize=None)
def _second_derivatives(facet_type: str) -> np.ndarray:
    """d2N/dxi_a dxi_b (nn, d, d): constant for every supported facet (P1, P2, Q1 bases).

    The gradients of these bases are affine in each coordinate, so a central difference of
    the gradients is exact (step 1/2: no cancellation worth mentioning).
    """
    el = element(facet_type)
    d = el.dim
    h = 0.5
    out = np.empty((el.num_nodes, d, d))
    for b in range(d):
        e = np.zeros((1, d))
        e[0, b] = h
        out[:, :, b] = (el.grad_shape(e)[0] - el.grad_shape(-e)[0]) / (2 * h)
    out = 0.5 * (out + out.transpose(0, 2, 1))
    out.setflags(write=False)
    return out


def facet_frame(jac: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Unit normal (m, dim) and tangents (m, dim-1, dim) from dx/dxi (m, dim, dim-1)."""
    if jac.shape[1] == 2:
        t = jac[:, :, 0] / np.linalg.norm(jac[:, :, 0], axis=1)[:, None]
        n = np.column_stack([t[:, 1], -t[:, 0]])
        return n, t[:, None, :]
    n = np.cross(jac[:, :, 0], jac[:, :, 1])
    n /= np.linalg.norm(n, axis=1)[:, None]
    t1 = jac[:, :, 0] / np.linalg.norm(jac[:, :, 0], axis=1)[:, None]
    t2 = np.cross(n, t1)
    return n, np.stack([t1, t2], axis=1)


def inside_reference(facet_type: str, xi: np.ndarray, tol: float) -> np.ndarray:
    """True where the local coordinates xi (m, d) lie in the reference facet (within tol)."""
    if facet_type in ("line", "line3", "quad"):
        return np.all(np.abs(xi) <= 1.0 + tol, axis=1)
    return (xi[:, 0] >= -tol) & (xi[:, 1] >= -tol) & (xi.sum(axis=1) <= 1.0 + tol)


def clip_to_reference(facet_type: str, xi: np.ndarray) -> np.ndarray:
    """The point of the reference facet nearest to xi (m, d) (reference coordinates)."""
    if facet_type in ("line", "line3", "quad"):
        return np.clip(xi, -1.0, 1.0)
    # triangle: clamp to the quadrant, then project on the hypotenuse where beyond it
    out = np.clip(xi, 0.0, None)
    over = out.sum(axis=1) > 1.0
    if np.any(over):
        shift = (out[over].sum(axis=1) - 1.0) / 2.0
        out[over] = np.clip(out[over] - shift[:, None], 0.0, 1.0)
    return out


def _clip_reference(facet_type: str, xi: np.ndarray) -> np.ndarray:
    """Pull Newton iterates back near the reference facet (keeps far iterates bounded)."""
    if facet_type in ("line", "line3", "quad"):
        return np.clip(xi, -2.0, 2.0)
    return np.clip(xi, -1.0, 2.0)


def _evaluate(el, xi: np.ndarray, coords: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """x(xi) (m, dim) and dx/dxi (m, dim, d) of facets coords (m, k, dim)."""
    xm = np.matmul(el.shape(xi)[:, None, :], coords)[:, 0]
    jac = np.matmul(coords.transpose(0, 2, 1), el.grad_shape(xi))
    return xm, jac


def _solve_small(h: np.ndarray, g: np.ndarray) -> np.ndarray:
    """h^-1 g for stacks of 1x1 or 2x2 matrices (closed form: numpy's batched solve is slow
    on tiny matrices)."""
    if h.shape[1] == 1:
        return g / h[:, 0, :]
    det = h[:, 0, 0] * h[:, 1, 1] - h[:, 0, 1] * h[:, 1, 0]
    s0 = (h[:, 1, 1] * g[:, 0] - h[:, 0, 1] * g[:, 1]) / det
    s1 = (h[:, 0, 0] * g[:, 1] - h[:, 1, 0] * g[:, 0]) / det
    return np.column_stack([s0, s1])


def _far_outside(facet_type: str, xi: np.ndarray) -> np.ndarray:
    if facet_type in ("line", "line3", "quad"):
        return np.abs(xi).max(axis=1) > 1.5
    return (xi.min(axis=1) < -0.5) | (xi.sum(axis=1) > 1.5)


def project_on_facets(
    x: np.ndarray, coords: np.ndarray, facet_type: str, iterations: int = 30, tol: float = 1e-12
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Closest point of x (m, dim) on the facets with node coordinates coords (m, k, dim).

    Newton on f(xi) = |x(xi) - x|^2 / 2 with the full Hessian J^T J + sum (x(xi) - x) d2x,
    vectorised over the m pairs; exact in one step for straight segments and flat triangles.
    Only the pairs still moving are iterated; pairs whose iterate stays far outside the
    reference facet (they cannot be paired) are dropped after 2 iterations.
    Returns (xi (m, d), x(xi) (m, dim), dx/dxi (m, dim, d)).
    """
    el = element(facet_type)
    m = x.shape[0]
    # work relative to each facet's first node: residuals of the size of the facet, not of
    # the coordinates, so xi converges to round-off whatever the mesh's offset and size
    origin = coords[:, 0, :]
    coords = coords - origin[:, None, :]
    x = x - origin
    xi = np.tile(el.nodes.mean(axis=0), (m, 1))  # start from the facet's centre
    h2 = _second_derivatives(facet_type)
    k, d = h2.shape[0], h2.shape[1]
    curved = bool(np.any(h2 != 0.0))  # straight segments and flat triangles: no curvature term
    if curved:  # d2x/dxi2 (m, dim, d*d), constant per facet
        d2x = np.matmul(coords.transpose(0, 2, 1), h2.reshape(k, d * d))
    active = np.arange(m)
    for it in range(iterations):
        xa, ca = xi[active], coords[active]
        xm, jac = _evaluate(el, xa, ca)
        r = xm - x[active]
        grad = np.matmul(r[:, None, :], jac)[:, 0]
        jtj = np.matmul(jac.transpose(0, 2, 1), jac)
        hess = jtj.copy()
        if curved:
            hess += np.matmul(r[:, None, :], d2x[active]).reshape(-1, d, d)
        # a far point on a strongly curved facet can make the Hessian indefinite: fall back
        # to Gauss-Newton (J^T J is always positive) there
        det = hess[:, 0, 0] if d == 1 else hess[:, 0, 0] * hess[:, 1, 1] - hess[:, 0, 1] ** 2
        bad = det <= 1e-12 * np.trace(jtj, axis1=1, axis2=2) ** d
        hess[bad] = jtj[bad]
        new = _clip_reference(facet_type, xa - _solve_small(hess, grad))
        xi[active] = new
        moving = np.linalg.norm(new - xa, axis=1) > tol
        if it >= 1:  # after a first (nearly exact) step, far-outside pairs are hopeless
            moving &= ~_far_outside(facet_type, new)
        active = active[moving]
        if active.size == 0:
            break
    xm, jac = _evaluate(el, xi, coords)
    return xi, xm + origin, jac


# ----------------------------------------------------------------------------- candidates


def _facet_boxes(coords: np.ndarray, radius: float) -> tuple[np.ndarray, np.ndarray]:
    return coords.min(axis=1) - radius, coords.max(axis=1) + radius


def candidate_pairs(
    xs: np.ndarray, lo: np.ndarray, hi: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """(slave index, facet index) pairs with the slave point inside the facet's box [lo, hi].

    Uniform bucket grid with cells at least as large as every box, so that a box touches at
    most 2 cells per axis: every box is registered in its cells, every point looks up its own
    cell. Cost O(points + facets + pairs).
    """
    dim = xs.shape[1]
    nf = lo.shape[0]
    if nf == 0 or xs.shape[0] == 0:
        return np.zeros(0, dtype=np.int64), np.zeros(0, dtype=np.int64)
    size = np.max(hi - lo)
    size = size if size > 0 else 1.0
    origin = np.minimum(lo.min(axis=0), xs.min(axis=0))
    cell_lo = np.floor((lo - origin) / size).astype(np.int64)
    cell_hi = np.floor((hi - origin) / size).astype(np.int64)
    span = np.minimum(cell_hi - cell_lo, 1)  # 0 or 1 per axis by the choice of the cell size
    ncell = np.maximum(cell_hi.max(axis=0), np.floor((xs - origin).max(axis=0) / size)) + 2
    ncell = ncell.astype(np.int64)
    # enumerate the 2^dim corners of each box's cell range, keep those inside the range
    offsets = np.array(np.meshgrid(*[[0, 1]] * dim, indexing="ij")).reshape(dim, -1).T
    ok = np.all(offsets[None, :, :] <= span[:, None, :], axis=2)  # (nf, 2^dim)
    fid, oid = np.nonzero(ok)
    cells = cell_lo[fid] + offsets[oid]
    key_f = np.ravel_multi_index(cells.T, ncell)
    order = np.argsort(key_f, kind="stable")
    key_f, fid = key_f[order], fid[order]
    pcell = np.floor((xs - origin) / size).astype(np.int64)
    key_s = np.ravel_multi_index(pcell.T, ncell)
    start = np.searchsorted(key_f, key_s, side="left")
    stop = np.searchsorted(key_f, key_s, side="right")
    count = stop - start
    sid = np.repeat(np.arange(xs.shape[0]), count)
    # positions start[s] .. stop[s]-1 for each slave, without a Python loop
    first = np.repeat(start - np.concatenate([[0], np.cumsum(count)[:-1]]), count)
    fcand = fid[first + np.arange(sid.size)]
    inside = np.all((xs[sid] >= lo[fcand]) & (xs[sid] <= hi[fcand]), axis=1)
    return sid[inside], fcand[inside]


# ----------------------------------------------------------------------------- pairing


def pair_nodes(
    points: np.ndarray,
    slave_nodes: np.ndarray,
    master_facets: np.ndarray,
    facet_type: str,
    search_radius: float | None = None,
    tol: float = 1e-2,
    slave_points: np.ndarray | None = None,
) -> Pairing:
    """Closest-point projection of every slave node on the master surface.

    points        (npts, dim)  node coordinates (current or initial configuration)
    slave_nodes   (n,)         slave node ids
    master_facets (nf, k)      master facet node ids, outward orientation (module docstring)
    facet_type                 line, line3 (2D); triangle, triangle6, quad (3D)
    search_radius              largest |gap| considered (default: the largest facet extent)
    tol                        tolerance on the local coordinates for "inside a facet"; a
                               projection outside by less is moved onto the facet's border
                               (so a larger tol pairs nodes facing convex master corners)
    slave_points  (n, dim)     slave positions if not points[slave_nodes] (e.g. deformed)

    Among the facets whose projection falls inside the facet (within tol), the one with the
    smallest distance wins (ties: smallest facet index, so the result does not depend on the
    order of evaluation). Nodes without such a facet are unpaired.
    """
    points = np.asarray(points, dtype=float)
    slave_nodes = np.asarray(slave_nodes, dtype=np.int64)
    master_facets = np.asarray(master_facets, dtype=np.int64)
    if facet_type not in FACET_DIM:
        raise ValueError(f"unsupported master facet type {facet_type!r}")
    dim = points.shape[1]
    if FACET_DIM[facet_type] != dim - 1:
        raise ValueError(f"{facet_type} facets do not bound a {dim}D body")
    xs = points[slave_nodes] if slave_points is None else np.asarray(slave_points, dtype=float)
    n, k = slave_nodes.size, master_facets.shape[1]
    coords = points[master_facets]  # (nf, k, dim)
    extent = np.max(coords.max(axis=1) - coords.min(axis=1)) if coords.size else 0.0
    radius = float(extent if search_radius is None else search_radius)
    lo, hi = _facet_boxes(coords, radius)
    sid, fid = candidate_pairs(xs, lo, hi)
    xi, xm, jac = _project_in_chunks(xs, coords, sid, fid, facet_type)
    inside = inside_reference(facet_type, xi, tol)
    # within the tolerance, the projection is pulled back onto the facet (its edge or vertex):
    # a node facing a convex corner of the master pairs with the corner
    out_of = ~inside_reference(facet_type, xi, 0.0)
    if np.any(out_of):
        xi[out_of] = clip_to_reference(facet_type, xi[out_of])
        el = element(facet_type)
        xm[out_of] = np.einsum("mk,mkx->mx", el.shape(xi[out_of]), coords[fid[out_of]])
        jac[out_of] = np.einsum("mka,mkx->mxa", el.grad_shape(xi[out_of]), coords[fid[out_of]])
    dist = np.linalg.norm(xs[sid] - xm, axis=1)
    keep = inside & (dist <= radius * (1.0 + 1e-12))
    sid, fid, xi, xm, jac, dist = sid[keep], fid[keep], xi[keep], xm[keep], jac[keep], dist[keep]
    # per slave: smallest distance (round-off ties broken by the facet index)
    order = np.lexsort((fid, dist, sid))
    best = order[np.r_[True, sid[order][1:] != sid[order][:-1]]] if order.size else order
    s = sid[best]

    out = empty_pairing(slave_nodes, dim, k)
    if s.size == 0:
        return out
    out.paired[s] = True
    out.facet[s] = fid[best]
    xib = xi[best]  # not clipped: weights, point and xi stay consistent
    out.xi[s] = xib
    out.master[s] = master_facets[fid[best]]
    out.weights[s] = element(facet_type).shape(xib)
    out.point[s] = xm[best]
    normal, tangents = facet_frame(jac[best])
    out.normal[s] = normal
    out.tangents[s] = tangents
    out.gap[s] = np.einsum("mx,mx->m", normal, xs[s] - xm[best])
    return out


CHUNK = 1 << 15  # candidate pairs per vectorised projection: bounded memory, cache-friendly


def _project_in_chunks(xs, coords, sid, fid, facet_type):
    """project_on_facets over the candidate pairs, CHUNK pairs at a time."""
    parts = [project_on_facets(xs[sid[i:i + CHUNK]], coords[fid[i:i + CHUNK]], facet_type)
             for i in range(0, max(sid.size, 1), CHUNK)]
    return tuple(np.concatenate(p) for p in zip(*parts))


def empty_pairing(slave_nodes: np.ndarray, dim: int, k: int) -> Pairing:
    """An all-unpaired pairing for the given slave nodes (k master nodes per entry)."""
    n = np.asarray(slave_nodes).size
    return Pairing(
        slave=np.asarray(slave_nodes, dtype=np.int64).copy(),
        paired=np.zeros(n, dtype=bool),
        facet=np.full(n, -1, dtype=np.int64),
        xi=np.zeros((n, dim - 1)),
        master=np.full((n, k), -1, dtype=np.int64),
        weights=np.zeros((n, k)),
        point=np.full((n, dim), np.nan),
        normal=np.zeros((n, dim)),
        tangents=np.zeros((n, dim - 1, dim)),
        gap=np.full(n, np.inf),
    )


def facet_spans(points: np.ndarray, slave_nodes: np.ndarray, master_facets: np.ndarray,
                radius: float) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Per slave node, the master facets whose box inflated by ``radius`` contains it, and
    their nodes (finite sliding: the facets a slave may visit while it stays within radius
    of where it is: its span). Returns (facet_ptr, facets, node_ptr, nodes): CSR over the slave
    nodes, facets and nodes increasing within each slave (facet indices are rows of
    ``master_facets``, in its canonical order)."""
    xs = np.asarray(points, dtype=float)[slave_nodes]
    coords = np.asarray(points, dtype=float)[master_facets]
    lo, hi = _facet_boxes(coords, radius)
    sid, fid = candidate_pairs(xs, lo, hi)
    order = np.lexsort((fid, sid))
    sid, fid = sid[order], fid[order]
    n = np.asarray(slave_nodes).size
    facet_ptr = np.concatenate([[0], np.cumsum(np.bincount(sid, minlength=n))])
    k = master_facets.shape[1]
    pairs = np.unique(np.column_stack([np.repeat(sid, k), master_facets[fid].ravel()]), axis=0)
    pairs = pairs.reshape(-1, 2)
    node_ptr = np.concatenate([[0], np.cumsum(np.bincount(pairs[:, 0], minlength=n))])
    return facet_ptr.astype(np.int64), fid, node_ptr.astype(np.int64), pairs[:, 1].copy()


def in_spans(facet: np.ndarray, facet_ptr: np.ndarray, facets: np.ndarray) -> np.ndarray:
    """True where entry i's facet is one of ``facets[facet_ptr[i]:facet_ptr[i+1]]`` (False
    for no facet, −1)."""
    return contains(facet_ptr, facets, np.arange(facet.size + 1, dtype=np.int64), facet)


def contains(ptr: np.ndarray, ids: np.ndarray, sub_ptr: np.ndarray,
             sub_ids: np.ndarray) -> np.ndarray:
    """For the CSR lists ``sub`` (the same entries as ``ptr``/``ids``; ids increasing within
    each entry of ``ids``, any order in ``sub``): whether each of sub's ids is in its entry's
    list of ``ids`` (nnz of sub,); False for a negative id."""
    n = ptr.size - 1
    big = int(max(ids.max(initial=0), sub_ids.max(initial=0))) + 1
    key = np.repeat(np.arange(n, dtype=np.int64), np.diff(ptr)) * big + ids
    sub = np.repeat(np.arange(n, dtype=np.int64), np.diff(sub_ptr)) * big + sub_ids
    if key.size == 0:
        return np.zeros(sub.size, dtype=bool)
    pos = np.minimum(np.searchsorted(key, sub), key.size - 1)
    return (sub_ids >= 0) & (key[pos] == sub)


def pair_on(points: np.ndarray, slave_nodes: np.ndarray, master_facets: np.ndarray,
            facet: np.ndarray, facet_type: str, tol: float = 1e-9) -> tuple[Pairing, np.ndarray]:
    """Each slave node projected on one given facet (``facet[i]``, a row of
    ``master_facets``), clipped to the facet as ``pair_nodes`` does within its tolerance:
    (the pairing, True where the unclipped projection lies in the facet within ``tol``, in
    reference coordinates: a slave on a vertex is in both facets whatever the round-off)."""
    points = np.asarray(points, dtype=float)
    xs = points[slave_nodes]
    coords = points[master_facets[facet]]
    xi, xm, jac = project_on_facets(xs, coords, facet_type)
    inside = inside_reference(facet_type, xi, tol)
    el = element(facet_type)
    out = ~inside_reference(facet_type, xi, 0.0)
    if out.any():
        xi[out] = clip_to_reference(facet_type, xi[out])
        xm[out] = np.einsum("mk,mkx->mx", el.shape(xi[out]), coords[out])
        jac[out] = np.einsum("mka,mkx->mxa", el.grad_shape(xi[out]), coords[out])
    normal, tangents = facet_frame(jac)
    p = Pairing(np.asarray(slave_nodes, dtype=np.int64).copy(), np.ones(xs.shape[0], bool),
                np.asarray(facet, dtype=np.int64).copy(), xi, master_facets[facet].copy(),
                el.shape(xi), xm, normal, tangents, np.einsum("mx,mx->m", normal, xs - xm))
    return p, inside
