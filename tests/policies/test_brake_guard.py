"""The brake guard over a learned policy (train.brake_guard_ttc): PDM-Closed's emergency brake on its acceleration."""

from __future__ import annotations

import dataclasses
import functools
import types

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from tests.integration_sim.conftest import CAR_AHEAD_X, braking_scenario
from tests.policies.scenes import ENV_CONFIG, as_state, empty_road_scenario
from vmax_sim.env import make_environment
from vmax_sim.evaluation import run_episode
from vmax_sim.evaluation.trained import trained_policy
from vmax_sim.metrics import MetricsConfig
from vmax_sim.observation import ObservationConfig
from vmax_sim.policies.brake_guard import BrakeGuard, emergency_acceleration
from vmax_sim.policies.route import Ego
from vmax_sim.training.config import TrainConfig, apply_overrides, brake_guard, policy_name

NORMALIZED_ENV = dataclasses.replace(ENV_CONFIG, normalize_actions=True)


def _holding_speed_learner():
    """A learner whose every action is [0, 0] in [-1, 1]: hold the speed, drive straight (constant velocity)."""
    return types.SimpleNamespace(act=lambda params, observation, key, deterministic: jnp.zeros((1, 2)))


@functools.lru_cache(maxsize=2)
def _episode_fn(guard: BrakeGuard | None):
    """One compilation per guard for the whole module (both scenarios are shaped alike)."""
    env = make_environment(NORMALIZED_ENV)
    policy = trained_policy(_holding_speed_learner(), "held", guard)
    return jax.jit(lambda state: run_episode(env, policy, state, jax.random.PRNGKey(0), MetricsConfig(),
                                             ObservationConfig(), params={}))


def _episode(scenario, guard: BrakeGuard | None):
    rollout = jax.device_get(_episode_fn(guard)(as_state(scenario)))
    return rollout, {k: np.asarray(v) for k, v in rollout.per_step.items()}


def test_the_guard_stops_a_driver_that_would_run_into_a_stopped_car():
    unguarded, _ = _episode(braking_scenario(), None)
    assert float(unguarded.episode["overlap"]) == 1.0  # holding 10 m/s it hits the car at x = 40 m

    guarded, steps = _episode(braking_scenario(), BrakeGuard())
    assert float(guarded.episode["overlap"]) == 0.0
    front = steps["sdc_x"] + 2.25
    assert front.max() < CAR_AHEAD_X - 2.25  # its front bumper never reaches the car's rear bumper
    assert steps["speed"][-1] < 2.0 and np.diff(steps["speed"]).min() >= -3.0 * 0.1 - 1e-3  # braked at 3 m/s^2


def test_the_guard_leaves_the_policy_alone_on_an_empty_road():
    unguarded, plain = _episode(empty_road_scenario(speed=8.0), None)
    guarded, steps = _episode(empty_road_scenario(speed=8.0), BrakeGuard())
    np.testing.assert_array_equal(steps["sdc_x"], plain["sdc_x"])  # to the last bit
    assert float(guarded.episode["overlap"]) == 0.0 and abs(steps["speed"][-1] - 8.0) < 0.05


def _accel_behind_a_stopped_car(gap_m: float, speed: float, accel: float, guard: BrakeGuard) -> float:
    """The guard's acceleration for an SDC (4.5 x 2 m, east at `speed`) whose front bumper is gap_m behind a stopped
    car's rear bumper, its driver asking for `accel` m/s^2."""
    ego = Ego(xy=jnp.zeros(2), yaw=jnp.float32(0.0), speed=jnp.float32(speed), length=jnp.float32(4.5),
              width=jnp.float32(2.0), prev_speed=jnp.float32(speed))
    car = jnp.array([[4.5 + gap_m, 0.0, 4.5, 2.0, 0.0]])
    return float(emergency_acceleration(ego, car, jnp.zeros((1, 2)), jnp.array([True]), jnp.float32(accel), guard))


def test_hold_stops_a_driver_speeding_up_towards_a_stopped_car_it_is_not_yet_close_to():
    # 2 m/s, 9 m behind: 4.5 s to collision, no brake; 3 m/s^2 held for 2 s reaches 8 m/s, 1.1 s from the car
    assert _accel_behind_a_stopped_car(9.0, 2.0, 3.0, BrakeGuard()) == pytest.approx(3.0)
    assert _accel_behind_a_stopped_car(9.0, 2.0, 3.0, BrakeGuard(hold=True)) == 0.0
    # what the hold leaves alone: a gentle push whose speed stays far enough, any braking, a free road
    assert _accel_behind_a_stopped_car(9.0, 2.0, 0.5, BrakeGuard(hold=True)) == pytest.approx(0.5)
    assert _accel_behind_a_stopped_car(9.0, 2.0, -1.0, BrakeGuard(hold=True)) == pytest.approx(-1.0)
    assert _accel_behind_a_stopped_car(80.0, 10.0, 3.0, BrakeGuard(hold=True)) == pytest.approx(3.0)
    # already within the guard's time: it brakes at 3 m/s^2 either way
    assert _accel_behind_a_stopped_car(9.0, 6.0, 3.0, BrakeGuard(hold=True)) == pytest.approx(-3.0)
    assert _accel_behind_a_stopped_car(9.0, 6.0, 3.0, BrakeGuard()) == pytest.approx(-3.0)


def test_brake_guard_hold_shapes_the_runs_guard_and_needs_one():
    held = apply_overrides(TrainConfig(), ["train.brake_guard_ttc=2", "train.brake_guard_hold=true"])
    assert brake_guard(held) == BrakeGuard(ttc_s=2.0, hold=True)
    with pytest.raises(ValueError, match="set train.brake_guard_ttc too"):
        apply_overrides(TrainConfig(), ["train.brake_guard_hold=true"])


def test_brake_guard_ttc_sets_the_runs_guard_and_refuses_bad_values():
    assert brake_guard(TrainConfig()) is None
    guarded = apply_overrides(TrainConfig(), ["train.brake_guard_ttc=1.5"])
    assert brake_guard(guarded) == BrakeGuard(ttc_s=1.5)
    # tables and pictures never show a guarded student as the student alone
    assert (policy_name(TrainConfig()), policy_name(guarded)) == ("sac-lq", "sac-lq+guard")
    with pytest.raises(ValueError, match="train.brake_guard_ttc must be in"):
        apply_overrides(TrainConfig(), ["train.brake_guard_ttc=-1"])
    with pytest.raises(ValueError, match="choose bicycle dynamics"):
        apply_overrides(TrainConfig(), ["env.dynamics=delta_local", "train.brake_guard_ttc=2"])
