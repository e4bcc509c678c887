"""What a run says while it works, on rank 0: one line per set-up phase with its time (mesh
read, checks, partition, numbering, pattern, operator, analysis, factorization), a line when a
phase is still running after ``ALIVE`` seconds (then after twice as long, ...), and with
``-v`` the Newton residual of every iteration and the Krylov iterations of every solve.

Levels: ``QUIET`` (errors and the final line only), ``NORMAL`` (phases and steps), ``VERBOSE``
(and the iterations). The reporter is the process's one (``configure`` sets it: the command
line, the Python API); code that is not run from either reports nothing, so a library call or a
test prints no phase lines unless it asks for them.

    with progress.phase("factorization"):
        pc.setUp()
    progress.detail(f"newton {it}: residual {r:.3e}")

The "still running" line comes from a timer thread: it shows while the phase runs Python code
or a call that releases the GIL. A single C call that holds it (a MUMPS factorization through
petsc4py) keeps the thread from running: such a phase announces itself when it starts
(``announce``), and the thread's late lines are dropped.
"""

from __future__ import annotations

import sys
import threading
import time
from contextlib import contextmanager
from typing import Callable, Iterator

QUIET, NORMAL, VERBOSE = 0, 1, 2
ALIVE = 10.0    # seconds before a running phase says it is alive
LATE = 1.0      # an alive line more than this late is not printed


class Reporter:
    """Rank 0's lines at a level; other ranks' reporters say nothing."""

    def __init__(self, level: int = NORMAL, rank: int = 0,
                 write: Callable[[str], None] | None = None, alive: float = ALIVE):
        self.level, self.rank, self.alive = level, rank, alive
        self.write = write or (lambda line: print(line, file=sys.stdout, flush=True))
        self.depth = 0          # nested phases are indented under their parent
        self._lock = threading.Lock()

    def say(self, line: str, level: int = NORMAL) -> None:
        if self.rank == 0 and self.level >= level:
            with self._lock:
                self.write(line)

    @contextmanager
    def phase(self, name: str, level: int = NORMAL, announce: bool = False) -> Iterator[None]:
        """Time the block; one line when it ends ("  name  1.234 s"), lines while it runs
        long; all at ``level``. ``announce``: a line when it starts too (a phase that is one
        long C call, which the timer thread cannot interrupt)."""
        indent = "  " * (self.depth + 1)
        if announce:
            self.say(f"{indent}{name} ...", level)
        t0 = time.perf_counter()
        done = threading.Event()
        watcher = None
        if self.rank == 0 and self.level >= level and self.alive > 0:
            watcher = threading.Thread(target=self._watch, args=(name, indent, t0, done, level),
                                       daemon=True)
            watcher.start()
        self.depth += 1
        try:
            yield
        finally:
            self.depth -= 1
            done.set()
            if watcher is not None:
                watcher.join()
            self.say(f"{indent}{name:<24s}{time.perf_counter() - t0:9.3f} s", level)

    def _watch(self, name: str, indent: str, t0: float, done: threading.Event, level: int) -> None:
        wait = self.alive
        while not done.wait(max(0.0, t0 + wait - time.perf_counter())):
            now = time.perf_counter() - t0
            # woken late: the GIL was held (a C call that has just returned), the news is stale
            if now < wait + LATE:
                self.say(f"{indent}{name}: still running ({now:.0f} s)", level)
            wait *= 2


_current = Reporter(QUIET)


def configure(level: int, rank: int = 0, write: Callable[[str], None] | None = None,
              alive: float = ALIVE) -> Reporter:
    """Set the process's reporter (the previous one is returned by ``current`` no more)."""
    global _current
    _current = Reporter(level, rank, write, alive)
    return _current


def current() -> Reporter:
    return _current


def phase(name: str, level: int = NORMAL):
    """``with progress.phase("pattern"): ...`` on the process's reporter."""
    return _current.phase(name, level)


def timed(name: str, fn: Callable, *args, **kwargs):
    """``fn(*args, **kwargs)`` as a phase: one line at a call site."""
    with _current.phase(name):
        return fn(*args, **kwargs)


def factorization(first: bool):
    """The phase of a factorization: its analysis comes with the first (a line at the normal
    level); the later ones (Newton iterations, steps) are detail."""
    return _current.phase("analysis+factorization" if first else "factorization",
                          NORMAL if first else VERBOSE, announce=first)


def say(line: str) -> None:
    """A line at the normal level (rank 0)."""
    _current.say(line, NORMAL)


def detail(line: str) -> None:
    """A line shown with ``-v`` only (rank 0)."""
    _current.say("    " + line, VERBOSE)
