"""The algebraic multigrid V-cycle on the condensed primal operator S (solvers.condensed):
GAMG, its finest level smoothed by SOR sweeps, its coarse operators made by PETSc's Galerkin
product with its intermediates freed, its coarse hierarchy kept across set-ups while it
serves."""

from __future__ import annotations

import gc
from contextlib import contextmanager
from typing import Iterator

from mpi4py import MPI
from petsc4py import PETSc

from parsolve import progress
from parsolve.solvers.options import inserted, product_clear

#: SOR sweeps (Richardson) on the finest level of the GAMG V-cycle on S, before and after the
#: coarse correction. Krylov iterations per solve (mean / max) on the 3D friction box at 16.9k
#: DOFs, 1 rank: 4, 6 and 8 sweeps 8.1 / 12 (2 steps), 6.8 / 10 and 6.0 / 9, GAMG's Chebyshev
#: 23.2 / 35, PETSc's ML (the V-cycle before) 7.1 / 10. SOR on every level divided by a
#: coarse operator's zero diagonal entry on 2 ranks. The sweeps are most of a solve's flops
#: (79 % with 8 at 122k), so fewer of them pay while the iterations grow little: at 122k DOFs
#: on 2 ranks (one bench run, load 2-3; CPU time per Newton iteration against plain
#: elasticity's) 8 sweeps 9.0 / 13 for 1.30x, 6 9.9 / 14 for 1.20x, 4 11.1 / 15 for 1.01x,
#: 3 11.9 / 16 for 0.98x (2: 13.5 / 18); 5 10.6 / 15. Per flop nothing else did better:
#: forward sweeps before the coarse correction and backward ones after (8 of them: the flops
#: of 4 symmetric ones) took 4's iterations to the solve (11.0 / 15), 6 of them 3's (11.9 /
#: 16); SOR's ω = 1.2 made the iterations irregular (4 sweeps: 15.2 / 22). At 2.08M DOFs on
#: 2 ranks (bench_relations_big.md) 4 sweeps took 16.0 / 24 (8: 13.5 / 20), the Krylov flops
#: of the run ~0.7x 8's; 3 would pass 25 there.
FINE_SWEEPS = 4
#: the same when S holds tied rows (solvers.tied: S = G K_eff H): on the mortar sphere
#: (16.7k DOFs, 1 rank) Krylov iterations per solve (mean / max) 31.7 / 34 with 8 sweeps, 24.0 /
#: 26 with 16, 22.3 / 24 with 20, 20.3 / 22 with 24 (the flops of a solve 1.6x 8 sweeps' at 20)
TIED_SWEEPS = 20


#: S's global rows from which, on several ranks, the V-cycle's Galerkin products take PETSc's
#: "allatonce" algorithm (``-matptap_via allatonce`` while it is set up, unless the user gave
#: -matptap_via): no intermediate products, the least memory, a slower set-up (_products_freed)
ALLATONCE_ROWS = 500_000


@contextmanager
def _products_freed(allatonce: bool = False) -> Iterator[None]:
    """The intermediates of the V-cycle's Galerkin products P^T A P freed once each coarse
    operator is made (``-mat_product_clear``, in PETSc's options while it is set up, unless
    given: read under no prefix, solvers.options.UNPREFIXED). PETSc's distributed product
    keeps them (A P, Pᵀ's parts, P's remote rows, on every level) for a later product of the
    same pattern, but the hierarchy is kept wholesale (VCycle) or made anew, never recomputed
    in place: they were only held. On the 122k-DOF friction box on 2 ranks (its first step's
    8 Newton iterations, the hierarchy made once and kept; scripts/results/
    bench_relations_scale.md), CPU time per Newton iteration and peak memory against plain
    elasticity's: PETSc's default product (``-matptap_via nonscalable``) freed 1.30x, 1.19x
    (1.34x, 1.19x in the same run's second such row; its set-up +106 MiB per rank); kept
    1.45x, 1.31x (+121 MiB); "allatonce" (the least memory, +48 MiB, but 22.5 s per set-up
    against 3.3) 1.72x, 1.10x (the last two in an earlier run). At 2M DOFs on 2 ranks the
    trade turns (scripts/results/bench_relations_big.md, docs/performance.md): freed 1.87x,
    1.40x; "allatonce" 1.83x, 1.28x (8 sweeps then; its set-up 600 s of a 3,100 s run on a
    loaded machine). The memory ratio of the freed products, log-linear in the DOFs between
    those two sizes, reaches the target's 1.3x near 540k: ``allatonce`` (``-matptap_via
    allatonce`` added, unless given) from ALLATONCE_ROWS. The preset so (4 sweeps, allatonce
    by size) at 2.08M on an idle machine: peak 9,482 MiB, 1.27x elasticity's; time per Newton
    iteration 1.30x (CPU 143.1 s summed against 110.4; wall 72.0 s against 55.6). Loaded
    (3-6): 1.26x, 1.35x CPU against elasticity at a like load."""
    added = {}
    if product_clear() is None:
        added["mat_product_clear"] = "true"
    if allatonce and not PETSc.Options().hasName("matptap_via"):
        added["matptap_via"] = "allatonce"
    with inserted("", added, record=False):   # (unprefixed: UNPREFIXED)
        yield


