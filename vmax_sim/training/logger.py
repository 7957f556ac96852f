"""Scalars of a run: one CSV row per log step (every key ever logged is a column) and TensorBoard events.

The CSV is rewritten whole when a new key appears (rare) and appended to otherwise; `truncate_after`
drops the rows a resumed run is about to log again, so the file equals an uninterrupted run's.
TensorBoard event files come from tensorboardX when it is installed (a warning otherwise).
"""

from __future__ import annotations

import csv
import math
import warnings
from pathlib import Path

STEP_KEY = "env_steps"


class RunLogger:
    """`write=False` keeps the rows in memory only (the processes of a multi-process run other than process 0)."""

    def __init__(self, run_dir: Path, tensorboard: bool = True, file_name: str = "metrics.csv", write: bool = True):
        self.path = Path(run_dir) / file_name
        self.write = write
        self.rows: list[dict[str, float]] = self._read() if write else []
        self.columns: list[str] = list(self.rows[0].keys()) if self.rows else [STEP_KEY]
        for row in self.rows:
            self.columns += [k for k in row if k not in self.columns]
        self._writer = None
        self._events: _QuietEvents | None = None
        if tensorboard and write:
            try:
                from tensorboardX import SummaryWriter
            except ImportError:
                warnings.warn("tensorboardX is not installed: no TensorBoard event files (the CSV is written)",
                              stacklevel=2)
            else:
                self._writer = SummaryWriter(str(Path(run_dir) / "tensorboard"))
                self._events = _guard_events(self._writer)

    def _read(self) -> list[dict[str, float]]:
        if not self.path.exists():
            return []
        with self.path.open(newline="") as handle:
            return [{k: float(v) for k, v in row.items() if v not in ("", None)} for row in csv.DictReader(handle)]

    def truncate_after(self, env_steps: int) -> None:
        """Keeps only the rows logged at or before `env_steps` (resume from a checkpoint)."""
        self.rows = [row for row in self.rows if row.get(STEP_KEY, 0) <= env_steps]
        self._rewrite()

    def log(self, env_steps: int, scalars: dict[str, float]) -> None:
        self._raise_writer_error()
        row = {STEP_KEY: float(env_steps)}
        row.update({k: float(v) for k, v in scalars.items()})
        self.rows.append(row)
        new = [k for k in row if k not in self.columns]
        if not self.write:
            self.columns += new
        elif new or not self.path.exists():  # a new column, or the first row (after a truncation to nothing too)
            self.columns += new
            self._rewrite()
        else:
            with self.path.open("a", newline="") as handle:
                csv.DictWriter(handle, self.columns).writerow(_formatted(row))
        if self._writer is not None:
            for key, value in row.items():
                if key != STEP_KEY and math.isfinite(value):
                    self._writer.add_scalar(key, value, env_steps)

    def _rewrite(self) -> None:
        if not self.write:
            return
        if not self.rows:
            self.path.unlink(missing_ok=True)
            return
        temporary = self.path.with_suffix(".csv.tmp")
        with temporary.open("w", newline="") as handle:
            writer = csv.DictWriter(handle, self.columns)
            writer.writeheader()
            writer.writerows(_formatted(row) for row in self.rows)
        temporary.replace(self.path)

    def _raise_writer_error(self) -> None:
        """The OS error the event writer met (a full disk), raised here once; `flush`, which also runs while
        another error is on its way out, never raises it."""
        if self._events is not None and self._events.error is not None:
            error, self._events.error = self._events.error, None
            raise error

    def flush(self) -> None:
        if self._writer is not None:
            self._writer.flush()

    def close(self) -> None:
        if self._writer is not None:
            self._writer.close()
        self._raise_writer_error()


class _QuietEvents:
    """tensorboardX's events file behind a guard: its writer thread (and its exit hook) would print a traceback
    on an OS error such as a full disk; the first error is kept for `RunLogger` to raise and later events dropped."""

    def __init__(self, inner, folder: Path):
        self._inner, self._folder, self.error, self.failed = inner, folder, None, False

    def _call(self, name: str, *args):
        if self.failed:
            return None
        try:
            return getattr(self._inner, name)(*args)
        except OSError as error:
            self.failed = True
            self.error = error if error.filename else OSError(error.errno, error.strerror, str(self._folder))
            return None

    def write_event(self, event) -> None:
        self._call("write_event", event)

    def flush(self) -> None:
        self._call("flush")

    def close(self) -> None:
        self._call("close")


def _guard_events(writer) -> _QuietEvents | None:
    """Puts `_QuietEvents` between tensorboardX's writer (its thread included) and its events file; None (no
    guard) when this tensorboardX is laid out otherwise."""
    file_writer = writer._get_file_writer()
    events = getattr(getattr(file_writer, "event_writer", None), "_ev_writer", None)
    worker = getattr(file_writer.event_writer, "_worker", None) if events is not None else None
    if events is None or not hasattr(worker, "_record_writer"):
        return None
    guard = _QuietEvents(events, Path(writer.logdir))
    file_writer.event_writer._ev_writer = guard
    worker._record_writer = guard
    return guard


def _formatted(row: dict[str, float]) -> dict[str, str]:
    return {k: repr(v) for k, v in row.items()}
