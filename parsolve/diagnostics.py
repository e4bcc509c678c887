"""What a singular system most likely means, said in the model's terms: a body (a connected
set of cells) that no relation holds, for a field whose operator has a kernel without one
(a displacement field: rigid-body motions; a steady scalar field: a constant). And what no
smaller step can cure (``no_equilibrium``): a failed attempt whose loads a smaller step would
not change, on a cause that says no state carries them."""

from __future__ import annotations

import numpy as np
from mpi4py import MPI

from parsolve.contact import friction as fr
from parsolve.evolution import Evolution


def bodies(cells: np.ndarray, npoints: int) -> np.ndarray:
    """Component label of every node (the smallest node id of its body); nodes of no cell keep
    their own id. Label propagation over the cells with pointer jumping, vectorised."""
    label = np.arange(npoints)
    while True:
        low = label[cells].min(axis=1)
        new = label.copy()
        np.minimum.at(new, cells, low[:, None])
        new = new[new]                     # pointer jumping: follow the labels' labels
        if np.array_equal(new, label):
            return label
        label = new


def _lowest_per_body(cells: np.ndarray, label: np.ndarray) -> np.ndarray:
    """Every node's label replaced by the lowest label of its body in ``cells``."""
    body = bodies(cells, label.size)
    low = label.copy()
    np.minimum.at(low, body, label)
    return low[body]


def bodies_distributed(comm, mesh) -> np.ndarray:
    """``bodies`` on a distributed mesh (a ``LocalMesh``): the label of every local node, the
    smallest input node id of its body over the whole mesh. Each round labels the bodies of
    every part, then a node's copies agree on their lowest label through its owner; a body
    crossing k parts takes about k rounds (only run when a solve has failed)."""
    n, n_owned, size = mesh.num_points, mesh.n_owned, comm.size
    label = np.asarray(mesh.global_nodes, dtype=np.int64).copy()
    owner = mesh.owner_of(np.arange(n_owned, n))
    order = np.argsort(owner, kind="stable")
    counts = np.bincount(owner, minlength=size)
    bounds = np.concatenate([[0], np.cumsum(counts)])
    ghosts = n_owned + order
    asked = comm.alltoall([mesh.node_new[ghosts[bounds[r]:bounds[r + 1]]] for r in range(size)])
    first = mesh.node_ranges[comm.rank]
    asked_local = [np.asarray(a, dtype=np.int64) - first for a in asked]  # owned: global order
    while True:
        before = label.copy()
        label = _lowest_per_body(mesh.cells, label)
        sent = comm.alltoall([label[ghosts[bounds[r]:bounds[r + 1]]] for r in range(size)])
        for idx, values in zip(asked_local, sent):   # owners take the lowest of every copy
            np.minimum.at(label, idx, values)
        back = comm.alltoall([label[idx] for idx in asked_local])
        if ghosts.size:
            label[ghosts] = np.concatenate(back)
        if not comm.allreduce(bool((label != before).any()), op=MPI.LOR):
            return label


