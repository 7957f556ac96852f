"""Dynamics models against hand-worked motions and their own inverses."""

from __future__ import annotations

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from conftest import REALDATA, smooth_bicycle_track
from hypothesis import given, settings
from hypothesis import strategies as st

from vmax_sim.datatypes import Trajectory, select_timestep
from vmax_sim.dynamics import (
    BICYCLE,
    BICYCLE_NO_REVERSE,
    DELTA_GLOBAL,
    DELTA_LOCAL,
    DT,
    STATE,
    bicycle_forward,
    bicycle_inverse,
    get_dynamics,
    wrap_angle,
)


def make_trajectory(x, y, yaw, vel_x, vel_y) -> Trajectory:
    """One object (1, T) from per-step sequences."""
    arrays = [np.asarray(v, np.float32)[None] for v in (x, y, yaw, vel_x, vel_y)]
    x, y, yaw, vel_x, vel_y = arrays
    ones = np.ones_like(x)
    return Trajectory(x=x, y=y, z=np.zeros_like(x), vel_x=vel_x, vel_y=vel_y, yaw=yaw, length=4.5 * ones,
                      width=2.0 * ones, height=1.5 * ones, valid=ones > 0,
                      timestamp_micros=(np.arange(x.shape[-1]) * 100_000).astype(np.int32)[None])


def state_at(x, y, yaw, speed) -> Trajectory:
    """One object, one step (1, 1) driving at `speed` along `yaw`."""
    return make_trajectory([x], [y], [yaw], [speed * np.cos(yaw)], [speed * np.sin(yaw)])


def test_straight_constant_speed_log_has_zero_action_and_is_reproduced():
    steps = np.arange(5)
    log = make_trajectory(10.0 * DT * steps, np.zeros(5), np.zeros(5), np.full(5, 10.0), np.zeros(5))
    action = bicycle_inverse(log, 2)
    np.testing.assert_allclose(action, [[0.0, 0.0]], atol=1e-5)
    nxt = bicycle_forward(action, select_timestep(log, 2))
    assert float(nxt.x[0, 0]) == pytest.approx(3.0, abs=1e-5)  # 2 m + 10 m/s * 0.1 s
    assert float(nxt.y[0, 0]) == pytest.approx(0.0, abs=1e-6)
    assert int(nxt.timestamp_micros[0, 0]) == 300_000


def test_acceleration_from_rest_moves_half_a_t_squared():
    nxt = bicycle_forward(jnp.array([[2.0, 0.0]]), state_at(0.0, 0.0, 0.0, 0.0))
    assert float(nxt.x[0, 0]) == pytest.approx(0.5 * 2.0 * DT**2, abs=1e-7)  # 1 cm
    assert float(nxt.vel_x[0, 0]) == pytest.approx(0.2, abs=1e-6)


def test_the_no_reverse_bicycle_brakes_to_a_stop_and_stays_there():
    # full braking at rest: the plain bicycle backs up, the no-reverse one holds still
    at_rest = state_at(5.0, 2.0, 0.0, 0.0)
    backed = bicycle_forward(jnp.array([[-6.0, 0.1]]), at_rest)
    assert float(backed.x[0, 0]) < 5.0 and float(backed.vel_x[0, 0]) < 0.0
    held = BICYCLE_NO_REVERSE.forward(jnp.array([[-6.0, 0.1]]), at_rest)
    assert float(held.x[0, 0]) == pytest.approx(5.0, abs=1e-7) and float(held.vel_x[0, 0]) == pytest.approx(0.0)
    # braking harder than the speed allows ends the step at rest, not reversing: 1 m/s needs only -10 m/s^2 * dt
    slow = BICYCLE_NO_REVERSE.forward(jnp.array([[-6.0, 0.0]]), state_at(0.0, 0.0, 0.0, 0.4))
    assert float(slow.vel_x[0, 0]) == pytest.approx(0.0, abs=1e-6)
    assert float(slow.x[0, 0]) == pytest.approx(0.02, abs=1e-6)  # v dt / 2 while stopping
    # any other action (speeding up, braking within the speed) is the plain bicycle's
    moving = state_at(1.0, -1.0, 0.3, 8.0)
    for action in ([[2.0, 0.05]], [[-3.0, -0.02]]):
        np.testing.assert_allclose(jax.tree.leaves(BICYCLE_NO_REVERSE.forward(jnp.array(action), moving)),
                                   jax.tree.leaves(bicycle_forward(jnp.array(action), moving)))
    assert get_dynamics("bicycle_no_reverse") is BICYCLE_NO_REVERSE and BICYCLE_NO_REVERSE.bounds == BICYCLE.bounds


def test_constant_curvature_arc_is_exact():
    # Circle of radius 20 m around (0, 20), driven counter-clockwise at 10 m/s from the origin.
    radius, speed = 20.0, 10.0
    angle = speed * DT * np.arange(6) / radius
    yaw = angle
    log = make_trajectory(radius * np.sin(angle), radius - radius * np.cos(angle), yaw,
                          speed * np.cos(yaw), speed * np.sin(yaw))
    action = bicycle_inverse(log, 0)
    np.testing.assert_allclose(action, [[0.0, 1 / radius]], atol=1e-5)
    current = select_timestep(log, 0)
    for step in range(1, 6):
        current = bicycle_forward(action, current)
        assert float(current.x[0, 0]) == pytest.approx(float(log.x[0, step]), abs=1e-5)
        assert float(current.y[0, 0]) == pytest.approx(float(log.y[0, step]), abs=1e-5)
        assert float(current.yaw[0, 0]) == pytest.approx(float(log.yaw[0, step]), abs=1e-5)


