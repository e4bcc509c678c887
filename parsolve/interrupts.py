"""SIGINT / SIGTERM during a run, on one rank or many.

On one rank a signal raises ``Interrupted`` at once. On several ranks that would leave the
ranks the signal found inside a collective call (a factorization, a gather) waiting for the
ones that left: a hang until the scheduler kills the job, with no status written. So there a
signal only marks itself, and the ranks look at the marks together (``check``) at points they
all pass: after each written step and at each Newton iteration. Every rank then raises the
same ``Interrupted`` at the same place, and the result file is closed with the status
"interrupted: SIGTERM" and its finished steps.

Through ``mpirun`` (Open MPI 4.1): mpirun forwards SIGUSR1 / SIGUSR2 to every rank at once,
but a SIGTERM or SIGINT sent to mpirun itself reaches the ranks only as a SIGCONT at once,
SIGTERM ``odls_base_sigkill_timeout`` seconds later (default 1) and SIGKILL as long again after
it, and mpirun then exits 1 (it cannot be told to forward SIGTERM: ess_base_forward_signals
refuses it). So SIGUSR2 here means SIGTERM and SIGUSR1 means SIGINT (same exit status, the
status says which signal came): ``scripts/mpirun.sh`` turns the SIGTERM / SIGINT it gets into
them, and a batch system can send them itself (``scancel --signal=USR2``, ``sbatch
--signal=USR2@60``).
"""

from __future__ import annotations

import os
import signal
import time
from contextlib import contextmanager

from mpi4py import MPI

from parsolve.errors import Interrupted

SIGNALS = (signal.SIGINT, signal.SIGTERM, signal.SIGUSR1, signal.SIGUSR2)
STANDS_FOR = {signal.SIGUSR1: signal.SIGINT, signal.SIGUSR2: signal.SIGTERM}  # as mpirun forwards
_pending = 0   # the last signal received and not yet acted on (several ranks)
LATE_WINDOW = 10.0   # s after a stop on several ranks during which a relayed copy is ignored
_stopped_at = float("-inf")   # when the last stop on several ranks happened (monotonic clock)


def _interrupted(signum: int) -> Interrupted:
    name = signal.Signals(signum).name
    meant = STANDS_FOR.get(signum)
    if meant is None:
        return Interrupted(signum, name)
    return Interrupted(meant, f"{meant.name} (sent as {name})")


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
        _drop_progress()

    previous = {s: signal.signal(s, handler) for s in SIGNALS}
    try:
        yield
    except Interrupted:
        if comm.size > 1:
            previous.update(_late_relays(previous))
        raise
    finally:
        _pending = 0
        for s, h in previous.items():
            signal.signal(s, h)


def _late_relays(previous: dict) -> dict:
    """After a stop on several ranks, the signals left at their default (terminate) ignore a
    copy that comes within ``LATE_WINDOW`` seconds, and terminate again after it. mpirun
    relays SIGUSR1 / SIGUSR2 (scripts/mpirun.sh's) and, after its own SIGTERM, SIGTERM to one
    rank after another, within its ``odls_base_sigkill_timeout`` (1 s) of each other: a rank
    stopped by the others' mark may get its own copy only after it has left the run, and would
    die of it before it says why (SIGUSR2: mpirun then exits 140, not 143; seen 1 CI run in
    2). The copy means the same stop, already done. A script that calls ``api.run``, catches
    ``Interrupted`` and carries on is terminated by a later SIGTERM as before (by Python's
    handler: once the C call it is in returns). (SIGINT's previous handler is Python's, not
    the default: a terminal's Ctrl-C reaches every rank at once, and mpirun relays no SIGINT.)"""
    global _stopped_at
    _stopped_at = time.monotonic()
    return {s: _late_copy for s in SIGNALS if previous[s] in (signal.SIG_DFL, _late_copy)}


def _late_copy(signum: int, frame) -> None:
    """A relayed copy of the last stop is ignored; after the window the signal's default."""
    if time.monotonic() - _stopped_at < LATE_WINDOW:
        return
    signal.signal(signum, signal.SIG_DFL)
    os.kill(os.getpid(), signum)


def _drop_progress() -> None:
    """Progress lines after a signal go to /dev/null. An mpirun that got SIGTERM stops reading
    the ranks' stdout before it relays the signal: a rank blocked writing a progress line into
    the full pipe never reached the step's end and was SIGKILLed with its file open (seen: a
    fast scene, 5 ms steps). The retried write now succeeds; the final message is on stderr."""
    try:
        fd = os.open(os.devnull, os.O_WRONLY)
        os.dup2(fd, 1)
        os.close(fd)
    except OSError:
        pass


def check(comm: MPI.Comm) -> None:
    """Collective over ``comm``: raise Interrupted on every rank when any rank got a signal."""
    global _pending
    signum = _pending if comm.size == 1 else comm.allreduce(_pending, op=MPI.MAX)
    if signum:
        _pending = 0   # acted on: raised once, on every rank
        raise _interrupted(signum)