#: the coarse hierarchy kept across set-ups (``VCycle.set_up``) while the last solve on it took
#: at most this many times the Krylov iterations of the worst solve on a hierarchy just made
#: (``-<prefix>reuse_growth``; 0: made anew at every set-up)
REUSE_GROWTH = 1.25


class VCycle:
    """One AMG V-cycle on a matrix, its options under ``prefix`` (``<solver>condensed_``):
    ``set_up(S)`` after each change of S's values, then ``apply(f, y)``: y ≈ S⁻¹ f.

    The coarse hierarchy (aggregates, interpolations, Galerkin coarse operators) is made at
    the first set-up and kept by the next ones while it serves: S's values change in place
    (the same matrix), so the finest level's smoothing and residuals see them at once; only
    the coarse corrections are those of an earlier S. It is made anew when S is another
    matrix, or when the last solve took more than REUSE_GROWTH times the applications
    (Krylov iterations) of the worst solve on a fresh hierarchy. GMRES runs on M itself: the
    answer is the same, only the iterations can change."""

    def __init__(self, comm: MPI.Comm, prefix: str):
        # the solvers gone before this one (their KSPs, ML's hierarchies) destroyed now:
        # PETSc defers their destruction to the end, and ML's set-up crashed (inside its
        # aggregation) after a few dozen solvers in one process. Collective: every rank
        # makes its first V-cycle here.
        gc.collect()   # (solvers in reference cycles: freed, their objects deferred)
        PETSc.garbage_cleanup(comm)
        self.comm, self.prefix = comm, prefix
        self.pc = PETSc.PC().create(comm)
        self.pc.setOptionsPrefix(prefix)
        self._configured = False
        self._made_for = None     # the handle of the matrix the hierarchy was made for
        self.applies = 0          # applications since the last set-up (its solve's iterations)
        self._fresh = 0           # the most applications of a solve on a fresh hierarchy
        self._on_fresh = False    # the applications since the last set-up are on a fresh one
        self.made = self.kept = 0   # set-ups that made the hierarchy, that kept it

    def set_up(self, mat: PETSc.Mat, sweeps: int = FINE_SWEEPS) -> None:
        """The V-cycle for ``mat``'s values: its hierarchy made anew, or kept (class doc);
        ``sweeps``: its finest level's SOR sweeps unless ``-<prefix>fine_sweeps`` is given."""
        if self._on_fresh:
            self._fresh = max(self._fresh, self.applies)
        keep = self._keeps(mat)
        self.applies = 0
        self._on_fresh = not keep
        if keep:
            self.kept += 1
            return
        self.pc.setReusePreconditioner(False)
        self.pc.setOperators(mat, mat)
        if not self._configured:
            self.pc.setFromOptions()
            self._configured = True
        with _products_freed(self._allatonce(mat)):
            self.pc.setUp()
        if self.pc.getType() == "gamg":
            self._fine_sor(sweeps)
        # (kept until set_up says otherwise: PCApply would remake it when S's values change)
        self.pc.setReusePreconditioner(True)
        self._made_for = mat.handle
        self.made += 1

    def _allatonce(self, mat: PETSc.Mat) -> bool:
        """The "allatonce" Galerkin products for ``mat`` (ALLATONCE_ROWS, several ranks): said
        in the run's log when first chosen."""
        rows = mat.getSize()[0]
        chosen = (self.comm.size > 1 and rows >= ALLATONCE_ROWS
                  and not PETSc.Options().hasName("matptap_via"))
        if chosen and not self.made:
            progress.say(f"condensed V-cycle: S of {rows:,} rows >= {ALLATONCE_ROWS:,} on "
                         f"{self.comm.size} ranks: Galerkin products allatonce (less memory)")
        return chosen

    def _keeps(self, mat: PETSc.Mat) -> bool:
        """The hierarchy kept for ``mat``: the same matrix, and the last solve within
        REUSE_GROWTH of the worst fresh one (the same answer on every rank)."""
        growth = PETSc.Options(self.prefix).getReal("reuse_growth", REUSE_GROWTH)
        keep = (growth > 0 and mat.handle == self._made_for
                and self.applies <= growth * self._fresh)
        return bool(self.comm.allreduce(int(keep), op=MPI.MIN))

    def apply(self, f: PETSc.Vec, y: PETSc.Vec) -> None:
        self.applies += 1
        self.pc.apply(f, y)

    def _fine_sor(self, sweeps: int) -> None:
        """GAMG's finest level smoothed by ``sweeps`` SOR sweeps (Richardson) instead of its
        Chebyshev (its coarser levels keep Chebyshev: their operators may hold a zero diagonal
        entry on 2 ranks, which SOR divides by). Set again after every set-up, which may make
        the levels anew. The sweeps: ``-<prefix>fine_sweeps``."""
        sweeps = PETSc.Options(self.prefix).getInt("fine_sweeps", sweeps)
        ksp = self.pc.getMGSmoother(self.pc.getMGLevels() - 1)
        if ksp.getType() != "richardson" or ksp.getPC().getType() != "sor":
            ksp.setType("richardson")
            ksp.getPC().setType("sor")
        ksp.setTolerances(max_it=sweeps)
