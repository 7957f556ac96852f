"""Closed-loop evaluation on hand-made straight-road scenarios: expert, constant policy, batching, traces."""

from __future__ import annotations

import json

import chex
import jax
import jax.numpy as jnp
import numpy as np
import pytest

from scenariomax.errors import InputError
from tests.integration_sim.conftest import braking_scenario, cruising_scenario, small_data_config
from vmax_sim.data import scenarios_to_batch
from vmax_sim.env import EnvConfig, make_environment
from vmax_sim.evaluation import evaluate, make_policy, make_rollout_fn, run_episode
from vmax_sim.metrics import MetricsConfig
from vmax_sim.observation import ObservationConfig


def test_expert_is_accurate_on_the_straight_road(road_shards):
    result = evaluate("expert", small_data_config(road_shards))
    summary = result.summary
    assert result.scenario_ids == ("cruise", "brake", "cruise-slow")
    assert summary["num_episodes"] == 3
    assert summary["accuracy"] == 1.0 and summary["accuracy_at_fault"] == 1.0
    # the expert replays its own log: full progress, under the 13.4 m/s limit, no TTC alarm, on one lane
    assert summary["metrics"]["ego_progress"] == pytest.approx(1.0, abs=1e-3)
    assert summary["metrics"]["offroad"] == 0.0 and summary["metrics"]["overlap"] == 0.0
    assert summary["nuplan_score"] == pytest.approx(1.0, abs=1e-3)
    assert summary["vmax_score"] == pytest.approx(1.0, abs=1e-3)
    assert np.max(result.episodes["log_divergence"]) < 0.05
    json.dumps(summary)  # JSON-serialisable


def test_constant_policy_runs_into_the_stopped_car(road_shards):
    result = evaluate("constant", small_data_config(road_shards))
    brake = result.scenario_ids.index("brake")
    assert result.episodes["overlap"][brake] == 1.0
    assert result.episodes["at_fault_collision"][brake] == 1.0  # the car ahead is stopped
    assert result.episodes["vmax_score"][brake] == 0.0
    # the cruising scenarios need no braking: the constant policy reproduces them
    assert result.episodes["accurate"][[0, 2]].tolist() == [1.0, 1.0]
    assert result.summary["accuracy"] == pytest.approx(2 / 3)


def _rollout(policy: str, scenario, env_config: EnvConfig):
    config = small_data_config("")
    env = make_environment(env_config)
    state = jax.tree.map(lambda a: a[0], scenarios_to_batch([scenario], config))
    return run_episode(env, make_policy(policy, env), state, jax.random.PRNGKey(0), MetricsConfig(),
                       ObservationConfig())


@pytest.mark.slow  # ~22 s on 2 cores: kept out of the 10-minute default suite
def test_collision_termination_fires_at_the_hand_worked_step():
    # keeping 10 m/s from x = 10 m at step 10, the SDC's front (x + 2.25) passes the car's rear
    # (37.75 m) when x > 35.5 m: first at step 36, the 26th policy step (index 25).
    rollout = _rollout("constant", braking_scenario(), EnvConfig(max_num_objects=8, terminate_on=("collision",)))
    overlap = np.asarray(rollout.per_step["overlap"])
    assert np.flatnonzero(overlap)[0] == 25
    assert np.flatnonzero(np.asarray(rollout.terminated))[0] == 25
    valid = np.asarray(rollout.step_valid)
    assert valid[:26].all() and not valid[26:].any()  # steps after the termination leave the episode


def test_no_termination_without_terminate_on():
    rollout = _rollout("constant", braking_scenario(), EnvConfig(max_num_objects=8, terminate_on=()))
    assert not np.asarray(rollout.terminated).any()
    assert np.asarray(rollout.step_valid).all()
    assert float(rollout.episode["overlap"]) == 1.0


@pytest.mark.slow  # 8-9 s on 2 cores: the default suite stays under 10 minutes
def test_batched_equals_unbatched(road_shards):
    one = evaluate("constant", small_data_config(road_shards, batch_size=1))
    three = evaluate("constant", small_data_config(road_shards, batch_size=3))
    assert one.episodes.keys() == three.episodes.keys()
    for name in one.episodes:
        np.testing.assert_allclose(one.episodes[name], three.episodes[name], rtol=1e-5, atol=1e-5, err_msg=name)


def test_no_recompiles_after_warm_up():
    config = small_data_config("")
    env_config = EnvConfig(max_num_objects=8)
    env = make_environment(env_config)
    policy = make_policy("expert", env)

    @chex.assert_max_traces(n=1)
    def episode(state, key):
        return run_episode(env, policy, state, key, MetricsConfig(), ObservationConfig())

    rollout_fn = jax.jit(jax.vmap(episode))
    keys = jax.random.split(jax.random.PRNGKey(0), 2)
    for batch in ([cruising_scenario("a"), braking_scenario("b")],
                  [braking_scenario("c"), cruising_scenario("d", 7.0)]):
        jax.block_until_ready(rollout_fn(scenarios_to_batch(batch, config), keys))


def test_evaluate_reuses_one_compilation(road_shards):
    from vmax_sim.evaluation.evaluate import _environment, _named_policy

    env = _environment(EnvConfig(max_num_objects=8), MetricsConfig())
    rollout_fn = make_rollout_fn(env, _named_policy("expert", env), MetricsConfig(), ObservationConfig())
    config = small_data_config(road_shards, batch_size=2)  # 3 scenarios: a full batch and a padded one
    before = rollout_fn._cache_size()
    evaluate("expert", config)
    after_first = rollout_fn._cache_size()
    evaluate("expert", config)
    assert after_first - before <= 1  # both batches of the first call share one compilation
    assert rollout_fn._cache_size() == after_first  # the second call compiles nothing


def test_callable_policy_gets_an_observation(road_shards):
    def brake_hard(observation, key):
        assert observation.objects.ndim == 3  # (n, k, features) for one scenario
        return jnp.array([-6.0, 0.0])

    result = evaluate(brake_hard, small_data_config(road_shards), num_scenarios=2)
    assert result.summary["policy"] == "brake_hard"
    assert result.episodes["overlap"].tolist() == [0.0, 0.0]  # stopping never hits anything here...
    assert result.episodes["making_progress"].tolist() == [0.0, 0.0]  # ...but makes no progress


def test_bad_inputs_give_clear_errors(road_shards, tmp_path):
    with pytest.raises(ValueError, match="unknown evaluation mode 'sideways'"):
        evaluate("expert", small_data_config(road_shards), mode="sideways")
    with pytest.raises(ValueError, match="unknown policy"):
        evaluate("idm-ish", small_data_config(road_shards))
    with pytest.raises(InputError):
        evaluate("expert", small_data_config(tmp_path / "missing"))
