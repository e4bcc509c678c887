"""Exceptions that map to the command line's exit statuses (DESIGN §5)."""

from __future__ import annotations


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
