"""A signal on one rank stops every rank at the same point (parsolve.interrupts): the ranks
agree in ``check``, so none is left waiting in a collective call."""

from __future__ import annotations

import os
import signal

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
        expected = signal.SIG_IGN if comm.size > 1 else signal.SIG_DFL
        assert signal.getsignal(sig) == expected
        if comm.size > 1:
            os.kill(os.getpid(), sig)            # the late copy: ignored
        comm.Barrier()
    finally:
        signal.signal(sig, before)
