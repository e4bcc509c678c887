"""Classical baseline for gas solubility: persistent variables c_s, c_g and a semi-smooth Newton
(primal-dual active set) on the complementarity  min(c_g, κ (c_sat − c_s)) = 0.

Not part of the package: ``scripts/bench_solubility.py`` calls ``run_baseline`` to compare
with parsolve's non-associated relation formulation. Same discretisation as parsolve's
diffusion effect (``parsolve.fem.diffusion``: conductivity matrices, lumped capacity, source
lumped per cell), one rank, PETSc seq AIJ + LU.

Per node i and time step (backward Euler, lumped capacity m_i, unknowns at t_{n+1}):

    mass balance   m_i (c_s + c_g − c_s⁰ − c_g⁰)_i + Δt (K_s c_s + K_g c_g)_i = Δt (F_i + Q_i)
    equilibrium    min(c_g,i , κ (c_sat,i − c_s,i)) = 0

(F: volume source, Q: boundary inflow of the dissolved phase). This is the sum of the two
phase equations, where the exchange r (+r on c_s, −r on c_g) cancels. A node is *saturated*
when c_g > κ (c_sat − c_s): its equilibrium row pins c_s = c_sat, else it pins c_g = 0. The
equilibrium row is placed in the row of the variable it pins and the mass row in the other,
so the Jacobian has a nonzero diagonal and PETSc's LU needs no pivoting. At a Dirichlet node
(c_s = c_b < c_sat) the mass row is replaced by c_s = c_b, and its residual is the boundary
inflow (the reaction).

    run_baseline(mesh, params, times) -> dict          (see its docstring)
"""

from __future__ import annotations

import time

import numpy as np
from petsc4py import PETSc

from parsolve.fem import diffusion
from parsolve.fem.integrals import facet_rule
from parsolve.mesh.mesh import Mesh


def _value(v, t: float) -> float:
    return float(v(t)) if callable(v) else float(v)


def _node_array(v, points: np.ndarray) -> np.ndarray:
    if callable(v):
        return np.asarray(v(points), dtype=float) * np.ones(len(points))
    return np.asarray(v, dtype=float) * np.ones(len(points))


class _Discretisation:
    """Global lumped capacity, conductivity pattern and values, source / boundary vectors."""

    def __init__(self, mesh: Mesh, params: dict):
        self.mesh = mesh
        n = mesh.num_points
        th = params.get("thickness", 1.0) if mesh.dim == 2 else 1.0
        self.thickness = th
        coords = mesh.points[mesh.cells]
        self.coords = coords
        self.centroids = coords.mean(axis=1)
        self.m = np.bincount(mesh.cells.ravel(),
                             weights=diffusion.lumped_mass(coords, mesh.cell_type, 1.0, th).T.ravel(),
                             minlength=n)
        c = mesh.cells
        rows = np.broadcast_to(c[:, :, None], c.shape + (c.shape[1],)).ravel()
        cols = np.broadcast_to(c[:, None, :], c.shape + (c.shape[1],)).ravel()
        key, inv = np.unique(rows * n + cols, return_inverse=True)
        self.pr, self.pc = key // n, key % n          # node pairs, sorted by row then column
        self.npairs = len(key)

        def pairs(k: float) -> np.ndarray:
            ke = diffusion.conductivity(coords, mesh.cell_type, k, th).values[0]  # (nen, nen, nc)
            return np.bincount(inv, weights=ke.transpose(2, 0, 1).ravel(), minlength=self.npairs)

        self.Ks = pairs(params["D_s"])
        self.Kg = pairs(params.get("D_g", 0.0))

    def apply(self, vals: np.ndarray, x: np.ndarray) -> np.ndarray:
        return np.bincount(self.pr, weights=vals * x[self.pc], minlength=self.mesh.num_points)

    def source(self, f, t: float) -> np.ndarray:
        """Volume source f(t, centroids) constant per cell, lumped (Σ_cells f_c m_a,c)."""
        fc = f(t, self.centroids) if callable(f) else f
        fc = np.asarray(fc, dtype=float) * np.ones(self.mesh.num_cells)
        fe = diffusion.source_vector(self.coords, self.mesh.cell_type, fc, self.thickness, lumped=True)
        return np.bincount(self.mesh.cells.ravel(), weights=fe.ravel(), minlength=self.mesh.num_points)

    def boundary(self, fluxes: dict, t: float) -> np.ndarray:
        out = np.zeros(self.mesh.num_points)
        for group, q in fluxes.items():
            facets = self.mesh.facet_groups[group]
            rule = facet_rule(self.mesh.points[facets], self.mesh.facet_type, self.thickness)
            fe = _value(q, t) * (rule.weights @ rule.N)   # ∫ q N_a over each facet
            out += np.bincount(facets.ravel(), weights=fe.ravel(), minlength=self.mesh.num_points)
        return out


