"""LearningEnv on hand-made roads: termination vs truncation, rewards, auto-reset order, no recompiles."""

from __future__ import annotations

import dataclasses
import functools

import chex
import jax
import jax.numpy as jnp
import numpy as np
import pytest

from tests.integration_sim.conftest import (
    DT,
    NUM_STEPS,
    braking_scenario,
    cruising_scenario,
    road_scenario,
    small_data_config,
)
from vmax_sim.data import scenarios_to_batch
from vmax_sim.env import EnvConfig
from vmax_sim.env.learning import LearningEnv
from vmax_sim.policies.traffic import idm_traffic
from vmax_sim.training.run import TRAFFIC_DRIVERS, TRAFFIC_SEES_SDC_COS

ENV = LearningEnv(EnvConfig(max_num_objects=8))


@functools.lru_cache(maxsize=4)
def jitted_reset(env: LearningEnv):
    """env.reset compiled once per env: run eagerly, its metrics and observation took ~40 s of this file's time."""
    return jax.jit(env.reset, static_argnums=1)


def pool():
    scenarios = [cruising_scenario("cruise"), braking_scenario("brake"), cruising_scenario("slow", 8.0)]
    return scenarios_to_batch(scenarios, small_data_config(""))


def run(policy, steps: int, batch_size: int = 2, env: LearningEnv = ENV):
    """Steps `batch_size` episodes with policy(state) -> (B, A); returns the stacked StepOutputs."""
    scenarios = pool()
    state = jitted_reset(env)(scenarios, batch_size, jax.random.PRNGKey(0))

    @jax.jit
    def roll(state):
        def body(state, _):
            state, out = env.step(state, policy(state), scenarios)
            return state, (out, state.sim.object_metadata.ids[:, 1])
        return jax.lax.scan(body, state, None, length=steps)

    return roll(state)[1]


@pytest.mark.slow  # 8-38 s on 2 cores: the default suite stays under 10 minutes
def test_expert_episode_truncates_with_positive_return_and_keeps_its_last_observation():
    out, _ = run(ENV.expert_action, 80)
    assert not bool(jnp.any(out.terminated))
    assert out.truncated[:-1].sum() == 0 and bool(jnp.all(out.truncated[-1]))  # time limit after 80 steps
    # navigation reward: +0.2 for every step that progressed along the route (cruise always does)
    assert float(out.episode_return[-1, 0]) == pytest.approx(float(jnp.sum(out.reward[:, 0])), abs=1e-4)
    assert float(out.episode_return[-1, 0]) > 0.2 * 75
    assert float(out.episode_flags["overlap"][-1].sum()) == 0.0
    # next_observation of the last step is the end of the episode, not the reset scene
    assert not np.allclose(out.next_observation.sdc[-1, 1], out.observation.sdc[0, 1])  # braked to a stop


@pytest.mark.slow  # 11-13 s of the default suite's 10-minute budget; runs in CI's slow stage
def test_collision_terminates_with_the_safety_penalty():
    # keep 10 m/s: the SDC of the braking scenario (episode 1) hits the stopped car
    out, _ = run(lambda state: jnp.zeros((2, 2)) + ENV.core.dynamics.normalize(jnp.zeros(2)), 60)
    hit = np.flatnonzero(np.asarray(out.terminated[:, 1]))
    assert hit.size >= 1
    step = hit[0]
    assert float(out.reward[step, 1]) <= -1.0 + 0.2 + 1e-6  # collision -1 (progress may still add 0.2)
    assert bool(out.episode_flags["overlap"][step, 1]) and not bool(out.truncated[step, 1])
    assert not bool(jnp.any(out.terminated[:, 0]))  # the cruise episode keeps going


