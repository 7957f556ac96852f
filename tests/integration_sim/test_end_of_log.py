"""An SDC whose log ends early (test-split scenarios: 11 logged steps, the future padded invalid): the episode
ends at its last valid step as a truncation ("end of log"); padded steps are never judged."""

from __future__ import annotations

import functools

import jax
import numpy as np
import pytest

from tests.integration_sim.conftest import cruising_scenario, small_data_config
from vmax_sim.data import scenarios_to_batch
from vmax_sim.env import EnvConfig, make_environment, sdc_log_ended
from vmax_sim.evaluation import make_policy, make_rollout_fn
from vmax_sim.metrics import MetricsConfig
from vmax_sim.observation import ObservationConfig

CONFIG = EnvConfig(max_num_objects=8)


def log_ending_at(last_valid_step: int, scenario_id: str = "ends"):
    """The cruise scenario with the SDC's log cut after `last_valid_step`; the padding (as converters write
    it) sits off the road and far from the route, so judging it would show."""
    scenario = cruising_scenario(scenario_id)
    valid, x, y = scenario.valid.copy(), scenario.x.copy(), scenario.y.copy()
    valid[0, last_valid_step + 1:] = False
    x[0, last_valid_step + 1:], y[0, last_valid_step + 1:] = -1.0, 40.0
    return scenario.replace(valid=valid, x=x, y=y)


def _state(scenario):
    return jax.tree.map(lambda a: a[0], scenarios_to_batch([scenario], small_data_config("")))


@functools.lru_cache(maxsize=1)
def _expert_rollout_fn():
    env = make_environment(CONFIG)
    return make_rollout_fn(env, make_policy("expert", env), MetricsConfig(), ObservationConfig())


def _expert_episode(scenario):
    """One expert episode (`run_episode`, jitted once for every test here)."""
    batch = scenarios_to_batch([scenario], small_data_config(""))
    rollout = _expert_rollout_fn()(batch, jax.random.split(jax.random.PRNGKey(0), 1), None)
    return jax.tree.map(lambda a: a[0], rollout)


def test_episode_ends_at_the_last_valid_sdc_step():
    rollout = _expert_episode(log_ending_at(40))
    valid = np.asarray(rollout.step_valid)
    assert valid.sum() == 30 and valid[:30].all()  # policy steps landing at t = 11 .. 40
    assert not np.asarray(rollout.terminated)[:30].any()  # ended by truncation, not by a termination
    episode = {k: float(v) for k, v in rollout.episode.items()}
    assert episode["end_of_log"] == 1.0
    assert episode["offroad"] == 0.0 and episode["overlap"] == 0.0 and episode["accurate"] == 1.0
    assert episode["log_divergence"] < 0.05
    assert episode["ego_progress"] == pytest.approx(1.0, abs=1e-3)


def test_full_log_runs_the_whole_episode():
    rollout = _expert_episode(cruising_scenario())
    assert np.asarray(rollout.step_valid).all()
    assert float(rollout.episode["end_of_log"]) == 0.0 and float(rollout.episode["accurate"]) == 1.0


def test_log_ending_at_the_start_step_judges_nothing():
    rollout = _expert_episode(log_ending_at(CONFIG.first_policy_timestep))
    assert not np.asarray(rollout.step_valid).any()
    episode = {k: float(v) for k, v in rollout.episode.items()}
    assert episode["end_of_log"] == 1.0 and episode["accurate"] == 1.0 and episode["log_divergence"] == 0.0


@pytest.mark.slow  # ~16 s on 2 cores: kept out of the 10-minute default suite
def test_environment_truncates_at_the_end_of_the_sdc_log():
    env = make_environment(CONFIG)
    state = env.reset(_state(log_ending_at(12)))
    assert not bool(sdc_log_ended(state)) and not bool(env.is_truncated(state))
    action = env.expert_action(state)
    state = env.step(state, action)  # t = 11
    assert not bool(env.is_truncated(state))
    state = env.step(state, env.expert_action(state))  # t = 12, the SDC's last logged step
    assert bool(sdc_log_ended(state)) and bool(env.is_truncated(state)) and not bool(env.is_terminated(state))
    no_sdc = state.replace(object_metadata=state.object_metadata.replace(
        is_sdc=np.zeros_like(state.object_metadata.is_sdc)))
    assert not bool(sdc_log_ended(no_sdc))


def test_an_episode_with_no_judged_step_is_left_out_of_the_summary(tmp_path):
    import scenariomax
    from tests.integration_sim.conftest import SMALL_SIZES, braking_scenario
    from vmax_sim.evaluation import evaluate

    # constant velocity fails "brake"; "ends" has no judged step (it would score as a perfect episode)
    scenarios = [braking_scenario("brake"), log_ending_at(CONFIG.first_policy_timestep, "ends")]
    scenariomax.write_shards(scenarios, tmp_path, sizes=SMALL_SIZES)
    result = evaluate("constant", small_data_config(tmp_path), env_config=CONFIG)
    assert result.episodes["judged_steps"].tolist()[1] == 0.0 and result.episodes["judged_steps"][0] > 0
    assert result.summary["num_episodes"] == 2 and result.summary["num_unjudged"] == 1
    assert result.summary["accuracy"] == 0.0  # over the one judged episode, not 0.5