@settings(max_examples=30, deadline=None)
@given(speed=st.floats(0.5, 30.0), yaw=st.floats(-3.1, 3.1), accel=st.floats(-6.0, 6.0),
       curvature=st.floats(-0.3, 0.3))
def test_bicycle_inverse_of_forward_recovers_the_action(speed, yaw, accel, curvature):
    current = state_at(5.0, -3.0, yaw, speed)
    action = jnp.array([[accel, curvature]], jnp.float32)
    nxt = bicycle_forward(action, current)
    recovered = BICYCLE.inverse_step(current, nxt)
    np.testing.assert_allclose(recovered[0, 0], accel, atol=2e-3)
    # Curvature is unobservable when the car (almost) stands still over the step.
    if abs(speed * DT + 0.5 * accel * DT**2) > 0.05:
        np.testing.assert_allclose(recovered[0, 1], curvature, atol=2e-3)


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_forward_of_inverse_reproduces_a_smooth_log_within_a_centimetre(seed):
    log = make_trajectory(*smooth_bicycle_track(seed))
    steps = jnp.arange(90)
    actions = jax.vmap(lambda t: bicycle_inverse(log, t))(steps)  # (90, 1, 2)
    predicted = jax.vmap(lambda a, t: bicycle_forward(a, select_timestep(log, t)))(actions, steps)
    error = np.hypot(predicted.x[:, 0, 0] - log.x[0, 1:], predicted.y[:, 0, 0] - log.y[0, 1:])
    assert error.max() < 0.01
    yaw_error = np.abs(wrap_angle(predicted.yaw[:, 0, 0] - log.yaw[0, 1:]))
    assert yaw_error.max() < 1e-4


@pytest.mark.parametrize("name", ["delta_local", "delta_global", "state"])
def test_delta_and_state_models_reproduce_any_step_exactly(name):
    model = get_dynamics(name)
    log = make_trajectory(*smooth_bicycle_track(3))
    action = model.inverse(log, 40)
    nxt = model.forward(action, select_timestep(log, 40))
    target = select_timestep(log, 41)
    for field in ("x", "y"):
        np.testing.assert_allclose(getattr(nxt, field), getattr(target, field), atol=1e-4)
    np.testing.assert_allclose(wrap_angle(nxt.yaw - target.yaw), 0.0, atol=1e-5)


def test_delta_local_action_is_in_the_object_frame():
    # Heading north (+y): one metre "forward" in the local frame is +1 in global y.
    nxt = DELTA_LOCAL.forward(jnp.array([[1.0, 0.0, 0.1]]), state_at(2.0, 3.0, np.pi / 2, 0.0))
    assert float(nxt.x[0, 0]) == pytest.approx(2.0, abs=1e-6)
    assert float(nxt.y[0, 0]) == pytest.approx(4.0, abs=1e-6)
    assert float(nxt.vel_y[0, 0]) == pytest.approx(10.0, abs=1e-4)  # 1 m in 0.1 s
    nxt_global = DELTA_GLOBAL.forward(jnp.array([[1.0, 0.0, 0.0]]), state_at(2.0, 3.0, np.pi / 2, 0.0))
    assert float(nxt_global.x[0, 0]) == pytest.approx(3.0, abs=1e-6)


def test_normalisation_maps_documented_bounds_onto_unit_box():
    assert BICYCLE.bounds == ((-6.0, 6.0), (-0.3, 0.3))
    np.testing.assert_allclose(BICYCLE.denormalize(jnp.array([1.0, -1.0])), [6.0, -0.3])
    np.testing.assert_allclose(BICYCLE.denormalize(jnp.array([0.5, 0.0])), [3.0, 0.0], atol=1e-6)
    np.testing.assert_allclose(BICYCLE.normalize(jnp.array([3.0, 0.15])), [0.5, 0.5], atol=1e-6)
    np.testing.assert_allclose(BICYCLE.normalize(jnp.array([100.0, -1.0])), [1.0, -1.0])  # clipped
    with pytest.raises(ValueError, match="no action bounds"):
        STATE.normalize(jnp.zeros(5))
    with pytest.raises(ValueError, match="unknown dynamics"):
        get_dynamics("teleport")


def test_forward_of_inverse_on_the_real_womd_record():
    record = REALDATA / "womd" / "motion_data_one_example.tfrecord"
    if not record.is_file():
        pytest.skip(f"real WOMD sample not found at {record} (only present in the project workspace)")
    import scenariomax

    scenario = next(scenariomax.read_shards(record))
    valid = scenario.valid[:, :-1] & scenario.valid[:, 1:]
    moving = valid & (np.hypot(scenario.velocity_x, scenario.velocity_y)[:, :-1] > 2.0)
    log = Trajectory(
        x=scenario.x, y=scenario.y, z=scenario.z, vel_x=scenario.velocity_x, vel_y=scenario.velocity_y,
        yaw=scenario.bbox_yaw, length=scenario.length, width=scenario.width, height=scenario.height,
        valid=scenario.valid, timestamp_micros=scenario.timestamp_micros.astype(np.int32))
    steps = jnp.arange(90)
    predicted = jax.vmap(lambda t: bicycle_forward(bicycle_inverse(log, t), select_timestep(log, t)))(steps)
    error = np.hypot(predicted.x[..., 0] - scenario.x[:, 1:].T, predicted.y[..., 0] - scenario.y[:, 1:].T).T
    error = error[moving]
    assert moving.sum() > 100
    # Real tracks are not exactly bicycle-consistent; a step's position error stays at centimetres.
    assert np.median(error) < 0.03, np.median(error)
