"""How a run ends (wall-clock budget, Ctrl-C / SIGTERM) and what it trains on (weighted data mixtures)."""

from __future__ import annotations

import csv
import itertools
import json
import math
import os
import signal
import subprocess
import sys
import time
from collections import Counter
from pathlib import Path

import pytest

from scenariomax.errors import InputError
from tests.training.conftest import NUM_OBJECTS, tiny_config
from vmax_sim.data import DataConfig
from vmax_sim.data.mixture import parse_sources, source_probabilities
from vmax_sim.training import train
from vmax_sim.training.logger import RunLogger
from vmax_sim.training.pool import stream_items
from vmax_sim.training.run import LastEpisodes, planned_env_steps


def _quiet(line: str) -> None:
    pass


@pytest.mark.slow  # a training run and its final evaluation (~30 s on 2 cores)
def test_the_wall_clock_budget_stops_with_a_final_checkpoint_and_evaluation(synthetic_shards, tmp_path):
    # a budget of 0.06 s: the run stops after its first chunk, far short of its 100,000 env steps
    config = tiny_config(synthetic_shards, "bc", "train.total_env_steps=100000", "train.max_wall_minutes=0.001")
    result = train(config, tmp_path / "run", progress=False, print_fn=_quiet)
    assert result.stopped == "max_wall_minutes" and 0 < result.env_steps < 100_000
    assert (tmp_path / "run" / "checkpoints" / str(result.env_steps)).is_dir()
    summary = json.loads((tmp_path / "run" / "summary.json").read_text())
    assert summary["stopped"] == "max_wall_minutes" and summary["final_evaluation"]["num_episodes"] == 4
    with (tmp_path / "run" / "eval.csv").open(newline="") as handle:
        assert [float(row["env_steps"]) for row in csv.DictReader(handle)] == [result.env_steps]
    assert (tmp_path / "run" / "learning_curve.png").exists()


def test_the_learning_rate_falls_with_the_run_by_steps_or_by_the_clock():
    """BC's `algo.lr_end_fraction`: the loop sets the share from the run's progress, the larger of its step share
    and its wall-clock share; a run with a constant rate is left as it is."""
    import jax.numpy as jnp

    from vmax_sim.agents.bc.learner import BCTrainState, ScheduledBCTrainState
    from vmax_sim.training.loop import TrainCarry
    from vmax_sim.training.run import run_progress, with_learning_rate_share

    def carry_of(learner) -> TrainCarry:  # the loop reads only the learner of its carry
        return TrainCarry(learner=learner, env=None, buffer=None, key=None, env_steps=jnp.int32(0))

    config = tiny_config(Path("shards"), "bc", "train.total_env_steps=1000", "train.max_wall_minutes=10",
                         "algo.lr_end_fraction=0.2", "algo.lr_decay_start=0.5")
    assert run_progress(config, 250, 0.0) == 0.25 and run_progress(config, 250, 450.0) == 0.75
    carry = carry_of(ScheduledBCTrainState(policy_params={}, opt_state=(), step=jnp.int32(0),
                                           lr_scale=jnp.float32(1.0)))

    def share(steps: int, wall_s: float) -> float:
        return float(with_learning_rate_share(carry, config, steps, wall_s).learner.lr_scale)

    assert share(400, 0.0) == 1.0  # before the decay starts
    assert share(750, 0.0) == pytest.approx(0.6) and share(100, 450.0) == pytest.approx(0.6)  # halfway down
    assert share(1000, 0.0) == pytest.approx(0.2) and share(0, 900.0) == pytest.approx(0.2)
    constant = carry_of(BCTrainState(policy_params={}, opt_state=(), step=jnp.int32(0)))
    assert with_learning_rate_share(constant, config, 1000, 900.0) is constant


def test_whole_chunks_round_the_planned_steps_up():
    assert planned_env_steps(4000, 1280) == 5120 and planned_env_steps(5120, 1280) == 5120


def test_the_progress_line_keeps_the_last_finished_episodes():
    last = LastEpisodes()
    assert last.postfix() == {"return": "-", "acc": "-"}
    last.update({"episodes": 2.0, "episode/return": 15.6, "episode/accuracy": 1.0})
    last.update({"episodes": 0.0, "episode/return": math.nan, "episode/accuracy": math.nan})  # none finished
    assert last.postfix() == {"return": "15.60", "acc": "1.00"}


def test_a_log_truncated_to_nothing_writes_its_header_again(tmp_path):
    logger = RunLogger(tmp_path, tensorboard=False)
    logger.log(10, {"loss": 1.0})
    logger.truncate_after(0)  # --resume before the first checkpoint
    logger.log(10, {"loss": 2.0})
    with (tmp_path / "metrics.csv").open(newline="") as handle:
        assert list(csv.DictReader(handle)) == [{"env_steps": "10.0", "loss": "2.0"}]


# ----------------------------------------------------------------------------- mixtures


