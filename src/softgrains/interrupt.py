"""SIGINT/SIGTERM as a request to stop cleanly between two steps (issue #5).

The first signal only sets a flag: the run loop finishes the step under way, writes a final
checkpoint and summary.json (status "interrupted") and returns. A second signal raises
KeyboardInterrupt at once (the last checkpoint written stays the good one).
"""

from __future__ import annotations

import signal
import threading
from types import FrameType

SIGNALS = (signal.SIGINT, signal.SIGTERM)


class StopRequest:
    """Installs the handlers (main thread only; elsewhere it does nothing) until
    :meth:`restore`; ``signum`` is the first signal received, or None."""

    def __init__(self) -> None:
        self.signum: int | None = None
        self._previous: dict[int, object] = {}
        if threading.current_thread() is threading.main_thread():
            for sig in SIGNALS:
                self._previous[sig] = signal.signal(sig, self._handle)

    def _handle(self, signum: int, frame: FrameType | None) -> None:
        if self.signum is not None:
            raise KeyboardInterrupt
        self.signum = signum

    @property
    def requested(self) -> bool:
        return self.signum is not None

    @property
    def name(self) -> str:
        return signal.Signals(self.signum).name if self.signum is not None else ""

    def restore(self) -> None:
        """Put the previous handlers back (idempotent)."""
        for sig, handler in self._previous.items():
            # None: the previous handler was not installed from Python
            signal.signal(sig, signal.SIG_DFL if handler is None else handler)
        self._previous = {}
