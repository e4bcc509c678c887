"""The local executor: ``parallel`` runs at a time, each a subprocess (under ``mpirun -n k``
when it has k > 1 ranks). Ctrl-C (or SIGTERM) stops every running child's process group, waits
for it, records the runs as interrupted and re-raises."""

from __future__ import annotations

import signal
import threading
import time
from pathlib import Path
from typing import Callable

from parsolve.batch import runner

STOPS = (signal.SIGINT, signal.SIGTERM)


def execute(folders: list[Path], parallel: int, log: Callable[[str], None]) -> None:
    """Run the prepared ``folders``; their outcomes are written into them."""
    pending = list(folders)
    running: dict[Path, tuple] = {}
    total, done = len(folders), 0
    # SIGTERM (a job scheduler stopping the batch) stops the runs as Ctrl-C does. SIGINT's
    # handler is set too, as `parsolve run` sets its own: a process started in the background
    # of a script inherits SIGINT ignored, and Python then installs no KeyboardInterrupt
    # (`kill -INT` did nothing). Only the main thread may install handlers.
    main = threading.current_thread() is threading.main_thread()
    old = {s: signal.signal(s, _raise_interrupt) for s in STOPS} if main else {}
    try:
        while pending or running:
            while pending and len(running) < max(1, parallel):
                folder = pending.pop(0)
                running[folder] = (runner.start(folder), time.perf_counter())
            for folder, (proc, t0) in list(running.items()):
                code = proc.poll()
                if code is None:
                    continue
                runner.finish(folder, runner.exit_status(code), time.perf_counter() - t0)
                del running[folder]
                done += 1
                log(f"[{done}/{total}] {folder.name}: {runner.status_of(folder)[0]}")
            time.sleep(0.02)
    except KeyboardInterrupt:
        log(f"batch: interrupted, stopping {len(running)} running run(s)")
        for folder, (proc, t0) in running.items():
            code = runner.stop(proc)
            runner.finish(folder, runner.exit_status(code), time.perf_counter() - t0)
        raise
    finally:
        for sig, handler in old.items():   # (None: a handler set outside Python)
            signal.signal(sig, signal.SIG_DFL if handler is None else handler)


def _raise_interrupt(signum, frame):
    raise KeyboardInterrupt
