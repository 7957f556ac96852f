"""IDM + pure pursuit: hand-worked formulas and closed-loop behaviour on hand-made roads."""

from __future__ import annotations

import math

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from tests.integration_sim.conftest import CAR_AHEAD_X, braking_scenario, cruising_scenario, small_data_config
from tests.policies.scenes import (
    CURVE_RADIUS,
    ENV_CONFIG,
    LEAD_SPEED,
    LIGHT_X,
    SPEED_LIMIT,
    as_state,
    curve_scenario,
    empty_road_scenario,
    episode,
    episode_fn,
    green_light_scenario,
    lead_car_scenario,
    red_light_scenario,
)
from vmax_sim.env import EnvConfig, make_environment
from vmax_sim.evaluation import POLICY_NAMES, evaluate, make_policy
from vmax_sim.policies import IDMConfig, idm_acceleration, idm_action, idm_policy, pure_pursuit_curvature
from vmax_sim.policies.idm import corridor_leader
from vmax_sim.policies.route import Objects

HALF_LENGTH = 2.25  # the hand-made vehicles are 4.5 m long


def test_idm_acceleration_matches_hand_worked_values():
    c = IDMConfig()  # a = 1.5, b = 2, T = 1.5 s, s0 = 2 m, delta = 4
    assert float(idm_acceleration(0.0, 10.0, jnp.inf, 0.0, c)) == pytest.approx(1.5)  # free road, standstill
    assert float(idm_acceleration(10.0, 10.0, jnp.inf, 0.0, c)) == pytest.approx(0.0, abs=1e-6)  # at v0
    assert float(idm_acceleration(5.0, 10.0, jnp.inf, 0.0, c)) == pytest.approx(1.5 * (1 - 0.5**4))
    # following at the desired gap s* = s0 + v T = 2 + 15 = 17 m at equal speeds: a (1 - 1 - 1) = -a
    assert float(idm_acceleration(10.0, 10.0, 17.0, 10.0, c)) == pytest.approx(-1.5, abs=1e-5)
    # closing at 5 m/s: s* = 17 + 10 * 5 / (2 sqrt(1.5 * 2)) = 17 + 14.434 m, gap 40 m
    s_star = 17.0 + 50.0 / (2.0 * math.sqrt(3.0))
    assert float(idm_acceleration(10.0, 10.0, 40.0, 5.0, c)) == pytest.approx(-1.5 * (s_star / 40.0) ** 2, rel=1e-5)


def test_pure_pursuit_is_exact_on_a_circle():
    radius = 25.0
    for angle in (0.1, 0.4, 1.0):  # target points on the circle through the pose, tangent to the heading
        target = jnp.array([radius * math.sin(angle), radius * (1 - math.cos(angle))])
        assert float(pure_pursuit_curvature(jnp.zeros(2), jnp.zeros(()), target)) == pytest.approx(1 / radius)
    # the same circle seen from a rotated, shifted pose; a target on the right gives a negative curvature
    yaw = 0.7
    rotation = jnp.array([[math.cos(yaw), -math.sin(yaw)], [math.sin(yaw), math.cos(yaw)]])
    target = rotation @ jnp.array([radius * math.sin(0.5), -radius * (1 - math.cos(0.5))]) + jnp.array([3.0, -4.0])
    value = pure_pursuit_curvature(jnp.array([3.0, -4.0]), jnp.asarray(yaw), target)
    assert float(value) == pytest.approx(-1 / radius, rel=1e-5)


@pytest.mark.slow  # 10-14 s of the default suite's 10-minute budget; runs in CI's slow stage
def test_idm_accelerates_to_the_speed_limit_on_an_empty_road():
    rollout, steps = episode("idm", empty_road_scenario(speed=5.0))
    speed, accel = steps["speed"], steps["accel"]
    assert speed[-1] > SPEED_LIMIT - 1.0 and np.all(speed < SPEED_LIMIT + 0.05)  # close to, never above, 13.4
    assert np.all(np.diff(speed) > -1e-3) and np.all(accel < 1.5 + 1e-3)  # smooth, at most a = 1.5 m/s^2
    assert np.max(np.abs(steps["sdc_y"])) < 0.05  # stays on the lane centre
    assert float(rollout.episode["speed_limit_compliance"]) == 1.0 and float(rollout.episode["comfort"]) == 1.0


