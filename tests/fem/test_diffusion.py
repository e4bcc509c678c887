"""Scalar diffusion kernels: patch tests, capacity matrices, sources, fluxes, exact 1D and
rotated-tensor solutions, and backward-Euler decay of one mode against the discrete eigenvalue."""

import numpy as np
import pytest

from parsolve.fem import diffusion
from parsolve.fem.integrals import facet_rule, integrate
from parsolve.mesh.generators import box, make_quadratic, rectangle

CELLS = ["triangle", "triangle6", "quad", "tetra", "tetra10", "hexahedron"]
K2 = np.array([[2.0, 0.5], [0.5, 1.0]])
K3 = np.array([[2.0, 0.5, 0.1], [0.5, 1.5, -0.3], [0.1, -0.3, 1.0]])


def distorted(cell: str, seed: int = 3):
    """Unit square / cube with randomly moved interior vertices (P2 edges kept straight)."""
    rng = np.random.default_rng(seed)
    linear = {"triangle6": "triangle", "tetra10": "tetra"}.get(cell, cell)
    mesh = rectangle(1.0, 1.0, 4, 3, cell=linear) if linear in ("quad", "triangle") \
        else box(1.0, 1.0, 1.0, 3, 2, 2, cell=linear)
    inner = np.all((mesh.points > 1e-12) & (mesh.points < 1 - 1e-12), axis=1)
    mesh.points = mesh.points.copy()
    mesh.points[inner] += rng.uniform(-0.07, 0.07, size=(inner.sum(), mesh.dim))
    if cell != linear:
        mesh = make_quadratic(mesh)
    return mesh


def assemble(mesh, element_values: np.ndarray) -> np.ndarray:
    """Dense global matrix from cell-last element matrices (1, nen, nen, nc)."""
    n = mesh.num_points
    A = np.zeros((n, n))
    c = mesh.cells
    np.add.at(A, (c[:, :, None], c[:, None, :]), element_values[0].transpose(2, 0, 1))
    return A


def assemble_vector(n: int, nodes: np.ndarray, ve: np.ndarray) -> np.ndarray:
    return np.bincount(nodes.ravel(), weights=ve.ravel(), minlength=n)


def boundary_nodes(mesh) -> np.ndarray:
    return np.flatnonzero(np.any((mesh.points < 1e-12) | (mesh.points > 1 - 1e-12), axis=1))


@pytest.mark.parametrize("cell", CELLS)
@pytest.mark.parametrize("tensor", [False, True])
def test_patch_linear_field(cell, tensor):
    """A linear field: zero residual at interior nodes, boundary residual = ∫ (k∇h·n) N_a,
    exact constant flux −k g in every cell and at every node."""
    mesh = distorted(cell)
    d = mesh.dim
    g = np.array([0.3, -0.7, 0.4])[:d]
    k = (K2 if d == 2 else K3) if tensor else 1.7
    kt = k if tensor else k * np.eye(d)
    h = 0.2 + mesh.points @ g
    coords = mesh.points[mesh.cells]
    r = assemble(mesh, diffusion.conductivity(coords, mesh.cell_type, k).values) @ h
    inner = np.setdiff1d(np.arange(mesh.num_points), boundary_nodes(mesh))
    assert np.abs(r[inner]).max() < 1e-13
    # boundary: the residual is the inflow (k ∇h)·n on each side, with the outward normal
    q_in = np.zeros(mesh.num_points)
    sides = {"left": 0, "right": 0, "bottom": 1, "top": 1} if d == 2 else \
        {"xmin": 0, "xmax": 0, "ymin": 1, "ymax": 1, "zmin": 2, "zmax": 2}
    for name, axis in sides.items():
        facets = mesh.facet_groups[name]
        n = np.zeros(d)
        n[axis] = -1.0 if name in ("left", "bottom", "xmin", "ymin", "zmin") else 1.0
        rule = facet_rule(mesh.points[facets], mesh.facet_type)
        fe = ((kt @ g) @ n) * (rule.weights @ rule.N)
        q_in += assemble_vector(mesh.num_points, facets, fe)
    assert np.abs(r - q_in).max() < 1e-13
    flux = diffusion.cell_flux(coords, mesh.cell_type, k, h[mesh.cells])
    assert np.abs(flux - (-kt @ g)).max() < 1e-13
    sums, w = diffusion.nodal_flux_sums(mesh.points, mesh.cells, mesh.cell_type, k, h)
    assert np.abs(sums / w[:, None] - (-kt @ g)).max() < 1e-13