class _Jacobian:
    """The 2n × 2n Jacobian in PETSc seq AIJ with a fixed pattern: row 2i+s holds the mass
    columns (2j, 2j+1 for the neighbours j of i) plus the diagonal pair, whichever equation
    it carries."""

    def __init__(self, disc: _Discretisation):
        n = disc.mesh.num_points
        self.n = n
        nnz_node = np.bincount(disc.pr, minlength=n)                 # neighbours per node
        per_row = 2 * nnz_node
        rowptr = np.concatenate([[0], np.cumsum(np.repeat(per_row, 2))])
        node_start = np.concatenate([[0], np.cumsum(nnz_node)])[:-1]
        # columns of row (2i + s): for each neighbour j (sorted): 2j, 2j+1
        cols_node = np.stack([2 * disc.pc, 2 * disc.pc + 1], axis=1).ravel()
        self.cols = _row_columns(cols_node, node_start, nnz_node)
        self.rowptr = rowptr.astype(PETSc.IntType)
        self.cols = self.cols.astype(PETSc.IntType)
        # position of pair p's (c_s, c_g) columns in row 2i and in row 2i + 1
        pair_rank = np.arange(disc.npairs) - node_start[disc.pr]
        self.pos_s0 = rowptr[2 * disc.pr] + 2 * pair_rank
        self.pos_s1 = rowptr[2 * disc.pr + 1] + 2 * pair_rank
        diag_pair = np.flatnonzero(disc.pr == disc.pc)
        self.diag_s0 = self.pos_s0[diag_pair][np.argsort(disc.pr[diag_pair])]
        self.diag_s1 = self.pos_s1[diag_pair][np.argsort(disc.pr[diag_pair])]
        self.A = PETSc.Mat().createAIJ((2 * n, 2 * n), csr=(self.rowptr, self.cols,
                                                             np.zeros(len(self.cols))),
                                       comm=PETSc.COMM_SELF)
        self.ksp = PETSc.KSP().create(comm=PETSc.COMM_SELF)
        self.ksp.setType("preonly")
        self.ksp.getPC().setType("lu")

    def solve(self, vals: np.ndarray, rhs: np.ndarray) -> np.ndarray:
        self.A.setValuesCSR(self.rowptr, self.cols, vals)
        self.A.assemble()
        self.ksp.setOperators(self.A)
        b = PETSc.Vec().createWithArray(rhs, comm=PETSc.COMM_SELF)
        x = b.duplicate()
        self.ksp.solve(b, x)
        if self.ksp.getConvergedReason() < 0:
            raise RuntimeError("LU solve failed")
        return x.getArray().copy()


def _row_columns(cols_node: np.ndarray, node_start: np.ndarray, nnz_node: np.ndarray) -> np.ndarray:
    """Each node's column block (2 × its neighbours), repeated for its two rows, vectorised."""
    rows_len = np.repeat(2 * nnz_node, 2)
    starts = np.repeat(2 * node_start, 2)
    offs = np.arange(rows_len.sum()) - np.repeat(np.cumsum(rows_len) - rows_len, rows_len)
    return cols_node[np.repeat(starts, rows_len) + offs]


