"""One progress display for long commands (conversion, evaluation, ...), always on stderr.

- On a terminal: a tqdm bar, with the total and an ETA when the total is known.
- Anywhere else (a log file, a pipe, CI): a plain line every `interval_s` seconds and one at the end, e.g.
  `converting: 120/400 scenarios (30%), 12.3/s, ETA 0:00:23`. No carriage-return frames fill the log.
- Disabled (`enabled=False`, the commands' --quiet): nothing at all.

    with Progress("converting", total=400, unit="scenarios", enabled=not quiet) as progress:
        for ...:
            progress.update(1)
            progress.set_postfix(failures=3)

The terminal test (`is_tty`), the stream, the clock and the reporting interval can be injected, so tests are
fast and deterministic.
"""

from __future__ import annotations

import os
import sys
import time
from collections.abc import Callable
from typing import TextIO

DEFAULT_INTERVAL_S = 10.0


def format_duration(seconds: float) -> str:
    """h:mm:ss, like tqdm's ETA."""
    whole = max(0, int(round(seconds)))
    return f"{whole // 3600}:{whole % 3600 // 60:02d}:{whole % 60:02d}"


def progress_line(desc: str, done: int, total: int | None, unit: str, rate: float,
                  postfix: dict[str, object] | None = None, finished_after_s: float | None = None) -> str:
    """One plain progress line: `desc: done/total unit (pct%), rate/s, ETA h:mm:ss[, key=value ...]`.

    Without a total: `desc: done unit, rate/s`. `finished_after_s` (the run's duration) replaces the ETA.
    """
    if total:
        line = f"{desc}: {done}/{total} {unit} ({100 * done // total}%), {rate:.1f}/s"
    else:
        line = f"{desc}: {done} {unit}, {rate:.1f}/s"
    if finished_after_s is not None:
        line += f", done in {format_duration(finished_after_s)}"
    elif total and rate > 0:
        line += f", ETA {format_duration(max(total - done, 0) / rate)}"
    if postfix:
        line += ", " + ", ".join(f"{key}={value}" for key, value in postfix.items())
    return line


def _stream_is_tty(stream: TextIO) -> bool:
    try:
        return bool(stream.isatty())
    except (AttributeError, ValueError):  # no isatty, or a closed stream
        return False


def _terminal_columns(stream: TextIO) -> int:
    try:
        return os.get_terminal_size(stream.fileno()).columns
    except (AttributeError, ValueError, OSError):  # not a real file (tests), or no terminal
        return 0


class Progress:
    """A progress display of `total` units (None: unknown). See the module docstring.

    desc: what is being done ("converting"); unit: what is counted, plural ("scenarios").
    enabled: False shows nothing. stream: where to write (default: sys.stderr at construction).
    is_tty: bar or plain lines (default: stream.isatty()). interval_s: seconds between plain lines.
    initial: units already done (a resumed run). leave: keep the bar on screen after close.
    clock: seconds, monotonic (tests inject a fake one).
    """

    def __init__(self, desc: str, total: int | None = None, unit: str = "items", enabled: bool = True, *,
                 stream: TextIO | None = None, is_tty: bool | None = None,
                 interval_s: float = DEFAULT_INTERVAL_S, initial: int = 0, leave: bool = False,
                 clock: Callable[[], float] = time.monotonic):
        self.desc, self.unit, self.enabled = desc, unit, enabled
        self.total = total
        self.done = initial
        self.interval_s = interval_s
        self.postfix: dict[str, object] = {}
        self._stream = stream if stream is not None else sys.stderr
        self._clock = clock
        self._start = clock()
        self._last_line = self._start
        self._initial = initial
        self._closed = False
        self._bar = None
        if enabled and (_stream_is_tty(self._stream) if is_tty is None else is_tty):
            from tqdm import tqdm

            # a pseudo-terminal of unset size reports 0 x 0, where tqdm would hide the bar: give it a size
            sized = _terminal_columns(self._stream) > 0
            self._bar = tqdm(total=total, initial=initial, desc=desc, unit=unit, file=self._stream, leave=leave,
                             dynamic_ncols=sized, ncols=None if sized else 100, nrows=None if sized else 24)

    @property
    def is_bar(self) -> bool:
        """True when drawing a terminal bar, False for plain lines or when disabled."""
        return self._bar is not None

    def update(self, n: int = 1) -> None:
        """Counts `n` more units done; on a non-terminal writes a line when `interval_s` has passed."""
        self.done += n
        if self._closed or not self.enabled:
            return
        if self._bar is not None:
            self._bar.update(n)
        elif self._clock() - self._last_line >= self.interval_s and not (self.total and self.done >= self.total):
            self._write_line(finished=False)  # (at the total, close's final line says it)

    def set_postfix(self, **values: object) -> None:
        """Extra fields shown after the count (the bar's postfix, or `key=value` on the plain lines)."""
        self.postfix.update(values)
        if self._bar is not None and not self._closed:
            self._bar.set_postfix({key: str(value) for key, value in self.postfix.items()}, refresh=False)

    def set_total(self, total: int | None) -> None:
        """The total once it becomes known (or changes)."""
        self.total = total
        if self._bar is not None and not self._closed:
            self._bar.total = total
            self._bar.refresh()

    def write(self, message: str) -> None:
        """A message line on the same stream that does not break the bar (written even when disabled)."""
        if self._bar is not None:
            self._bar.write(message, file=self._stream)
        else:
            print(message, file=self._stream, flush=True)

    def close(self, final_line: bool = True) -> None:
        """Ends the display: the bar is closed, a non-terminal gets the final line (unless `final_line` is
        False, e.g. after an error, so the error stays the last line). Safe to call twice."""
        if self._closed or not self.enabled:
            return
        self._closed = True
        if self._bar is not None:
            self._bar.close()
        elif final_line:
            self._write_line(finished=True)

    def _write_line(self, finished: bool) -> None:
        now = self._clock()
        self._last_line = now
        elapsed = now - self._start
        rate = (self.done - self._initial) / elapsed if elapsed > 0 else 0.0  # this session's units only
        print(progress_line(self.desc, self.done, self.total, self.unit, rate, self.postfix,
                            finished_after_s=elapsed if finished else None), file=self._stream, flush=True)

    def __enter__(self) -> Progress:
        return self

    def __exit__(self, exc_type, exc, traceback) -> None:
        self.close(final_line=exc_type is None)


__all__ = ["Progress", "progress_line", "format_duration", "DEFAULT_INTERVAL_S"]
