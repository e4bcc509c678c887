"""The preset of a scene that names none (``[solver] preset`` absent, or "auto"): MUMPS or the
iterative preset, by the problem's size and kind, from scripts/results/bench_relations.md.

The kind is the dimension. A 2D problem takes MUMPS: its fill grows like n log n only (the 2D
crossover was not measured). A 3D one takes MUMPS below the
measured crossover and the iterative preset above it: MUMPS' time grows like n², its memory
like n^(4/3) (48 KB/DOF at 234k DOFs on the 3D friction box), while the iterative preset's grow
about like n (Krylov iterations per solve, mean, 4.8 → 6.0 → 7.2 from 1× to 64× the cells with
the nodal rows condensed, 20 → 23 → 32 on the augmented form; rtol 2.5e-14).
Pure Python, no PETSc: the memory check (mesh.memory) asks it before any solver exists.
"""

from __future__ import annotations

#: 3D DOFs from which the iterative preset is chosen. On the 3D friction box (one rank,
#: bench_relations.md) MUMPS took 0.95x the iterative preset's time at 441 DOFs, 0.87x at 2.5k
#: and 1.64x (1.8x the memory) at 17k: the friction crossover lies near 4k DOFs (log-linear
#: between the two); with the nodal rows condensed 0.82x, 0.73x and 1.60x (1.45x the
#: memory), the crossover between 2.5k and 17k. The mortar sphere (rows spread over slave and master facets, poorly
#: served by the Jacobi on the sparse Schur approximation) was 5.6x faster with MUMPS at 16.7k
#: DOFs (120-498 Krylov iterations per solve, at the preset's earlier aggregation threshold
#: 0.05; not measured since): 50k, past both, keeps it on MUMPS longer
CROSSOVER_3D = 50_000


def choose(dofs: int, dim: int) -> tuple[str, str]:
    """(preset, the reason in words) for a problem of ``dofs`` unknowns in ``dim`` dimensions."""
    if dim < 3:
        return "direct", f"auto: {dim}D, {dofs:,} DOFs: MUMPS"
    if dofs < CROSSOVER_3D:
        return "direct", f"auto: 3D, {dofs:,} DOFs < {CROSSOVER_3D:,}: MUMPS is faster there"
    return "iterative", (f"auto: 3D, {dofs:,} DOFs >= {CROSSOVER_3D:,}: Krylov + AMG is faster "
                         "and smaller there")
