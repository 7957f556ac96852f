"""Environment reset/step, wrappers and the gym adapter on hand-made scenarios."""

from __future__ import annotations

import dataclasses

import chex
import jax
import jax.numpy as jnp
import numpy as np
import pytest
from conftest import make_scenario, small_config

from vmax_sim.data import scenario_to_state, scenarios_to_batch
from vmax_sim.datatypes import Action, select_timestep
from vmax_sim.dynamics import wrap_angle
from vmax_sim.env import (
    AutoResetEnvironment,
    BatchedEnvironment,
    EnvConfig,
    Environment,
    EpisodeLimit,
    GymEnv,
    MultiAgentEnvironment,
    combine_termination_fns,
    expert_actions,
    sdc_and_agents_action,
)

CONFIG = EnvConfig(max_num_objects=8)


@pytest.fixture(scope="module")
def batch():
    """Three scenarios, unbatched states stacked (map index left out: the env does not read it)."""
    return scenarios_to_batch([make_scenario(seed) for seed in range(3)], small_config())


def unbatch(state, index):
    return jax.tree.map(lambda a: a[index], state)


def zero_action(num_objects=8, dim=2, valid=True):
    return Action(data=jnp.zeros((num_objects, dim)), valid=jnp.full((num_objects, 1), valid))


def test_reset_starts_after_the_log_history(batch):
    env = Environment(CONFIG)
    state = env.reset(unbatch(batch, 0))
    assert int(state.timestep) == 10
    sim = state.sim_trajectory
    assert bool(sim.valid[0, :11].all()) and not bool(sim.valid[:, 11:].any())
    np.testing.assert_array_equal(sim.x[:, :11], state.log_trajectory.x[:, :11])
    assert state.object_metadata.is_controlled.tolist() == [True] + [False] * 7


def test_step_drives_the_sdc_and_replays_everyone_else(batch):
    env = Environment(CONFIG)
    state = env.reset(unbatch(batch, 0))
    current = state.current_sim_trajectory
    speed = float(jnp.hypot(current.vel_x[0, 0], current.vel_y[0, 0]))
    nxt = jax.jit(env.step)(state, zero_action())
    assert int(nxt.timestep) == 11
    sim, log = nxt.sim_trajectory, nxt.log_trajectory
    moved = float(jnp.hypot(sim.x[0, 11] - sim.x[0, 10], sim.y[0, 11] - sim.y[0, 10]))
    assert moved == pytest.approx(speed * 0.1, rel=1e-4)  # zero accel and curvature: straight on
    assert float(sim.yaw[0, 11]) == pytest.approx(float(sim.yaw[0, 10]), abs=1e-6)
    for field in ("x", "y", "yaw", "vel_x", "valid"):
        np.testing.assert_array_equal(getattr(sim, field)[1:, 11], getattr(log, field)[1:, 11])
    assert not bool(sim.valid[4, 11])  # the late car is still absent, as in the log


def test_the_cached_current_step_is_the_trajectory_at_the_timestep(batch):
    """reset and step keep `current_sim` (what a step reads instead of slicing every (N, T) field) equal to
    the trajectory's slice; a trajectory or timestep changed through `replace` re-reads it, never stale."""
    env = Environment(CONFIG)
    state = env.reset(batch)  # batched: per-scene timesteps
    step = jax.jit(env.step)
    action = Action(data=jnp.tile(jnp.asarray([[1.5, 0.02]]), (3, 8, 1)), valid=jnp.ones((3, 8, 1), bool))
    for _ in range(5):
        sliced = select_timestep(state.sim_trajectory, state.timestep)
        chex.assert_trees_all_equal(state.current_sim, sliced)
        state = step(state, action)
    moved = state.replace(sim_trajectory=state.sim_trajectory.replace(x=state.sim_trajectory.x + 1.0))
    np.testing.assert_array_equal(moved.current_sim.x, state.current_sim.x + 1.0)
    rewound = state.replace(timestep=state.timestep - 2)
    chex.assert_trees_all_equal(rewound.current_sim, select_timestep(state.sim_trajectory, state.timestep - 2))
    loaded = unbatch(batch, 0)
    assert loaded.current_sim is None  # loader states slice on demand
    chex.assert_trees_all_equal(loaded.current_sim_trajectory, select_timestep(loaded.sim_trajectory, loaded.timestep))


def test_invalid_action_makes_the_controlled_object_invalid(batch):
    env = Environment(CONFIG)
    nxt = env.step(env.reset(unbatch(batch, 0)), zero_action(valid=False))
    assert not bool(nxt.sim_trajectory.valid[0, 11])