def run_baseline(mesh: Mesh, params: dict, times: np.ndarray) -> dict:
    """March the solubility problem through ``times`` (times[0] is the initial time).

    params: ``D_s`` (float), ``D_g`` (float, 0: immobile gas), ``c_sat`` (float or
    f(points) → (npoints,)), ``source`` (float or f(t, centroids) → (ncells,): volume source
    of the total, per unit volume and time), ``dirichlet`` ({node group: c_b or c_b(t)} on
    c_s, c_b < c_sat), ``flux`` ({facet group: q or q(t)}, inflow of c_s per unit area),
    ``c_s0``, ``c_g0`` (float or f(points)), ``thickness`` (2D), ``kappa`` (1.0), ``tol``
    (1e-12, relative), ``max_iter`` (50).

    Returns arrays, one row per time (row 0 the initial state): ``c_s``, ``c_g``
    (nsteps+1, npoints), ``saturated`` (bool, same shape), ``mass`` (Σ m_i (c_s + c_g)),
    ``source_in``, ``boundary_in`` (Δt × rates of the step), ``balance_error`` (relative to
    the largest mass), ``iterations`` (Newton iterations = LU solves per step), ``step_time``
    (s), and ``time`` (total s), ``lumped`` (the nodal capacities m_i).
    """
    t_start = time.perf_counter()
    disc = _Discretisation(mesh, params)
    jac = _Jacobian(disc)
    n = mesh.num_points
    pts = mesh.points
    csat = _node_array(params["c_sat"], pts)
    kappa = float(params.get("kappa", 1.0))
    tol, max_iter = float(params.get("tol", 1e-12)), int(params.get("max_iter", 50))
    dirichlet = params.get("dirichlet", {})
    fixed = np.zeros(n, bool)
    for group in dirichlet:
        fixed[mesh.node_groups[group]] = True
    cs = _node_array(params.get("c_s0", 0.0), pts)
    cg = _node_array(params.get("c_g0", 0.0), pts)
    hist = {k: [] for k in ("c_s", "c_g", "saturated", "mass", "source_in", "boundary_in",
                            "iterations", "step_time")}

    def record(sat, src, bnd, its, dt_wall):
        for k, v in (("c_s", cs), ("c_g", cg), ("saturated", sat), ("mass", disc.m @ (cs + cg)),
                     ("source_in", src), ("boundary_in", bnd), ("iterations", its),
                     ("step_time", dt_wall)):
            hist[k].append(np.copy(v))

    record(cg > kappa * (csat - cs), 0.0, 0.0, 0, 0.0)
    for t_old, t in zip(times[:-1], times[1:]):
        t0 = time.perf_counter()
        dt = t - t_old
        F = disc.source(params.get("source", 0.0), t)
        Q = disc.boundary(params.get("flux", {}), t)
        cb = np.zeros(n)
        for group, v in dirichlet.items():
            cb[mesh.node_groups[group]] = _value(v, t)
        old = disc.m * (cs + cg)
        cs, cg, sat, its = _newton(disc, jac, cs.copy(), cg.copy(), old, dt, F + Q, csat, kappa,
                                   fixed, cb, tol, max_iter)
        mass_res = disc.m * (cs + cg) - old + dt * (disc.apply(disc.Ks, cs) + disc.apply(disc.Kg, cg)) \
            - dt * (F + Q)
        record(sat, dt * F.sum(), dt * Q.sum() + mass_res[fixed].sum(), its, time.perf_counter() - t0)
    out = {k: np.array(v) for k, v in hist.items()}
    scale = max(np.abs(out["mass"]).max(), 1e-300)
    out["balance_error"] = np.concatenate([[0.0], np.abs(
        np.diff(out["mass"]) - out["source_in"][1:] - out["boundary_in"][1:]) / scale])
    out["time"] = time.perf_counter() - t_start
    out["lumped"] = disc.m
    return out


