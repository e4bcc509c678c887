"""Mortar (segment-to-segment) contact rows in 3D on triangle, quad and triangle6 faces, dual
multipliers.

The 3D counterpart of ``mortar.py`` (read it first: the rows, their normalisation and the
properties are the same). For slave node i

    row_i . q = n_i . (D_ii u(s_i) − Σ_a M_ia u(a)),   D_ii = ∫ ψ_i φ_i = ∫ φ_i dA = w_i,
                                                      M_ia = ∫ ψ_i N_a∘π dA,

over the slave surface, π the projection on the master along the slave face's normal.

**Why dual multipliers.** With the standard basis (ψ_i = φ_i) D is the slave surface's mass
matrix: a row couples a slave node to its neighbours, the unilateral condition holds on the
weighted gaps of a *coupled* set, and the active set (one node = one row, opened or closed on
its own sign) of ``rows.py`` and the contact effect no longer fits. With Wohlmuth's dual
basis, ψ_i = Σ_j A_ij φ_j per slave face with ∫ ψ_i φ_j = δ_ij ∫ φ_j, D is diagonal, a row
involves its slave node alone, and dividing row i by w_i gives a node-to-face row whose master
weights are M_ia / w_i: a ``Pairing``, used unchanged by the rows, the friction dual and the
outputs. The dual basis loses nothing the patch test needs (constants and linear fields are
transferred exactly, a uniform pressure gives the nodal forces p w_i).

**Integration (segments).** Each candidate (slave face, master face) pair (a bounding-box
search on the bucket grid of ``pairing.candidate_pairs``, then the facing test on the faces'
normals) is split into sub-triangle pairs (a quad is two triangles (0, 1, 2), (0, 2, 3)). The
master sub-triangle is projected orthogonally on the slave sub-triangle's plane and clipped
against it (Sutherland–Hodgman, a loop over the 3 clipping edges, vectorised over the pairs);
the convex polygon is fanned into triangles, each integrated by a 7-point degree-5 rule. At a
quadrature point x the slave coordinate ξ is where the slave normal through x meets the slave
face (x itself for a triangle, for a flat quad the inverse bilinear map) and the master one η
where it meets the master face (Newton on x_m(η) − x − t n = 0, exact in one step for
triangles); t is the normal gap (> 0 open). The mass matrix ∫φφᵀ of the dual basis and the
integrals D, M are computed with the same points, so biorthogonality, Σ_a M_ia = w_i (a constant
is transferred exactly) and Σ_a M_ia x_a = w_i x_i on a flat interface (a linear field) hold to
round-off whatever the rule's exactness. The patch test also needs w_i and ∫ N_a over the
covered part *exact* (they are the consistent nodal forces of the uniform stress): exact for
triangles and parallelogram quads (affine maps: polynomial integrands of degree ≤ 4, the rule
is of degree 5); a non-parallelogram quad has a rational inverse map, so its integrals, and
the patch test, are met to the rule's accuracy only (measured: 3e-7 of p in the stress of a
randomly distorted 3×3 against 4×4 hexahedral patch). A warped quad is integrated on its two
triangles' planes (an approximation of its area of the order of the warp). As in 2D, the
dual basis of a partially covered face is biorthogonal on its covered part, and faces covered
by less than ``min_cover`` of their area are ignored.

**Quadratic faces (triangle6): Popp et al. (2012)'s modified basis.** The corner shape
functions of the quadratic triangle integrate to zero, so w_i = ∫φ_i vanishes and no dual
basis biorthogonal to them exists. The slave side is interpolated instead with Ñ = T N:
Ñ_c = N_c + α Σ N_m (the midsides adjacent to corner c), Ñ_m = (1 − 2α) N_m, α = 1/5; the Ñ
still sum to one and ∫Ñ > 0, the dual basis is biorthogonal to Ñ, D stays diagonal, and the
slave displacement u_s = Σ N_j d_j = Σ Ñ_j d̃_j has the transformed nodal values d̃_c = d_c,
d̃_m = (d_m − α (d_a + d_b)) / (1 − 2α) (edge ab). A corner's row is then a node-to-face row
as for linear faces; a midside's, multiplied by 1 − 2α, has its slave node with coefficient 1
and its edge's two corners among the "master" entries with weight α (``_midside_rows``): the
Pairing layout is kept, each row still has one slave node of its own. A row's multiplier is
the transformed one: a uniform pressure gives λ_i = p w_i / share_i (``Mortar.weight``; share
1 − 2α at a midside), the nodal forces p ∫N_j follow from the rows' entries, and a resultant
weighs each multiplier by its row's slave share (the contact effect does). The master side
keeps its standard N. Faces are clipped on their corner triangles (exact for flat faces
with straight edges); the slave and master coordinates of a point come from the quadratic
maps. quad8 faces (no parsolve element has them) are refused.
"""