def test_jitted_step_traces_once(batch):
    env = Environment(CONFIG)

    @jax.jit
    @chex.assert_max_traces(n=1)
    def step(state, action):
        return env.step(state, action)

    state = env.reset(unbatch(batch, 0))
    for _ in range(3):
        state = step(state, expert_actions(state))
    state = step(env.reset(unbatch(batch, 1)), zero_action())  # another scenario, same shapes
    assert int(state.timestep) == 11


@pytest.mark.slow  # 8-9 s on 2 cores: the default suite stays under 10 minutes
def test_vmapped_batch_equals_separate_calls(batch):
    env = Environment(CONFIG)
    batched = BatchedEnvironment(env)
    accel = jnp.array([1.0, -2.0, 0.5])
    actions = Action(data=jnp.zeros((3, 8, 2)).at[:, :, 0].set(accel[:, None]).at[:, :, 1].set(0.05),
                     valid=jnp.ones((3, 8, 1), bool))
    state_b = jax.jit(batched.reset)(batch)
    step_b = jax.jit(batched.step)
    step_1 = jax.jit(env.step)
    singles = [env.reset(unbatch(batch, i)) for i in range(3)]
    for _ in range(3):
        state_b = step_b(state_b, actions)
        singles = [step_1(s, unbatch(actions, i)) for i, s in enumerate(singles)]
    for i, single in enumerate(singles):
        chex.assert_trees_all_close(unbatch(state_b, i), single, atol=1e-5)
    # The env also works on batched states directly (no vmap) with the same result.
    direct = env.step(env.reset(batch), actions)
    chex.assert_trees_all_close(direct, jax.vmap(env.step)(batched.reset(batch), actions), atol=1e-5)


def test_expert_replay_reproduces_the_logged_sdc_for_80_steps(batch):
    env = Environment(CONFIG)

    @jax.jit
    def rollout(state):
        def body(state, _):
            state = env.step(state, expert_actions(state))
            return state, None
        final, _ = jax.lax.scan(body, env.reset(state), None, length=80)
        return final

    final = jax.vmap(rollout)(batch)
    sim, log = final.sim_trajectory, final.log_trajectory
    assert final.timestep.tolist() == [90, 90, 90]
    error = jnp.hypot(sim.x[:, 0, 11:] - log.x[:, 0, 11:], sim.y[:, 0, 11:] - log.y[:, 0, 11:])
    assert float(error.max()) < 0.5, float(error.max())
    yaw_error = jnp.abs(wrap_angle(sim.yaw[:, 0, 11:] - log.yaw[:, 0, 11:]))
    assert float(yaw_error.max()) < 1e-3
    assert bool(env.is_truncated(jax.tree.map(lambda a: a[0], final)))


def test_termination_fn_and_episode_limits(batch):
    def is_past_x50(state):
        return state.current_sim_trajectory.x[..., 0, 0] > 50.0

    fn = combine_termination_fns({"past_x50": is_past_x50}, ["past_x50"])
    env = Environment(dataclasses.replace(CONFIG, episode_length=20), termination_fn=fn)
    state = env.reset(unbatch(batch, 0))
    step = jax.jit(env.step)
    steps = 0
    while not bool(env.is_done(state)):
        state = step(state, expert_actions(state))
        steps += 1
    assert steps <= 20
    assert bool(env.is_terminated(state)) == bool(state.current_sim_trajectory.x[0, 0] > 50.0)
    limited = EpisodeLimit(Environment(CONFIG), max_steps=5)
    state = limited.reset(unbatch(batch, 0))
    for _ in range(5):
        assert not bool(limited.is_done(state))
        state = limited.step(state, zero_action())
    assert bool(limited.is_truncated(state)) and not bool(limited.is_terminated(state))
    with pytest.raises(ValueError, match="no termination function"):
        combine_termination_fns({}, ["collision"])


def test_multi_agent_env_drives_the_controllable_objects(batch):
    env = MultiAgentEnvironment(CONFIG)
    state = env.reset(unbatch(batch, 0))
    assert state.object_metadata.is_controlled.tolist() == [True, True, False, False, True, False, False, False]
    braking = Action(data=jnp.zeros((8, 2)).at[:, 0].set(-6.0), valid=jnp.ones((8, 1), bool))
    action = sdc_and_agents_action(state, expert_actions(state), braking)
    nxt = env.step(state, action)
    sim, log = nxt.sim_trajectory, nxt.log_trajectory
    assert float(sim.vel_x[1, 11]) == pytest.approx(float(log.vel_x[1, 10]) - 0.6, abs=1e-4)  # braked
    assert float(sim.x[0, 11]) == pytest.approx(float(log.x[0, 11]), abs=0.02)  # expert SDC
    np.testing.assert_array_equal(sim.x[2, 11], log.x[2, 11])  # not controllable: log replay
    assert not bool(sim.valid[4, 11])  # controllable but not yet present: follows the log