@pytest.mark.parametrize("cell", CELLS)
def test_conductivity_symmetric_singular(cell):
    """K is symmetric, positive semi-definite, and its kernel is the constants."""
    mesh = distorted(cell)
    k = K2 if mesh.dim == 2 else K3
    K = assemble(mesh, diffusion.conductivity(mesh.points[mesh.cells], mesh.cell_type, k).values)
    assert np.abs(K - K.T).max() < 1e-13
    ev = np.linalg.eigvalsh(K)
    assert abs(ev[0]) < 1e-12 and ev[1] > 1e-3


@pytest.mark.parametrize("cell", CELLS)
def test_factored_matches_values(cell):
    """Per-region tensors in factored form hold the same numbers as the full values; with one
    region, ``ElementMatrices.reduce`` gives one row per pair (a scalar field's d² = 1)."""
    mesh = distorted(cell)
    d, nc = mesh.dim, mesh.num_cells
    tensors = np.stack([np.eye(d) * 3.0, K2 if d == 2 else K3])
    region = np.arange(nc) % 2
    coords = mesh.points[mesh.cells]
    full = diffusion.conductivity(coords, mesh.cell_type, tensors[region])
    fact = diffusion.conductivity_factored(coords, mesh.cell_type, tensors, region)
    t = fact.tensors[fact.cell_material][:, :, 0]              # (nc, d²)
    values = np.einsum("cm,mabc->abc", t, fact.geometric)
    assert np.abs(values - full.values[0]).max() < 1e-12 * np.abs(values).max()
    one = diffusion.conductivity_factored(coords, mesh.cell_type, tensors[1:], np.zeros(nc, int))
    nen = mesh.cells.shape[1]
    slots = np.arange(nen * nen * nc).reshape(nen, nen, nc)  # one slot per entry: no summation
    a = one.reduce(slots, slots.size)
    b = diffusion.conductivity(coords, mesh.cell_type, tensors[1]).reduce(slots, slots.size)
    assert a.shape == b.shape == (1, slots.size)
    assert np.abs(a - b).max() < 1e-12 * np.abs(a).max()


@pytest.mark.parametrize("cell", CELLS)
def test_mass_sums_and_lumping(cell):
    mesh = distorted(cell)
    coords = mesh.points[mesh.cells]
    cap = np.linspace(1.0, 2.0, mesh.num_cells)
    vol = diffusion.lumped_mass(coords, mesh.cell_type, 1.0).sum(axis=0)  # per-cell volume
    assert abs(vol.sum() - 1.0) < 1e-13
    M = diffusion.mass(coords, mesh.cell_type, cap, thickness=0.5)
    assert np.allclose(M.sum(axis=(0, 1, 2)), 0.5 * cap * vol, rtol=1e-13, atol=0)
    assert np.abs(M - M.transpose(0, 2, 1, 3)).max() < 1e-15
    ml = diffusion.lumped_mass(coords, mesh.cell_type, cap, thickness=0.5)
    assert ml.min() > 0
    assert np.allclose(ml.sum(axis=0), 0.5 * cap * vol, rtol=1e-13, atol=0)
    # the assembled consistent mass integrates a linear field exactly: 1ᵀ M h = ∫ c h
    h = 1.0 + mesh.points @ np.array([0.5, -0.25, 0.75])[:mesh.dim]
    Mg = assemble(mesh, diffusion.mass(coords, mesh.cell_type, 1.0))
    sv = assemble_vector(mesh.num_points, mesh.cells,
                         diffusion.source_vector(coords, mesh.cell_type, h[mesh.cells]))
    assert abs(Mg.sum(axis=0) @ h - sv.sum()) < 1e-13
    assert abs(sv @ np.ones(mesh.num_points) - (Mg @ h).sum()) < 1e-13


