"""The first factorization's two parts timed apart for the progress lines: the analysis
(ordering and symbolic factorization: MUMPS' analysis phase) and the numeric factorization,
read from PETSc's event log (MatLUFactorSym / MatLUFactorNum, their Cholesky twins), which
``start`` turns on. Without the log both read 0 and no line is shown."""

from __future__ import annotations

from contextlib import contextmanager
from typing import Iterator

from petsc4py import PETSc

from parsolve import progress

EVENTS = {"analysis": ("MatLUFactorSym", "MatCholFctrSym"),
          "numeric": ("MatLUFactorNum", "MatCholFctrNum")}


def start() -> None:
    """PETSc's default event log on (what -log_view does; a second call changes nothing)."""
    PETSc.Log.begin()


def _seconds() -> dict[str, float]:
    try:
        return {part: sum(PETSc.Log.Event(e).getPerfInfo()["time"] for e in events)
                for part, events in EVENTS.items()}
    except PETSc.Error:   # the log is off (a library call that did not start it): no line
        return {part: 0.0 for part in EVENTS}


@contextmanager
def factorization(first: bool) -> Iterator[None]:
    """``progress.factorization(first)``, then for the first one a line with its parts."""
    before = _seconds() if first else None
    with progress.factorization(first):
        yield
    if first:
        after = _seconds()
        part = {k: after[k] - before[k] for k in after}
        if any(part.values()):
            progress.say(f"    analysis {part['analysis']:.3f} s, numeric factorization "
                         f"{part['numeric']:.3f} s")
