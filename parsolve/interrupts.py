"""SIGINT / SIGTERM during a run, on one rank or many.

On one rank a signal raises ``Interrupted`` at once. On several ranks that would leave the
ranks the signal found inside a collective call (a factorization, a gather) waiting for the
ones that left: a hang until the scheduler kills the job, with no status written. So there a
signal only marks itself, and the ranks look at the marks together (``check``) at points they
all pass: after each written step and at each Newton iteration. Every rank then raises the
same ``Interrupted`` at the same place, and the result file is closed with the status
"interrupted: SIGTERM" and its finished steps.
"""

from __future__ import annotations

import signal
from contextlib import contextmanager

from mpi4py import MPI

from parsolve.errors import Interrupted

SIGNALS = (signal.SIGINT, signal.SIGTERM)
_pending = 0   # the last signal received and not yet acted on (several ranks)


def _interrupted(signum: int) -> Interrupted:
    return Interrupted(signum, signal.Signals(signum).name)


@contextmanager
def interruptible(comm: MPI.Comm = MPI.COMM_WORLD):
    """Within the block, SIGINT / SIGTERM stop the run (see the module); the previous handlers
    come back afterwards."""
    global _pending
    _pending = 0

    def handler(signum, frame):
        global _pending
        if comm.size == 1:
            raise _interrupted(signum)
        _pending = signum

    previous = {s: signal.signal(s, handler) for s in SIGNALS}
    try:
        yield
    finally:
        _pending = 0
        for s, h in previous.items():
            signal.signal(s, h)


def check(comm: MPI.Comm) -> None:
    """Collective over ``comm``: raise Interrupted on every rank when any rank got a signal."""
    global _pending
    signum = _pending if comm.size == 1 else comm.allreduce(_pending, op=MPI.MAX)
    if signum:
        _pending = 0   # acted on: raised once, on every rank
        raise _interrupted(signum)