from __future__ import annotations

import numpy as np

from parsolve.contact.mortar import Mortar, master_half
from parsolve.contact.pairing import Pairing, candidate_pairs, empty_pairing, facet_frame
from parsolve.fem.elements import element

# sub-triangles of a face's corners (a triangle6 face is clipped on its corner triangle)
SPLIT = {"triangle": np.array([[0, 1, 2]]), "quad": np.array([[0, 1, 2], [0, 2, 3]]),
         "triangle6": np.array([[0, 1, 2]])}
# triangle6 (meshio order: corners 0-2, then the midsides of 01, 12, 20): (midside, its corners)
EDGE_MIDS = {"triangle6": np.array([[3, 0, 1], [4, 1, 2], [5, 2, 0]])}
ALPHA = 0.2   # Popp et al. (2012)'s modification: a corner takes α of each adjacent midside

# 7-point degree-5 rule on the triangle (Radon; Dunavant's rule 5): barycentric points and
# weights summing to 1 (multiplied by the triangle's area)
_R15 = np.sqrt(15.0)
_A1, _B1 = (9 - 2 * _R15) / 21, (6 + _R15) / 21
_A2, _B2 = (9 + 2 * _R15) / 21, (6 - _R15) / 21
RULE_BARY = np.array([[1 / 3, 1 / 3, 1 / 3],
                      [_A1, _B1, _B1], [_B1, _A1, _B1], [_B1, _B1, _A1],
                      [_A2, _B2, _B2], [_B2, _A2, _B2], [_B2, _B2, _A2]])
RULE_WEIGHTS = np.array([9 / 40] + [(155 + _R15) / 1200] * 3 + [(155 - _R15) / 1200] * 3)


