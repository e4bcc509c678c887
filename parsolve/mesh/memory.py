"""Will it fit? Memory estimated from the scene before anything large is allocated.

Figures are peak resident memory measured with ``/usr/bin/time -f %M`` on ``parsolve run``
(rectangle of P1 triangles / box of P1 tetrahedra, left side clamped, one traction; this
machine, PETSc 3.18 + MUMPS, 2026-12-01):

    2D direct     201² nodes  80 802 DOFs:  328 MB (1 rank), 221 MB per rank (2 ranks)
    2D direct     401² nodes 321 602 DOFs: 1085 MB (1 rank), 644 MB per rank (2 ranks)
    2D iterative  401² nodes 321 602 DOFs:  814 MB (1 rank), 550 MB per rank (2 ranks)
    3D direct      21³ nodes  27 783 DOFs:  612 MB (1 rank), 394 MB per rank (2 ranks)
    empty run (Python, numpy, PETSc, MPI): 92 MB

So: 92 MB + DOFs × (0.2 KB for the whole mesh + c / ranks), with c = 3.1 KB (2D direct),
2.2 KB (2D iterative), 18.6 KB × (DOFs / 27 783)^(1/3) (3D direct: a nested-dissection
factor grows like n^(4/3)), 3D iterative taken as 2D's × 2 (27 nonzeros per row against 9).
The estimate is honest to about a factor of two; a scene is refused only when the estimate
exceeds what the machine has available.

The two shares are checked apart: the mesh (the 0.2 KB share) — on the rank-0 path rank 0
alone builds the whole mesh (``check_whole_mesh``, on rank 0's machine); on the slice path
(parallel mesh files, generated meshes) every rank holds its share of it
(``check_part``) — then every rank holds its part of the solve (``check_fits``: the other
share over the ranks; every machine's verdict, the worst for all).
"""

from __future__ import annotations

import ctypes
import functools
from contextlib import contextmanager
from typing import Iterator

from parsolve.errors import InputError

BASE = 92e6
WHOLE_MESH_PER_DOF = 200.0   # the whole mesh, on the one rank that builds it
PER_DOF = {(2, "direct"): 3.1e3, (2, "iterative"): 2.2e3, (3, "iterative"): 4.4e3}
DIRECT_3D = (18.6e3, 27783)  # bytes per DOF at this many DOFs; grows like DOFs^(1/3)

# set by ``agreed_over``: ranks then take one decision together (None: this process alone)
_COMM = None


def cell_counts(generator: str, params: dict, order: int = 1) -> tuple[int, int, int]:
    """(points, cells, dim) of a generated mesh, from its parameters alone (nothing built)."""
    if generator == "sphere_on_block":   # two bodies: the generator module counts them
        from parsolve.mesh.generators import sphere_on_block_counts

        return sphere_on_block_counts(params, order)
    cell = params.get("cell")
    n = {k: int(v) for k, v in params.items()
         if k in ("nx", "ny", "nz", "n_radial", "n_angular") and isinstance(v, (int, float))}
    if generator == "box":
        nx, ny, nz = n.get("nx", 1), n.get("ny", 1), n.get("nz", 1)
        points, hexes = (nx + 1) * (ny + 1) * (nz + 1), nx * ny * nz
        cell = cell or "hexahedron"
        if cell == "hexahedron":
            return points, hexes, 3
        # 6 tetrahedra per hexahedron; P2 adds a node per edge: grid edges, face diagonals
        # and one body diagonal per hexahedron
        quadratic = cell == "tetra10" or order == 2
        edges = (nx * (ny + 1) * (nz + 1) + (nx + 1) * ny * (nz + 1) + (nx + 1) * (ny + 1) * nz
                 + nx * ny * (nz + 1) + nx * (ny + 1) * nz + (nx + 1) * ny * nz + hexes)
        return points + (edges if quadratic else 0), 6 * hexes, 3
    if generator == "rectangle":
        nx, ny = n.get("nx", 1), n.get("ny", 1)
    else:
        nx, ny = n.get("n_radial", 1), n.get("n_angular", 1)
    points, quads = (nx + 1) * (ny + 1), nx * ny
    cell = cell or "quad"
    if cell == "quad":
        return points, quads, 2
    quadratic = cell == "triangle6" or order == 2
    return points + (3 * quads + nx + ny if quadratic else 0), 2 * quads, 2


def estimate_bytes(dofs: int, dim: int, preset: str, nranks: int = 1) -> float:
    """Peak resident memory of one rank during the solve, its part of the mesh (see the
    module's figures)."""
    if preset == "auto":   # what the scene will get (solvers.choice)
        from parsolve.solvers.choice import choose

        preset = choose(dofs, dim)[0]
    if dim == 3 and preset == "direct":
        per_dof = DIRECT_3D[0] * (max(dofs, 1) / DIRECT_3D[1]) ** (1 / 3)
    else:
        per_dof = PER_DOF[(dim, preset)]
    return BASE + dofs * per_dof / nranks


