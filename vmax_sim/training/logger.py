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
    def __init__(self, run_dir: Path, tensorboard: bool = True, file_name: str = "metrics.csv"):
        self.path = Path(run_dir) / file_name
        self.rows: list[dict[str, float]] = self._read()
        self.columns: list[str] = list(self.rows[0].keys()) if self.rows else [STEP_KEY]
        for row in self.rows:
            self.columns += [k for k in row if k not in self.columns]
        self._writer = None
        if tensorboard:
            try:
                from tensorboardX import SummaryWriter
            except ImportError:
                warnings.warn("tensorboardX is not installed: no TensorBoard event files (the CSV is written)",
                              stacklevel=2)
            else:
                self._writer = SummaryWriter(str(Path(run_dir) / "tensorboard"))

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
        row = {STEP_KEY: float(env_steps)}
        row.update({k: float(v) for k, v in scalars.items()})
        self.rows.append(row)
        new = [k for k in row if k not in self.columns]
        if new or not self.path.exists():  # a new column, or the first row (after a truncation to nothing too)
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
        if not self.rows:
            self.path.unlink(missing_ok=True)
            return
        temporary = self.path.with_suffix(".csv.tmp")
        with temporary.open("w", newline="") as handle:
            writer = csv.DictWriter(handle, self.columns)
            writer.writeheader()
            writer.writerows(_formatted(row) for row in self.rows)
        temporary.replace(self.path)

    def flush(self) -> None:
        if self._writer is not None:
            self._writer.flush()

    def close(self) -> None:
        if self._writer is not None:
            self._writer.close()


def _formatted(row: dict[str, float]) -> dict[str, str]:
    return {k: repr(v) for k, v in row.items()}
