"""A small output file written whole or not at all: under a temporary name beside it (same
suffix, so that a writer choosing its format by the suffix still does), renamed once written.
A failure (a full disk) leaves neither the file cut nor the temporary name behind."""

from __future__ import annotations

import os
from collections.abc import Callable
from pathlib import Path


def write_whole(path: str | Path, write: Callable[[str], None]) -> None:
    """``write(name)`` then the rename over ``path``; an OSError names ``path``."""
    out = Path(path)
    tmp = out.with_name(f".{out.name}.{os.getpid()}.tmp{out.suffix}")
    try:
        write(str(tmp))
        os.replace(tmp, out)
    except OSError as exc:
        raise OSError(exc.errno, exc.strerror or str(exc), str(out)) from None
    finally:
        tmp.unlink(missing_ok=True)
