"""Ctrl-C and SIGTERM during training: finish the chunk in flight, save a checkpoint, stop.

A chunk is a few seconds of jitted work whose input carry is donated, so interrupting it in the middle
would lose the carry; the first signal only asks the loop to stop after the chunk, the second one
interrupts at once (the last periodic checkpoint is then what remains).
"""

from __future__ import annotations

import signal
import threading
from collections.abc import Callable

STOP_SIGNALS = (signal.SIGINT, signal.SIGTERM)


class StopRequests:
    """Context manager: `requested` turns true at the first SIGINT / SIGTERM (main thread only; elsewhere the
    handlers cannot be installed and signals keep their usual effect)."""

    def __init__(self, on_first: Callable[[str], None] | None = None):
        self.requested = False
        self.signal_name = ""
        self._on_first = on_first
        self._previous: dict = {}

    def _handle(self, signum, frame) -> None:
        if self.requested:  # a second signal: stop now
            raise KeyboardInterrupt
        self.requested = True
        self.signal_name = signal.Signals(signum).name
        if self._on_first is not None:
            self._on_first(self.signal_name)

    def __enter__(self) -> StopRequests:
        if threading.current_thread() is threading.main_thread():
            for signum in STOP_SIGNALS:
                self._previous[signum] = signal.signal(signum, self._handle)
        return self

    def __exit__(self, *exc) -> None:
        for signum, handler in self._previous.items():
            signal.signal(signum, handler)
        self._previous.clear()
