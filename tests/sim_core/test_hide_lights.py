"""`hide_lights`: training scenarios read as if recorded without traffic-light states (as most real scenes are)."""

from __future__ import annotations

import dataclasses

import jax
import numpy as np
import pytest
from conftest import make_scenario, small_config

from vmax_sim.data import DataConfig, scenario_to_numpy_state
from vmax_sim.data.convert import lights_hidden
from vmax_sim.env.metrics_adapter import observation_inputs
from vmax_sim.training import apply_overrides, preset_config
from vmax_sim.training.run import data_config, train_data_config


def test_hidden_lights_leave_no_light_and_change_nothing_else():
    scenario = make_scenario(0)
    shown = scenario_to_numpy_state(scenario, small_config())
    hidden = scenario_to_numpy_state(scenario, dataclasses.replace(small_config(), hide_lights=1.0))
    assert shown.log_traffic_light.valid.any()  # the scenario has a light to hide
    lights = hidden.log_traffic_light
    assert lights.state.shape == shown.log_traffic_light.state.shape  # same shapes: one compiled step for both
    assert not lights.valid.any() and not lights.state.any() and (lights.lane_ids == -1).all()
    rest = [jax.tree.leaves(s.replace(log_traffic_light=None)) for s in (shown, hidden)]
    assert all(np.array_equal(a, b) for a, b in zip(*rest))


def test_the_draw_is_fixed_per_scenario_and_near_the_share():
    ids = [f"synthetic-0-{i:06d}" for i in range(2000)]
    draws = [lights_hidden(i, 0.5) for i in ids]
    assert draws == [lights_hidden(i, 0.5) for i in ids]  # the same scenario is always lit or always unlit
    assert 0.45 < np.mean(draws) < 0.55
    assert not any(lights_hidden(i, 0.0) for i in ids) and all(lights_hidden(i, 1.0) for i in ids)
    # a larger share hides a superset: raising it never shows a light that was hidden
    assert all(lights_hidden(i, 0.7) for i, hid in zip(ids, draws) if hid)


def test_only_the_training_stream_hides_lights():
    assert preset_config().data.hide_lights == 0.5  # the default preset reads half its training scenes unlit
    assert preset_config().data.hide_lights_from == "all"  # from its teacher too (sessions 45-48)
    assert preset_config("sac").data.hide_lights == 0.0
    config = apply_overrides(preset_config(), ["data.hide_lights=0.3"])
    assert train_data_config(config, "shards", seed=0).hide_lights == 0.3
    assert data_config(config, "held_out").hide_lights == 0.0  # evaluation shows the lights a record has


@pytest.mark.parametrize("value", ["-0.1", "1.5"])
def test_a_share_outside_zero_to_one_is_refused(value):
    with pytest.raises(ValueError, match="hide_lights must be in"):
        apply_overrides(preset_config(), [f"data.hide_lights={value}"])
    with pytest.raises(ValueError, match="hide_lights must be in"):
        DataConfig(hide_lights=float(value))


def _student_only(share: float) -> DataConfig:
    return dataclasses.replace(small_config(), hide_lights=share, hide_lights_from="student")


def test_lights_hidden_from_the_student_stay_in_the_state_and_leave_its_observation():
    scenario = make_scenario(0)
    shown = scenario_to_numpy_state(scenario, small_config())
    hidden = scenario_to_numpy_state(scenario, _student_only(1.0))
    # the teacher, the traffic and the metrics read the same lights as in a lit scene
    assert all(np.array_equal(a, b) for a, b in zip(jax.tree.leaves(shown.log_traffic_light),
                                                    jax.tree.leaves(hidden.log_traffic_light)))
    assert bool(hidden.lights_hidden) and shown.lights_hidden is None
    seen = observation_inputs(jax.device_put(shown)).light_valid
    assert np.asarray(seen).any()  # the lit scene shows its light
    assert not np.asarray(observation_inputs(jax.device_put(hidden)).light_valid).any()


def test_a_scene_the_draw_leaves_lit_shows_its_lights_to_the_student():
    lit = scenario_to_numpy_state(make_scenario(0), _student_only(1e-9))  # a share no crc32 draw falls under
    assert lit.lights_hidden is not None and not bool(lit.lights_hidden)  # every state of the stream: one pytree
    assert np.asarray(observation_inputs(jax.device_put(lit)).light_valid).any()


def test_whom_the_lights_are_hidden_from_is_a_training_data_setting():
    config = apply_overrides(preset_config(), ["data.hide_lights_from=student"])
    assert train_data_config(config, "shards", seed=0).hide_lights_from == "student"
    assert data_config(config, "held_out").hide_lights == 0.0
    with pytest.raises(ValueError, match="hide_lights_from must be one of"):
        apply_overrides(preset_config(), ["data.hide_lights_from=teacher"])
