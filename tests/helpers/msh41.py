"""Gmsh MSH 4.1 files written by hand (ASCII or binary) for the reader's tests: meshio's own
writer refuses meshes of several cell types without entity data."""

from __future__ import annotations

from pathlib import Path

import numpy as np

GMSH_TYPE = {"vertex": 15, "line": 1, "line3": 8, "triangle": 2, "triangle6": 9, "quad": 3,
             "quad9": 10, "quad8": 16, "tetra": 4, "tetra10": 11, "hexahedron": 5}
DIM = {"vertex": 0, "line": 1, "line3": 1, "triangle": 2, "triangle6": 2, "quad": 2,
       "quad9": 2, "quad8": 2, "tetra": 3, "tetra10": 3, "hexahedron": 3}
TO_GMSH = {"tetra10": [0, 1, 2, 3, 4, 5, 6, 7, 9, 8]}


def blocks_of(mesh) -> list[tuple[str, np.ndarray, list[int]]]:
    """A meshio mesh's cells as (type, cells, physical tags) blocks, one per (type, tag)."""
    tags = mesh.cell_data.get("gmsh:physical")
    out = []
    for k, block in enumerate(mesh.cells):
        phys = np.asarray(tags[k]) if tags is not None else np.zeros(len(block.data), int)
        for t in np.unique(phys):
            out.append((block.type, np.asarray(block.data)[phys == t], [int(t)] if t > 0 else []))
    return out


def write_msh41(path: Path, points: np.ndarray, blocks, names: dict, binary: bool,
                node_tags: np.ndarray | None = None, node_blocks: int = 2) -> None:
    """``blocks``: (meshio type, cells in meshio's node order (point indices), physical
    tags of the block's entity); ``names``: (dim, tag) -> name. ``node_tags``: each point's
    tag (default 1..N); the nodes are written in ``node_blocks`` blocks in point order."""
    points = np.asarray(points, dtype=float)
    if points.shape[1] == 2:
        points = np.column_stack([points, np.zeros(len(points))])
    tags = np.arange(1, len(points) + 1) if node_tags is None else np.asarray(node_tags)
    size_t, i4 = np.dtype("<u8"), np.dtype("<i4")
    parts: list[bytes] = []

    def text(s: str) -> None:
        parts.append(s.encode())

    def put(values, dtype) -> None:   # binary numbers, or ASCII words on one line
        values = np.asarray(values).ravel()
        if binary:
            parts.append(values.astype(dtype).tobytes())
        else:
            text(" ".join(repr(float(v)) if dtype == "<f8" else str(int(v)) for v in values)
                 + "\n")

    text(f"$MeshFormat\n4.1 {int(binary)} 8\n")
    if binary:
        parts.append(np.array([1], i4).tobytes() + b"\n")
    text("$EndMeshFormat\n")
    if names:
        text(f"$PhysicalNames\n{len(names)}\n")
        for (dim, tag), name in names.items():
            text(f'{dim} {tag} "{name}"\n')
        text("$EndPhysicalNames\n")
    text("$Comments\nnot read $Nodes\n$EndComments\n")
    entities = [[] for _ in range(4)]   # per dimension: (entity tag, physical tags)
    for k, (kind, _, phys) in enumerate(blocks):
        entities[DIM[kind]].append((k + 1, phys))
    text("$Entities\n")
    put([len(e) for e in entities], size_t)
    for dim, ents in enumerate(entities):
        for tag, phys in ents:
            if binary:
                put([tag], i4)
                put(np.zeros(3 if dim == 0 else 6), "<f8")
                put([len(phys)], size_t)
                put(phys, i4)
                if dim:
                    put([0], size_t)
            else:
                box = "0 0 0" if dim == 0 else "0 0 0 1 1 1"
                text(f"{tag} {box} {len(phys)} {' '.join(map(str, phys))}"
                     + (" 0\n" if dim else "\n"))
    text("\n$EndEntities\n" if binary else "$EndEntities\n")
    cuts = np.linspace(0, len(points), node_blocks + 1).astype(int)
    text("$Nodes\n")
    put([node_blocks, len(points), tags.min(), tags.max()], size_t)
    for a, b in zip(cuts[:-1], cuts[1:]):
        if binary:
            put([3, 1, 0], i4)
            put([b - a], size_t)
            put(tags[a:b], size_t)
            put(points[a:b], "<f8")
        else:
            text(f"3 1 0 {b - a}\n")
            for t in tags[a:b]:
                text(f"{t}\n")
            for p in points[a:b]:
                text(" ".join(repr(float(v)) for v in p) + "\n")
    text("\n$EndNodes\n" if binary else "$EndNodes\n")
    total = sum(len(c) for _, c, _ in blocks)
    text("$Elements\n")
    put([len(blocks), total, 1, total], size_t)
    first = 1
    for k, (kind, cells, _) in enumerate(blocks):
        cells = np.asarray(cells)
        cells = cells[:, TO_GMSH[kind]] if kind in TO_GMSH else cells
        rows = np.column_stack([np.arange(first, first + len(cells)), tags[cells]])
        first += len(cells)
        if binary:
            put([DIM[kind], k + 1, GMSH_TYPE[kind]], i4)
            put([len(cells)], size_t)
            put(rows, size_t)
        else:
            text(f"{DIM[kind]} {k + 1} {GMSH_TYPE[kind]} {len(cells)}\n")
            for r in rows:
                text(" ".join(map(str, r)) + " \n")
    text("\n$EndElements\n" if binary else "$EndElements\n")
    Path(path).write_bytes(b"".join(parts))
