"""Exceptions that map onto the command line's exit statuses (INTERFACE.md).

- :class:`CaseError` -> exit status 2: the case file or the arguments are invalid. The message
  names the key, the value and what is allowed.
- :class:`SimulationError` -> exit status 3: the simulation failed (diverged, left the grid,
  inverted an element...). The message says what, where and what to try.
"""

from __future__ import annotations

EXIT_OK = 0
EXIT_INVALID = 2  # CaseError
EXIT_FAILED = 3  # SimulationError
EXIT_INTERRUPTED = 130  # Ctrl-C (a run stopped by a signal exits 128 + the signal)


class CaseError(ValueError):
    """An invalid case file, key or command-line argument (exit status 2)."""


class SimulationError(RuntimeError):
    """A run that cannot go on (exit status 3); ``diagnosis`` holds structured details."""

    def __init__(self, message: str, **diagnosis: object) -> None:
        super().__init__(message)
        self.diagnosis = diagnosis