def test_idm_follows_a_slower_car_at_a_safe_gap():
    scenario = lead_car_scenario()
    rollout, steps = episode("idm", scenario)
    lead_x = scenario.x[1, 11:91]  # per-step metrics are taken after each step, at steps 11 .. 90
    gap = lead_x - steps["sdc_x"] - 2 * HALF_LENGTH
    assert float(rollout.episode["overlap"]) == 0.0 and np.min(gap) > 2.0
    assert steps["speed"][-1] == pytest.approx(LEAD_SPEED, abs=0.5)  # settles at the leader's speed ...
    assert 9.0 < gap[-1] < 15.0  # ... near the desired gap s0 + v T = 2 + 6 x 1.5 = 11 m


def test_idm_stops_behind_a_stopped_car():
    rollout, steps = episode("idm", braking_scenario())
    front = steps["sdc_x"] + HALF_LENGTH
    rear_of_car = CAR_AHEAD_X - HALF_LENGTH
    assert float(rollout.episode["overlap"]) == 0.0
    assert steps["speed"][-1] < 0.1 and rear_of_car - 4.0 < front[-1] < rear_of_car - 1.0  # ~ s0 = 2 m short


def _objects_ahead(lateral, speed, arc) -> Objects:
    """Cars 4.5 x 1.8 m at `arc` m along the path, `lateral` m to its left, driving `speed` m/s along it."""
    n = len(lateral)
    speed = jnp.asarray(speed, jnp.float32)
    return Objects(boxes=jnp.zeros((n, 5)), vel=jnp.stack([speed, jnp.zeros(n)], axis=1),
                   valid=jnp.ones(n, bool), arc=jnp.asarray(arc, jnp.float32),
                   lateral=jnp.asarray(lateral, jnp.float32), half_along=jnp.full(n, HALF_LENGTH),
                   half_across=jnp.full(n, 0.9), speed_along=speed, yaw_rate=jnp.zeros(n))


def test_standing_clearance_passes_a_parked_car_beside_the_lane_but_not_one_in_it():
    lane = IDMConfig().lane_half_width
    beside = _objects_ahead([-2.3], [0.0], [20.0])  # a parked car whose side is 1.4 m from the path
    gap, _ = corridor_leader(beside, 0.0, 0.0, HALF_LENGTH, lane)
    assert float(gap) == pytest.approx(20.0 - 2 * HALF_LENGTH)  # the lane corridor queues behind it
    passing = 0.9 + 0.2  # the car's half width + 0.2 m to spare
    gap, _ = corridor_leader(beside, 0.0, 0.0, HALF_LENGTH, lane, passing, 0.3)
    assert math.isinf(float(gap))  # passed
    # a car driving there, or one at rest in the lane, still leads
    for objects in (_objects_ahead([-2.3], [5.0], [20.0]), _objects_ahead([-2.3, 0.4], [0.0, 0.0], [15.0, 30.0])):
        gap, _ = corridor_leader(objects, 0.0, 0.0, HALF_LENGTH, lane, passing, 0.3)
        assert np.isfinite(float(gap))
    assert float(corridor_leader(_objects_ahead([-2.3, 0.4], [0.0, 0.0], [15.0, 30.0]), 0.0, 0.0, HALF_LENGTH,
                                 lane, passing, 0.3)[0]) == pytest.approx(30.0 - 2 * HALF_LENGTH)