@pytest.fixture(scope="module")
def second_shards(tmp_path_factory) -> Path:
    """4 synthetic scenarios of another seed (their ids differ from synthetic_shards')."""
    from scenariomax import ConvertSettings, Sizes, SyntheticSource, convert, make_transform

    out = tmp_path_factory.mktemp("second") / "shards"
    sizes = Sizes(num_objects=NUM_OBJECTS)
    transform, transform_settings = make_transform()
    convert(SyntheticSource(num_scenarios=4, seed=9, sizes=sizes),
            ConvertSettings(out=out, workers=1, sizes=sizes, progress=False, transform=transform,
                            transform_settings=transform_settings))
    return out


def _draw_ids(spec: str, count: int, seed: int = 0) -> list[str]:
    config = DataConfig(path=spec, num_objects=NUM_OBJECTS, shuffle_seed=seed, repeat=True, prefetch=0,
                        map_index_cache=False)
    return [scenario.scenario_id for scenario, _ in itertools.islice(stream_items(config), count)]


@pytest.mark.slow  # ~13 s on 2 cores: kept out of the 10-minute default suite
def test_a_weighted_mixture_draws_its_sources_in_proportion(synthetic_shards, second_shards):
    draws = 600
    ids = _draw_ids(f"{synthetic_shards}:3,{second_shards}:1", draws)
    share = Counter(i.split("-")[1] for i in ids)["9"] / draws  # synthetic-<seed>-<index>
    assert abs(share - 0.25) < 3 * math.sqrt(0.25 * 0.75 / draws), share  # within 3 standard errors
    assert ids == _draw_ids(f"{synthetic_shards}:3,{second_shards}:1", draws)  # seeded: a resume replays it
    assert ids != _draw_ids(f"{synthetic_shards}:3,{second_shards}:1", draws, seed=1)


def test_mixture_specs_parse_and_refuse_bad_weights():
    sources = parse_sources("synthetic:0.7, shards/womd:0.3,more")
    assert [s.path for s in sources] == ["synthetic", "shards/womd", "more"]
    assert list(source_probabilities(sources)) == pytest.approx([0.35, 0.15, 0.5])
    with pytest.raises(InputError, match="weight must be a positive number"):
        parse_sources("a:0,b:1")


@pytest.mark.slow  # a training run and its final evaluation (~25 s on 2 cores)
def test_a_mixture_trains(synthetic_shards, second_shards, tmp_path):
    config = tiny_config(synthetic_shards, "bc", f"data.train={synthetic_shards}:1,{second_shards}:1",
                         "train.total_env_steps=20", "train.eval_every=0")
    result = train(config, tmp_path / "mixed", progress=False, print_fn=_quiet)
    assert result.summary["finished"]


def test_a_missing_mixture_source_is_named_before_anything_runs(synthetic_shards, tmp_path):
    missing = tiny_config(synthetic_shards, "bc", f"data.train={synthetic_shards}:1,{tmp_path / 'nope'}:1")
    with pytest.raises(InputError, match="nope"):
        train(missing, tmp_path / "missing", progress=False, print_fn=_quiet)


# ----------------------------------------------------------------------------- Ctrl-C


@pytest.mark.slow  # a CLI training run in a subprocess (~40 s on 2 cores)
@pytest.mark.parametrize("signum", [signal.SIGINT, signal.SIGTERM])
def test_an_interrupt_saves_a_checkpoint_at_the_current_step(synthetic_shards, tmp_path, signum):
    from tests.training.test_train import _cli_overrides

    run = tmp_path / "run"
    args = [sys.executable, "-m", "vmax_cli.vmax_cli", "train", "--preset", "bc-mlp", "--out", str(run), "--quiet",
            *_cli_overrides(synthetic_shards), "train.total_env_steps=10000000", "train.checkpoint_every=10000000"]
    process = subprocess.Popen(args, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    deadline = time.time() + 240
    while time.time() < deadline and not _logged_steps(run):  # training under way
        time.sleep(0.2)
    time.sleep(1.0)
    os.kill(process.pid, signum)
    stdout, stderr = process.communicate(timeout=60)
    assert process.returncode == 130, stderr
    steps = _logged_steps(run)[-1]
    assert (run / "checkpoints" / str(steps)).is_dir()  # everything logged is in the checkpoint
    assert f"continue with: vmax-sim train --resume {run}" in stdout
    assert "Traceback" not in stderr


def _logged_steps(run: Path) -> list[int]:
    try:
        with (run / "metrics.csv").open(newline="") as handle:
            return [int(float(row["env_steps"])) for row in csv.DictReader(handle)]
    except (OSError, KeyError, ValueError):
        return []


def test_a_run_directory_in_use_is_refused_in_one_line(synthetic_shards, tmp_path):
    hold = ("import sys, time; from scenariomax.locks import FolderLock\n"
            "with FolderLock(sys.argv[1], 'training run'):\n    print('held', flush=True); time.sleep(60)")
    holder = subprocess.Popen([sys.executable, "-c", hold, str(tmp_path / "run")], stdout=subprocess.PIPE, text=True)
    try:
        assert holder.stdout.readline().strip() == "held"
        config = tiny_config(synthetic_shards, "bc", "train.total_env_steps=20")
        with pytest.raises(InputError, match=rf"in use by another training run \(pid {holder.pid}\)"):
            train(config, tmp_path / "run", progress=False, print_fn=_quiet)
        assert not (tmp_path / "run" / "config.json").exists()  # nothing written
    finally:
        holder.kill()
        holder.wait()