def test_row_sum_would_fail_on_triangle6():
    """Why HRZ: the consistent row sums of triangle6 vertices are zero, HRZ weights are 1/19,
    16/57 of the area (vertex, midside)."""
    mesh = rectangle(1.0, 1.0, 1, 1, cell="triangle6")
    coords = mesh.points[mesh.cells]
    M = diffusion.mass(coords, "triangle6")[0]
    assert np.abs(M.sum(axis=1)[:3]).max() < 1e-15
    ml = diffusion.lumped_mass(coords, "triangle6")
    assert np.allclose(ml[:3], 0.5 / 19) and np.allclose(ml[3:], 0.5 * 16 / 57)


@pytest.mark.parametrize("cell", CELLS)
def test_lumped_source_keeps_uniform(cell):
    """A uniform source with the lumped option is exactly f times the lumped mass."""
    mesh = distorted(cell)
    coords = mesh.points[mesh.cells]
    f = diffusion.source_vector(coords, mesh.cell_type, 2.5, lumped=True)
    assert np.allclose(f, 2.5 * diffusion.lumped_mass(coords, mesh.cell_type).T, rtol=1e-14)
    if cell in ("triangle", "quad", "tetra", "hexahedron"):  # row sums = ∫ N_a
        assert np.allclose(f, diffusion.source_vector(coords, mesh.cell_type, 2.5), rtol=1e-13)


@pytest.mark.parametrize("cell", ["quad", "triangle6", "hexahedron", "tetra10"])
def test_facet_flux_node_values(cell):
    """A boundary inflow given by node values q = 1 + 2y (+ z) on the x = 0 side: the vector
    sums to ∫ q (thickness 0.5 in 2D), and to ∫ q y against the field y (q and y are linear,
    so their interpolants are exact and the facet rule of degree 2·order integrates q y)."""
    mesh = rectangle(1.0, 1.0, 3, 4, cell=cell) if cell in ("quad", "triangle6") \
        else box(1.0, 1.0, 1.0, 2, 3, 2, cell=cell)
    side = "left" if mesh.dim == 2 else "xmin"
    facets = mesh.facet_groups[side]
    p = mesh.points
    q = 1.0 + 2.0 * p[:, 1] + (p[:, 2] if mesh.dim == 3 else 0.0)
    th = 0.5 if mesh.dim == 2 else 1.0
    rule = facet_rule(p[facets], mesh.facet_type, th)
    fe = integrate(rule, (q[facets] @ rule.N.T)[..., None])[..., 0]
    assert abs(fe.sum() - th * (2.0 if mesh.dim == 2 else 2.5)) < 1e-13
    # ∫ (1 + 2y + z) y over the side: 1/2 + 2/3 (+ 1/4 in 3D)
    assert abs((fe * p[facets][:, :, 1]).sum() - th * (7 / 6 + (0.25 if mesh.dim == 3 else 0))) < 1e-13


def solve_dirichlet(mesh, K, F, fixed, values):
    free = np.setdiff1d(np.arange(mesh.num_points), fixed)
    h = np.zeros(mesh.num_points)
    h[fixed] = values
    h[free] = np.linalg.solve(K[np.ix_(free, free)], F[free] - K[np.ix_(free, fixed)] @ h[fixed])
    return h


@pytest.mark.parametrize("cell", ["quad", "triangle", "triangle6"])
def test_strip_steady_source(cell):
    """−k h'' = f on a strip, h = 0 at both ends: h = f x (1 − x) / 2k, exact at the nodes for
    P1/Q1 (1D nodal exactness) and everywhere for P2."""
    mesh = rectangle(1.0, 0.1, 8, 1, cell=cell)
    k, f = 1.3, 4.0
    coords = mesh.points[mesh.cells]
    K = assemble(mesh, diffusion.conductivity(coords, cell, k, thickness=0.2).values)
    F = assemble_vector(mesh.num_points, mesh.cells,
                        diffusion.source_vector(coords, cell, f, thickness=0.2))
    fixed = np.union1d(mesh.node_groups["left"], mesh.node_groups["right"])
    h = solve_dirichlet(mesh, K, F, fixed, 0.0)
    x = mesh.points[:, 0]
    assert np.abs(h - f * x * (1 - x) / (2 * k)).max() < 1e-13
    # exact outflow through each end: f/2 per unit area, times the end area 0.1 × 0.2
    r = K @ h - F
    for side in ("left", "right"):
        assert abs(r[mesh.node_groups[side]].sum() + f / 2 * 0.02) < 1e-13