def test_idm_stops_at_a_red_light_and_drives_through_a_green_one():
    rollout, steps = episode("idm", red_light_scenario())
    front = steps["sdc_x"] + HALF_LENGTH
    assert float(rollout.episode["red_light"]) == 0.0
    # IDM creeps up to its stop: 80 steps from 10 m/s end a little over s0 = 2 m short, nearly stopped
    assert steps["speed"][-1] < 0.5 and np.all(np.diff(steps["speed"]) < 1e-3) and LIGHT_X - 5.0 < front[-1] < LIGHT_X
    rollout, steps = episode("idm", green_light_scenario())
    assert steps["sdc_x"][-1] > LIGHT_X + 10.0 and float(rollout.episode["red_light"]) == 0.0
    rollout, _ = episode("constant", red_light_scenario())  # the scenario does catch a driver not stopping
    assert float(rollout.episode["red_light"]) == 1.0


def test_pure_pursuit_tracks_a_curved_lane_below_the_bend_speed():
    rollout, steps = episode("idm", curve_scenario(speed=8.0))
    radius = np.hypot(steps["sdc_x"], steps["sdc_y"] - CURVE_RADIUS)
    assert np.max(np.abs(radius - CURVE_RADIUS)) < 0.3  # on the lane centre within 30 cm
    assert float(rollout.episode["offroad"]) == 0.0 and float(rollout.episode["comfort"]) == 1.0
    bend_speed = math.sqrt(IDMConfig().bend_lateral_accel * CURVE_RADIUS)  # 8.9 m/s for 2 m/s^2 in a 40 m bend
    assert np.max(steps["speed"]) < bend_speed + 0.1 and steps["speed"][-1] > bend_speed - 0.5
    assert steps["sdc_yaw"][-1] > 1.5  # it went round the bend (8 s x ~8.5 m/s / 40 m ~ 1.7 rad)


def test_idm_is_registered_and_checks_its_dynamics():
    assert {"idm", "pdm", "random"} <= set(POLICY_NAMES)
    env = make_environment(ENV_CONFIG)
    assert make_policy("idm", env).name == "idm" and not make_policy("idm", env).needs_observation
    with pytest.raises(ValueError, match="bicycle dynamics"):
        idm_policy(make_environment(EnvConfig(max_num_objects=8, dynamics="delta_local")))
    no_reverse = make_environment(EnvConfig(max_num_objects=8, dynamics="bicycle_no_reverse"))
    assert {make_policy(name, no_reverse).name for name in ("idm", "pdm", "constant")} == {"idm", "pdm", "constant"}
    with pytest.raises(ValueError, match="IDMConfig.time_headway"):
        IDMConfig(time_headway=0.0)


def test_idm_action_in_normalised_units():
    state = make_environment(ENV_CONFIG).reset(as_state(empty_road_scenario(speed=5.0)))
    env = make_environment(EnvConfig(max_num_objects=8, normalize_actions=True))
    physical, action = jax.jit(lambda s: (idm_action(s, IDMConfig(), ENV_CONFIG.first_policy_timestep),
                                          idm_policy(env).action_fn(None, s, None, jax.random.PRNGKey(0))))(state)
    np.testing.assert_allclose(action.data[0], env.dynamics.normalize(physical), atol=1e-6)
    assert action.valid[:, 0].tolist() == [True] + [False] * 7  # only the SDC's slot
    assert 0.0 < float(physical[0]) <= 1.5 and abs(float(physical[1])) < 1e-3


@pytest.mark.slow  # 8-38 s on 2 cores: the default suite stays under 10 minutes
def test_batched_idm_equals_unbatched_without_recompiling(policy_shards):
    batched = evaluate("idm", small_data_config(policy_shards, batch_size=2))
    index = {name: i for i, name in enumerate(batched.scenario_ids)}
    scenarios = {"cruise": cruising_scenario("cruise"), "brake": braking_scenario("brake"),
                 "lead": lead_car_scenario("lead"), "red": red_light_scenario("red")}
    for name, scenario in scenarios.items():  # IDM never collides here, so termination changes nothing
        single, _ = episode("idm", scenario)
        for key in ("vmax_score", "ego_progress", "overlap", "red_light", "comfort"):
            assert float(single.episode[key]) == pytest.approx(float(batched.episodes[key][index[name]]),
                                                               abs=1e-5), key
    assert batched.summary["accuracy"] == 1.0
    assert episode_fn("idm")._cache_size() == 1  # the unbatched episode compiled once for every scenario
