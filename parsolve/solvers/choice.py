"""The preset of a scene that names none (``[solver] preset`` absent, or "auto"): MUMPS or the
iterative preset, by the problem's size and kind, from scripts/results/bench_relations.md.

The kind is the dimension. A 2D problem takes MUMPS: its fill grows like n log n only (the 2D
crossover was not measured). A 3D one takes MUMPS below the
measured crossover and the iterative preset above it: MUMPS' time grows like n², its memory
like n^(4/3) (48 KB/DOF at 234k DOFs on the 3D friction box), while the iterative preset's grow
about like n (Krylov iterations per solve 20 → 24 → 32 from 1× to 64× the cells, rtol 1e-13).
Pure Python, no PETSc: the memory check (mesh.memory) asks it before any solver exists.
"""

from __future__ import annotations

#: 3D DOFs from which the iterative preset is chosen: on the 3D friction box MUMPS took 0.6×
#: the iterative preset's time at 2.5k DOFs and 1.5× (1.7× the memory) at 17k; the mortar
#: sphere at 16.7k DOFs was 5.6× faster with MUMPS (120-498 Krylov iterations per solve:
#: bench_relations.md): 50k, past the friction box's crossover, keeps the mortar on MUMPS longer
CROSSOVER_3D = 50_000


def choose(dofs: int, dim: int) -> tuple[str, str]:
    """(preset, the reason in words) for a problem of ``dofs`` unknowns in ``dim`` dimensions."""
    if dim < 3:
        return "direct", f"auto: {dim}D, {dofs:,} DOFs: MUMPS"
    if dofs < CROSSOVER_3D:
        return "direct", f"auto: 3D, {dofs:,} DOFs < {CROSSOVER_3D:,}: MUMPS is faster there"
    return "iterative", (f"auto: 3D, {dofs:,} DOFs >= {CROSSOVER_3D:,}: Krylov + AMG is faster "
                         "and smaller there")
