"""Training over several processes (`jax.distributed`): the settings, the scenario stream's shares, the replay's
per-block checkpoint files, and two local CPU processes training and resuming one run to the curve of one
process with the same two devices."""

from __future__ import annotations

import csv
import os
import signal
import socket
import subprocess
import sys
import threading
import time
from pathlib import Path

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from scenariomax.errors import InputError
from tests.training.conftest import tiny_config
from vmax_sim.training.distributed import distributed_settings
from vmax_sim.training.pool import ScenarioStream, StreamShare, interleave, own_count, share_order

# --------------------------------------------------------------------------------------------- settings


def test_settings_from_flags_then_environment_and_one_process_is_none():
    assert distributed_settings(environ={}) is None
    flags = distributed_settings("10.0.0.1:1234", 4, 2, environ={})
    assert (flags.coordinator, flags.num_processes, flags.process_id) == ("10.0.0.1:1234", 4, 2)
    environ = {"JAX_COORDINATOR_ADDRESS": "node1:999", "JAX_NUM_PROCESSES": "2", "JAX_PROCESS_ID": "1"}
    from_env = distributed_settings(environ=environ)
    assert (from_env.coordinator, from_env.num_processes, from_env.process_id) == ("node1:999", 2, 1)
    assert distributed_settings(process_id=0, environ=environ).process_id == 0  # a flag wins over its variable
    assert distributed_settings("h:1", 1, 0, environ={}) is None  # one process: nothing to join
    detected = distributed_settings(detect=True, environ={})  # srun / mpirun fill in the rest
    assert (detected.coordinator, detected.num_processes, detected.process_id) == (None, None, None)


@pytest.mark.parametrize("args, message", [
    (("h:1", 2, None), "--process-id"),
    ((None, 2, 0), "--coordinator"),
    (("h:1", 2, 2), r"--process-id must be in \[0, 2\)"),
    (("nohost", 2, 0), "HOST:PORT"),
])
def test_incomplete_or_wrong_settings_are_one_line_errors(args, message):
    with pytest.raises(InputError, match=message):
        distributed_settings(*args, environ={})


def test_processes_split_the_shard_check_by_file(tmp_path):
    import scenariomax
    from tests.conftest import straight_road_scenario
    from vmax_sim.data.precheck import check_shards

    sizes = scenariomax.Sizes(num_objects=4, num_roadgraph=400)
    for name, count in (("a", 2), ("b", 3)):
        scenarios = (scenariomax.fit_to_budget(straight_road_scenario(f"{name}{i}"), sizes) for i in range(count))
        scenariomax.write_shards(scenarios, tmp_path / name, sizes)
    paths = [str(tmp_path / "a"), str(tmp_path / "b")]
    assert [check_shards(paths, progress=False, share=(p, 2)) for p in range(2)] == [2, 3]


# --------------------------------------------------------------------------------------------- stream shares


