"""Gmsh MSH 4.1 and 2.2 files (ASCII and binary) read by block, never whole.

``scan`` walks the file once and keeps its layout: the physical names, the entities' physical
tags, and where each block of ``$Nodes`` and ``$Elements`` lies (binary: its byte offset; ASCII:
the offsets of every ``MARK``-th line). MSH 2.2 has no entities: its elements' blocks are the
runs of consecutive elements of one type and tag count, and each row carries its physical tag
(the first tag): the layout keeps how many rows of a block have each tag
(``Layout.row_tags``), and a block of several tags has its rows' tags read with its rows
(``Layout.in_group``), so a file whose elements alternate tags is a few blocks, not one per
element. Rows of the blocks
are then read by ranges with numpy (``Layout.node_rows``, ``Layout.element_rows``): a rank
reads its slice of the nodes and of the cells (``GmshSlices``, the slice path of
``mesh.slices``), ``parsolve mesh convert`` streams the file by chunks (``convert``). The
regions are those meshio's reading gives (``reader``):

* a physical group named in ``$PhysicalNames`` takes the blocks of its dimension whose entity
  lists its tag; the entity's first physical tag, unnamed, gives a group named by its number;
* by the dimension of their elements, groups are cell groups (volume cells), facet groups
  (facets of the volume type's facet type) or node groups (lower dimensions);
* points are in the file's order (node tags mapped to it), cells in the file's order of the
  volume blocks, facets of a group in the file's order of its blocks.

MSH 4.0 and other formats are read by meshio (``reader``).
"""

from __future__ import annotations

import os
from dataclasses import dataclass, field

import numpy as np

from parsolve.errors import InputError
from parsolve.mesh.mesh import CELL_INFO

MARK = 4096            # ASCII: the offset of every MARK-th line of a block is kept
CHUNK = 1 << 22        # bytes read at a time when lines are counted
ROWS = 1 << 17         # rows per chunk when a whole section is streamed (convert)

# Gmsh element type -> (meshio name, nodes, dimension)
TYPES = {1: ("line", 2, 1), 2: ("triangle", 3, 2), 3: ("quad", 4, 2), 4: ("tetra", 4, 3),
         5: ("hexahedron", 8, 3), 6: ("wedge", 6, 3), 7: ("pyramid", 5, 3), 8: ("line3", 3, 1),
         9: ("triangle6", 6, 2), 10: ("quad9", 9, 2), 11: ("tetra10", 10, 3),
         12: ("hexahedron27", 27, 3), 13: ("wedge18", 18, 3), 14: ("pyramid14", 14, 3),
         15: ("vertex", 1, 0), 16: ("quad8", 8, 2), 17: ("hexahedron20", 20, 3),
         18: ("wedge15", 15, 3), 19: ("pyramid13", 13, 3)}
# Gmsh's node order -> meshio's (VTK's), for the types whose orders differ (meshio's table)
ORDER = {"tetra10": [0, 1, 2, 3, 4, 5, 6, 7, 9, 8],
         "hexahedron20": [0, 1, 2, 3, 4, 5, 6, 7, 8, 11, 13, 9, 16, 18, 19, 17, 10, 12, 14, 15],
         "hexahedron27": [0, 1, 2, 3, 4, 5, 6, 7, 8, 11, 13, 9, 16, 18, 19, 17, 10, 12, 14, 15,
                          22, 23, 21, 24, 20, 25, 26]}


def version_of(path: str) -> str | None:
    """The MSH version of a Gmsh file ("4.1", "2.2", ...), None if ``path`` is no Gmsh file."""
    try:
        with open(path, "rb") as fh:
            head = fh.read(256).split(b"\n")
    except OSError:
        return None
    if len(head) < 2 or head[0].strip() != b"$MeshFormat":
        return None
    words = head[1].split()
    return words[0].decode(errors="replace") if words else ""


