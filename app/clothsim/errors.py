"""Errors a user can act on: each renders as one line and maps to exit code 2."""

from __future__ import annotations

from pathlib import Path


class ClothsimError(Exception):
    """An error caused by the user's input or environment (not a bug).

    The CLI prints ``str(error)`` on one line and exits with :attr:`exit_code`.
    """

    exit_code = 2


class FieldError(ClothsimError):
    """A value is invalid: names where it came from (a file, or nothing for a command-line flag or
    an API setter), the field (``cloth.ks``, ``--steps``) and the problem, on one line."""

    def __init__(self, source: str | Path | None, field: str, problem: str) -> None:
        self.source = str(source) if source is not None else None
        self.field = field
        self.problem = problem
        where = ": ".join(p for p in (self.source, field) if p)
        super().__init__(f"{where}: {problem}" if where else problem)


class SceneError(FieldError):
    """A scene file is malformed: names the file, the field path and the problem."""

    def __init__(self, path: str | Path | None, field: str, problem: str) -> None:
        super().__init__(str(path) if path is not None else "<scene>", field, problem)
        self.path: str = self.source or "<scene>"


class SimulationBlowUp(ClothsimError):
    """The state became non-finite or its energy exploded during a run."""