def test_auto_reset_cycles_through_the_pool(batch):
    env = Environment(dataclasses.replace(CONFIG, episode_length=3))
    auto = AutoResetEnvironment(env, batch_size=2)
    carry = auto.reset(batch)
    step = jax.jit(auto.step)
    action = Action(data=jnp.zeros((2, 8, 2)), valid=jnp.ones((2, 8, 1), bool))
    first_x = [float(batch.log_trajectory.x[i, 0, 10]) for i in range(3)]
    for _ in range(2):
        carry = step(carry, action)
        assert not bool(carry.done.any())
    carry = step(carry, action)  # third step ends both episodes: scenarios 2 and 0 start
    assert carry.done.tolist() == [True, True]
    assert carry.state.timestep.tolist() == [10, 10]
    assert [float(carry.state.sim_trajectory.x[i, 0, 10]) for i in range(2)] == [first_x[2], first_x[0]]
    assert int(carry.next_scenario) == 1


def test_gym_adapter_runs_an_episode(batch):
    env = Environment(dataclasses.replace(CONFIG, normalize_actions=True, episode_length=5))
    gym = GymEnv(env, batch)
    obs, info = gym.reset(seed=0)
    assert obs.shape == gym.observation_space.shape == (8 * 9,)
    assert obs.dtype == np.float32
    np.testing.assert_allclose(obs[:2], [0.0, 0.0], atol=1e-4)  # the SDC sits at its own origin
    assert gym.action_space.shape == (2,) and gym.action_space.contains(np.zeros(2, np.float32))
    done, steps = False, 0
    while not done:
        obs, reward, terminated, truncated, info = gym.step(np.array([0.5, 0.0], np.float32))
        done, steps = terminated or truncated, steps + 1
    assert steps == 5 and truncated and reward == 0.0 and info["timestep"] == 15
    with pytest.raises(ValueError, match="action has shape"):
        gym.step(np.zeros(3))


def test_wrong_object_budget_is_a_clear_error(batch):
    with pytest.raises(ValueError, match="max_num_objects"):
        Environment(EnvConfig(max_num_objects=16)).reset(unbatch(batch, 0))
    with pytest.raises(ValueError, match="controlled"):
        EnvConfig(controlled="everyone")


def test_env_step_with_the_map_index_in_the_state():
    pytest.importorskip("vmax_sim.map_index", reason="part B's map index is not in this checkout")
    state = scenario_to_state(make_scenario(4), small_config(include_map_index=True))
    env = Environment(CONFIG)
    nxt = jax.jit(env.step)(env.reset(state), zero_action())
    assert int(nxt.timestep) == 11
    chex.assert_trees_all_equal(nxt.map_index, state.map_index)


def test_expert_replay_corrects_a_biased_heading(batch):
    # Rotate every logged heading by 2 degrees: pure heading/speed matching would drift sideways by
    # ~ 0.035 * 80 m; the expert's position feedback keeps the car on the logged path.
    state = unbatch(batch, 0)
    log = state.log_trajectory
    biased = state.replace(log_trajectory=log.replace(yaw=log.yaw + np.deg2rad(2.0)))
    env = Environment(CONFIG)

    def body(state, _):
        return env.step(state, expert_actions(state)), None

    final, _ = jax.jit(lambda s: jax.lax.scan(body, env.reset(s), None, length=80))(biased)
    sim = final.sim_trajectory
    error = jnp.hypot(sim.x[0, 11:] - log.x[0, 11:], sim.y[0, 11:] - log.y[0, 11:])
    assert float(error.max()) < 0.2, float(error.max())


def test_expert_replay_on_the_real_womd_record():
    from conftest import REALDATA

    record = REALDATA / "womd" / "motion_data_one_example.tfrecord"
    if not record.is_file():
        pytest.skip(f"real WOMD sample not found at {record} (only present in the project workspace)")
    import scenariomax
    from vmax_sim.data import DataConfig

    scenario = next(scenariomax.read_shards(record))
    config = DataConfig(num_objects=64, num_roadgraph_points=1000, include_map_index=False)
    state = scenario_to_state(scenario, config)
    env = Environment(EnvConfig(max_num_objects=64))

    def body(state, _):
        return env.step(state, expert_actions(state)), None

    final, _ = jax.jit(lambda s: jax.lax.scan(body, env.reset(s), None, length=80))(state)
    sdc = int(np.argmax(state.object_metadata.is_sdc))
    sim, log = final.sim_trajectory, final.log_trajectory
    error = jnp.hypot(sim.x[sdc, 11:] - log.x[sdc, 11:], sim.y[sdc, 11:] - log.y[sdc, 11:])
    assert float(error.max()) < 0.5, float(error.max())
