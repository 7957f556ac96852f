"""Reactive mode: controllable agents driven along their own paths; collisions among them counted apart."""

from __future__ import annotations

import jax
import numpy as np
import pytest

from tests.evaluation import modes_scenes
from tests.evaluation.modes_scenes import PARKED_X
from tests.integration_sim.conftest import small_data_config
from vmax_sim.data import load_batch
from vmax_sim.env import EnvConfig
from vmax_sim.evaluation import evaluate
from vmax_sim.evaluation.modes import EvalMode
from vmax_sim.evaluation.reactive import choose_agents

WHOLE_EPISODES = EnvConfig(max_num_objects=8, terminate_on=())

parked_shards = modes_scenes.parked_shards  # the fixture


def _run(policy, shards, mode):
    """(EvaluationResult, final simulated x (E, N, T)) of every scenario of `shards`."""
    xs = []
    result = evaluate(policy, small_data_config(shards), mode=mode, env_config=WHOLE_EPISODES,
                      on_batch=lambda ids, batch, rollout, real: xs.append(np.asarray(rollout.trajectory["x"])[:real]))
    return result, np.concatenate(xs)


def test_loader_puts_each_agents_path_in_its_slot(parked_shards):
    state = jax.device_get(load_batch(small_data_config(parked_shards, include_agent_paths=True)))
    paths = state.agent_paths
    assert paths.x.shape == (2, 8, 200)
    has_path = paths.valid.any(-1)
    assert has_path[:, 1].all() and not has_path[:, [0, 2]].any()  # the agent only: not the SDC, not the parked car
    assert paths.on_route[:, 1].tolist() == [True, False]  # the shard's lane path / one built from the log
    fallback = paths.x[1, 1][paths.valid[1, 1]]
    np.testing.assert_allclose(np.diff(fallback), 1.0, atol=1e-4)  # 1 m apart along its logged positions
    assert fallback[0] == pytest.approx(0.0) and fallback[-1] == pytest.approx(90.0)
    slots, valid = choose_agents(jax.tree.map(lambda a: a[0], state), 4, 10)
    assert int(slots[0]) == 1 and valid.tolist() == [True, False, False, False]
    assert load_batch(small_data_config(parked_shards)).agent_paths is None  # not loaded unless asked


@pytest.mark.slow  # 11-13 s of the default suite's 10-minute budget; runs in CI's slow stage
def test_idm_agent_stops_behind_a_parked_car_instead_of_replaying_into_it(parked_shards):
    result, x = _run("expert", parked_shards, "reactive")
    assert result.summary["mode"] == "reactive" and result.summary["mode_options"]["agents"] == "idm"
    assert result.episodes["other_collision"].tolist() == [0.0, 0.0]  # with a lane path and with one from the log
    assert result.episodes["num_agents"].tolist() == [1.0, 1.0]
    rear_bumper = PARKED_X - 2.25
    for episode in x:
        front = episode[1, 10:] + 2.25  # the agent's front bumper over the episode
        assert front.max() < rear_bumper - 1.0  # it never reaches the parked car...
        assert front[-1] > rear_bumper - 6.0 and front[-1] - front[-6] < 0.6  # ...and comes to a halt behind it
        np.testing.assert_allclose(episode[2], PARKED_X)  # the parked car replays its log
    assert result.summary["accuracy"] == 1.0  # the SDC's scores are its own


def test_other_collisions_are_counted_when_the_agents_cannot_react(parked_shards):
    # self-play with the constant-velocity policy: the agent keeps 10 m/s into the parked car
    result, x = _run("constant", parked_shards, EvalMode("reactive", agents="same"))
    assert result.episodes["other_collision"].tolist() == [1.0, 1.0]
    assert result.summary["metrics"]["other_collision"] == 1.0
    assert (x[:, 1, -1] > PARKED_X).all()  # drove through it
    assert result.summary["accuracy"] == 1.0  # not the SDC's collision


@pytest.mark.slow
def test_pdm_agent_stops_behind_a_parked_car(parked_shards):
    result, x = _run("expert", parked_shards, EvalMode("reactive", agents="pdm"))
    assert result.summary["mode_options"]["agents"] == "pdm"
    assert result.episodes["other_collision"].tolist() == [0.0, 0.0]
    assert (x[:, 1, 10:] + 2.25 < PARKED_X - 2.25).all()  # its front bumper never reaches the parked car


def test_learned_traffic_acts_in_the_units_of_the_evaluation_environment(parked_shards):
    """A trained policy acts in [-1, 1], as its training environment took it. Around a rule-based SDC the evaluation
    steps in physical units, so the agent's full brake must arrive as the model's 6 m/s^2 (it arrived as 1 m/s^2,
    and learned traffic rear-ended an IDM SDC in a quarter of the scenes)."""
    import jax.numpy as jnp

    from vmax_sim.datatypes import sdc_action
    from vmax_sim.env import Environment
    from vmax_sim.env.agent_view import agent_view
    from vmax_sim.evaluation.reactive import make_agent_fn
    from vmax_sim.metrics import MetricsConfig
    from vmax_sim.observation import ObservationConfig
    from vmax_sim.policies.base import Policy

    brake = Policy("brake", lambda params, state, observation, key: sdc_action(state, jnp.array([-1.0, 0.5])))
    mode = EvalMode(name="reactive", agents="learned", agent_policy=(brake, None, ObservationConfig()),
                    agent_run="a run")
    state = jax.tree.map(lambda a: a[0], load_batch(small_data_config(parked_shards, include_agent_paths=True)))
    for normalised, expected in ((False, [-6.0, 0.15]), (True, [-1.0, 0.5])):
        env = Environment(EnvConfig(max_num_objects=8, normalize_actions=normalised))
        agent_fn = make_agent_fn(mode, env, None, MetricsConfig(), ObservationConfig())
        action, valid = agent_fn(None, agent_view(state, 1), jax.random.PRNGKey(0))
        np.testing.assert_allclose(action, expected, rtol=1e-6)
        assert bool(valid)


def test_learned_traffic_keeps_behind_its_log_unless_set_free(parked_shards):
    """Learned agents follow the reactive mode's rule for every agent driver (`agent_follow_log`, on by default): a
    policy at full throttle is held at its logged pace (self-play agents faster than their logs ran into the lane
    changes and crossings the log had timed: SDC collisions in 2.3% of scenes against IDM traffic's 0.3%);
    `--agents-free` lets it go at its own."""
    import dataclasses

    import jax.numpy as jnp

    from tests.evaluation.modes_scenes import AGENT_SPEED
    from tests.integration_sim.conftest import DT
    from vmax_sim.datatypes import sdc_action
    from vmax_sim.policies.base import Policy

    throttle = Policy("throttle", lambda params, state, observation, key: sdc_action(state, jnp.array([1.0, 0.0])))
    mode = EvalMode(name="reactive", agents="learned", agent_policy=(throttle, None, None), agent_run="a run")
    capped, free = (_run("expert", parked_shards, dataclasses.replace(mode, agent_follow_log=follow))
                    for follow in (True, False))
    assert capped[0].summary["mode_options"]["agent_follow_log"] is True
    logged = AGENT_SPEED * DT * np.arange(capped[1].shape[-1])  # the agent's logged x at every step
    for episode in capped[1]:
        assert episode[1, 10:].max() > 50.0  # it drives...
        assert (episode[1, 10:] <= logged[10:] + 0.05).all()  # ...never ahead of its log
    assert (free[1][:, 1, -1] > logged[-1] + 20.0).all()  # set free, full throttle takes it far ahead
