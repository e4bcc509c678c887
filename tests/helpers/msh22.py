"""Gmsh MSH 2.2 files written by hand (ASCII or binary) for the reader's tests: node tags in any
order, elements with their physical tag first and a varying number of tags, binary blocks that
hold several physical tags (each a run the reader must split)."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from helpers.msh41 import GMSH_TYPE, TO_GMSH


def write_msh22(path: Path, points: np.ndarray, blocks, names: dict, binary: bool,
                node_tags: np.ndarray | None = None) -> None:
    """``blocks``: (meshio type, cells in meshio's node order (point indices), physical tags:
    the first is the elements'; none: tag 0), as ``msh41.write_msh41``; ``names``: (dim, tag)
    -> name. ASCII elements of the odd blocks carry three tags, of the even ones two; binary
    blocks of one type in a row are one element block."""
    points = np.asarray(points, dtype=float)
    if points.shape[1] == 2:
        points = np.column_stack([points, np.zeros(len(points))])
    tags = np.arange(1, len(points) + 1) if node_tags is None else np.asarray(node_tags)
    parts: list[bytes] = [f"$MeshFormat\n2.2 {int(binary)} 8\n".encode()]
    if binary:
        parts.append(np.array([1], "<i4").tobytes() + b"\n")
    parts.append(b"$EndMeshFormat\n")
    if names:
        parts.append(f"$PhysicalNames\n{len(names)}\n".encode())
        parts += [f'{dim} {tag} "{name}"\n'.encode() for (dim, tag), name in names.items()]
        parts.append(b"$EndPhysicalNames\n")
    parts.append(f"$Nodes\n{len(points)}\n".encode())
    if binary:
        rows = np.zeros(len(points), np.dtype([("tag", "<i4"), ("xyz", "<f8", (3,))]))
        rows["tag"], rows["xyz"] = tags, points
        parts += [rows.tobytes(), b"\n"]
    else:
        parts += [f"{t} {' '.join(repr(float(v)) for v in p)}\n".encode()
                  for t, p in zip(tags, points)]
    total = sum(len(c) for _, c, _ in blocks)
    parts.append(f"$EndNodes\n$Elements\n{total}\n".encode())
    first = 1
    for k, (kind, cells, phys) in enumerate(blocks):
        cells = np.asarray(cells)
        cells = cells[:, TO_GMSH[kind]] if kind in TO_GMSH else cells
        lead = [phys[0] if phys else 0, k + 1] + ([k] if k % 2 and not binary else [])
        ids = np.arange(first, first + len(cells))
        first += len(cells)
        if binary:
            rows = np.column_stack([ids, np.tile(lead, (len(cells), 1)), tags[cells]])
            same = k and blocks[k - 1][0] == kind   # one block with the previous
            head = [] if same else [np.array([GMSH_TYPE[kind], _run(blocks, k), 2], "<i4")]
            parts += [h.tobytes() for h in head] + [rows.astype("<i4").tobytes()]
        else:
            for i, row in zip(ids, tags[cells]):
                parts.append(f"{i} {GMSH_TYPE[kind]} {len(lead)} "
                             f"{' '.join(map(str, lead))} {' '.join(map(str, row))}\n".encode())
    parts.append(b"\n$EndElements\n" if binary else b"$EndElements\n")
    Path(path).write_bytes(b"".join(parts))


def _run(blocks, k: int) -> int:
    """The elements of block ``k`` and the blocks of its type right after it."""
    n = 0
    for kind, cells, _ in blocks[k:]:
        if kind != blocks[k][0]:
            break
        n += len(cells)
    return n
