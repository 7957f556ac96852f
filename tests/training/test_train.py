"""End-to-end training runs on tiny settings: every algorithm runs, logs, checkpoints, evaluates;
a stopped run resumes to the same curve; `vmax-sim train` / `evaluate --policy RUN_DIR` work."""

from __future__ import annotations

import csv
import json
import os
import shutil
import signal
import subprocess
import sys
import time
from pathlib import Path

import jax
import numpy as np
import pytest

from tests.training.conftest import tiny_config
from vmax_sim.training import train

TIMING_COLUMNS = {"sps", "wall_s", "peak_rss_mb", "data_wait_s"}


def rows(run_dir: Path) -> list[dict]:
    with (run_dir / "metrics.csv").open(newline="") as handle:
        return [{k: v for k, v in row.items() if k not in TIMING_COLUMNS} for row in csv.DictReader(handle)]


@pytest.fixture(scope="module")
def whole_run(synthetic_shards, tmp_path_factory):
    """An uninterrupted tiny SAC run of 120 env steps (6 chunks of 20; checkpoints at 40, 80, 120)."""
    config = tiny_config(synthetic_shards, "sac", "train.total_env_steps=120")
    run = tmp_path_factory.mktemp("whole") / "run"
    return config, run, train(config, run, progress=False, print_fn=lambda line: None)


@pytest.mark.slow  # ~90 s on 2 cores: CI runs it in the slow pass
def test_sac_run_writes_everything_a_researcher_opens(whole_run):
    config, run, result = whole_run
    assert result.env_steps == 120 and result.summary["finished"]
    assert (run / "config.json").exists() and (run / "learning_curve.png").stat().st_size > 10_000
    assert list((run / "tensorboard").glob("events.out.tfevents.*"))
    logged = rows(run)
    assert [float(r["env_steps"]) for r in logged] == [20.0, 40.0, 60.0, 80.0, 100.0, 120.0]
    assert "learner/critic_loss" in logged[0] and "episode/return" in logged[0]
    final = json.loads((run / "summary.json").read_text())["final_evaluation"]
    assert final["num_episodes"] == 4 and 0.0 <= final["vmax_score"] <= 1.0
    assert sorted(int(p.name) for p in (run / "checkpoints").iterdir() if p.name.isdigit()) == [80, 120]  # keep 2
    with pytest.raises(Exception, match="already holds a training run"):
        train(config, run, progress=False, print_fn=lambda line: None)


@pytest.mark.slow
@pytest.mark.parametrize("algo", ["ppo", "bc", "bc_sac"])
def test_every_algorithm_trains_and_evaluates(synthetic_shards, tmp_path, algo):
    extra = ["algo.unroll_length=4", "algo.num_minibatches=2", "algo.batch_size=4"] if algo == "ppo" else []
    config = tiny_config(synthetic_shards, algo, "train.total_env_steps=40", "train.chunk_steps=2", *extra)
    result = train(config, tmp_path / algo, progress=False, print_fn=lambda line: None)
    assert result.summary["finished"] and result.final_evaluation["num_episodes"] == 4
    losses = [k for k in rows(tmp_path / algo)[-1] if k.startswith("learner/")]
    assert losses and all(np.isfinite(float(rows(tmp_path / algo)[-1][k])) for k in losses)


@pytest.mark.slow  # ~90 s on 2 cores: CI runs it in the slow pass
def test_stopped_run_resumes_to_the_uninterrupted_curve(whole_run, tmp_path):
    config, whole_dir, _ = whole_run
    # stopped after 3 chunks (60 steps; the last checkpoint is at 40), then resumed
    train(config, tmp_path / "cut", progress=False, print_fn=lambda line: None, stop_after_chunks=3)
    assert len(rows(tmp_path / "cut")) == 3
    train(None, tmp_path / "cut", resume=True, progress=False, print_fn=lambda line: None)
    whole, resumed = rows(whole_dir), rows(tmp_path / "cut")
    assert [r["env_steps"] for r in resumed] == [r["env_steps"] for r in whole]
    for left, right in zip(whole, resumed):
        for key in left:
            np.testing.assert_allclose(float(left[key]), float(right[key]), rtol=1e-4, atol=1e-5, err_msg=key)


