"""Mortar (segment-to-segment) contact rows in 2D, with dual Lagrange multipliers.

Node-to-segment rows (``pairing.py``) collocate the gap at the slave nodes; they transmit a
uniform pressure exactly only when every master node is a slave node. Mortar rows test the
gap against a multiplier field over the slave surface instead: for slave node i

    row_i . q = n_i . ∫_Γs ψ_i (u_s − u_m∘π) ds
              = n_i . (D_ii u(s_i) − Σ_a M_ia u(a)),      D_ii = ∫ ψ_i φ_i ds = ∫ φ_i ds = w_i,
                                                          M_ia = ∫ ψ_i N_a∘π ds,

with φ_i the slave shape functions, N_a the master's, π the projection of the slave surface on
the master along the slave facet's normal, n_i the unit nodal normal (the average of the slave
facet normals at the node, pointing from the master towards the slave as in ``pairing.py``)
and ψ_i the **dual** multiplier basis (Wohlmuth): ψ_i = Σ_j A_ij φ_j on each slave facet with
∫ ψ_i φ_j ds = δ_ij ∫ φ_j ds, so that D is diagonal. The slave side of row i is then the slave
node alone, and dividing the row by w_i gives exactly a node-to-segment row whose master
weights are M_ia / w_i instead of N_a(ξ_i): a ``Pairing``. Everything in ``rows.py`` (Dn, Dt,
the frictional dual Dn − μ Dt·s) and the contact effect use it unchanged, in the same layout.

Properties (tests/contact/test_mortar.py):

* Σ_a M_ia = w_i (the ψ_i sum to one where the slave is covered): a constant jump c gives
  the integrated row value c·w_i, a rigid translation gives zero;
* on a straight interface with coincident sides any linear field is reproduced exactly
  (Σ_a M_ia x_a = w_i x_i); matching meshes give node-to-segment rows times w_i;
* the multiplier of the normalised row is a nodal force: a uniform pressure p gives
  λ_i = −p w_i and the uniform stress is the discrete solution (the contact patch test).

The weighted gap is ∫ ψ_i g0 ds = w_i n_i . (x_s_i − Σ_a (M_ia / w_i) x_a), the row applied
to the coordinates (biorthogonality: ∫ ψ_i x_s ds = w_i x_s_i on isoparametric facets), so
``g = g0 + Dn·q`` stays exact under rigid translations.

Integration: every (slave facet, master facet) pair is clipped in the slave facet's reference
coordinate (the master's end nodes projected on the slave facet), and each piece is integrated
by Gauss–Legendre; the master coordinate of a slave quadrature point is where the slave normal
through it meets the master facet. For straight line facets the map is affine and 2 points
integrate everything exactly; line3 uses 5 points (exact for straight line3 facets). Partially
covered slave facets (the ends of an interface) get a dual basis that is biorthogonal on the
covered part (Popp et al. 2013), so the identities above hold for their nodes too; a facet
covered by less than ``min_cover`` of its length is ignored (its dual basis would be
ill-conditioned) and slave nodes with no covered facet are left out.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from parsolve.contact.pairing import Pairing, candidate_pairs, empty_pairing, facet_frame, \
    project_on_facets
from parsolve.contact.rows import Rows, normal_rows, normal_values, tangent_rows
from parsolve.fem.elements import element

QUADRATURE = {"line": 2, "line3": 5}
CORNERS = 2  # line and line3: the end nodes come first


@dataclass
class Mortar:
    """Mortar rows of a 2D interface.

    pairing  normalised rows as a ``Pairing`` (row i divided by w_i): slave node, its master
             nodes with weights M_ia / w_i (padded with zero weights to a common width), the
             nodal normal and tangent, the averaged gap; ``facet`` is −1 and ``xi`` 0 (a row
             spans several master facets)
    weight   (n,) w_i = ∫ φ_i ds over the covered part of the slave surface
    """

    pairing: Pairing
    weight: np.ndarray

    @property
    def weighted_gap(self) -> np.ndarray:
        """∫ ψ_i g0 ds (n,)."""
        return self.weight * self.pairing.gap


def mortar_pairing(
    points: np.ndarray,
    slave_facets: np.ndarray,
    master_facets: np.ndarray,
    facet_type: str,
    search_radius: float | None = None,
    min_cover: float = 1e-6,
    radial: bool = False,
    half: np.ndarray | None = None,
) -> Mortar:
    """Mortar rows of the slave facets against the master facets (2D: line or line3).

    points        (npts, 2)  node coordinates
    slave_facets  (ns, k)    slave facets, outward orientation of the slave body
    master_facets (nm, k)    master facets, outward orientation of the master body
    search_radius            largest |gap| paired (default: the largest facet extent)
    min_cover                slave facets covered by less than this fraction are ignored
    radial                   axisymmetric (x = r): the integrals weighted by r, i.e. over
                             the surface of revolution (the 2π cancels in the normalised
                             rows), the dual basis biorthogonal for that measure
    half          (2,)       the largest master half-extent per axis (default: these
                             facets'; a rank pairing part of the surface gives the whole's)
    """
    points = np.asarray(points, dtype=float)
    sf = np.asarray(slave_facets, dtype=np.int64)
    mf = np.asarray(master_facets, dtype=np.int64)
    if facet_type not in QUADRATURE or points.shape[1] != 2:
        raise ValueError(f"mortar rows need 2D line or line3 facets, not {facet_type!r}")
    el = element(facet_type)
    xs_f, xm_f = points[sf], points[mf]                       # (ns, k, 2), (nm, k, 2)
    extent = max(_extent(xs_f), _extent(xm_f))
    radius = float(extent if search_radius is None else search_radius)
    e, f = _candidates(xs_f, xm_f, radius, half)
    lo, hi = _overlap(xs_f[e], xm_f[f], facet_type)
    keep = hi - lo > 1e-12
    e, f, lo, hi = e[keep], f[keep], lo[keep], hi[keep]
    if e.size == 0:
        return Mortar(empty_pairing(np.zeros(0, dtype=np.int64), 2, 0), np.zeros(0))
    pieces = _integrate_pieces(el, xs_f[e], xm_f[f], lo, hi, QUADRATURE[facet_type], radial)
    phi, jw, nm, gap = pieces
    # pieces whose slave and master are farther apart than the search radius are not paired
    near = np.abs(gap) <= radius * (1.0 + 1e-12)
    e, f, phi, jw, nm = e[near], f[near], phi[near], jw[near], nm[near]
    a_dual, covered = _dual_coefficients(phi, jw, e, sf.shape[0], xs_f, el, min_cover)
    ok = covered[e]
    s_nodes, m_nodes, m_ia, weight = _integrals(phi[ok], jw[ok], nm[ok], a_dual[e[ok]],
                                                sf[e[ok]], mf[f[ok]], points.shape[0])
    normals = _nodal_normals(points, sf[covered], el)
    return _assemble(points, s_nodes, m_nodes, m_ia, weight, normals)


def mortar_rows(mortar: Mortar, integrated: bool = True) -> tuple[Rows, Rows, np.ndarray]:
    """(Dn, Dt, values of ``Dn·q ≥ values``) of the mortar rows, in the layout of ``rows.py``.

    ``integrated``: the rows as integrals, n_i·∫ψ_i(u_s − u_m∘π) ds and values −∫ψ_i g0 ds;
    otherwise divided by w_i (the form the contact effect uses: multipliers are nodal forces,
    the gap a length): ``normal_rows(mortar.pairing)`` etc.
    """
    p = mortar.pairing
    rn, rt, b = normal_rows(p), tangent_rows(p), normal_values(p)
    if integrated:
        w = mortar.weight
        rn.coef = rn.coef * w[rn.row]
        rt.coef = rt.coef * np.repeat(w, p.dim - 1)[rt.row]
        b = b * w
    return rn, rt, b


# ----------------------------------------------------------------------------- geometry


def master_half(coords: np.ndarray) -> np.ndarray:
    """The largest half-extent per axis of facets (nf, k, dim) (zeros for none)."""
    if coords.shape[0] == 0:
        return np.zeros(coords.shape[-1])
    return 0.5 * (coords.max(axis=1) - coords.min(axis=1)).max(axis=0)


def _extent(coords: np.ndarray) -> float:
    return float(np.max(coords.max(axis=1) - coords.min(axis=1))) if coords.size else 0.0


def _candidates(xs_f: np.ndarray, xm_f: np.ndarray, radius: float,
                half: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray]:
    """(slave facet, master facet) pairs whose boxes, inflated by the radius, may overlap:
    master facet centres against slave boxes inflated by the radius and the largest master
    half-extent (bucket grid of ``pairing.candidate_pairs``)."""
    half = master_half(xm_f) if half is None else half
    lo = xs_f.min(axis=1) - radius - half
    hi = xs_f.max(axis=1) + radius + half
    centres = 0.5 * (xm_f.min(axis=1) + xm_f.max(axis=1))
    f, e = candidate_pairs(centres, lo, hi)
    # the master must face the slave: opposite outward normals at the facets' centres
    ns = _centre_normal(xs_f[e])
    nm = _centre_normal(xm_f[f])
    facing = np.einsum("mx,mx->m", ns, nm) < 0.0
    return e[facing], f[facing]


def _centre_normal(coords: np.ndarray) -> np.ndarray:
    """Outward unit normal (m, 2) at the centre of line facets (first two nodes: the ends)."""
    t = coords[:, 1] - coords[:, 0]
    n = np.column_stack([t[:, 1], -t[:, 0]])
    return n / np.linalg.norm(n, axis=1)[:, None]


def _overlap(xs: np.ndarray, xm: np.ndarray, facet_type: str) -> tuple[np.ndarray, np.ndarray]:
    """Interval [lo, hi] of the slave reference coordinate covered by the master facet: its
    end nodes projected on the slave facet (closest point: along the slave normal), clipped
    to [−1, 1] (hi ≤ lo: no overlap)."""
    m = xs.shape[0]
    if facet_type == "line":   # straight: the orthogonal projection in closed form
        t = xs[:, 1] - xs[:, 0]
        rel = xm[:, :CORNERS] - xs[:, None, 0]
        xi = 2.0 * np.einsum("mcx,mx->mc", rel, t) / np.einsum("mx,mx->m", t, t)[:, None] - 1.0
    else:
        ends = xm[:, :CORNERS].reshape(m * CORNERS, 2)
        xi = project_on_facets(ends, np.repeat(xs, CORNERS, axis=0), facet_type)[0]
        xi = xi[:, 0].reshape(m, CORNERS)
    return np.clip(xi.min(axis=1), -1.0, 1.0), np.clip(xi.max(axis=1), -1.0, 1.0)


def _integrate_pieces(el, xs, xm, lo, hi, nq: int, radial: bool = False):
    """Per piece (slave facet xs clipped to [lo, hi] against master facet xm) and quadrature
    point: slave shape functions φ (P, nq, k), |dx/dξ| × weight (P, nq) (× r when
    ``radial``), master shape functions at the projection N (P, nq, k), and the normal gap at
    the piece's centre (P,)."""
    gx, gw = np.polynomial.legendre.leggauss(nq)
    mid, half = 0.5 * (lo + hi), 0.5 * (hi - lo)
    xi = mid[:, None] + half[:, None] * gx[None, :]           # (P, nq)
    P, k = xs.shape[0], xs.shape[1]
    phi = el.shape(xi.reshape(-1, 1)).reshape(P, nq, k)
    dphi = el.grad_shape(xi.reshape(-1, 1))[:, :, 0].reshape(P, nq, k)
    x = np.einsum("pgk,pkx->pgx", phi, xs)
    dx = np.einsum("pgk,pkx->pgx", dphi, xs)
    jac = np.linalg.norm(dx, axis=2)
    jw = jac * half[:, None] * gw[None, :]
    if radial:   # (2 points integrate φ_i φ_j r exactly on line facets, 5 on line3)
        jw = jw * x[..., 0]
    normal = np.stack([dx[..., 1], -dx[..., 0]], axis=2) / jac[..., None]   # slave outward
    eta = _ray_on_master(el, x, normal, xm)
    nm = el.shape(eta.reshape(-1, 1)).reshape(P, nq, k)
    xmg = np.einsum("pga,pax->pgx", nm, xm)
    c = nq // 2 if nq % 2 else 0
    gap = -np.einsum("px,px->p", normal[:, c], x[:, c] - xmg[:, c])   # > 0 open
    return phi, jw, nm, gap


