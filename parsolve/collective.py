"""Input errors raised together: a check that runs on each rank's part of the mesh may fail on
one rank only; every rank must then raise the same error (none may be left waiting in the next
collective call)."""

from __future__ import annotations

from typing import Callable, TypeVar

from parsolve.errors import InputError

T = TypeVar("T")


def agree(comm, fn: Callable[..., T], *args, **kwargs) -> T:
    """``fn(*args, **kwargs)`` on every rank; if it raised InputError on any rank, every rank
    raises the lowest such rank's error. Collective."""
    result, error = None, None
    try:
        result = fn(*args, **kwargs)
    except InputError as exc:
        error = (exc.message, exc.source, exc.key)
    errors = comm.allgather(error)
    first = next((e for e in errors if e is not None), None)
    if first is not None:
        raise InputError(*first)
    return result