def mortar_pairing_3d(
    points: np.ndarray,
    slave_facets: np.ndarray,
    master_facets: np.ndarray,
    facet_type: str,
    search_radius: float | None = None,
    min_cover: float = 1e-6,
    half: np.ndarray | None = None,
) -> Mortar:
    """Mortar rows of the slave faces against the master faces (3D: triangle or quad).

    points        (npts, 3)  node coordinates
    slave_facets  (ns, k)    slave faces, outward orientation of the slave body
    master_facets (nm, k)    master faces, outward orientation of the master body
    search_radius            largest |gap| paired (default: the largest face extent)
    min_cover                slave faces covered by less than this fraction are ignored
    half          (3,)       the largest master half-extent per axis (default: these faces';
                             a rank pairing part of the surface gives the whole's)
    """
    points = np.asarray(points, dtype=float)
    sf = np.asarray(slave_facets, dtype=np.int64)
    mf = np.asarray(master_facets, dtype=np.int64)
    if facet_type not in SPLIT or points.shape[1] != 3:
        raise ValueError(f"3D mortar rows need triangle, quad or triangle6 faces, not "
                         f"{facet_type!r}")
    el = element(facet_type)
    modified = _modified_basis(facet_type, el.nodes.shape[0])
    xs_f, xm_f = points[sf], points[mf]
    extent = max(_extent(xs_f), _extent(xm_f))
    radius = float(extent if search_radius is None else search_radius)
    e, f = _candidates(xs_f, xm_f, radius, half)
    pieces = _segments(el, xs_f, xm_f, e, f)
    if pieces is None:
        return Mortar(empty_pairing(np.zeros(0, dtype=np.int64), 3, 0), np.zeros(0))
    owner, phi, nm, jw, gap = pieces
    near = np.all(np.abs(gap) <= radius * (1.0 + 1e-12), axis=1)
    owner, phi, nm, jw = owner[near], phi[near], nm[near], jw[near]
    if modified is not None:   # Ñ = T N on the slave side (the master keeps N)
        phi = np.einsum("tgj,kj->tgk", phi, modified)
    fe = e[owner]
    a_dual, covered = _dual_coefficients(phi, jw, fe, xs_f, min_cover)
    ok = covered[fe]
    s_nodes, m_nodes, m_ia, weight = _integrals(phi[ok], jw[ok], nm[ok], a_dual[fe[ok]],
                                                sf[fe[ok]], mf[f[owner[ok]]], points.shape[0])
    share = np.ones(points.shape[0])
    if modified is not None:
        s_nodes, m_nodes, m_ia, share = _midside_rows(sf[covered], EDGE_MIDS[facet_type],
                                                      s_nodes, m_nodes, m_ia, weight)
    normals = _nodal_normals(points, sf[covered], el)
    return _assemble(points, s_nodes, m_nodes, m_ia, weight, normals, share)


def overlap_areas(points: np.ndarray, slave_facets: np.ndarray, master_facets: np.ndarray,
                  facet_type: str, search_radius: float | None = None) -> np.ndarray:
    """Area of each slave face covered by the master surface (ns,), by the same segments as
    the rows (for checks: on a matching flat interface they sum to its area)."""
    points = np.asarray(points, dtype=float)
    sf = np.asarray(slave_facets, dtype=np.int64)
    xs_f, xm_f = points[sf], points[np.asarray(master_facets, dtype=np.int64)]
    radius = float(max(_extent(xs_f), _extent(xm_f)) if search_radius is None else search_radius)
    e, f = _candidates(xs_f, xm_f, radius)
    pieces = _segments(element(facet_type), xs_f, xm_f, e, f)
    if pieces is None:
        return np.zeros(sf.shape[0])
    owner, _, _, jw, _ = pieces
    return np.bincount(e[owner], weights=jw.sum(axis=1), minlength=sf.shape[0])


# ----------------------------------------------------------------------------- search


def _extent(coords: np.ndarray) -> float:
    return float(np.max(coords.max(axis=1) - coords.min(axis=1))) if coords.size else 0.0


def _face_normal(coords: np.ndarray) -> np.ndarray:
    """Unit normal (m, 3) of faces from their corners (quad: the diagonals' cross product)."""
    if coords.shape[1] == 4:
        n = np.cross(coords[:, 2] - coords[:, 0], coords[:, 3] - coords[:, 1])
    else:
        n = np.cross(coords[:, 1] - coords[:, 0], coords[:, 2] - coords[:, 0])
    return n / np.linalg.norm(n, axis=1)[:, None]


def _candidates(xs_f: np.ndarray, xm_f: np.ndarray, radius: float,
                half: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray]:
    """(slave face, master face) pairs whose boxes, inflated by the radius, may overlap (master
    centres against slave boxes inflated by the radius and the largest master half-extent),
    the master facing the slave (opposite normals); sorted by (slave, master)."""
    half = master_half(xm_f) if half is None else half
    lo = xs_f.min(axis=1) - radius - half
    hi = xs_f.max(axis=1) + radius + half
    centres = 0.5 * (xm_f.min(axis=1) + xm_f.max(axis=1))
    f, e = candidate_pairs(centres, lo, hi)
    # the boxes themselves (the slave's inflated by the radius) overlap, the faces face
    lo_s, hi_s = xs_f[e].min(axis=1) - radius, xs_f[e].max(axis=1) + radius
    boxes = np.all((xm_f[f].min(axis=1) <= hi_s) & (xm_f[f].max(axis=1) >= lo_s), axis=1)
    facing = np.einsum("mx,mx->m", _face_normal(xs_f[e]), _face_normal(xm_f[f])) < 0.0
    e, f = e[boxes & facing], f[boxes & facing]
    order = np.lexsort((f, e))
    return e[order], f[order]


