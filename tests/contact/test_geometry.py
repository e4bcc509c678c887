"""parsolve.contact.geometry: the geometric stiffness of a slave on its master facet (the
force's dependence on the facet's frame and on the projection) against the closed form on a
segment (2D), in 3D against the full Jacobian of the forces (the rank claimed), and against a
curved obstacle's closed form."""

import numpy as np
import pytest

from parsolve.contact.geometry import facet_forces, facet_terms, local_terms


def closed_form(x, along_n, along_t, clip):
    """G on (slave, x1, x2) from docs/contact.md (contact.geometry's docstring):
    [v⊥; −N₁ v⊥; −N₂ v⊥] δθ + [0; v; −v] δξ, l δθ = n·(δx2 − δx1),
    l δξ = t·(δx_s − N_a δx_a) + g δθ (no δξ when the projection is clipped)."""
    a = x[2] - x[1]
    length = np.linalg.norm(a)
    t = a / length
    n = np.array([t[1], -t[0]])                      # pairing.facet_frame's normal
    xi = (x[0] - x[1]) @ t / length
    gap = (x[0] - x[1]) @ n
    xi_c = min(max(xi, 0.0), 1.0)
    v = along_n * n + along_t * t
    turned = -(v @ n) * t + (v @ t) * n
    u_a = np.concatenate([turned, -(1 - xi_c) * turned, -xi_c * turned]) / length
    w_a = np.concatenate([np.zeros(2), -n, n])
    u_b = np.concatenate([np.zeros(2), v, -v]) / length
    w_b = np.concatenate([t, -(1 - xi_c) * t - gap / length * n, -xi_c * t + gap / length * n])
    return np.outer(u_a, w_a) + (0.0 if clip else np.outer(u_b, w_b))


def terms(xs, coords, ft, force_of):
    w, u = facet_terms(xs, coords, ft, force_of)
    m = xs.shape[0]
    return np.einsum("mra,mrb->mab", u.reshape(m, w.shape[1], -1), w.reshape(m, w.shape[1], -1))


@pytest.mark.parametrize("seed", range(6))
@pytest.mark.parametrize("slave_xi", [0.3, 1.4])
def test_segment_is_the_closed_form(seed, slave_xi):
    """Random segments, gaps and forces (normal and friction parts, in the segment's frame):
    the two terms equal the closed form to 1e-8 of G; past the segment's end (the projection
    clipped there) the sliding term is gone."""
    rng = np.random.default_rng(seed)
    x1 = rng.normal(size=2)
    angle = rng.uniform(0, 2 * np.pi)
    x2 = x1 + rng.uniform(0.5, 2.0) * np.array([np.cos(angle), np.sin(angle)])
    a = x2 - x1
    n = np.array([a[1], -a[0]]) / np.linalg.norm(a)
    slave = x1 + slave_xi * a + rng.uniform(-0.1, 0.1) * np.linalg.norm(a) * n
    along_n, along_t = rng.normal(size=2)

    def force_of(normal, tangents, entries):
        return along_n * normal + along_t * tangents[:, 0]

    g = terms(slave[None], np.array([[x1, x2]]), "line", force_of)[0]
    exact = closed_form(np.array([slave, x1, x2]), along_n, along_t, slave_xi > 1)
    np.testing.assert_allclose(g, exact, atol=1e-8 * np.abs(exact).max())


FACETS = {
    "triangle": np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0]], float),
    "quad": np.array([[-1, -1, 0], [1, -1, 0], [1, 1, 0], [-1, 1, 0]], float),
    "triangle6": np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0], [0.5, 0, 0], [0.5, 0.5, 0],
                           [0, 0.5, 0]], float),
}


@pytest.mark.parametrize("ft", sorted(FACETS))
def test_3d_facets_have_rank_four(ft):
    """Warped 3D facets (bilinear, quadratic), a slave above each, a force with normal and
    tangential parts in the facet's frame: the four terms (two turns of the normal, two slides
    of the projection) are the whole Jacobian of the forces, whose columns are central
    differences of ``facet_forces`` (to 1e-7 of G)."""
    rng = np.random.default_rng(3)
    m = 4
    coords = FACETS[ft][None] + rng.normal(scale=0.05, size=(m,) + FACETS[ft].shape)
    xs = coords.mean(axis=1) + np.array([0.05, -0.03, 0.1]) + rng.normal(scale=0.02, size=(m, 3))
    along = rng.normal(size=(m, 3))

    def force_of(normal, tangents, entries):
        a = along[entries]
        return a[:, :1] * normal + a[:, 1:2] * tangents[:, 0] + a[:, 2:] * tangents[:, 1]

    g = terms(xs, coords, ft, force_of)
    k = coords.shape[1]
    x = np.concatenate([xs[:, None], coords], axis=1).reshape(m, -1)
    full = np.empty_like(g)
    h = 1e-5
    for j in range(x.shape[1]):
        f = []
        for sign in (1, -1):
            y = x.copy()
            y[:, j] += sign * h
            y = y.reshape(m, 1 + k, 3)
            f.append(facet_forces(y[:, 0], y[:, 1:], ft, force_of, np.arange(m)).reshape(m, -1))
        full[:, :, j] = (f[0] - f[1]) / (2 * h)
    np.testing.assert_allclose(g, full, atol=1e-7 * np.abs(full).max())


@pytest.mark.parametrize("dim", [2, 3])
def test_curved_obstacle_is_the_normal_s_turn(dim):
    """Against a circle (2D) or a sphere (3D) the normal force −λ n(x_s), n = (x_s − c)/ρ, turns
    with the slave: G = −λ (I − n nᵀ) / ρ, of rank dim − 1 (to 1e-8 of G)."""
    from parsolve.contact import obstacles

    rng = np.random.default_rng(dim)
    m, radius = 5, 2.0
    xs = rng.normal(size=(m, dim))
    xs *= ((radius + rng.uniform(-0.01, 0.01, size=m)) / np.linalg.norm(xs, axis=1))[:, None]
    lam = rng.uniform(0.5, 2.0, size=m)
    project = obstacles.cylinder if dim == 2 else obstacles.sphere

    def forces(y, entries):
        o = project(y[:, 0], np.arange(y.shape[0]), np.zeros(dim), radius, False) if dim == 3 \
            else project(y[:, 0], np.arange(y.shape[0]), np.zeros(dim), radius, None, False)
        return (-lam[entries, None] * o.normal)[:, None, :]

    w, u = local_terms(xs[:, None], forces, dim - 1, np.full(m, 1e-6 * radius))
    g = np.einsum("mra,mrb->mab", u.reshape(m, dim - 1, dim), w.reshape(m, dim - 1, dim))
    rho = np.linalg.norm(xs, axis=1)
    n = xs / rho[:, None]
    exact = -lam[:, None, None] * (np.eye(dim) - n[:, :, None] * n[:, None, :]) / rho[:, None, None]
    np.testing.assert_allclose(g, exact, atol=1e-8 * np.abs(exact).max())