def whole_mesh_bytes(dofs: int) -> float:
    """Peak memory of the one rank that builds the whole mesh (rank 0)."""
    return BASE + dofs * WHOLE_MESH_PER_DOF


def available_bytes(local: int = 1) -> float | None:
    """The tighter of MemAvailable, RLIMIT_AS and the cgroup limit (parsolve.mesh.limits) for
    ``local`` ranks on this machine (RLIMIT_AS is per rank); what bound it is kept in
    ``AVAILABLE_BOUND`` for the message. Not collective: rank 0 alone checks the whole mesh."""
    global AVAILABLE_BOUND
    from parsolve.mesh import limits

    have, AVAILABLE_BOUND = limits.available_bytes(local)
    return float(have) if have else None


AVAILABLE_BOUND = "MemAvailable"


def gib(n: float) -> str:
    g = n / 2**30
    return f"{g:.0f} GiB" if g >= 10 else f"{g:.1f} GiB" if g >= 0.1 else f"{n / 2**20:.0f} MiB"


@contextmanager
def agreed_over(comm) -> Iterator[None]:
    """Inside, memory checks are collective over ``comm``: every rank reaches the same verdict
    (ranks on different machines see different memory)."""
    global _COMM
    previous, _COMM = _COMM, comm
    try:
        yield
    finally:
        _COMM = previous


def _layout() -> tuple[int, int]:
    """(ranks in all, ranks on this machine)."""
    if _COMM is None or _COMM.size == 1:
        return 1, 1
    from mpi4py import MPI

    local = _COMM.Split_type(MPI.COMM_TYPE_SHARED)
    try:
        return _COMM.size, local.size
    finally:
        local.Free()


def check_whole_mesh(points: int, dim: int, source: str | None, key: str | None,
                     what: str) -> None:
    """InputError when building the whole mesh does not fit this machine (this process
    alone: rank 0 builds it; the solve is checked once the mesh is distributed)."""
    dofs = points * dim
    _verdict(whole_mesh_bytes(dofs), dofs, 1, 1, source, key, what + " built on one rank",
             collective=False)


def check_part(points: int, dim: int, source: str | None, key: str | None, what: str) -> None:
    """InputError when this machine's ranks' shares of the mesh (the slice path: each rank
    a slice, then its part, of the whole mesh's 0.2 KB per DOF) do not fit. Collective
    inside ``agreed_over``."""
    nranks, local = _layout()
    dofs = points * dim
    _verdict(local * (BASE + dofs * WHOLE_MESH_PER_DOF / nranks), dofs, nranks, local, source,
             key, what + " read by slices")


def check_fits(points: int, dim: int, preset: str, source: str | None, key: str | None,
               what: str) -> None:
    """InputError when the solve's estimate, each rank its share, exceeds the memory this
    machine has available (collective inside ``agreed_over``)."""
    nranks, local = _layout()
    dofs = points * dim
    _verdict(local * estimate_bytes(dofs, dim, preset, nranks), dofs, nranks, local, source,
             key, what)


def _verdict(need: float, dofs: int, nranks: int, local: int, source: str | None,
             key: str | None, what: str, collective: bool = True) -> None:
    have = available_bytes(local)
    verdict = (need / have if have else 0.0, need, have or 0.0)
    if collective and _COMM is not None and _COMM.size > 1:
        verdict = _COMM.allreduce(verdict, op=_max_op())  # the worst machine decides for all
    ratio, need, have = verdict
    if ratio > 1.0:
        ranks = f" ({local} of {nranks} ranks on one machine)" if nranks > 1 else ""
        raise InputError(f"too large for this machine: {what} ({_count(dofs)} DOFs) needs "
                         f"about {gib(need)}{ranks}, this machine has {gib(have)} available "
                         f"(bound by {AVAILABLE_BOUND})",
                         source, key)


def _count(n: int) -> str:
    return f"{n:,}".replace(",", " ") if n < 10**7 else f"{n:.2e}"


def _max_op():
    from mpi4py import MPI

    return MPI.MAX


@functools.lru_cache(maxsize=1)
def _malloc_trim():
    """glibc's ``malloc_trim`` (None elsewhere)."""
    try:
        return ctypes.CDLL(None).malloc_trim
    except (OSError, AttributeError):
        return None


def release() -> None:
    """Give the pages of freed arrays back to the system. numpy's arrays of a few MiB come
    from malloc's heap (its mmap threshold rises to the largest array freed, up to 32 MiB),
    which keeps them resident once freed: on 4 ranks of a 1.57M-tetrahedra box the mesh
    stage's resident memory was 1.7× its live arrays' peak, each phase starting above the
    last one's garbage. Called between the mesh stage's phases."""
    trim = _malloc_trim()
    if trim is not None:
        trim(0)