@pytest.mark.parametrize("num", [2, 3])
@pytest.mark.parametrize("first", [0, 1, 5])
@pytest.mark.parametrize("count", [1, 4, 7])
def test_shares_interleave_back_into_stream_order(num, first, count):
    stream = np.arange(first, first + count)
    shares = [stream[stream % num == p] for p in range(num)]
    assert [len(share) for share in shares] == [own_count(first, count, StreamShare(p, num)) for p in range(num)]
    width = -(-count // num)
    padded = np.stack([np.pad(share, (0, width - len(share)), constant_values=-1) for share in shares])
    np.testing.assert_array_equal(interleave({"n": padded}, first, count, num)["n"], stream)
    process, _ = share_order(first, count, num)
    np.testing.assert_array_equal(process, stream % num)


class _ThreadExchange:
    """Processes played by threads: each hands in its share and gets everyone's back (as process_allgather)."""

    def __init__(self, num: int):
        self.num, self.parts, self.barrier = num, {}, threading.Barrier(num)

    def of(self, index: int):
        def exchange(tree):
            self.parts[index] = tree
            self.barrier.wait()
            out = jax.tree.map(lambda *leaves: np.stack(leaves), *[self.parts[p] for p in range(self.num)])
            self.barrier.wait()
            return out
        return exchange


def test_streams_sharing_the_scenarios_return_the_whole_streams_takes(synthetic_shards):
    """Two processes each convert every other scenario; after the exchange both hold what one process reading the
    whole stream takes (uneven takes padded), and neither converted the other's."""
    from vmax_sim.training.run import train_data_config

    config = train_data_config(tiny_config(synthetic_shards), str(synthetic_shards), seed=3)
    takes = [4, 3, 1]
    whole = ScenarioStream(config, start=1)
    expected = [whole.take(count) for count in takes]
    whole.close()
    exchange = _ThreadExchange(2)
    streams = [ScenarioStream(config, start=1, share=StreamShare(p, 2, exchange.of(p))) for p in range(2)]
    results: dict[int, list] = {}

    def run(p):
        results[p] = [streams[p].take(count) for count in takes]

    threads = [threading.Thread(target=run, args=(p,)) for p in range(2)]
    for thread in threads:
        thread.start()
    for thread in threads:
        thread.join(timeout=120)
    for stream in streams:
        stream.close()
    for p in range(2):
        assert streams[p].consumed == 1 + sum(takes)
        for got, want in zip(results[p], expected):
            jax.tree.map(np.testing.assert_array_equal, got, want)


def test_a_process_left_nothing_by_the_first_take_says_the_pool_is_too_small(synthetic_shards):
    from vmax_sim.training.run import train_data_config

    config = train_data_config(tiny_config(synthetic_shards), str(synthetic_shards), seed=3)
    stream = ScenarioStream(config, share=StreamShare(1, 2, lambda tree: tree))
    with pytest.raises(ValueError, match="pool_size must be at least the process count"):
        stream.take(1)
    stream.close()


# --------------------------------------------------------------------------------------------- checkpoint blocks


def test_replay_written_per_block_restores_under_one_process_or_several(tmp_path):
    from vmax_sim.training import checkpoint

    leaves = [jnp.arange(2 * 5 * 3, dtype=jnp.float16).reshape(2, 5, 3), jnp.asarray([7, 9], jnp.int32),
              jnp.asarray(11, jnp.int32)]
    for index, leaf in enumerate(leaves[:2]):
        checkpoint._write_own_blocks(tmp_path, index, leaf)  # one process holding every block: b0 and b1
    checkpoint._write_leaf(tmp_path / "2.npy", leaves[2])  # replicated scalars: one whole file
    assert sorted(p.name for p in tmp_path.iterdir()) == ["0.b0.npy", "0.b1.npy", "1.b0.npy", "1.b1.npy", "2.npy"]
    for index, leaf in enumerate(leaves):
        one = checkpoint._read_leaf(tmp_path, index, jnp.zeros_like(leaf))
        several = checkpoint._read_own_blocks(tmp_path, index, jnp.zeros_like(leaf))
        np.testing.assert_array_equal(one, leaf)
        np.testing.assert_array_equal(several, leaf)
    with pytest.raises(InputError, match="replay buffer of shape"):
        checkpoint._read_leaf(tmp_path, 0, jnp.zeros((2, 4, 3), jnp.float16))


# --------------------------------------------------------------------------------------------- two processes

TIMING_COLUMNS = {"sps", "wall_s", "peak_rss_mb", "data_wait_s"}
# learning from step 20 with 8-transition batches: every chunk of 20 env steps updates the learner
LEARNS_EARLY = ["algo.learning_starts=20", "algo.batch_size=8"]


def _rows(path: Path) -> list[dict]:
    with path.open(newline="") as handle:
        return [{k: v for k, v in row.items() if k not in TIMING_COLUMNS} for row in csv.DictReader(handle)]


def _free_port() -> int:
    with socket.socket() as probe:
        probe.bind(("127.0.0.1", 0))
        return probe.getsockname()[1]


def _train_args(shards: Path) -> list[str]:
    from tests.training.test_train import _cli_overrides

    return ["train", "--preset", "sac-mlp", "--quiet", *_cli_overrides(shards), *LEARNS_EARLY]


def _launch(args: list[str], env: dict, processes: int = 1) -> list[subprocess.Popen]:
    """`processes` local processes of `vmax-sim ARGS` joined by jax.distributed (one: a plain process)."""
    command = [sys.executable, "-m", "vmax_cli.vmax_cli", *args]
    if processes == 1:
        return [subprocess.Popen(command, env=env, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)]
    port = _free_port()
    return [subprocess.Popen([*command, "--coordinator", f"127.0.0.1:{port}", "--num-processes", str(processes),
                              "--process-id", str(index)], env=env, stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                             text=True) for index in range(processes)]


def _finish(launched: list[subprocess.Popen], returncode: int = 0) -> list[str]:
    outputs = [process.communicate(timeout=600) for process in launched]
    for process, (out, err) in zip(launched, outputs):
        assert process.returncode == returncode, out + err
    return [out for out, _ in outputs]


def _assert_same_rows(left: list[dict], right: list[dict]) -> None:
    assert [r["env_steps"] for r in left] == [r["env_steps"] for r in right]
    for a, b in zip(left, right):
        for key in a:
            np.testing.assert_allclose(float(a[key]), float(b[key]), rtol=1e-5, atol=1e-6, err_msg=key)


@pytest.mark.slow  # three launches of tiny SAC runs: ~3 min of 2 quiet cores' time (5.5 min beside other jobs)
def test_two_processes_train_and_resume_to_the_curve_of_one_process_with_two_devices(synthetic_shards, tmp_path):
    """One process with two CPU devices vs two processes with one each (same global batch, same mesh): every
    process converts half of the scenarios and the stream exchange rebuilds the same pool, so the curves match.
    A SIGINT to process 1 alone stops both after the same chunk with a checkpoint; `--resume` finishes the run
    (the replay restored from per-block files)."""
    # the resumed processes reuse the first ones' compilations
    cache = {"JAX_COMPILATION_CACHE_DIR": str(tmp_path / "jax-cache"),
             "JAX_PERSISTENT_CACHE_MIN_COMPILE_TIME_SECS": "0"}
    env = {**os.environ, "JAX_PLATFORMS": "cpu", **cache}
    env.pop("XLA_FLAGS", None)
    args = [*_train_args(synthetic_shards), "train.total_env_steps=80"]
    one, two = tmp_path / "one-process", tmp_path / "two-processes"
    reference = _launch([*args, "--out", str(one)], {**env, "XLA_FLAGS": "--xla_force_host_platform_device_count=2"})
    first = _launch([*args, "--out", str(two)], env, processes=2)
    deadline = time.time() + 600
    while time.time() < deadline and not (two / "checkpoints" / "20").exists() and first[1].poll() is None:
        time.sleep(0.2)
    first[1].send_signal(signal.SIGINT)  # the stop loop is running once the first checkpoint is there
    outputs = _finish(first, returncode=130)
    assert "data-parallel over 2 devices of 2 processes (2 envs each)" in outputs[0]
    assert "a stop request: checkpoint saved" in outputs[0] and "trained" not in outputs[1]  # process 0 reports
    stopped = int(float(_rows(two / "metrics.csv")[-1]["env_steps"]))
    assert 20 < stopped < 80 and (two / "checkpoints" / str(stopped)).exists()  # both stopped after one chunk
    replay = sorted(p.name for p in (two / "checkpoints" / str(stopped) / "replay").iterdir())
    assert "0.b0.npy" in replay and "0.b1.npy" in replay  # each process wrote its own block
    outputs = _finish(_launch(["train", "--resume", str(two), "--quiet"], env, processes=2))
    assert f"resumed {two} at {stopped} env steps" in outputs[0] and "trained 80 env steps" in outputs[0]
    _finish(reference)
    assert [float(r["env_steps"]) for r in _rows(two / "metrics.csv")] == [20.0, 40.0, 60.0, 80.0]
    assert float(_rows(two / "metrics.csv")[0]["learner/critic_loss"]) != 0.0  # the learner learnt from chunk one
    _assert_same_rows(_rows(one / "metrics.csv"), _rows(two / "metrics.csv"))
    _assert_same_rows(_rows(one / "eval.csv"), _rows(two / "eval.csv"))


@pytest.mark.slow  # two launches of a tiny self-play run: ~2 min of 2 quiet cores' time
def test_selfplay_trains_over_two_processes_to_the_curve_of_one_process_with_two_devices(synthetic_shards, tmp_path):
    """`ppo-selfplay` data-parallel: the agent rows of each process's scenes, per-agent GAE and masks, give the same
    learning curve and evaluations (self-play goals included) as one process with two devices."""
    env = {**os.environ, "JAX_PLATFORMS": "cpu"}
    env.pop("XLA_FLAGS", None)
    from tests.training.test_train import _cli_overrides

    args = ["train", "--preset", "ppo-selfplay", "--quiet", *_cli_overrides(synthetic_shards), "selfplay.max_agents=4",
            "algo.num_envs=4", "algo.unroll_length=4", "algo.num_minibatches=2", "algo.batch_size=4",
            "train.chunk_steps=1", "train.total_env_steps=32", "train.checkpoint_every=16"]
    one, two = tmp_path / "one-process", tmp_path / "two-processes"
    reference = _launch([*args, "--out", str(one)], {**env, "XLA_FLAGS": "--xla_force_host_platform_device_count=2"})
    outputs = _finish(_launch([*args, "--out", str(two)], env, processes=2))
    assert "data-parallel over 2 devices of 2 processes" in outputs[0]
    _finish(reference)
    rows = _rows(two / "metrics.csv")
    assert rows and float(rows[-1]["agent_steps"]) > float(rows[-1]["env_steps"])  # several agents per scene
    _assert_same_rows(_rows(one / "metrics.csv"), rows)
    evaluation = _rows(two / "eval.csv")
    assert "selfplay/goal_reached" in evaluation[0]
    _assert_same_rows(_rows(one / "eval.csv"), evaluation)
