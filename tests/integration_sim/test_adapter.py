"""The SimulatorState -> StepInputs / ObservationInputs adapter and the metric-based termination."""

from __future__ import annotations

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from tests.integration_sim.conftest import braking_scenario, cruising_scenario, small_data_config
from vmax_sim.data import scenarios_to_batch
from vmax_sim.env import EnvConfig, make_environment
from vmax_sim.env.metrics_adapter import (
    observation_inputs,
    reference_arcs,
    step_inputs,
    termination_fns,
)


def _state(scenario):
    return jax.tree.map(lambda a: a[0], scenarios_to_batch([scenario], small_data_config("")))


def _shift_sdc(state, dy: float = 0.0, dx: float = 0.0):
    """Moves the SDC's simulated box at the current step."""
    sim = state.sim_trajectory
    t = state.timestep
    return state.replace(sim_trajectory=sim.replace(x=sim.x.at[0, t].add(dx), y=sim.y.at[0, t].add(dy)))


def test_step_inputs_hold_the_sdc_history_and_exclude_its_slot():
    env = make_environment(EnvConfig(max_num_objects=8))
    state = env.reset(_state(cruising_scenario()))  # timestep 10: SDC at x = 10 m, cars at 30 and 50 m
    inputs = step_inputs(state, reference_arcs(state, env.config))
    np.testing.assert_allclose(inputs.sdc_xy[:, 0], [8.0, 9.0, 10.0], atol=1e-4)  # last = now
    np.testing.assert_allclose(inputs.object_boxes[1, :2], [30.0, 0.0], atol=1e-4)
    assert inputs.object_valid.tolist()[:3] == [False, True, True]
    assert not inputs.object_valid[3:].any()  # padded slots
    # path starts at x = -40: the logged start (x = 10) and end (x = 90) arcs
    np.testing.assert_allclose(inputs.path_log_arc[0], [50.0, 130.0], atol=1e-3)
    obs = observation_inputs(state, 5)
    np.testing.assert_allclose(obs.sdc_xy[:, 0], [6.0, 7.0, 8.0, 9.0, 10.0], atol=1e-4)
    assert obs.object_valid[0].tolist() == [False] * 5 and obs.object_valid[1].all()
    np.testing.assert_allclose(obs.sdc_size, [state.sim_trajectory.length[0, 10], state.sim_trajectory.width[0, 10]])


@pytest.mark.slow  # ~11 s on 2 cores: kept out of the 10-minute default suite
def test_termination_predicates_match_hand_placed_boxes():
    fns = termination_fns()
    state = make_environment(EnvConfig(max_num_objects=8)).reset(_state(braking_scenario()))
    assert not fns["collision"](state) and not fns["offroad"](state) and not fns["red_light"](state)
    # the stopped car's rear is at 37.75 m; the SDC's front at x + 2.25
    assert fns["collision"](_shift_sdc(state, dx=35.6 - 10.0))
    assert not fns["collision"](_shift_sdc(state, dx=35.4 - 10.0))
    # the right road edge is at y = -2: the SDC (2 m wide) leaves the road below y = -1
    assert fns["offroad"](_shift_sdc(state, dy=-1.2))
    assert not fns["offroad"](_shift_sdc(state, dy=-0.8))


def test_environment_terminates_only_on_the_named_metrics():
    state = _shift_sdc(make_environment(EnvConfig(max_num_objects=8)).reset(_state(braking_scenario())), dy=-1.5)
    assert bool(make_environment(EnvConfig(max_num_objects=8, terminate_on=("offroad",))).is_terminated(state))
    assert not bool(make_environment(EnvConfig(max_num_objects=8, terminate_on=("collision",))).is_terminated(state))
    assert make_environment(EnvConfig(max_num_objects=8, terminate_on=())).termination_fn is None
    with pytest.raises(ValueError, match="no termination function"):
        make_environment(EnvConfig(max_num_objects=8, terminate_on=("speeding",)))


@pytest.mark.slow  # 8-38 s on 2 cores: the default suite stays under 10 minutes
def test_termination_works_on_batched_states():
    config = small_data_config("")
    batch = scenarios_to_batch([braking_scenario("a"), braking_scenario("b")], config)
    env = make_environment(EnvConfig(max_num_objects=8))
    state = env.reset(batch)
    sim = state.sim_trajectory
    state = state.replace(sim_trajectory=sim.replace(y=sim.y.at[1, 0, 10].add(-1.5)))  # only episode 1 off-road
    assert env.is_terminated(state).tolist() == [False, True]
    assert jnp.asarray(env.is_terminated(state)).shape == (2,)
