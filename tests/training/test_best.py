"""train.keep_best: RUN/best holds the checkpoint of the best held-out score (V-Max; self-play: clean goal-reaching),
evaluable as a run."""

from __future__ import annotations

import csv
import json

import pytest

from tests.training.conftest import tiny_config
from vmax_sim.training import train
from vmax_sim.training.best import SELFPLAY_SCORE, BestCheckpoint
from vmax_sim.training.run_policy import evaluate_run


@pytest.mark.slow  # ~60 s on 2 cores (a tiny BC run and two evaluations): the default suite stays under 10 minutes
def test_the_best_evaluated_checkpoint_is_kept_and_evaluates_to_its_recorded_score(synthetic_shards, tmp_path):
    config = tiny_config(synthetic_shards, "bc", "train.total_env_steps=80", "train.chunk_steps=2",
                         "train.eval_every=16", "algo.learning_rate=0.01")
    run = tmp_path / "run"
    train(config, run, progress=False, print_fn=lambda line: None)
    with (run / "eval.csv").open(newline="") as handle:
        evaluations = [(int(float(row["env_steps"])), float(row["vmax_score"])) for row in csv.DictReader(handle)]
    assert len(evaluations) >= 3
    best_steps, best_score = max(evaluations, key=lambda row: row[1])  # the first of equal scores stays
    best_steps = next(steps for steps, score in evaluations if score == best_score)
    record = json.loads((run / "best" / "best.json").read_text())
    assert record["env_steps"] == best_steps and record["vmax_score"] == pytest.approx(best_score)
    assert [p.name for p in (run / "best" / "checkpoints").iterdir() if p.name.isdigit()] == [str(best_steps)]
    assert not (run / "best" / "checkpoints" / str(best_steps) / "replay").exists()  # the policy, not the buffer
    # a run directory of its own: evaluated alone, it scores what the run recorded
    again = evaluate_run(run / "best", num_scenarios=config.train.eval_scenarios,
                         batch_size=config.train.eval_batch_size)
    assert again.summary["vmax_score"] == pytest.approx(best_score, abs=1e-5)
    # a resumed run carries on from the recorded score: an equal or lower one is not kept
    kept = BestCheckpoint(run)
    assert kept.score == pytest.approx(best_score)
    assert not kept.offer(999, {"vmax_score": best_score, "accuracy": 0.0, "accuracy_at_fault": 0.0}, None, {})


def test_a_selfplay_run_keeps_its_best_goal_reaching_not_the_sdc_score(tmp_path):
    best = tmp_path / "run" / "best"
    best.mkdir(parents=True)
    (best / "best.json").write_text(json.dumps({"env_steps": 50, "vmax_score": 0.7, SELFPLAY_SCORE: 0.8}))
    kept = BestCheckpoint(tmp_path / "run", SELFPLAY_SCORE)
    assert kept.score == pytest.approx(0.8) and kept.score_name == "clean goal-reaching"
    # a better SDC among log replay with fewer agents at their goals is not self-play's better checkpoint
    assert not kept.offer(90, {"vmax_score": 0.95, SELFPLAY_SCORE: 0.74, "accuracy": 1.0, "accuracy_at_fault": 1.0},
                          None, {})
