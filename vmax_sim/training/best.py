"""The best held-out checkpoint of a run (`train.keep_best`), kept beside the latest ones.

A policy's score moves a lot from one checkpoint to the next (docs/learning.md: real-scene accuracy swung by
15-30 points 100k env steps apart), so the last checkpoint is a poor pick. After each evaluation on the held-out
split (never on the scenes the policy is finally judged on), the checkpoint with the best V-Max score so far is
written to RUN/best/ as a run directory of its own (config.json, checkpoints/<env steps>/ without the replay
buffer, best.json with its scores): `vmax-sim evaluate --policy RUN/best` evaluates it like any run.
"""

from __future__ import annotations

import json
import math
from pathlib import Path

from vmax_sim.training import distributed
from vmax_sim.training.checkpoint import CheckpointStore, write_policy_directory

BEST_DIR = "best"
RECORD_FILE = "best.json"


def best_score(directory: Path) -> float:
    """The V-Max score recorded in a best-checkpoint directory, -inf when there is none (or it cannot be read)."""
    try:
        return float(json.loads((directory / RECORD_FILE).read_text())["vmax_score"])
    except (OSError, ValueError, KeyError, TypeError):
        return -math.inf


class BestCheckpoint:
    """Keeps RUN/best/ holding the checkpoint of the best held-out V-Max score seen so far (resumed runs carry on
    from the recorded score)."""

    def __init__(self, run_dir: Path):
        self.run_dir = Path(run_dir)
        self.directory = self.run_dir / BEST_DIR
        self.score = best_score(self.directory)
        self._store: CheckpointStore | None = None  # opened at the first checkpoint kept

    def offer(self, env_steps: int, summary: dict, carry, host: dict) -> bool:
        """Writes `carry` (its replay buffer left out) when `summary`'s V-Max score beats the best so far. -> kept"""
        score = float(summary["vmax_score"])
        if not distributed.any_process([score > self.score])[0]:
            return False
        if self._store is None:
            self._store = CheckpointStore(self.directory / "checkpoints", keep=1)
        self._store.save(env_steps, carry.replace(buffer=None), host, with_buffer=False)
        record = {"env_steps": int(env_steps), "vmax_score": score, "accuracy": float(summary["accuracy"]),
                  "accuracy_at_fault": float(summary["accuracy_at_fault"])}
        write_policy_directory(self.run_dir, self.directory, RECORD_FILE, record)
        self.score = score
        return True


__all__ = ["BEST_DIR", "BestCheckpoint", "best_score"]
