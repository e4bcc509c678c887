"""Small file systems for the tests of a full disk: a tmpfs mounted for the test (a skip where
mounting is not permitted), optionally filled to its last byte."""

from __future__ import annotations

import contextlib
import subprocess
from pathlib import Path

import pytest


@contextlib.contextmanager
def mounted(where: Path, size: str, full: bool = False):
    """A tmpfs of ``size`` at ``where`` (a new folder), unmounted afterwards; ``full``: a file
    ``fill`` takes every byte of it."""
    where.mkdir()
    mount = subprocess.run(["mount", "-t", "tmpfs", "-o", f"size={size}", "tmpfs", str(where)],
                           capture_output=True, text=True)
    if mount.returncode != 0:
        pytest.skip(f"cannot mount a small tmpfs here: {mount.stderr.strip()}")
    try:
        if full:
            fill(where)
        yield where
    finally:
        subprocess.run(["umount", "-l", str(where)], check=False)


def fill(where: Path) -> None:
    """``where/fill`` grown until the disk refuses a byte more."""
    with pytest.raises(OSError):
        with open(where / "fill", "ab") as fh:
            while True:
                fh.write(b"\0" * (64 << 10))
                fh.flush()
