"""PDM-Closed: proposals, scoring, collision avoidance, batching and compilation."""

from __future__ import annotations

import dataclasses

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from tests.integration_sim.conftest import (
    CAR_AHEAD_X,
    NUM_STEPS,
    braking_scenario,
    cruising_scenario,
    road_scenario,
    small_data_config,
)
from tests.policies.scenes import ENV_CONFIG, as_state, empty_road_scenario, episode, episode_fn, lead_car_scenario
from vmax_sim.env import make_environment
from vmax_sim.evaluation import evaluate
from vmax_sim.policies import PDMConfig, pdm_plan
from vmax_sim.policies.idm import perceive
from vmax_sim.policies.pdm import forecast, proposal_grid

PARKED_X, PARKED_Y = 40.0, -2.0  # a car parked half on the kerb: its left side is 1 m into the SDC's lane


def parked_car_scenario(scenario_id: str = "parked") -> object:
    """The SDC at 8 m/s on the straight road; a car stands at x = 40 m, 2 m right of the lane centre."""
    time = np.arange(NUM_STEPS) * 0.1
    xs = np.stack([8.0 * time, np.full(NUM_STEPS, PARKED_X)])
    scenario = road_scenario(scenario_id, xs, np.stack([np.full(NUM_STEPS, 8.0), np.zeros(NUM_STEPS)]))
    y = np.zeros_like(scenario.y)
    y[1] = PARKED_Y
    return dataclasses.replace(scenario, y=y)


def _plan(scenario, config: PDMConfig | None = None):
    config = config or PDMConfig()
    state = make_environment(ENV_CONFIG).reset(as_state(scenario))
    return jax.jit(lambda s: pdm_plan(s, config, ENV_CONFIG.first_policy_timestep))(state)


@pytest.mark.slow  # 10-14 s of the default suite's 10-minute budget; runs in CI's slow stage
def test_fifteen_proposals_and_the_full_speed_centre_one_wins_on_an_empty_road():
    offsets, fractions = proposal_grid(PDMConfig())
    assert offsets.shape == (15,) and sorted(set(np.asarray(offsets).tolist())) == [-1.0, 0.0, 1.0]
    assert sorted(set(np.asarray(fractions).astype(float).round(2).tolist())) == [0.2, 0.4, 0.6, 0.8, 1.0]
    action, props, scores = _plan(empty_road_scenario(speed=5.0))
    assert props.arc.shape == (15, 21) and props.accel.shape == (15, 20)  # 4 s in 0.2 s steps
    assert np.all((np.asarray(scores["score"]) >= 0.0) & (np.asarray(scores["score"]) <= 1.0))
    best = int(jnp.argmax(scores["score"]))
    assert float(props.offset[best]) == 0.0 and best == 0  # centre, 100 % of the limit
    assert float(scores["ego_progress"][0]) == 1.0 and float(scores["ego_progress"][4]) < 0.6
    # the proposals' acceleration changes by at most max_jerk (4 m/s^3) from the one executed last (0)
    assert 0.0 < float(action[0]) <= 4.0 * 0.1 + 1e-5 and abs(float(action[1])) < 1e-3
    assert np.all(np.abs(np.diff(np.asarray(props.accel), axis=1)) <= 4.0 * 0.2 + 1e-4)


def test_forecasts_move_objects_at_constant_velocity():
    scenario = lead_car_scenario()
    state = make_environment(ENV_CONFIG).reset(as_state(scenario))
    times = jnp.arange(5, dtype=jnp.float32)

    @jax.jit
    def forecasts(state):
        scene = perceive(state, PDMConfig().idm, ENV_CONFIG.first_policy_timestep)
        lead = jnp.array([1])  # slot 1: the lead car at 6 m/s
        return forecast(scene, lead, times), forecast(scene, lead, times, stop_time=jnp.array([2.0]))

    fc, stopped = forecasts(state)  # the second stands still from t = 2 s
    start = float(scenario.x[1, 10])
    np.testing.assert_allclose(np.asarray(fc.boxes[:, 0, 0]), start + 6.0 * np.arange(5), atol=1e-3)
    np.testing.assert_allclose(np.asarray(fc.arc[:, 0]) - np.asarray(fc.arc[0, 0]), 6.0 * np.arange(5), atol=0.05)
    np.testing.assert_allclose(np.asarray(stopped.boxes[:, 0, 0]), start + 6.0 * np.minimum(np.arange(5), 2.0),
                               atol=1e-3)
    assert np.asarray(stopped.vel[3:, 0]).tolist() == [[0.0, 0.0], [0.0, 0.0]]


@pytest.mark.slow  # ~22 s on 2 cores: kept out of the 10-minute default suite
def test_pdm_stops_where_the_constant_velocity_policy_crashes():
    constant, _ = episode("constant", braking_scenario())
    assert float(constant.episode["overlap"]) == 1.0 and float(constant.episode["at_fault_collision"]) == 1.0
    rollout, steps = episode("pdm", braking_scenario())
    assert float(rollout.episode["overlap"]) == 0.0 and steps["speed"][-1] < 0.5
    assert steps["sdc_x"][-1] + 2.25 < CAR_AHEAD_X - 2.25  # its front stays behind the stopped car's rear


def test_pdm_swerves_round_a_car_jutting_into_the_lane_where_idm_waits():
    idm, idm_steps = episode("idm", parked_car_scenario())
    assert float(idm.episode["overlap"]) == 0.0 and idm_steps["sdc_x"][-1] < PARKED_X - 4.5  # stuck behind it
    pdm, steps = episode("pdm", parked_car_scenario())
    assert float(pdm.episode["overlap"]) == 0.0 and float(pdm.episode["offroad"]) == 0.0
    assert steps["sdc_x"][-1] > PARKED_X + 10.0  # passed it ...
    assert 0.5 < np.max(steps["sdc_y"]) < 1.5  # ... about 1 m to the left (the +1 m proposals)


def test_pdm_config_errors_are_one_line():
    with pytest.raises(ValueError, match="forecast must be one of"):
        PDMConfig(forecast="psychic")
    with pytest.raises(ValueError, match="step_s <= horizon_s"):
        PDMConfig(horizon_s=0.1, step_s=0.2)
    with pytest.raises(ValueError, match="at least one lateral offset"):
        PDMConfig(lateral_offsets=())


@pytest.mark.slow  # 8-38 s on 2 cores: the default suite stays under 10 minutes
def test_batched_pdm_equals_unbatched_without_recompiling(policy_shards):
    batched = evaluate("pdm", small_data_config(policy_shards, batch_size=2))
    assert batched.summary["accuracy"] == 1.0
    index = {name: i for i, name in enumerate(batched.scenario_ids)}
    for name, scenario in (("cruise", cruising_scenario("cruise")), ("brake", braking_scenario("brake")),
                           ("lead", lead_car_scenario("lead"))):
        single, _ = episode("pdm", scenario)  # no collision here, so termination changes nothing
        for key in ("vmax_score", "ego_progress", "overlap", "comfort", "ttc_within_bound"):
            assert float(single.episode[key]) == pytest.approx(float(batched.episodes[key][index[name]]),
                                                               abs=1e-4), key
    assert episode_fn("pdm")._cache_size() == 1