# ----------------------------------------------------------------------------- segments


def _segments(el, xs_f, xm_f, e, f):
    """Integration points of the clipped (slave, master) sub-triangle pairs: per fan triangle
    its candidate pair (T,), slave shape functions φ (T, g, k), master shape functions at the
    projection N (T, g, k), area × weight (T, g) and normal gap (T, g); None if nothing
    overlaps."""
    split = SPLIT["quad" if xs_f.shape[1] == 4 else "triangle"]
    ns = split.shape[0]
    # every candidate × slave sub-triangle × master sub-triangle
    cand = np.repeat(np.arange(e.size), ns * ns)
    a = np.tile(np.repeat(np.arange(ns), ns), e.size)
    b = np.tile(np.arange(ns), e.size * ns)
    tri = xs_f[e[cand][:, None], split[a]]                     # (P, 3, 3) slave sub-triangle
    mas = xm_f[f[cand][:, None], split[b]]                     # (P, 3, 3) master sub-triangle
    origin = tri[:, 0]
    e1 = tri[:, 1] - origin
    e1 /= np.linalg.norm(e1, axis=1)[:, None]
    normal = _face_normal(tri)
    e2 = np.cross(normal, e1)
    frame = np.stack([e1, e2], axis=2)                         # (P, 3, 2)
    t2 = np.einsum("pvx,pxa->pva", tri - origin[:, None], frame)
    m2 = np.einsum("pvx,pxa->pva", mas - origin[:, None], frame)
    # sub-triangle pairs whose boxes in the slave plane are disjoint have nothing to clip
    near = np.all((m2.min(axis=1) <= t2.max(axis=1)) & (m2.max(axis=1) >= t2.min(axis=1)), axis=1)
    keep = np.flatnonzero(near)
    if keep.size == 0:
        return None
    poly, count = _clip(m2[keep], t2[keep])
    fan, owner = _fan(poly, count)
    owner = keep[owner]
    if owner.size == 0:
        return None
    area = 0.5 * np.abs(_cross2(fan[:, 1] - fan[:, 0], fan[:, 2] - fan[:, 0]))
    keep = area > 0.0
    fan, owner, area = fan[keep], owner[keep], area[keep]
    if owner.size == 0:
        return None
    q2 = np.einsum("gv,tva->tga", RULE_BARY, fan)               # (T, g, 2)
    x = origin[owner][:, None] + np.einsum("tga,txa->tgx", q2, frame[owner])
    n = np.broadcast_to(normal[owner][:, None], x.shape)
    c = cand[owner]
    xi, _ = _ray_on_face(el, x, n, xs_f[e[c]])
    eta, gap = _ray_on_face(el, x, n, xm_f[f[c]])
    T, g = xi.shape[:2]
    phi = el.shape(xi.reshape(-1, 2)).reshape(T, g, -1)
    nm = el.shape(eta.reshape(-1, 2)).reshape(T, g, -1)
    jw = area[:, None] * RULE_WEIGHTS[None, :]
    return c, phi, nm, jw, gap


def _cross2(u: np.ndarray, v: np.ndarray) -> np.ndarray:
    return u[..., 0] * v[..., 1] - u[..., 1] * v[..., 0]


