"""PETSc options: defaults in code, then the scene, then the command line; inserted under the
solver's prefix only for the life of a solve (petsctools' way), so that two solvers never see
each other's settings."""

from __future__ import annotations

from contextlib import contextmanager
from typing import Iterator

from petsc4py import PETSc


def parse_cli(args: list[str]) -> dict[str, str]:
    """``-key value`` / ``-flag`` pairs from the command line, leading dash removed."""
    opts: dict[str, str] = {}
    i = 0
    while i < len(args):
        key = args[i]
        if not key.startswith("-") or len(key) < 2:
            raise ValueError(f"expected a PETSc option, got {key!r}")
        value = ""
        if i + 1 < len(args) and not _is_option(args[i + 1]):
            value = args[i + 1]
            i += 1
        opts[key.lstrip("-")] = value
        i += 1
    return opts


def _is_option(word: str) -> bool:
    if not word.startswith("-"):
        return False
    try:
        float(word)  # a negative number is a value
        return False
    except ValueError:
        return True


def merge(*layers: dict[str, str]) -> dict[str, str]:
    """Later layers win."""
    out: dict[str, str] = {}
    for layer in layers:
        out.update(layer)
    return out


@contextmanager
def inserted(prefix: str, options: dict[str, str]) -> Iterator[None]:
    """Put ``options`` under ``prefix`` in PETSc's database, and take them out afterwards."""
    db = PETSc.Options()
    keys = [prefix + k if not k.startswith(prefix) else k for k in options]
    saved = {k: db.getString(k) for k in keys if db.hasName(k)}
    for k, v in zip(keys, options.values()):
        db.setValue(k, v)
    try:
        yield
    finally:
        for k in keys:
            db.delValue(k)
        for k, v in saved.items():
            db.setValue(k, v)
