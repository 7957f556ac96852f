"""The best held-out checkpoint of a run (`train.keep_best`), kept beside the latest ones.

A policy's score moves a lot from one checkpoint to the next (docs/learning.md: real-scene accuracy swung by
15-30 points 100k env steps apart), so the last checkpoint is a poor pick. After each evaluation on the held-out
split (never on the scenes the policy is finally judged on), the checkpoint with the best score so far is
written to RUN/best/ as a run directory of its own (config.json, checkpoints/<env steps>/ without the replay
buffer, best.json with its scores): `vmax-sim evaluate --policy RUN/best` evaluates it like any run. The score is
the SDC's V-Max score, or for a self-play run the share of agents that reach their goal cleanly (its objective: the
SDC among log replay is not what self-play trains).
"""

from __future__ import annotations

import json
import math
from pathlib import Path

from vmax_sim.training import distributed
from vmax_sim.training.checkpoint import CheckpointStore, write_policy_directory

BEST_DIR = "best"
RECORD_FILE = "best.json"
SDC_SCORE = "vmax_score"
SELFPLAY_SCORE = "selfplay/goal_reached_clean"  # agents reaching their goal with no collision, off-road, red light
SCORE_NAMES = {SDC_SCORE: "V-Max score", SELFPLAY_SCORE: "clean goal-reaching"}


def best_score(directory: Path, metric: str = SDC_SCORE) -> float:
    """The score `metric` recorded in a best-checkpoint directory, -inf when there is none (or it cannot be read)."""
    try:
        return float(json.loads((directory / RECORD_FILE).read_text())[metric])
    except (OSError, ValueError, KeyError, TypeError):
        return -math.inf


class BestCheckpoint:
    """Keeps RUN/best/ holding the checkpoint of the best held-out score (`metric`, a key of the evaluation
    summary) seen so far (resumed runs carry on from the recorded score)."""

    def __init__(self, run_dir: Path, metric: str = SDC_SCORE):
        self.run_dir = Path(run_dir)
        self.directory = self.run_dir / BEST_DIR
        self.metric = metric
        self.score = best_score(self.directory, metric)
        self._store: CheckpointStore | None = None  # opened at the first checkpoint kept

    @property
    def score_name(self) -> str:
        return SCORE_NAMES.get(self.metric, self.metric)

    def offer(self, env_steps: int, summary: dict, carry, host: dict) -> bool:
        """Writes `carry` (its replay buffer left out) when `summary`'s score beats the best so far. -> kept"""
        score = float(summary[self.metric])
        if not distributed.any_process([score > self.score])[0]:
            return False
        if self._store is None:
            self._store = CheckpointStore(self.directory / "checkpoints", keep=1)
        self._store.save(env_steps, carry.replace(buffer=None), host, with_buffer=False)
        record = {"env_steps": int(env_steps), "vmax_score": float(summary["vmax_score"]), self.metric: score,
                  "accuracy": float(summary["accuracy"]), "accuracy_at_fault": float(summary["accuracy_at_fault"])}
        write_policy_directory(self.run_dir, self.directory, RECORD_FILE, record)
        self.score = score
        return True


__all__ = ["BEST_DIR", "SDC_SCORE", "SELFPLAY_SCORE", "BestCheckpoint", "best_score"]
