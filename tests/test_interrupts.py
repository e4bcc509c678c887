"""A signal on one rank stops every rank at the same point (parsolve.interrupts): the ranks
agree in ``check``, so none is left waiting in a collective call."""

from __future__ import annotations

import os
import signal
import subprocess
import sys

import pytest
from mpi4py import MPI

from parsolve import interrupts
from parsolve.errors import Interrupted


def test_a_signal_on_one_rank_stops_every_rank_at_the_check():
    comm = MPI.COMM_WORLD
    before = signal.getsignal(signal.SIGTERM)
    with interrupts.interruptible(comm):
        interrupts.check(comm)                       # nothing pending: no effect
        if comm.rank == comm.size - 1:
            if comm.size == 1:
                with pytest.raises(Interrupted):     # one rank: at once
                    os.kill(os.getpid(), signal.SIGTERM)
                interrupts._pending = signal.SIGTERM  # as if it had arrived during a call
            else:
                os.kill(os.getpid(), signal.SIGTERM)  # several ranks: only marked
        comm.Barrier()
        with pytest.raises(Interrupted) as err:
            interrupts.check(comm)
    assert err.value.exit_status == 143 and str(err.value) == "interrupted: SIGTERM"
    assert signal.getsignal(signal.SIGTERM) is before   # the previous handler is back
    interrupts.check(comm)                               # acted on once: nothing pending


@pytest.mark.parametrize("sig, name", [(signal.SIGUSR2, "SIGTERM (sent as SIGUSR2)"),
                                       (signal.SIGTERM, "SIGTERM")])
def test_a_late_relayed_signal_after_the_stop_does_not_kill_a_rank(sig, name):
    """mpirun relays SIGUSR2 (scripts/mpirun.sh's) and, after its own SIGTERM, SIGTERM to the
    ranks one after another: a rank stopped by another's mark may get its copy after it has
    left the run. It must not die of it (exit 140 instead of 143 for SIGUSR2; for SIGTERM,
    before rank 0 says why)."""
    comm = MPI.COMM_WORLD
    before = signal.signal(sig, signal.SIG_DFL)
    try:
        with pytest.raises(Interrupted) as err:
            with interrupts.interruptible(comm):
                if comm.rank == 0:
                    interrupts._pending = sig    # rank 0's copy came first
                interrupts.check(comm)
        assert str(err.value) == f"interrupted: {name}"
        expected = interrupts._late_copy if comm.size > 1 else signal.SIG_DFL
        assert signal.getsignal(sig) == expected
        if comm.size > 1:
            os.kill(os.getpid(), sig)            # the late copy: ignored
        comm.Barrier()
    finally:
        signal.signal(sig, before)


AFTER_THE_WINDOW = """
import os, signal, sys
from parsolve import interrupts
from parsolve.errors import Interrupted

class TwoRanks:      # a stop on several ranks, seen from rank 0, without MPI
    size, rank = 2, 0
    def allreduce(self, value, op=None):
        return value

try:
    with interrupts.interruptible(TwoRanks()):
        interrupts._pending = signal.SIGTERM
        interrupts.check(TwoRanks())
except Interrupted:
    pass
os.kill(os.getpid(), signal.SIGTERM)           # the late copy, within the window: ignored
print("alive", flush=True)
interrupts._stopped_at -= interrupts.LATE_WINDOW   # the window is over
os.kill(os.getpid(), signal.SIGTERM)           # a new SIGTERM: terminates, as by default
print("not reached", flush=True)
"""


@pytest.mark.skipif(MPI.COMM_WORLD.rank != 0, reason="a subprocess of one rank")
def test_sigterm_terminates_again_once_the_late_copies_window_is_over():
    """The late copies of a stop are ignored for ``LATE_WINDOW`` seconds only: a script that
    catches ``Interrupted`` and carries on is terminated by a later SIGTERM."""
    run = subprocess.run([sys.executable, "-c", AFTER_THE_WINDOW], capture_output=True,
                         text=True, timeout=60, env={k: v for k, v in os.environ.items()
                                                  if not k.startswith(("OMPI_", "PMIX_", "OPAL_"))})
    assert run.stdout.split() == ["alive"]
    assert run.returncode == -signal.SIGTERM, run.stderr