def _ray_on_master(el, x: np.ndarray, n: np.ndarray, xm: np.ndarray, iterations: int = 30,
                   tol: float = 1e-13) -> np.ndarray:
    """Master reference coordinate η (P, nq) where the line through x along n meets the master
    facet: (x_m(η) − x) × n = 0, exact for straight facets (start on the chord), Newton on
    the points still moving for curved ones."""
    # relative to the facet's first node: residuals of the facet's size, η to round-off
    x = x - xm[:, None, 0]
    xm = xm - xm[:, None, 0]
    a, b = xm[:, None, 0], xm[:, None, 1]
    eta = 2.0 * (-_cross(a - x, n) / _cross(b - a, n)) - 1.0
    if xm.shape[1] == CORNERS:
        return eta
    P, nq = eta.shape
    flat, xf, nf = eta.ravel(), x.reshape(-1, 2), n.reshape(-1, 2)
    facet = np.repeat(np.arange(P), nq)
    active = np.arange(flat.size)
    for _ in range(iterations):
        e = flat[active, None]
        coords = xm[facet[active]]
        xe = np.matmul(el.shape(e)[:, None, :], coords)[:, 0]
        de = np.matmul(el.grad_shape(e)[:, :, 0][:, None, :], coords)[:, 0]
        step = _cross(xe - xf[active], nf[active]) / _cross(de, nf[active])
        flat[active] -= step
        active = active[np.abs(step) > tol]
        if active.size == 0:
            break
    return flat.reshape(P, nq)