def _clip(subject: np.ndarray, clip: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Sutherland–Hodgman: the triangles ``subject`` (P, 3, 2) clipped by the counter-clockwise
    triangles ``clip`` (P, 3, 2), vectorised over P (a loop over the 3 clipping edges). Returns
    the polygons padded to a common width (P, w, 2) and their vertex counts (P,). A vertex on a
    clipping edge counts as inside (duplicated vertices make zero-area fan triangles)."""
    poly, count = subject.copy(), np.full(subject.shape[0], 3, dtype=np.int64)
    rows = np.arange(subject.shape[0])[:, None]
    for k in range(3):
        a, d = clip[:, k], clip[:, (k + 1) % 3] - clip[:, k]
        w = poly.shape[1]
        i = np.arange(w)[None, :]
        nxt = np.where(i + 1 < count[:, None], i + 1, 0)
        cur_p, nxt_p = poly, poly[rows, nxt]
        dc = _cross2(d[:, None], cur_p - a[:, None])           # ≥ 0: inside (left of the edge)
        dn = _cross2(d[:, None], nxt_p - a[:, None])
        valid = i < count[:, None]
        inside = dc >= 0.0
        cross = valid & (inside != (dn >= 0.0))
        t = np.where(cross, dc / np.where(cross, dc - dn, 1.0), 0.0)
        hit = cur_p + t[..., None] * (nxt_p - cur_p)
        cand = np.stack([cur_p, hit], axis=2).reshape(-1, 2 * w, 2)
        mask = np.stack([valid & inside, cross], axis=2).reshape(-1, 2 * w)
        order = np.argsort(~mask, axis=1, kind="stable")
        count = mask.sum(axis=1)
        width = max(int(count.max()), 1)
        poly = cand[rows, order[:, :width]]
    return poly, count


def _fan(poly: np.ndarray, count: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Fan triangles (0, j, j+1) of the convex polygons with at least 3 vertices: (T, 3, 2)
    and the polygon of each (T,)."""
    w = poly.shape[1]
    if w < 3:
        return np.zeros((0, 3, 2)), np.zeros(0, dtype=np.int64)
    j = np.arange(1, w - 1)
    ok = j[None, :] + 1 < count[:, None]                        # (P, w-2)
    p, col = np.nonzero(ok)
    jj = j[col]
    fan = np.stack([poly[p, 0], poly[p, jj], poly[p, jj + 1]], axis=1)
    return fan, p


def _ray_on_face(el, x: np.ndarray, n: np.ndarray, coords: np.ndarray, iterations: int = 30,
                 tol: float = 1e-13) -> tuple[np.ndarray, np.ndarray]:
    """Reference coordinates η (T, g, 2) and distance t (T, g) where the line x + t n meets the
    face of corners ``coords`` (T, k, 3): Newton on x_m(η) − x − t n = 0 (exact in one step for
    triangles), relative to the face's first node (residuals of the face's size)."""
    T, g = x.shape[:2]
    rel = (coords - coords[:, None, 0])[:, None]                # (T, 1, k, 3)
    xr = x - coords[:, None, 0]
    eta = np.broadcast_to(el.nodes.mean(axis=0), (T, g, 2)).copy()
    t = np.zeros((T, g))
    for _ in range(iterations):
        flat = eta.reshape(-1, 2)
        N = el.shape(flat).reshape(T, g, -1)
        dN = el.grad_shape(flat).reshape(T, g, -1, 2)
        xm = np.einsum("tgk,tkx->tgx", N, rel[:, 0])
        jac = np.einsum("tgka,tkx->tgxa", dN, rel[:, 0])       # (T, g, 3, 2)
        res = xm - xr - t[..., None] * n
        mat = np.concatenate([jac, -n[..., None]], axis=3)      # (T, g, 3, 3)
        step = np.linalg.solve(mat, -res[..., None])[..., 0]
        eta += step[..., :2]
        t += step[..., 2]
        if np.max(np.abs(step[..., :2])) <= tol:
            break
    return eta, t


# ----------------------------------------------------------------------------- dual basis


def _face_areas(xs_f: np.ndarray) -> np.ndarray:
    split = SPLIT["quad" if xs_f.shape[1] == 4 else "triangle"]
    tri = xs_f[:, split]                                        # (ns, s, 3, 3)
    c = np.cross(tri[:, :, 1] - tri[:, :, 0], tri[:, :, 2] - tri[:, :, 0])
    return 0.5 * np.linalg.norm(c, axis=2).sum(axis=1)


def _dual_coefficients(phi, jw, fe, xs_f, min_cover: float):
    """Per slave face the dual coefficients A (ns, k, k) (ψ_i = Σ_j A_ij φ_j, biorthogonal on
    the face's covered part: A = diag(∫φ) (∫φφᵀ)⁻¹), and the mask of the faces covered
    enough."""
    nfaces, k = xs_f.shape[0], phi.shape[2]
    mass = np.zeros((nfaces, k, k))
    np.add.at(mass, fe, np.einsum("tgi,tgj,tg->tij", phi, phi, jw))
    cover = np.bincount(fe, weights=jw.sum(axis=1), minlength=nfaces)
    covered = cover > min_cover * _face_areas(xs_f)
    a = np.zeros((nfaces, k, k))
    if np.any(covered):
        mc = mass[covered]
        a[covered] = mc.sum(axis=2)[:, :, None] * np.linalg.inv(mc)
    return a, covered


def _integrals(phi, jw, nm, a_dual, s_faces, m_faces, npts: int):
    """COO (slave node, master node, ∫ψ_i N_a dA) over the fan triangles; w (npts,) = ∫φ_i
    dA."""
    psi = np.einsum("tij,tgj->tgi", a_dual, phi)
    m_loc = np.einsum("tgi,tga,tg->tia", psi, nm, jw)
    d_loc = np.einsum("tgi,tg->ti", phi, jw)
    k, km = s_faces.shape[1], m_faces.shape[1]
    s_nodes = np.repeat(s_faces[:, :, None], km, axis=2)
    m_nodes = np.repeat(m_faces[:, None, :], k, axis=1)
    weight = np.bincount(s_faces.ravel(), weights=d_loc.ravel(), minlength=npts)
    return s_nodes.ravel(), m_nodes.ravel(), m_loc.ravel(), weight


def _nodal_normals(points: np.ndarray, faces: np.ndarray, el) -> np.ndarray:
    """Unit normal per node (npts, 3): the average of the slave faces' unit normals at the
    node, pointing into the slave (minus the slave's outward normal)."""
    out = np.zeros_like(points)
    if faces.shape[0] == 0:
        return out
    dphi = el.grad_shape(el.nodes)                              # (k nodes, k shape, 2)
    jac = np.einsum("akd,fkx->faxd", dphi, points[faces])      # (f, k, 3, 2)
    n, _ = facet_frame(jac.reshape(-1, 3, 2))
    np.add.at(out, faces.ravel(), -n)
    norm = np.linalg.norm(out, axis=1)
    used = norm > 0
    out[used] /= norm[used, None]
    return out


def tangent_basis(normal: np.ndarray) -> np.ndarray:
    """Orthonormal tangents (n, 2, 3) of unit normals, (t1, t2, n) right-handed: t1 is the
    coordinate axis least aligned with n (the first on a tie) made orthogonal to n."""
    axis = np.eye(3)[np.argmin(np.abs(normal), axis=1)]
    t1 = axis - np.einsum("mx,mx->m", axis, normal)[:, None] * normal
    t1 /= np.linalg.norm(t1, axis=1)[:, None]
    return np.stack([t1, np.cross(normal, t1)], axis=1)


# ----------------------------------------------------------------------------- quadratic faces


def _modified_basis(facet_type: str, k: int) -> np.ndarray | None:
    """T (k, k) of the modified slave basis Ñ = T N of a quadratic face (None: linear faces):
    Ñ_c = N_c + α Σ N_m over the midsides m adjacent to corner c, Ñ_m = (1 − 2α) N_m. The Ñ
    sum to one and ∫Ñ > 0 for 0 < α < ½ (triangle6: ∫N_c = 0, ∫N_m = A/3, so ∫Ñ_c = 2αA/3,
    ∫Ñ_m = (1 − 2α)A/3), so the dual basis biorthogonal to Ñ exists."""
    if facet_type not in EDGE_MIDS:
        return None
    t = np.eye(k)
    mids = EDGE_MIDS[facet_type]
    t[mids[:, 1], mids[:, 0]] = ALPHA
    t[mids[:, 2], mids[:, 0]] = ALPHA
    t[mids[:, 0], mids[:, 0]] = 1.0 - 2.0 * ALPHA
    return t


def _midside_rows(faces, mids, s_nodes, m_nodes, m_ia, weight):
    """The rows of the transformed slave displacements d̃ (u_s = Σ Ñ_j d̃_j = Σ N_j d_j):
    d̃_c = d_c at a corner, d̃_m = (d_m − α (d_a + d_b)) / (1 − 2α) at the midside of edge ab.
    A corner's row is unchanged; a midside's row, times (1 − 2α) so that its slave node keeps
    the coefficient 1, gains its edge's two corners as entries of weight α (after division by
    w_m), the master weights times (1 − 2α). Returns the COO with those entries and each
    node's share (1 − 2α at a midside, 1 elsewhere: the row's multiplier over its share is
    the multiplier of the unscaled row)."""
    share = np.ones(weight.shape[0])
    edge = faces[:, mids].reshape(-1, 3)                      # (midside, corner a, corner b)
    edge[:, 1:].sort(axis=1)                                  # the neighbour sees b, a
    edge = np.unique(edge, axis=0)                            # a midside shared by two faces
    share[edge[:, 0]] = 1.0 - 2.0 * ALPHA
    extra_s = np.repeat(edge[:, 0], 2)
    extra_m = edge[:, 1:].ravel()
    extra_v = ALPHA * weight[extra_s]
    return (np.concatenate([s_nodes, extra_s]), np.concatenate([m_nodes, extra_m]),
            np.concatenate([m_ia * share[s_nodes], extra_v]), share)


# ----------------------------------------------------------------------------- pairing


def _assemble(points, s_nodes, m_nodes, values, weight, normals, share) -> Mortar:
    """The normalised rows as a Pairing: per slave node with w_i > 0, its master nodes (sorted)
    with weights M_ia / w_i, padded with zero weights on the row's first master node; the
    Mortar's weights w_i / share_i (a uniform pressure p gives the row multipliers p w_i /
    share_i)."""
    npts = points.shape[0]
    ukey, inv = np.unique(s_nodes * npts + m_nodes, return_inverse=True)
    m_ia = np.bincount(inv, weights=values)
    s, a = ukey // npts, ukey % npts
    nz = m_ia != 0.0
    s, a, m_ia = s[nz], a[nz], m_ia[nz]
    slave = np.flatnonzero(weight > 0.0)
    slave = slave[np.isin(slave, s)]
    on = np.isin(s, slave)
    s, a, m_ia = s[on], a[on], m_ia[on]
    n = slave.size
    if n == 0:
        return Mortar(empty_pairing(slave, 3, 0), np.zeros(0))
    row = np.searchsorted(slave, s)
    count = np.bincount(row, minlength=n)
    start = np.concatenate([[0], np.cumsum(count)[:-1]])
    col = np.arange(s.size) - np.repeat(start, count)
    master = np.repeat(a[start][:, None], int(count.max()), axis=1)
    weights = np.zeros(master.shape)
    master[row, col] = a
    weights[row, col] = m_ia / weight[s]
    normal = normals[slave]
    point = np.einsum("mk,mkx->mx", weights, points[master])
    gap = np.einsum("mx,mx->m", normal, points[slave] - point)
    pairing = Pairing(slave=slave, paired=np.ones(n, dtype=bool),
                      facet=np.full(n, -1, dtype=np.int64), xi=np.zeros((n, 2)),
                      master=master.astype(np.int64), weights=weights, point=point,
                      normal=normal, tangents=tangent_basis(normal), gap=gap)
    return Mortar(pairing, weight[slave] / share[slave])