def _newton(disc, jac, cs, cg, old, dt, load, csat, kappa, fixed, cb, tol, max_iter):
    """Semi-smooth Newton (primal-dual active set) for one step; returns the new c_s, c_g,
    the saturated set and the number of LU solves."""
    cs[fixed] = cb[fixed]
    for it in range(max_iter + 1):
        sat = (cg > kappa * (csat - cs)) & ~fixed
        mass = disc.m * (cs + cg) - old + dt * (disc.apply(disc.Ks, cs) + disc.apply(disc.Kg, cg)) \
            - dt * load
        mass[fixed] = cs[fixed] - cb[fixed]
        eq = np.where(sat, kappa * (csat - cs), cg)
        scale = np.abs(old).max() + np.abs(dt * load).max() + np.abs(disc.m * (cs + cg)).max()
        # converged on the residual of the semi-smooth system, not on a repeated set: where
        # c_g ≈ κ (c_sat − c_s) ≈ 0 (m at c_sat) round-off can flip a node back and forth
        if max(np.abs(mass).max(), np.abs(eq).max() * disc.m.max()) <= tol * scale:
            return cs, cg, sat, it
        if it == max_iter:
            break
        vals, rhs = _system(disc, jac, dt, sat, fixed, kappa, mass, eq)
        dx = jac.solve(vals, rhs)
        cs, cg = cs - dx[0::2], cg - dx[1::2]
    raise RuntimeError(f"semi-smooth Newton did not converge in {max_iter} iterations")


def _system(disc, jac, dt, sat, fixed, kappa, mass, eq):
    """Jacobian values in the fixed pattern and the right-hand side (residual), with the
    equilibrium row in the row of the variable it pins (c_s if saturated, else c_g)."""
    n = disc.mesh.num_points
    vals = np.zeros(len(jac.cols))
    # mass row of node i goes to row 2i (unsaturated) or 2i+1 (saturated)
    mrow_s = np.where(sat[disc.pr], jac.pos_s1, jac.pos_s0)        # position of (i, c_s of j)
    ms_diag = np.where(disc.pr == disc.pc, disc.m[disc.pr], 0.0)
    vals[mrow_s] = dt * disc.Ks + ms_diag
    vals[mrow_s + 1] = dt * disc.Kg + ms_diag
    # Dirichlet nodes: mass row → c_s = c_b (row 2i, since a fixed node is never saturated)
    fixed_pair = fixed[disc.pr]
    vals[jac.pos_s0[fixed_pair]] = 0.0
    vals[jac.pos_s0[fixed_pair] + 1] = 0.0
    fixed_nodes = np.flatnonzero(fixed)
    vals[jac.diag_s0[fixed_nodes]] = 1.0
    # equilibrium rows: saturated → −κ on c_s in row 2i; otherwise 1 on c_g in row 2i+1
    s_nodes, u_nodes = np.flatnonzero(sat), np.flatnonzero(~sat)
    vals[jac.diag_s0[s_nodes]] = -kappa
    vals[jac.diag_s1[u_nodes] + 1] = 1.0
    rhs = np.empty(2 * n)
    rhs[0::2] = np.where(sat, eq, mass)
    rhs[1::2] = np.where(sat, mass, eq)
    return vals, rhs


def _grow_shrink_params() -> dict:
    """The shipped 1D scene (tests/reference/solubility_fv.py GROW_SHRINK) as baseline params."""
    return {"D_s": 0.1, "c_sat": 1.0, "dirichlet": {"right": 0.0},
            "source": lambda t, xc: np.where((xc[:, 0] < 0.25) & (t <= 0.5 + 1e-12), 4.0, 0.0)}


def main() -> None:
    """Table: the grow-shrink scene on Q1 strips under refinement (one rank)."""
    from parsolve.mesh.generators import rectangle

    times = np.linspace(0.0, 2.0, 101)
    print("| elements | nodes | LU solves | max / step | mean / step | time (s) | "
          "max balance error | max saturated nodes |")
    print("|---|---|---|---|---|---|---|---|")
    for nx in (40, 80, 160, 320, 640):
        mesh = rectangle(1.0, 0.05, nx, 1, cell="quad")
        r = run_baseline(mesh, _grow_shrink_params(), times)
        its = r["iterations"][1:]
        print(f"| {nx} | {mesh.num_points} | {its.sum()} | {its.max()} | {its.mean():.2f} | "
              f"{r['time']:.2f} | {r['balance_error'].max():.1e} | {r['saturated'].sum(axis=1).max()} |")


if __name__ == "__main__":
    main()