def _cross(u: np.ndarray, v: np.ndarray) -> np.ndarray:
    """z component of u × v for stacks of 2-vectors."""
    return u[..., 0] * v[..., 1] - u[..., 1] * v[..., 0]


# ----------------------------------------------------------------------------- dual basis


def _dual_coefficients(phi, jw, e, nfacets: int, xs_f, el, min_cover: float):
    """Per slave facet the dual coefficients A (ns, k, k), ψ_i = Σ_j A_ij φ_j, biorthogonal on
    the facet's covered part: A = diag(∫φ) (∫φφᵀ)⁻¹; and the mask of facets covered enough."""
    k = phi.shape[2]
    mass = np.zeros((nfacets, k, k))
    np.add.at(mass, e, np.einsum("pgi,pgj,pg->pij", phi, phi, jw))
    cover = np.zeros(nfacets)
    np.add.at(cover, e, jw.sum(axis=1))
    length = _facet_lengths(xs_f, el)
    covered = cover > min_cover * length
    a = np.zeros((nfacets, k, k))
    if np.any(covered):
        mc = mass[covered]
        diag = mc.sum(axis=2)                                   # ∫ φ_i over the covered part
        a[covered] = diag[:, :, None] * _inverse(mc)
    return a, covered


def _inverse(m: np.ndarray) -> np.ndarray:
    """Inverses of a stack of small matrices (closed forms for 2x2 and 3x3: numpy's batched
    inverse is slow on tiny matrices)."""
    if m.shape[1] == 3:   # columns of the inverse: cross products of the rows over det
        r0, r1, r2 = m[:, 0], m[:, 1], m[:, 2]
        cols = np.stack([np.cross(r1, r2), np.cross(r2, r0), np.cross(r0, r1)], axis=2)
        return cols / np.einsum("mx,mx->m", r0, cols[:, :, 0])[:, None, None]
    if m.shape[1] != 2:
        return np.linalg.inv(m)
    det = m[:, 0, 0] * m[:, 1, 1] - m[:, 0, 1] * m[:, 1, 0]
    out = np.stack([np.stack([m[:, 1, 1], -m[:, 0, 1]], 1), np.stack([-m[:, 1, 0], m[:, 0, 0]], 1)], 1)
    return out / det[:, None, None]


