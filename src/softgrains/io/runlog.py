"""The run's log (``run.log`` plus the terminal) and its progress bar."""

from __future__ import annotations

import itertools
import logging
import sys
from pathlib import Path
from types import TracebackType
from typing import Self

import numpy as np
from tqdm import tqdm

_run_ids = itertools.count()


class _ConsoleHandler(logging.Handler):
    """Writes records to stderr through ``tqdm.write`` so an active progress bar stays intact."""

    def emit(self, record: logging.LogRecord) -> None:
        try:
            tqdm.write(self.format(record), file=sys.stderr)
        except (OSError, ValueError, TypeError):
            self.handleError(record)


class _ConsoleFormatter(logging.Formatter):
    """Plain messages for INFO; ``LEVEL: message`` for anything else."""

    def format(self, record: logging.LogRecord) -> str:
        message = super().format(record)
        return message if record.levelno == logging.INFO else f"{record.levelname}: {message}"


def open_run_log(out_dir: str | Path, verbose_console: bool) -> logging.Logger:
    """A fresh logger writing INFO and above to ``out_dir/run.log`` and to stderr.

    ``run.log`` is appended to (a resumed run continues it) and flushed after every record.
    The console shows INFO and above when ``verbose_console``, else only warnings and errors
    (e.g. while a progress bar is shown).
    """
    out_dir = Path(out_dir)
    out_dir.mkdir(parents=True, exist_ok=True)
    logger = logging.getLogger(f"softgrains.run.{next(_run_ids)}")
    logger.setLevel(logging.INFO)
    logger.propagate = False

    file_handler = logging.FileHandler(out_dir / "run.log", mode="a", encoding="utf-8")
    file_handler.setFormatter(
        logging.Formatter("%(asctime)s %(levelname)-7s %(message)s", "%Y-%m-%d %H:%M:%S")
    )
    console_handler = _ConsoleHandler(logging.INFO if verbose_console else logging.WARNING)
    console_handler.setFormatter(_ConsoleFormatter("%(message)s"))
    logger.addHandler(file_handler)
    logger.addHandler(console_handler)
    return logger


def close_run_log(logger: logging.Logger) -> None:
    """Detach and close the handlers that :func:`open_run_log` attached."""
    for handler in list(logger.handlers):
        logger.removeHandler(handler)
        handler.close()


def _format_figure(value: object) -> str:
    return f"{value:.4g}" if isinstance(value, float | np.floating) else str(value)


class Progress:
    """A progress bar on stderr, shown only when ``enabled`` and stderr is a terminal.

    When the bar is off every method does nothing: the caller logs periodic lines instead
    (see :attr:`active`).
    """

    def __init__(self, total_steps: int | None, enabled: bool) -> None:
        """``total_steps`` may be ``None`` when the run stops on a criterion, not a step count."""
        self._bar: tqdm | None = None
        if enabled and sys.stderr.isatty():
            self._bar = tqdm(
                total=total_steps, file=sys.stderr, unit="step", dynamic_ncols=True, leave=True
            )

    @property
    def active(self) -> bool:
        """Whether the bar is shown."""
        return self._bar is not None

    def update(self, step: int, time: float, **figures: object) -> None:
        """Move the bar to ``step``; show the simulated ``time`` [s] and key ``figures``."""
        if self._bar is None:
            return
        postfix = {"t": f"{time:.4g} s"}
        postfix.update({name: _format_figure(value) for name, value in figures.items()})
        self._bar.set_postfix(postfix, refresh=False)
        self._bar.update(step - self._bar.n)

    def close(self) -> None:
        """Close the bar (idempotent)."""
        if self._bar is not None:
            self._bar.close()
            self._bar = None

    def __enter__(self) -> Self:
        return self

    def __exit__(
        self,
        exc_type: type[BaseException] | None,
        exc: BaseException | None,
        tb: TracebackType | None,
    ) -> None:
        self.close()
