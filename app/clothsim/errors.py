"""Errors a user can act on: each renders as one line and maps to exit code 2."""

from __future__ import annotations

from pathlib import Path


class ClothsimError(Exception):
    """An error caused by the user's input or environment (not a bug).

    The CLI prints ``str(error)`` on one line and exits with :attr:`exit_code`.
    """

    exit_code = 2


class SceneError(ClothsimError):
    """A scene file is malformed: names the file, the field path and the problem."""

    def __init__(self, path: str | Path | None, field: str, problem: str) -> None:
        self.path = str(path) if path is not None else "<scene>"
        self.field = field
        self.problem = problem
        where = f"{self.path}: {field}" if field else self.path
        super().__init__(f"{where}: {problem}")


class SimulationBlowUp(ClothsimError):
    """The state became non-finite or its energy exploded during a run."""