@pytest.mark.parametrize("cell", ["triangle6", "tetra10"])
def test_rotated_tensor_quadratic(cell):
    """h = (e·x)²/2 along a principal direction e of a rotated tensor k: −div(k∇h) = −k_e.
    P2 reproduces it exactly with Dirichlet data on the whole boundary."""
    mesh = distorted(cell, seed=5)
    d = mesh.dim
    rng = np.random.default_rng(2)
    R, _ = np.linalg.qr(rng.normal(size=(d, d)))
    kdiag = np.array([3.0, 0.5, 1.2])[:d]
    k = R @ np.diag(kdiag) @ R.T
    e = R[:, 0]
    coords = mesh.points[mesh.cells]
    K = assemble(mesh, diffusion.conductivity(coords, cell, k).values)
    F = assemble_vector(mesh.num_points, mesh.cells, diffusion.source_vector(coords, cell, -kdiag[0]))
    exact = 0.5 * (mesh.points @ e) ** 2
    fixed = boundary_nodes(mesh)
    h = solve_dirichlet(mesh, K, F, fixed, exact[fixed])
    assert np.abs(h - exact).max() < 1e-12
    # the flux −k∇h = −k_e (e·x) e at the nodes, exactly (P2 gradient is linear)
    sums, w = diffusion.nodal_flux_sums(mesh.points, mesh.cells, cell, k, h)
    expected = -kdiag[0] * (mesh.points @ e)[:, None] * e[None, :]
    assert np.abs(sums / w[:, None] - expected).max() < 1e-11


@pytest.mark.parametrize("cell", ["quad", "triangle"])
@pytest.mark.parametrize("lump", [False, True])
def test_backward_euler_mode_decay(cell, lump):
    """c ḣ = k Δh on the unit square, h = 0 on the boundary, started from the lowest discrete
    mode v of the pencil (K, M) (dense numpy): backward Euler scales it by exactly
    1/(1 + Δt λ) per step. The mode is the interpolated sin πx sin πy (exactly, for Q1 and for
    lumped P1 on this structured mesh), and λ → 2π² k/c."""
    n, k, c, dt, steps = 10, 0.8, 2.0, 0.01, 20
    mesh = rectangle(1.0, 1.0, n, n, cell=cell)
    coords = mesh.points[mesh.cells]
    K = assemble(mesh, diffusion.conductivity(coords, cell, k).values)
    Me = diffusion.lumped_as_matrices(diffusion.lumped_mass(coords, cell, c)) if lump \
        else diffusion.mass(coords, cell, c)
    M = assemble(mesh, Me)
    free = np.setdiff1d(np.arange(mesh.num_points), boundary_nodes(mesh))
    Kf, Mf = K[np.ix_(free, free)], M[np.ix_(free, free)]
    Li = np.linalg.inv(np.linalg.cholesky(Mf))
    lams, V = np.linalg.eigh(Li @ Kf @ Li.T)
    lam, v = lams[0], Li.T @ V[:, 0]
    assert np.abs(Kf @ v - lam * (Mf @ v)).max() < 1e-12 * np.abs(Kf @ v).max()
    x, y = mesh.points[free].T
    mode = np.sin(np.pi * x) * np.sin(np.pi * y)
    v *= (mode @ v) / (v @ v)                                  # same sign and scale
    exact_mode = cell == "quad" or lump
    assert np.abs(v - mode).max() < (1e-12 if exact_mode else 0.02)
    assert abs(lam / (2 * np.pi**2 * k / c) - 1) < 0.05
    h = v.copy()
    A = Mf + dt * Kf
    for _ in range(steps):
        h = np.linalg.solve(A, Mf @ h)
    assert np.abs(h - v * (1 + dt * lam) ** -steps).max() < 1e-13


def test_bad_shapes():
    mesh = rectangle(1.0, 1.0, 2, 2)
    coords = mesh.points[mesh.cells]
    with pytest.raises(ValueError, match="conductivity"):
        diffusion.conductivity(coords, "quad", np.ones(3))
    with pytest.raises(ValueError, match="capacity"):
        diffusion.mass(coords, "quad", np.ones(5))