def _integrals(phi, jw, nm, a_dual, s_facets, m_facets, npts: int):
    """COO (slave node, master node, ∫ψ_i N_a ds) over the pieces, and w (npts,) = ∫φ_i ds."""
    psi = np.einsum("pij,pgj->pgi", a_dual, phi)              # (P, nq, k)
    m_loc = np.einsum("pgi,pga,pg->pia", psi, nm, jw)         # ∫ ψ_i N_a ds per piece
    d_loc = np.einsum("pgi,pg->pi", phi, jw)                  # ∫ φ_i ds per piece
    k, km = s_facets.shape[1], m_facets.shape[1]
    s_nodes = np.repeat(s_facets[:, :, None], km, axis=2)
    m_nodes = np.repeat(m_facets[:, None, :], k, axis=1)
    weight = np.bincount(s_facets.ravel(), weights=d_loc.ravel(), minlength=npts)
    return s_nodes.ravel(), m_nodes.ravel(), m_loc.ravel(), weight


def _facet_lengths(xs_f: np.ndarray, el, nq: int = 5) -> np.ndarray:
    gx, gw = np.polynomial.legendre.leggauss(nq)
    dphi = el.grad_shape(gx[:, None])[:, :, 0]                  # (nq, k)
    dx = np.einsum("gk,fkx->fgx", dphi, xs_f)
    return np.linalg.norm(dx, axis=2) @ gw