MSH2 = ("2", "2.0", "2.1", "2.2")   # one layout (2.0 and 2.1 lack features 2.2 added)


def ours(path: str) -> bool:
    """A Gmsh file this module reads: MSH 4.1 or 2.x, or a version meshio does not read either
    (its error then names the section); 4.0 is meshio's."""
    version = version_of(path)
    return version is not None and version not in ("4", "4.0")


@dataclass
class Rows:
    """``n`` rows of ``cols`` numbers of a block: binary ones at byte ``offset``, or ASCII lines
    whose every MARK-th one starts at ``marks[k]``; an element's node tags follow its ``lead``
    first numbers (its tag; MSH 2: tag, type, tag count and tags)."""

    n: int
    cols: int
    dtype: str | np.dtype
    offset: int = 0
    marks: np.ndarray | None = None
    lead: int = 1
    phys: int = -1     # MSH 2: the column of the rows' physical tag (-1: the entity's)

    def read(self, fh, start: int, stop: int, fail) -> np.ndarray:
        count = max(stop - start, 0)
        if count == 0:
            return np.zeros((0, self.cols), dtype=self.dtype)
        if self.marks is None:
            size = np.dtype(self.dtype).itemsize
            fh.seek(self.offset + start * self.cols * size)
            data = np.frombuffer(fh.read(count * self.cols * size), dtype=self.dtype)
        else:
            fh.seek(int(self.marks[start // MARK]))
            _lines(fh, start % MARK, fail)
            text, _ = _lines(fh, count, fail, keep=True)
            data = _numbers(text, self.dtype)
        if data.size != count * self.cols:
            raise fail(f"truncated or malformed block ({data.size} numbers where "
                       f"{count * self.cols} were expected)")
        return data.reshape(count, self.cols)


def _numbers(text: bytes, dtype: str) -> np.ndarray:
    """The numbers of ASCII ``text`` (fewer than written when one is malformed)."""
    import warnings

    with warnings.catch_warnings():
        warnings.simplefilter("error")   # numpy warns (not raises) on a malformed number
        try:
            return np.fromstring(text, dtype=dtype, sep=" ")
        except (DeprecationWarning, ValueError):
            return np.zeros(0, dtype)


def _lines(fh, count: int, fail, keep: bool = False, every: int = 0):
    """Read ``count`` lines from ``fh``'s position (left at the next line). Returns (their
    bytes if ``keep``, the offsets of every ``every``-th of them)."""
    kept, marks, start, left = [], [], fh.tell(), count
    if every:
        marks.append(np.array([start], dtype=np.int64))
    seen = 0   # lines passed before this chunk
    while left > 0:
        at = fh.tell()
        chunk = fh.read(CHUNK)
        if not chunk:
            raise fail(f"the file ends {left} line(s) before the block does (truncated?)")
        ends = np.flatnonzero(np.frombuffer(chunk, dtype=np.uint8) == 10)
        take = ends[:left]
        if every and take.size:   # starts of lines seen + k·every, k ≥ 1
            first = (-seen - 1) % every
            marks.append(at + take[first::every].astype(np.int64) + 1)
        if take.size == left:
            cut = int(take[-1]) + 1
            fh.seek(at + cut)
            if keep:
                kept.append(chunk[:cut])
            break
        if keep:
            kept.append(chunk)
        left -= take.size
        seen += take.size
    marks = np.concatenate(marks)[:-(-count // every) if count else 1] if every else None
    return b"".join(kept) if keep else None, marks


@dataclass
class Layout:
    """What ``scan`` found: names, entities' physical tags, and the blocks."""

    path: str
    names: dict = field(default_factory=dict)       # (dim, tag) -> name
    physical: dict = field(default_factory=dict)    # (dim, entity) -> physical tags
    node_blocks: list = field(default_factory=list)  # (tags Rows, coordinates Rows | None)
    element_blocks: list = field(default_factory=list)   # (dim, entity, type name, Rows)
    row_tags: dict = field(default_factory=dict)    # MSH 2 block -> {physical tag: rows}
    num_nodes: int = 0
    tag_range: tuple = (1, 0)

    def fail(self, section: str):
        return lambda message: InputError(message, self.path, section)

    def open(self):
        return open(self.path, "rb")

    def node_rows(self, fh, start: int, stop: int) -> tuple[np.ndarray, np.ndarray]:
        """(tags, x y z) of the nodes ``start:stop`` in the file's order."""
        tags, xyz, first = [], [], 0
        for t, c in self.node_blocks:
            a, b = max(start - first, 0), min(stop - first, t.n)
            if a < b and c is not None:
                tags.append(t.read(fh, a, b, self.fail("$Nodes"))[:, 0])
                xyz.append(c.read(fh, a, b, self.fail("$Nodes"))[:, :3])
            elif a < b:   # MSH 2: "tag x y z" rows (binary: int32 and 3 doubles)
                rows = t.read(fh, a, b, self.fail("$Nodes"))
                binary = rows.dtype.names is not None
                tags.append(rows["tag"][:, 0] if binary else rows[:, 0])
                xyz.append(rows["xyz"][:, 0] if binary else rows[:, 1:4])
            first += t.n
        if not tags:
            return np.zeros(0, np.int64), np.zeros((0, 3))
        return np.concatenate(tags).astype(np.int64), np.concatenate(xyz)

    def element_rows(self, fh, blocks: list[int], start: int, stop: int) -> np.ndarray:
        """The node tags (meshio's order) of rows ``start:stop`` of ``blocks`` (one type)
        concatenated in the file's order."""
        out, first = [], 0
        for b in blocks:
            kind, rows = self.element_blocks[b][2], self.element_blocks[b][3]
            lo, hi = max(start - first, 0), min(stop - first, rows.n)
            if lo < hi:
                data = rows.read(fh, lo, hi, self.fail("$Elements"))[:, rows.lead:]
                out.append(data[:, ORDER[kind]] if kind in ORDER else data)
            first += rows.n
        if not out:
            cols = self.nodes_per_row(blocks[0]) if blocks else 0
            return np.zeros((0, cols), np.int64)
        return np.concatenate(out, dtype=np.int64, casting="unsafe")   # (one copy)

    def nodes_per_row(self, b: int) -> int:
        rows = self.element_blocks[b][3]
        return rows.cols - rows.lead

    def block_names(self, b: int) -> list[str]:
        """The groups block ``b``'s elements are in (as meshio's reading gives them)."""
        dim, entity = self.element_blocks[b][0], self.element_blocks[b][1]
        if b in self.row_tags:
            return sorted({n for t in self.row_tags[b] for n in self._names(dim, (t,))})
        return self._names(dim, self.physical.get((dim, entity), ()))

    def _names(self, dim: int, tags: tuple) -> list[str]:
        """The groups of an element with physical ``tags``: the named ones, and the first
        when unnamed (by its number)."""
        names = [self.names[(dim, t)] for t in tags if (dim, t) in self.names]
        if tags and tags[0] > 0 and (dim, tags[0]) not in self.names:
            names.append(str(tags[0]))
        return sorted(set(names))

    def _tags_of(self, b: int, name: str) -> list[int]:
        """The physical tags of block ``b``'s rows that are in group ``name`` (MSH 2)."""
        dim = self.element_blocks[b][0]
        return [t for t in self.row_tags[b] if name in self._names(dim, (t,))]

    def group_count(self, blocks: list[int], name: str) -> int:
        """The rows of ``blocks`` in group ``name``."""
        total = 0
        for b in blocks:
            if b in self.row_tags:
                total += sum(self.row_tags[b][t] for t in self._tags_of(b, name))
            elif name in self.block_names(b):
                total += self.element_blocks[b][3].n
        return total

    def in_group(self, fh, blocks: list[int], name: str, start: int, stop: int) -> np.ndarray:
        """Whether each of rows ``start:stop`` of ``blocks`` (concatenated) is in group
        ``name``: from the header, or the rows' own tags in a block of several (read)."""
        out, first = np.zeros(max(stop - start, 0), dtype=bool), 0
        for b in blocks:
            rows, base = self.element_blocks[b][3], first
            lo, hi = max(start - base, 0), min(stop - base, rows.n)
            first += rows.n
            if lo >= hi or name not in self.block_names(b):
                continue
            at = slice(base + lo - start, base + hi - start)
            tags = self._tags_of(b, name) if b in self.row_tags else None
            if tags is None or len(self.row_tags[b]) == 1:
                out[at] = True
            else:
                phys = rows.read(fh, lo, hi, self.fail("$Elements"))[:, rows.phys]
                out[at] = np.isin(phys, tags)
        return out


def scan(path: str, key: str = "mesh.file") -> Layout:
    """The layout of the MSH 4.1 or 2.2 file ``path`` (one pass, bounded memory); InputError naming
    the file and the section otherwise."""
    path = os.fspath(path)
    if not os.path.isfile(path):
        raise InputError("mesh file not found" if not os.path.exists(path)
                         else "mesh path is not a file", path, key)
    lay = Layout(path)
    with open(path, "rb") as fh:
        fmt = _Format(fh, lay)
        seen, last = set(), "$MeshFormat"
        while True:
            line = fh.readline()
            if not line:
                break
            head = line.strip()
            if not head:
                continue
            if not head.startswith(b"$"):
                raise lay.fail(last)(
                    f"unexpected line {head[:40].decode(errors='replace')!r}")
            name = head[1:].decode(errors="replace")
            if not seen and name != "MeshFormat":
                raise lay.fail("$MeshFormat")("no $MeshFormat section first")
            reader = getattr(fmt, name, None) if name in _SECTIONS else None
            if reader is None:
                _skip_section(fh, name, lay.fail(f"${name}"))
            else:
                reader()
                _end(fh, name, lay.fail(f"${name}"))
            seen.add(name)
            last = f"${name}"
    for name in ("MeshFormat", "Nodes", "Elements"):
        if name not in seen:
            raise lay.fail(f"${name}")(f"no ${name} section")
    return lay


_SECTIONS = ("MeshFormat", "PhysicalNames", "Entities", "Nodes", "Elements")


class _Format:
    """The sections' readers (methods named as the sections), ASCII or binary."""

    def __init__(self, fh, lay: Layout):
        self.fh, self.lay, self.binary, self.size_t, self.msh2 = fh, lay, False, "<u8", False

    def MeshFormat(self) -> None:
        fail = self.lay.fail("$MeshFormat")
        words = self.fh.readline().split()
        if len(words) != 3:
            raise fail("expected 'version file-type data-size'")
        version = words[0].decode(errors="replace")
        if version != "4.1" and version not in MSH2:
            raise fail(f"unsupported MSH version {version} (read here: 4.1 and 2.2; 4.0 by "
                       "meshio)")
        self.binary, self.msh2 = words[1] == b"1", version in MSH2
        if words[2] not in (b"4", b"8"):
            raise fail(f"data size {words[2].decode(errors='replace')} (4 or 8 expected)")
        self.size_t = "<u8" if words[2] == b"8" else "<u4"
        if self.binary:
            one = self.fh.read(4)
            if len(one) != 4 or np.frombuffer(one, "<i4")[0] != 1:
                raise fail("a big-endian or damaged binary file (the int 1 is not read back)")
            self.fh.readline()

    def PhysicalNames(self) -> None:
        fail = self.lay.fail("$PhysicalNames")
        try:
            for _ in range(int(self.fh.readline())):
                dim, tag, name = self.fh.readline().decode().split(maxsplit=2)
                self.lay.names[(int(dim), int(tag))] = name.strip().strip('"')
        except ValueError:
            raise fail("expected 'dim tag \"name\"' lines") from None

    def _ints(self, n: int, dtype: str, fail) -> np.ndarray:
        """n numbers of the section's header data (ASCII: the next words, any lines)."""
        if self.binary:
            size = np.dtype(dtype).itemsize
            data = np.frombuffer(self.fh.read(n * size), dtype=dtype)
        else:
            data = []
            while len(data) < n:
                line = self.fh.readline()
                if not line or line.startswith(b"$"):
                    break
                data += line.split()
            try:
                data = np.array(data[:n], dtype=np.float64 if dtype == "<f8" else np.int64)
            except ValueError:
                raise fail("malformed numbers") from None
        if data.size != n:
            raise fail("truncated or malformed section")
        return data

    def Entities(self) -> None:
        fail = self.lay.fail("$Entities")
        counts = self._ints(4, self.size_t, fail)
        for dim, n in enumerate(counts):
            for _ in range(int(n)):
                if self.binary:
                    tag = int(self._ints(1, "<i4", fail)[0])
                    self._ints(3 if dim == 0 else 6, "<f8", fail)
                    tags = self._ints(int(self._ints(1, self.size_t, fail)[0]), "<i4", fail)
                    if dim > 0:
                        self._ints(int(self._ints(1, self.size_t, fail)[0]), "<i4", fail)
                else:   # one line per entity
                    words = self.fh.readline().split()
                    at = 4 if dim == 0 else 7
                    try:
                        tag, nphys = int(words[0]), int(words[at])
                        tags = np.array(words[at + 1:at + 1 + nphys], dtype=np.int64)
                    except (ValueError, IndexError):
                        raise fail("malformed entity line") from None
                self.lay.physical[(dim, tag)] = tuple(int(t) for t in tags)

    def Nodes(self) -> None:
        fail = self.lay.fail("$Nodes")
        if self.msh2:
            return self._nodes2(fail)
        nblocks, total, low, high = (int(v) for v in self._ints(4, self.size_t, fail))
        self.lay.num_nodes, self.lay.tag_range = total, (low, high)
        for _ in range(nblocks):
            head = self._block_head(fail)
            dim, parametric, n = int(head[0]), int(head[2]), int(head[3])
            if parametric:
                raise fail("parametric nodes are not supported")
            tags = self._rows(n, 1, self.size_t, fail)
            coords = self._rows(n, 3, "<f8", fail)
            self.lay.node_blocks.append((tags, coords))
        if sum(t.n for t, _ in self.lay.node_blocks) != total:
            raise fail(f"the blocks hold {sum(t.n for t, _ in self.lay.node_blocks)} nodes, "
                       f"the header says {total}")

    def Elements(self) -> None:
        fail = self.lay.fail("$Elements")
        if self.msh2:
            return self._elements2(fail)
        nblocks = int(self._ints(4, self.size_t, fail)[0])
        for _ in range(nblocks):
            dim, entity, kind, n = (int(v) for v in self._block_head(fail))
            if kind not in TYPES:
                raise fail(f"unknown element type {kind}")
            name, nodes, _ = TYPES[kind]
            rows = self._rows(n, 1 + nodes, self.size_t, fail)
            self.lay.element_blocks.append((dim, entity, name, rows))

    def _nodes2(self, fail) -> None:
        """MSH 2: a count line, then "tag x y z" rows (binary: int32 tag, 3 doubles)."""
        n = self._count(fail)
        if self.binary:
            rows = self._rows(n, 1, np.dtype([("tag", "<i4"), ("xyz", "<f8", (3,))]), fail)
        else:
            rows = self._rows(n, 4, "<f8", fail)
        self.lay.node_blocks.append((rows, None))
        self.lay.num_nodes = n

    def _elements2(self, fail) -> None:
        """MSH 2: a count line, then "tag type ntags tags... nodes..." rows (binary: blocks
        headed by type, count, ntags, of int32 rows "tag tags... nodes..."). Each run of
        rows of one type, tag count and physical tag is a block."""
        n = self._count(fail)
        runs = _Runs(self.lay)
        if not self.binary:
            left = n
            while left > 0:
                left -= _ascii_chunk(self.fh, left, runs, fail)
            runs.close()
            return
        while n > 0:
            kind, count, ntags = (int(v) for v in self._ints(3, "<i4", fail))
            if kind not in TYPES or count < 0 or ntags < 0 or count > n:
                raise fail(f"malformed element block header ({kind} {count} {ntags})")
            cols = 1 + ntags + TYPES[kind][1]
            start = self.fh.tell()
            self._rows(count, cols, "<i4", fail)   # past the block (checks the file's size)
            self.fh.seek(start)
            for a in range(0, count, ROWS):
                b = min(a + ROWS, count)
                data = np.frombuffer(self.fh.read((b - a) * cols * 4), "<i4").reshape(-1, cols)
                phys = data[:, 1] if ntags else np.zeros(b - a, np.int64)
                runs.add(kind, ntags, phys, offsets=start + np.arange(a, b) * cols * 4)
            runs.close()
            n -= count

    def _count(self, fail) -> int:
        try:
            return int(self.fh.readline())
        except ValueError:
            raise fail("expected the number of rows") from None

    def _block_head(self, fail) -> np.ndarray:
        """entityDim entityTag (parametric | type) (int) count (size_t)."""
        if not self.binary:
            return self._ints(4, "<i8", fail)
        head = self._ints(3, "<i4", fail)
        return np.append(head.astype(np.int64), self._ints(1, self.size_t, fail).astype(np.int64))

    def _rows(self, n: int, cols: int, dtype: str | np.dtype, fail) -> Rows:
        if self.binary:
            rows = Rows(n, cols, dtype, offset=self.fh.tell())
            self.fh.seek(rows.offset + n * cols * np.dtype(dtype).itemsize)
            if self.fh.tell() > os.fstat(self.fh.fileno()).st_size:
                raise fail("the file ends before the block does (truncated?)")
            return rows
        _, marks = _lines(self.fh, n, fail, every=MARK)
        return Rows(n, cols, "<f8" if dtype == "<f8" else "<i8", marks=marks)


class _Runs:
    """MSH 2 element rows, a chunk at a time, gathered into blocks: runs of consecutive rows
    of one (type, tag count), with how many rows have each physical tag. ASCII rows keep the
    offset of every MARK-th line, binary ones their first row's offset (a run never spans two
    binary blocks)."""

    def __init__(self, lay: Layout):
        self.lay, self.key, self.n, self.marks, self.tags = lay, None, 0, [], {}

    def add(self, kind: int, ntags: int | np.ndarray, phys: np.ndarray,
            offsets: np.ndarray, ascii_rows: bool = False) -> None:
        """Rows of types ``kind`` (one or per row), tag counts ``ntags``, physical tags
        ``phys``, starting at byte ``offsets``."""
        if phys.size == 0:
            return
        kinds = np.broadcast_to(kind, phys.shape)
        ntags = np.broadcast_to(ntags, phys.shape)
        change = np.flatnonzero((kinds[1:] != kinds[:-1]) | (ntags[1:] != ntags[:-1])) + 1
        for a, b in zip(np.r_[0, change], np.r_[change, phys.size]):
            key = (int(kinds[a]), int(ntags[a]), ascii_rows)
            if key != self.key:
                self.close()
                self.key = key
            if ascii_rows:   # the offsets of the run's rows MARK·k
                self.marks.append(offsets[a + (-self.n) % MARK:b:MARK])
            elif not self.n:
                self.marks.append(offsets[a:a + 1])
            for tag, count in zip(*np.unique(phys[a:b], return_counts=True)):
                self.tags[int(tag)] = self.tags.get(int(tag), 0) + int(count)
            self.n += int(b - a)

    def close(self) -> None:
        """The current run as a block."""
        if self.key is None:
            return
        kind, ntags, ascii_rows = self.key
        name, nodes, dim = TYPES[kind]
        marks = np.concatenate(self.marks)
        lead = 3 + ntags if ascii_rows else 1 + ntags
        phys = (3 if ascii_rows else 1) if ntags else -1
        rows = (Rows(self.n, lead + nodes, "<i8", marks=marks, lead=lead, phys=phys)
                if ascii_rows else Rows(self.n, lead + nodes, "<i4", offset=int(marks[0]),
                                        lead=lead, phys=phys))
        self.lay.row_tags[len(self.lay.element_blocks)] = self.tags
        self.lay.element_blocks.append((dim, 0, name, rows))
        self.key, self.n, self.marks, self.tags = None, 0, [], {}


_NODES = np.zeros(max(TYPES) + 1, np.int64)   # Gmsh type -> nodes (0: unknown)
for _kind, (_, _count, _) in TYPES.items():
    _NODES[_kind] = _count


def _ascii_chunk(fh, left: int, runs: _Runs, fail) -> int:
    """Parse the whole lines of a chunk from ``fh``'s position (at most ``left``) as MSH 2
    ASCII element rows into ``runs``; ``fh`` is left after them. Returns the rows read."""
    at = fh.tell()
    chunk = fh.read(CHUNK)
    data = np.frombuffer(chunk, dtype=np.uint8)
    ends = np.flatnonzero(data == 10)[:left]
    if ends.size == 0 or ends.size < left and len(chunk) < CHUNK:
        raise fail("the file ends before the block does (truncated?)")
    cut = int(ends[-1]) + 1
    fh.seek(at + cut)
    space = data[:cut] <= 32
    word = np.flatnonzero(~space & np.r_[True, space[:-1]])   # each number's first byte
    counts = np.bincount(np.searchsorted(ends, word), minlength=ends.size)
    numbers = _numbers(chunk[:cut], "<i8")
    first = np.cumsum(counts) - counts
    if numbers.size != word.size or counts.min() < 3:
        raise fail("malformed element row (expected 'tag type ntags tags... nodes...')")
    kinds, ntags = numbers[first + 1], numbers[first + 2]
    known = (kinds > 0) & (kinds < _NODES.size)
    nodes = _NODES[np.where(known, kinds, 0)]
    if (nodes == 0).any() or (counts != 3 + ntags + nodes).any():
        bad = int(np.flatnonzero((nodes == 0) | (counts != 3 + ntags + nodes))[0])
        raise fail(f"malformed element row of type {kinds[bad]} ({counts[bad]} numbers)")
    phys = np.where(ntags > 0, numbers[np.minimum(first + 3, numbers.size - 1)], 0)
    runs.add(kinds, ntags, phys, at + np.r_[0, ends[:-1] + 1], ascii_rows=True)
    return int(ends.size)


def _end(fh, name: str, fail) -> None:
    """The section's end line (after binary data: a newline, then ``$EndName``)."""
    while True:
        line = fh.readline()
        if not line:
            raise fail(f"the file ends before $End{name} (truncated?)")
        if line.strip():
            break
    if line.strip() != f"$End{name}".encode():
        raise fail(f"expected $End{name}, found {line.strip()[:40].decode(errors='replace')!r}")


def _skip_section(fh, name: str, fail) -> None:
    """Past ``$EndName`` of a section not read (comments, data): searched by chunks."""
    end = f"$End{name}".encode()
    while True:
        at = fh.tell()
        chunk = fh.read(CHUNK)
        if not chunk:
            raise fail(f"the file ends before $End{name} (truncated?)")
        k = chunk.find(end)
        if k >= 0:
            fh.seek(at + k)
            fh.readline()
            return
        fh.seek(at + max(len(chunk) - len(end), 1))
