"""The preset of a scene that names none (``[solver] preset`` absent, or "auto"): MUMPS or the
iterative preset, by the problem's size and kind, from scripts/results/bench_relations.md.

The kind is the dimension. A 2D problem takes MUMPS: its fill grows like n log n only (the 2D
crossover was not measured). A 3D one takes MUMPS below the
measured crossover and the iterative preset above it: MUMPS' time grows like n², its memory
like n^(4/3) (48 KB/DOF at 234k DOFs on the 3D friction box), while the iterative preset's grow
about like n (Krylov iterations per solve, mean, 2.3 → 4.1 → 6.3 from 1× to 64× the cells with
the nodal rows condensed, 16.2 → 17.1 → 23.2 on the augmented form; rtol 2.5e-14).
Pure Python, no PETSc: the memory check (mesh.memory) asks it before any solver exists.
"""

from __future__ import annotations

#: 3D DOFs from which the iterative preset is chosen. On the 3D friction box (one rank,
#: bench_relations.md, the nodal rows condensed) MUMPS took 0.97x the iterative preset's time
#: at 441 DOFs, 0.92x at 2.5k and 1.79x (2.1x the memory) at 16.9k: the crossover of nodal
#: rows lies near 3.2k DOFs (log-linear between the last two); on the augmented form 1.04x,
#: 1.14x and 1.95x. The mortar sphere (rows spread over slave and master facets: the augmented
#: form, 69-298 Krylov iterations per solve, mean 215) was 4.0x faster with MUMPS at 16.7k
#: DOFs, its only size measured. 50k stands, not as the nodal rows' crossover (far past it:
#: MUMPS costs them 1.8x the time and 2.1x the memory at 16.9k already) but as the guard of
#: multi-node rows, unmeasured past 16.7k. It stays one crossover for both kinds: the kind is
#: decided on the assembled operator's patterns (``solvers.condensed``, per operator); read
#: from the model's relations it would need the model and a collective over spread rows, while
#: mesh.memory asks here from the mesh's size alone, before any model exists, and must get the
#: run's answer.
CROSSOVER_3D = 50_000


def choose(dofs: int, dim: int) -> tuple[str, str]:
    """(preset, the reason in words) for a problem of ``dofs`` unknowns in ``dim`` dimensions."""
    if dim < 3:
        return "direct", f"auto: {dim}D, {dofs:,} DOFs: MUMPS"
    if dofs < CROSSOVER_3D:
        return "direct", f"auto: 3D, {dofs:,} DOFs < {CROSSOVER_3D:,}: MUMPS is faster there"
    return "iterative", (f"auto: 3D, {dofs:,} DOFs >= {CROSSOVER_3D:,}: Krylov + AMG is faster "
                         "and smaller there")