def unsupported(model) -> list[str]:
    """One sentence per (body, field) that no relation touches, for fields whose operator is
    singular without one (steady fields). Labels of the whole mesh's bodies from the parts,
    the relations' input nodes looked up among each rank's owned nodes, cells counted by the
    rank owning their lowest-owner node: everything exchanged is a body's or a relation's
    size. Collective."""
    comm, mesh, fields = model.comm, model.mesh, model.fields
    if model.transient:  # a capacity holds a scalar field; only displacements can float
        checked = [f for f in fields if f.displacement]
    else:
        checked = list(fields)
    label = bodies_distributed(comm, mesh)
    n_owned = mesh.n_owned
    owned_ids = np.asarray(mesh.global_nodes[:n_owned], dtype=np.int64)  # increasing input id
    mine = mesh.owner_of(mesh.cells).min(axis=1) == comm.rank
    cell_label = label[mesh.cells[mine, 0]]
    cell_ids = np.asarray(mesh.global_cells, dtype=np.int64)[mine]
    names = np.unique(np.concatenate(comm.allgather(np.unique(cell_label))))
    out = []
    for f in checked:
        cols = fields.columns(f.name)
        held = []
        for r in model.relations:
            node, col = np.divmod(np.asarray(r.a_dofs, dtype=np.int64), fields.ncomp)
            node = node[np.isin(col, cols)]
            pos = np.minimum(np.searchsorted(owned_ids, node), max(n_owned - 1, 0))
            here = (owned_ids[pos] == node) if n_owned else np.zeros(node.size, dtype=bool)
            held.append(label[pos[here]])
        held = np.unique(np.concatenate(comm.allgather(np.unique(np.concatenate(held + [[]]))
                                                       .astype(np.int64))))
        for b in names[~np.isin(names, held)]:
            ids = cell_ids[cell_label == b]
            ncells = comm.allreduce(int(ids.size))
            first = comm.allreduce(int(ids.min()) if ids.size else np.iinfo(np.int64).max, op=MPI.MIN)
            last = comm.allreduce(int(ids.max()) if ids.size else -1, op=MPI.MAX)
            out.append(_sentence(f.name, names.size, ncells, first, last))
    return out


def _sentence(field: str, nbodies: int, ncells: int, first: int, last: int) -> str:
    which = f"body of {ncells} cells (cells {first}..{last})" if nbodies > 1 else "the body"
    return f"no relation holds field {field!r} on {which}"


def no_equilibrium(model, t0: float, t1: float) -> tuple[str, ...]:
    """What says, after an attempt from the converged state at ``t0`` to ``t1`` failed, that
    no smaller step can succeed (empty if nothing): every smaller step poses the same
    equations from the same state (``loads_held``) and a frictional contact's closed nodes
    all slide at the last iterate (the tangential load beyond μN: no state carries it).
    Collective (every rank the same answer)."""
    if not loads_held(model, t0, t1):
        return ()
    return tuple(f"every closed node of {name!r} slides"
                 for name in beyond_friction(model.comm, model.effects))


def loads_held(model, t0: float, t1: float) -> bool:
    """Whether a step from ``t0`` to any t in (t0, t1] poses the same equations: a model
    without rates (a transient step depends on its size), every known load's and relation's
    evolution constant over [t0, t1], and no load that names the time. (Read from the scene's
    declarations: the same on every rank.)"""
    if model.transient:
        return False
    duals = {r.meta.get("dual") for r in model.relations} | set(model.reference_patterns)
    parts = [part for name, pattern in model.patterns.items() if name not in duals
             for part in pattern.parts]
    if any(vector.term.timed for vector, _ in parts):
        return False
    evolutions = [evol for _, evol in parts] + [r.evolution for r in model.relations]
    # (an evolution that is a plain function of t, not an ``Evolution``: not known constant)
    return all(isinstance(e, Evolution) and e.constant_over(t0, t1) for e in evolutions)


def beyond_friction(comm, effects) -> list[str]:
    """The frictional contacts some of whose nodes are closed and none sticks at the last
    iterate (over every rank: a contact built per rank holds its own nodes' states)."""
    out = []
    for e in effects:
        state = getattr(e, "node_state", None)
        if state is None or not getattr(e, "frictional", False):
            continue
        # a buffer reduction: the pickled ``allreduce`` applies Python's max to arrays, which
        # raises on the reducing rank only and leaves the others waiting
        flags = np.array([(state != fr.OPEN).any(), (state == fr.STICK).any()], dtype=np.int8)
        comm.Allreduce(MPI.IN_PLACE, flags, op=MPI.MAX)
        closed, sticking = flags
        if closed and not sticking:
            out.append(getattr(getattr(e, "spec", None), "name", type(e).__name__))
    return out