@pytest.mark.slow
def test_a_finished_run_extends_with_more_env_steps(whole_run, tmp_path):
    config, whole_dir, _ = whole_run
    extended = tmp_path / "extended"
    shutil.copytree(whole_dir, extended)
    result = train(None, extended, resume=True, progress=False, print_fn=lambda line: None,
                   resume_overrides=["train.total_env_steps=160"])
    assert result.env_steps == 160
    logged = rows(extended)
    assert [float(r["env_steps"]) for r in logged] == [20.0, 40.0, 60.0, 80.0, 100.0, 120.0, 140.0, 160.0]
    assert logged[:6] == rows(whole_dir)  # the first 120 steps untouched
    assert json.loads((extended / "config.json").read_text())["config"]["train"]["total_env_steps"] == 160


def test_resume_changes_only_the_run_length_and_its_schedule(synthetic_shards):
    from scenariomax.errors import InputError
    from vmax_sim.training.run import resumed_config

    saved = tiny_config(synthetic_shards, "sac", "train.total_env_steps=120")
    longer = resumed_config(saved, ["train.total_env_steps=3e6", "train.eval_every=1000"])
    assert (longer.train.total_env_steps, longer.train.eval_every) == (3_000_000, 1000)
    assert longer.algo_config == saved.algo_config
    with pytest.raises(InputError, match="only train.total_env_steps"):
        resumed_config(saved, ["algo.learning_rate=1e-3"])


def _cli(*args: str, env=None, **kwargs) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-m", "vmax_cli.vmax_cli", *args], capture_output=True, text=True,
                          env=env, **kwargs)


def _cli_overrides(shards: Path) -> list[str]:
    config_words = ["data.num_objects=16", "data.num_roadgraph_points=5000", "data.num_paths=4",
                    "data.max_num_lights=8", "algo_preset=debug", "network.embed_dim=16", "network.output_dim=32",
                    "network.mlp_hidden=32", "obs.num_objects=4", "obs.num_history=2", "obs.num_path_targets=4",
                    "train.chunk_steps=5", "train.pool_size=6", "train.pool_refresh=2", "train.eval_scenarios=4",
                    "train.eval_batch_size=4", "train.eval_every=0", "train.checkpoint_every=20"]
    return ["--data", str(shards), "--eval-data", str(shards), *config_words]


@pytest.mark.slow
def test_cli_train_then_evaluate_the_run(synthetic_shards, tmp_path):
    run = tmp_path / "cli-run"
    done = _cli("train", "--preset", "bc-mlp", "--out", str(run), "--quiet", *_cli_overrides(synthetic_shards),
                "train.total_env_steps=40")
    assert done.returncode == 0, done.stderr
    assert "trained 40 env steps" in done.stdout and "vmax_score" in done.stdout
    evaluated = _cli("evaluate", "--policy", str(run), "--data", str(synthetic_shards), "--num-scenarios", "4",
                     "--json")
    assert evaluated.returncode == 0, evaluated.stderr
    assert json.loads(evaluated.stdout)["num_episodes"] == 4
    # the same weights with PDM-Closed's emergency brake over them, and without it again: named for what drives
    guarded = _cli("evaluate", "--policy", str(run), "--data", str(synthetic_shards), "--num-scenarios", "4",
                   "--brake-guard", "2", "--json")
    assert guarded.returncode == 0, guarded.stderr
    assert json.loads(guarded.stdout)["policy"] == "bc-mlp+guard@cli-run"
    held = _cli("evaluate", "--policy", str(run), "--data", str(synthetic_shards), "--num-scenarios", "4",
                "--brake-guard", "2+hold", "--json")
    assert held.returncode == 0, held.stderr
    assert json.loads(held.stdout)["policy"] == "bc-mlp+guard@cli-run"
    plain = _cli("evaluate", "--policy", str(run), "--data", str(synthetic_shards), "--num-scenarios", "4",
                 "--brake-guard", "off", "--json")
    assert json.loads(plain.stdout)["policy"] == "bc-mlp@cli-run"
    bad = _cli("train", "--preset", "bc-mlp", "--out", str(tmp_path / "x"), "algo.learnin_rate=1")
    assert bad.returncode == 2 and bad.stderr.count("\n") == 1 and "learnin_rate" in bad.stderr
    missing = _cli("evaluate", "--policy", str(tmp_path / "nothing"))
    assert missing.returncode == 2 and "not a training run directory" in missing.stderr


