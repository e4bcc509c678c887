"""The memory a job really has: the tightest of the machine's available memory, the process's
address-space limit and its cgroup's memory limit.

A batch system rarely gives a job the whole machine: SLURM confines it to a cgroup
(``memory.max``, cgroup v2; ``memory.limit_in_bytes``, v1), ``ulimit -v`` / ``prlimit --as``
cap the address space. A check against MemAvailable alone passes meshes that then fail inside
MUMPS or with a MemoryError.

``root`` arguments (default ``/``) let tests point the readers at a tree of fake files.
"""

from __future__ import annotations

import resource
from pathlib import Path

UNLIMITED = 2**62   # cgroup v1 writes "no limit" as a huge page-rounded number


def available_bytes(processes: int = 1, root: str | Path = "/") -> tuple[int, str]:
    """(bytes, what bound them): the tightest of MemAvailable, ``processes`` times this
    process's RLIMIT_AS headroom (each rank has its own limit) and the cgroup's limit minus
    its usage. ``processes``: the ranks on this machine the caller needs memory for."""
    root = Path(root)
    space = address_space_headroom(root)
    bounds = [(meminfo_available(root), "MemAvailable"),
              (None if space is None else space * processes,
               "the address-space limit RLIMIT_AS (ulimit -v)"),
              cgroup_headroom(root)]
    known = [(int(b), what) for b, what in bounds if b is not None]
    if not known:
        return 0, "no memory information"
    return min(known)


def meminfo_available(root: Path) -> int | None:
    value = _meminfo(root / "proc" / "meminfo", "MemAvailable:")
    return None if value is None else value * 1024


def address_space_headroom(root: Path) -> int | None:
    """RLIMIT_AS minus this process's current address space (VmSize); None without a limit."""
    soft, _ = resource.getrlimit(resource.RLIMIT_AS)
    if soft == resource.RLIM_INFINITY:
        return None
    size = _meminfo(root / "proc" / "self" / "status", "VmSize:")
    return max(soft - (size or 0) * 1024, 0)


def cgroup_headroom(root: Path) -> tuple[int | None, str]:
    """(limit minus usage of the tightest cgroup this process is in or under, its name)."""
    try:
        lines = (root / "proc" / "self" / "cgroup").read_text().splitlines()
    except OSError:
        return None, ""
    best: tuple[int | None, str] = (None, "")
    for line in lines:
        _, controllers, path = line.split(":", 2)
        if controllers == "":        # v2: one unified hierarchy
            base, files = root / "sys" / "fs" / "cgroup", ("memory.max", "memory.current")
        elif "memory" in controllers.split(","):
            base, files = root / "sys" / "fs" / "cgroup" / "memory", \
                ("memory.limit_in_bytes", "memory.usage_in_bytes")
        else:
            continue
        for folder in _ancestors(base, path):
            headroom = _headroom(folder / files[0], folder / files[1], folder / "memory.stat")
            if headroom is not None and (best[0] is None or headroom < best[0]):
                best = (headroom, f"the cgroup limit {folder / files[0]}")
    return best


def _ancestors(base: Path, path: str) -> list[Path]:
    """The cgroup's folder and its parents up to the hierarchy's root (a limit anywhere above
    applies); in a cgroup namespace the path may be missing: then the root alone."""
    parts = [p for p in path.strip("/").split("/") if p]
    return [base.joinpath(*parts[:k]) for k in range(len(parts), -1, -1)
            if base.joinpath(*parts[:k]).is_dir()]


def _headroom(limit_file: Path, usage_file: Path, stat_file: Path) -> int | None:
    """Limit minus usage, the usage without the inactive page cache (the kernel reclaims it
    before it refuses memory)."""
    try:
        limit = limit_file.read_text().strip()
        usage = int(usage_file.read_text().strip())
    except (OSError, ValueError):
        return None
    if limit == "max" or not limit.isdigit() or int(limit) >= UNLIMITED:
        return None
    cache = 0
    try:
        for line in stat_file.read_text().splitlines():
            key, _, value = line.partition(" ")
            if key in ("inactive_file", "total_inactive_file"):
                cache = int(value)  # v1 lists both: total_ (with descendants) comes later
    except (OSError, ValueError):
        pass
    return max(int(limit) - max(usage - cache, 0), 0)


def _meminfo(path: Path, key: str) -> int | None:
    """The kB value of ``key`` in a /proc file of "Key:  value kB" lines."""
    try:
        with open(path) as f:
            for line in f:
                if line.startswith(key):
                    return int(line.split()[1])
    except (OSError, ValueError, IndexError):
        pass
    return None