def _nodal_normals(points: np.ndarray, facets: np.ndarray, el) -> np.ndarray:
    """Unit normal per node (npts, 2): the average of the slave facets' unit normals at the
    node, pointing out of the master (into the slave: minus the slave's outward normal)."""
    dphi = el.grad_shape(el.nodes)[:, :, 0]                     # (k nodes, k shape)
    dx = np.einsum("ak,fkx->fax", dphi, points[facets])        # dx/dξ at each facet node
    n, _ = facet_frame(dx.reshape(-1, 2, 1))
    out = np.zeros_like(points)
    np.add.at(out, facets.ravel(), -n)
    norm = np.linalg.norm(out, axis=1)
    used = norm > 0
    out[used] /= norm[used, None]
    return out


# ----------------------------------------------------------------------------- pairing


def _assemble(points, s_nodes, m_nodes, values, weight, normals) -> Mortar:
    """The normalised rows as a Pairing: per slave node with w_i > 0, its master nodes (sorted)
    with weights M_ia / w_i, padded with zero weights on the row's first master node."""
    npts = points.shape[0]
    key = s_nodes * npts + m_nodes
    ukey, inv = np.unique(key, return_inverse=True)
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
        return Mortar(empty_pairing(slave, 2, 0), np.zeros(0))
    row = np.searchsorted(slave, s)
    count = np.bincount(row, minlength=n)
    width = int(count.max())
    start = np.concatenate([[0], np.cumsum(count)[:-1]])
    col = np.arange(s.size) - np.repeat(start, count)
    master = np.repeat(a[start][:, None], width, axis=1)
    weights = np.zeros((n, width))
    master[row, col] = a
    weights[row, col] = m_ia / weight[s]
    normal = normals[slave]
    point = np.einsum("mk,mkx->mx", weights, points[master])
    gap = np.einsum("mx,mx->m", normal, points[slave] - point)
    tangents = np.column_stack([-normal[:, 1], normal[:, 0]])[:, None, :]
    pairing = Pairing(slave=slave, paired=np.ones(n, dtype=bool),
                      facet=np.full(n, -1, dtype=np.int64), xi=np.zeros((n, 1)),
                      master=master.astype(np.int64), weights=weights, point=point,
                      normal=normal, tangents=tangents, gap=gap)
    return Mortar(pairing, weight[slave])
