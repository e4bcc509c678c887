"""The geometric stiffness of node-to-segment / node-to-face rows under finite sliding.

A slave s in contact with a facet of a deformable master receives the force v (the
relations' D λ on it: normal and friction parts, written in the facet's frame) and passes
−N_a(ξ) v to the facet's nodes, ξ its projection. When the bodies move with λ held, the force
turns with the facet and its point of application slides along it (2D, a straight segment
(x1, x2) of length l, gap g:

    δθ = n · (δx2 − δx1) / l                   (the segment's rotation; δt = n δθ, δn = −t δθ)
    δξ = [t · (δx_s − N_a δx_a) + g δθ] / l     (the projection's slide)
    δf = [v⊥; −N_1 v⊥; −N_2 v⊥] δθ + [0; v; −v] δξ,   v⊥ = −(v·n) t + (v·t) n

and in 3D the same with the normal's two turns and ξ's two components), so
G = ∂f/∂x has rank 2 (dim − 1). Finite sliding's re-pairing makes the rows exact at each
iterate; G is the part of the Jacobian they leave out (the force's dependence on the
geometry), whose absence makes a sliding step's iterations converge linearly (2D ironing:
10–14 per step at a rate of ~0.08). The contact enters it in the Newton matrix as a term on
each slave's node tuple (``effects.row_terms``): −Σ u wᵀ added to K, i.e. K − G, the tangent
of f_int − D(q) λ.

G is computed, for any facet type, by central differences of the forces on the facet's
geometry (``facet_terms``; tests/contact/test_geometry.py checks it against the closed form
above) and compressed to its leading singular triplets: G = Σ σ U Vᵀ, u = σ U, w = V.
A projection clipped to the facet's edge does not slide with the slave (its ξ is held there).
Against a rigid cylinder or sphere the force on the slave turns with the obstacle's normal at
its projection (rank dim − 1, on the slave's own block; a plane has none).
"""

from __future__ import annotations

import numpy as np

from parsolve.contact.pairing import clip_to_reference, facet_frame, inside_reference, \
    project_on_facets
from parsolve.fem.elements import element


def facet_forces(xs: np.ndarray, coords: np.ndarray, facet_type: str, force_of,
                 entries: np.ndarray) -> np.ndarray:
    """The forces (m, 1 + k, dim) a slave at xs (m, dim) in contact with its facet (nodes
    coords (m, k, dim)) passes to itself and the facet's nodes: [v; −N_a(ξ) v], ξ its
    projection (clipped to the facet, as the pairing does), v = force_of(normal, tangents,
    entries) in the facet's frame there (``pairing.facet_frame``; ``entries``: which slave
    each row is)."""
    el = element(facet_type)
    xi, _, jac = project_on_facets(xs, coords, facet_type)
    out = ~inside_reference(facet_type, xi, 0.0)
    if out.any():
        xi[out] = clip_to_reference(facet_type, xi[out])
        jac[out] = np.einsum("mka,mkx->mxa", el.grad_shape(xi[out]), coords[out])
    normal, tangents = facet_frame(jac)
    v = force_of(normal, tangents, entries)
    return np.concatenate([v[:, None, :], -el.shape(xi)[:, :, None] * v[:, None, :]], axis=1)


def facet_terms(xs: np.ndarray, coords: np.ndarray, facet_type: str, force_of,
                step: float = 1e-6) -> tuple[np.ndarray, np.ndarray]:
    """The geometric stiffness G = ∂f/∂x (λ held) of ``facet_forces`` as r = 2 (dim − 1)
    rank-one terms per slave (the normal's dim − 1 turns, the projection's dim − 1 slides):
    (w, u), each (m, r, 1 + k, dim), G = Σ u wᵀ (``local_terms``, the step × the facet's
    size)."""
    dim = xs.shape[1]
    size = np.linalg.norm(coords[:, -1] - coords[:, 0], axis=1)

    def forces(y, entries):
        return facet_forces(y[:, 0], y[:, 1:], facet_type, force_of, entries)
    return local_terms(np.concatenate([xs[:, None, :], coords], axis=1), forces,
                       2 * (dim - 1), step * size)


def local_terms(x: np.ndarray, forces, rank: int, h: np.ndarray
                ) -> tuple[np.ndarray, np.ndarray]:
    """The Jacobian of ``forces(y, entries)`` (M, p, dim) on the local geometries x (m, p, dim)
    (a slave and its facet's nodes; a slave alone against a curved obstacle) as ``rank``
    rank-one terms (w, u), each (m, rank, p, dim). Central differences of step h (m,) (a few
    1e-6 of the geometry: the forces' differences then give the Jacobian to ~1e-10, ample for
    a Newton matrix), all perturbed geometries in one batch (``entries``: which of the m each
    row is), then its leading singular triplets (u = σ U, w = V)."""
    m, p, dim = x.shape
    nv = p * dim
    h = np.maximum(h, 1e-300)
    # batch (sign, coordinate, entry): x ± h e_j
    shift = np.concatenate([np.eye(nv), -np.eye(nv)])[:, None, :] * h[None, :, None]
    y = (x.reshape(1, m, nv) + shift).reshape(-1, p, dim)
    f = forces(y, np.tile(np.arange(m), 2 * nv)).reshape(2, nv, m, nv)
    jac = ((f[0] - f[1]) / (2.0 * h[None, :, None])).transpose(1, 2, 0)   # (m, f row, x col)
    left, sigma, right = np.linalg.svd(jac)
    u = (left[:, :, :rank] * sigma[:, None, :rank]).transpose(0, 2, 1).reshape(m, rank, p, dim)
    w = right[:, :rank, :].reshape(m, rank, p, dim)
    return w, u