@pytest.mark.slow  # ~60 s on 2 cores (it compiles several repeat counts): the default suite stays under 10 minutes
def test_a_repeated_action_is_held_for_k_steps_and_stops_at_the_episode_end():
    """action_repeat 4: one transition is 4 simulator steps (timestep +4, the rewards of the 4 steps summed);
    the 80-step episode takes 20 transitions; a crash within the 4 steps ends the transition there."""
    repeat = LearningEnv(EnvConfig(max_num_objects=8), action_repeat=4)
    hold = lambda state: jnp.zeros((2, 2)) + repeat.core.dynamics.normalize(jnp.zeros(2))  # noqa: E731
    scenarios = pool()
    state = jitted_reset(repeat)(scenarios, 2, jax.random.PRNGKey(0))
    after, out = jax.jit(lambda s: repeat.step(s, hold(s), scenarios))(state)
    np.testing.assert_array_equal(np.asarray(after.sim.timestep - state.sim.timestep), [4, 4])
    single, _ = run(hold, 4)  # the same action, one simulator step per transition
    np.testing.assert_allclose(np.asarray(out.reward), np.asarray(single.reward.sum(axis=0)), atol=1e-5)

    cruise, _ = run(repeat.expert_action, 20, env=repeat)
    assert cruise.truncated[:-1, 0].sum() == 0 and bool(cruise.truncated[-1, 0])  # 20 x 4 = the 80 steps
    crash, _ = run(hold, 15, env=repeat)
    hit = np.flatnonzero(np.asarray(crash.terminated[:, 1]))
    single_hit = np.flatnonzero(np.asarray(run(hold, 60)[0].terminated[:, 1]))[0]
    assert hit.size >= 1 and hit[0] == single_hit // 4  # the transition holding the crash step ends the episode
    assert bool(crash.episode_flags["overlap"][hit[0], 1])
    assert float(crash.reward[hit[0], 1]) <= -1.0 + 4 * 0.2 + 1e-6


@pytest.mark.slow  # ~14 s (a compilation of its own); the default suite ran 9:40 of its 10 minutes
def test_finished_episodes_restart_on_the_next_pool_scenarios():
    out, second_object_ids = run(ENV.expert_action, 81, batch_size=2)
    # episodes 0, 1 run scenarios 0, 1 of the pool; after 80 steps both restart on scenarios 2 then 0
    before, after = np.asarray(second_object_ids[0]), np.asarray(second_object_ids[-1])
    pool_ids = np.asarray(pool().object_metadata.ids[:, 1])
    np.testing.assert_array_equal(before, pool_ids[[0, 1]])
    np.testing.assert_array_equal(after, pool_ids[[2, 0]])


@pytest.mark.slow  # 10-14 s of the default suite's 10-minute budget; runs in CI's slow stage
def test_step_compiles_once():
    scenarios = pool()
    state = jitted_reset(ENV)(scenarios, 2, jax.random.PRNGKey(0))

    @jax.jit
    @chex.assert_max_traces(n=1)
    def step(state, action):
        return ENV.step(state, action, scenarios)

    for _ in range(3):
        state, _ = step(state, jnp.zeros((2, 2)))


def follower_scenario():
    """The SDC at x = 30 m and a controllable follower at x = 0, both logged at a steady 10 m/s on one lane (the
    follower has its own path). An SDC that brakes is rear-ended by the follower's log."""
    time = np.arange(NUM_STEPS) * DT
    xs = np.stack([30.0 + 10.0 * time, 10.0 * time])
    path_x = np.arange(-20.0, 250.0)
    return dataclasses.replace(
        road_scenario("follower", xs, np.full_like(xs, 10.0)), is_controllable=np.array([True, True]),
        agent_path_object_index=np.array([1]), agent_path_valid=np.ones((1, len(path_x)), bool),
        agent_path_xyz=np.stack([path_x, 0 * path_x, 0 * path_x], 1)[None].astype(np.float32),
        agent_path_arc_length=(path_x - path_x[0])[None].astype(np.float32))


