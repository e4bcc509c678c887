"""One run per result file, and room to close it when the disk fills.

``OUT.h5.lock`` beside the result is opened and locked (``fcntl.flock``, advisory, exclusive,
non-blocking) by rank 0 before any output file is touched, and held until the run has closed
its files. A second run writing the same ``-o`` finds it locked and is refused (exit 2) before
it writes anything. (flock works across NFS clients on Linux; Lustre needs its ``flock``
mount option.)

The lock file also holds a **reserve** (RESERVE_BYTES allocated with ``posix_fallocate``): when
a write fails with a full disk, :func:`free_reserve` gives that space back so that HDF5 can
still write the metadata of the closing file and the status; without it the close itself fails
and leaves a file no reader opens (in the swmr mode HDF5 may even crash). A disk without room
for the reserve is a full disk from the start: the run stops before any output file exists
(exit 4, "No space left on device").
"""

from __future__ import annotations

import errno
import fcntl
import os
from pathlib import Path

RESERVE_BYTES = 1 << 20
_held: dict[Path, "OutputLock"] = {}   # result path -> this process's lock on it


def lock_path(result: str | Path) -> Path:
    result = Path(result)
    return result.with_name(result.name + ".lock")


class OutputLock:
    """The lock on one result file (taken by one process: rank 0)."""

    def __init__(self, result: str | Path):
        self.result = Path(result).absolute()
        self.path = lock_path(self.result)
        self.fd: int | None = None

    def acquire(self) -> bool:
        """True once held; False if another run holds it."""
        while True:
            fd = os.open(self.path, os.O_RDWR | os.O_CREAT, 0o644)
            try:
                fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
            except BlockingIOError:
                os.close(fd)
                return False
            try:   # the holder before us may have unlinked the file we locked: lock the new one
                same = os.fstat(fd).st_ino == os.stat(self.path).st_ino
            except FileNotFoundError:
                same = False
            if same:
                self.fd = fd
                _held[self.result] = self
                return True
            os.close(fd)

    def reserve(self, nbytes: int = RESERVE_BYTES) -> bool:
        """False when the disk has no room for the reserve: a run started there could not
        close its result once the disk fills (HDF5 left without room crashes or leaves a
        file no reader opens), so it does not start."""
        try:
            os.posix_fallocate(self.fd, 0, nbytes)
        except OSError as exc:
            if exc.errno in (errno.ENOSPC, errno.EDQUOT):
                return False
            # another error (a file system without fallocate): the run goes without a reserve
        return True

    def free_reserve(self) -> None:
        if self.fd is not None:
            os.ftruncate(self.fd, 0)

    def release(self) -> None:
        if self.fd is None:
            return
        _held.pop(self.result, None)
        try:   # unlinked while still locked: a run waiting on this inode re-checks (acquire)
            self.path.unlink(missing_ok=True)
        finally:
            os.close(self.fd)
            self.fd = None


def free_reserve(result: str | Path) -> bool:
    """Give back the reserve of ``result``'s lock; False when this process holds no lock on
    it (a run not started from the command line: no reserve)."""
    lock = _held.get(Path(result).absolute())
    if lock is None:
        return False
    lock.free_reserve()
    return True