@pytest.mark.slow
def test_data_parallel_over_two_cpu_devices(synthetic_shards, tmp_path):
    env = dict(os.environ, XLA_FLAGS="--xla_force_host_platform_device_count=2", JAX_PLATFORMS="cpu")
    done = _cli("train", "--preset", "sac-mlp", "--out", str(tmp_path / "dp"), "--quiet",
                *_cli_overrides(synthetic_shards), "train.total_env_steps=40", env=env)
    assert done.returncode == 0, done.stderr
    assert "data-parallel over 2 devices (2 envs each)" in done.stdout
    last = rows(tmp_path / "dp")[-1]
    assert np.isfinite(float(last["learner/critic_loss"]))


@pytest.mark.slow
def test_kill_9_then_resume_continues_the_curve(synthetic_shards, tmp_path):
    """A real kill -9 once the first checkpoint exists; --resume finishes the run and its curve equals
    an uninterrupted one."""
    run = tmp_path / "killed"
    args = ["train", "--preset", "sac-mlp", "--quiet", *_cli_overrides(synthetic_shards),
            "train.total_env_steps=400", "train.checkpoint_every=100", "train.keep_checkpoints=10"]
    process = subprocess.Popen([sys.executable, "-m", "vmax_cli.vmax_cli", *args, "--out", str(run)],
                               stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    deadline = time.time() + 300
    # Kill the moment the first checkpoint lands (keep_checkpoints=10: none is pruned while we look).
    while time.time() < deadline and not (run / "checkpoints" / "100").exists():
        time.sleep(0.2)
    os.kill(process.pid, signal.SIGKILL)
    process.wait()
    assert (run / "checkpoints" / "100").exists()
    assert not (run / "checkpoints" / "400").exists(), "the run finished before it could be killed"
    resumed = _cli("train", "--resume", str(run), "--quiet")
    assert resumed.returncode == 0, resumed.stderr
    whole = _cli(*args, "--out", str(tmp_path / "whole"))
    assert whole.returncode == 0, whole.stderr
    left, right = rows(tmp_path / "whole"), rows(run)
    assert [r["env_steps"] for r in left] == [r["env_steps"] for r in right]
    for a, b in zip(left, right):
        for key in a:
            np.testing.assert_allclose(float(a[key]), float(b[key]), rtol=1e-4, atol=1e-5, err_msg=key)


@pytest.mark.slow  # ~40 s on 2 cores
def test_a_run_that_sees_the_sdc_size_and_objects_along_its_route_trains_and_its_policy_loads_for_evaluation(
        synthetic_shards, tmp_path):
    from vmax_sim.training.run_policy import evaluate_run, load_trained_policy

    config = tiny_config(synthetic_shards, "bc", "obs.sdc_size=true", "obs.object_route_frame=true",
                         "train.total_env_steps=40", "train.chunk_steps=2")
    train(config, tmp_path / "sized", progress=False, print_fn=lambda line: None)
    loaded = load_trained_policy(tmp_path / "sized")
    assert loaded.config.obs.sdc_size and loaded.config.obs.object_route_frame
    kernels = [leaf.shape for leaf in jax.tree.leaves(loaded.params) if getattr(leaf, "ndim", 0) == 2]
    assert (2 * 9, 16) in kernels  # the SDC token: 2 steps of 6 + 2 size columns + a mask, into embed_dim 16
    assert (2 * 15, 16) in kernels  # an object token: 2 steps of 12 + 2 route columns + a mask
    evaluated = evaluate_run(tmp_path / "sized", str(synthetic_shards), num_scenarios=4, batch_size=4)
    assert evaluated.summary["num_episodes"] == 4