@pytest.mark.slow  # ~100 s on 2 cores (two env compilations): the default suite stays under 10 minutes
@pytest.mark.parametrize("traffic", ["log", "idm", "idm_pass", "idm_follow", "idm_follow_pass"])
def test_idm_traffic_brakes_for_a_braking_learner_that_log_traffic_rear_ends(traffic):
    env = LearningEnv(EnvConfig(max_num_objects=8), traffic=TRAFFIC_DRIVERS[traffic],
                      traffic_sees_sdc_cos=TRAFFIC_SEES_SDC_COS.get(traffic))
    pool = scenarios_to_batch([follower_scenario()], small_data_config("", include_agent_paths=True))

    def brake_to_a_stop(state):  # straight on, braking at up to 6 m/s^2 until it stands (the model would reverse)
        now = jax.tree.map(lambda a: a[:, 0, state.sim.timestep[0]], state.sim.sim_trajectory)  # the SDC, (B,)
        speed = jnp.hypot(now.vel_x, now.vel_y)
        accel = -jnp.clip(speed / DT, 0.0, 6.0)
        return env.core.dynamics.normalize(jnp.stack([accel, jnp.zeros_like(accel)], -1))

    @jax.jit
    def episode(pool):
        state = env.reset(pool, 1, jax.random.PRNGKey(0))

        def body(state, _):
            state, out = env.step(state, brake_to_a_stop(state), pool)
            return state, (out, state.sim.sim_trajectory.x[0, :2, state.sim.timestep[0]])
        return jax.lax.scan(body, state, None, length=45)[1]

    out, xs = episode(pool)  # xs (T, 2): the SDC's and the follower's x
    first_done = int(np.argmax(np.asarray(out.done[:, 0])))
    if traffic == "log":  # the logged follower keeps 10 m/s into the stopped SDC
        assert bool(out.terminated[first_done, 0]) and bool(out.episode_flags["overlap"][first_done, 0])
    else:  # IDM slows the follower down behind it; the SDC stands still until the time limit
        assert not bool(jnp.any(out.terminated[:, 0]))
        assert not bool(jnp.any(out.episode_flags["overlap"]))
        sdc_x, follower_x = np.asarray(xs).T
        assert follower_x[-1] + 2.25 < sdc_x[-1] - 2.25 - 1.0  # its front bumper > 1 m behind the SDC's rear one
        assert np.diff(follower_x)[-1] < 0.5 * np.diff(follower_x)[0]  # at well under half its speed


def test_idm_follow_traffic_sees_the_learner_only_while_it_drives_their_way():
    """`train.traffic=idm_follow`: the follower brakes for the SDC ahead on its way, but one that turns across it is
    invisible to it (it crosses or meets it as its log does, as evaluation's replayed traffic)."""
    from vmax_sim.env.agent_view import sdc_seen_only_the_same_way

    state = jax.tree.map(lambda a: a[0], scenarios_to_batch([follower_scenario()],
                                                            small_data_config("", include_agent_paths=True)))
    cos = TRAFFIC_SEES_SDC_COS["idm_follow"]
    t = int(state.timestep)
    seen = sdc_seen_only_the_same_way(state, 1, cos).sim_trajectory.valid
    assert bool(seen[0, t]) and bool(jnp.all(seen == state.sim_trajectory.valid))
    sim = state.sim_trajectory
    across = state.replace(sim_trajectory=sim.replace(yaw=sim.yaw.at[0].set(sim.yaw[0] + np.pi / 2)))
    hidden = sdc_seen_only_the_same_way(across, 1, cos).sim_trajectory.valid
    assert not bool(jnp.any(hidden[0])) and bool(jnp.all(hidden[1] == sim.valid[1]))


def test_idm_traffic_needs_the_agents_paths():
    env = LearningEnv(EnvConfig(max_num_objects=8), traffic=idm_traffic)
    with pytest.raises(ValueError, match=r"traffic while training \(train.traffic\) needs the agents' paths"):
        env.reset(pool(), 1, jax.random.PRNGKey(0))
