"""Exceptions that map to the command line's exit statuses (DESIGN §5).

    0 success · 2 InputError · 3 SolverError · 4 OutputError · 130 / 143 Interrupted
"""

from __future__ import annotations

EXIT_INPUT = 2
EXIT_SOLVER = 3
EXIT_OUTPUT = 4


class InputError(Exception):
    """Invalid input: scene, mesh, region, relation. Exit status 2.

    ``source`` is the file (scene or mesh) and ``key`` the dotted key in it, so that the
    one-line message points at what to fix.
    """

    def __init__(self, message: str, source: str | None = None, key: str | None = None):
        self.source = source
        self.key = key
        self.message = message
        super().__init__(self.oneline())

    def oneline(self) -> str:
        where = ": ".join(p for p in (self.source, self.key) if p)
        return f"{where}: {self.message}" if where else self.message


class SolverError(Exception):
    """The solver failed (no convergence, singular system). Exit status 3."""


class OutputError(Exception):
    """Writing results failed (disk full, file system gone). Exit status 4; the steps already
    written stay readable."""


class Interrupted(Exception):
    """SIGINT / SIGTERM: exit status 128 + signal number (130 / 143)."""

    def __init__(self, signum: int, name: str):
        self.signum, self.name = signum, name
        super().__init__(f"interrupted: {name}")

    @property
    def exit_status(self) -> int:
        return 128 + self.signum
