"""A test hook that ends the writing process at a chosen point of a step's write, the way a hard
kill (SIGKILL, the OOM killer, a node failure) does: no handler, no flush, no close.

Set in the environment of a run (tests/io/test_kill_points.py):

* ``PARSOLVE_KILL_WRITE=STEP:POINT`` — the process sends itself SIGKILL right after the
  POINT-th write action (one dataset's row, a resize, a flush; counted from 1) of saved step
  STEP (counted from 1);
* ``PARSOLVE_KILL_WRITE=STEP:@SECONDS`` — SECONDS after step STEP's write begins, SIGALRM with
  its default action ends the process wherever it is, inside an HDF5 call included (a Python
  handler would only run between two calls); a write that ends before then is killed at its
  end (SIGKILL), so the kill always falls inside or right after step STEP, never after the
  run has closed its file, whatever the machine's speed.

Unset (the normal case) both calls below do nothing.
"""

from __future__ import annotations

import os
import signal

ENV = "PARSOLVE_KILL_WRITE"


def _parse(text: str | None) -> tuple[int, int, float]:
    """(step, point, seconds); step 0 when unset."""
    if not text:
        return 0, 0, 0.0
    step, _, at = text.partition(":")
    if at.startswith("@"):
        return int(step), 0, float(at[1:])
    return int(step), int(at), 0.0


_STEP, _POINT, _SECONDS = _parse(os.environ.get(ENV))
_count = 0


def step_begins(step: int) -> None:
    """Called as the write of saved step ``step`` (from 1) begins."""
    global _count
    _count = 0
    if _STEP and step == _STEP and _SECONDS > 0:
        signal.signal(signal.SIGALRM, signal.SIG_DFL)
        signal.setitimer(signal.ITIMER_REAL, _SECONDS)


def passed(step: int) -> None:
    """Called after each write action of step ``step``."""
    global _count
    _count += 1
    if _STEP and step == _STEP and _count == _POINT:
        os.kill(os.getpid(), signal.SIGKILL)


def step_ends(step: int) -> None:
    """Called once the write of saved step ``step`` is whole: a timed kill of that step that
    has not fired yet fires now."""
    if _STEP and step == _STEP and _SECONDS > 0:
        signal.setitimer(signal.ITIMER_REAL, 0)
        os.kill(os.getpid(), signal.SIGKILL)
