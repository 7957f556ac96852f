"""Adversarial mode: one vehicle re-planned (by gradient through the bicycle rollout) to cut in on the SDC,
always inside its kinematic bounds, never from behind, and the evaluated SDC meets it."""

from __future__ import annotations

import dataclasses

import jax
import numpy as np
import pytest

import scenariomax
from tests.integration_sim.conftest import DT, NUM_STEPS, SMALL_SIZES, road_scenario, small_data_config
from tests.training.conftest import synthetic_shards  # noqa: F401 - a fixture (12 enriched synthetic scenes)
from vmax_sim.data import DataConfig, scenario_to_state, scenarios_to_batch
from vmax_sim.dynamics.bicycle import bicycle_inverse_step, heading_speed
from vmax_sim.env import EnvConfig, Environment
from vmax_sim.evaluation import evaluate
from vmax_sim.evaluation.adversary import plan_adversary
from vmax_sim.evaluation.modes import AdversaryConfig, EvalMode

FIRST, EPISODE = 10, 80
CONFIG = AdversaryConfig()
ENV = EnvConfig(max_num_objects=8)


def side_by_side(scenario_id: str = "side") -> scenariomax.Scenario:
    """The SDC at 10 m/s along y = 0; a car in the next lane (y = 3.5 m) 8 m ahead at the same speed."""
    time = np.arange(NUM_STEPS) * DT
    scenario = road_scenario(scenario_id, np.stack([10.0 * time, 8.0 + 10.0 * time]), np.full((2, NUM_STEPS), 10.0))
    return dataclasses.replace(scenario, y=np.stack([np.zeros(NUM_STEPS), np.full(NUM_STEPS, 3.5)]).astype(np.float32))


def follower(scenario_id: str = "behind") -> scenariomax.Scenario:
    """The SDC at 10 m/s; a car 6 m behind it (1.5 m bumper to bumper) in its lane at the same speed."""
    time = np.arange(NUM_STEPS) * DT
    return road_scenario(scenario_id, np.stack([10.0 * time, -6.0 + 10.0 * time]), np.full((2, NUM_STEPS), 10.0))


def planned(scenario: scenariomax.Scenario, config: AdversaryConfig = CONFIG):
    state = Environment(ENV).reset(scenario_to_state(scenario, small_data_config("unused")))
    new, info = jax.jit(lambda s: plan_adversary(s, config, FIRST, EPISODE))(state)
    return state, new, {k: float(v) for k, v in info.items()}


def assert_within_bounds(log, slot: int, config: AdversaryConfig):
    """Speed, acceleration, curvature, lateral acceleration and curvature rate of the written future."""
    row = jax.tree.map(lambda a: np.asarray(a[slot]), log)
    speed = np.asarray(heading_speed(log))[slot]
    future = np.arange(FIRST, FIRST + EPISODE + 1)
    assert row.valid[future].all()
    accel = np.diff(speed[future]) / DT
    assert accel.max() <= config.max_accel + 1e-3 and accel.min() >= -config.max_decel - 1e-3
    assert speed[future].min() >= -1e-4
    take = lambda t: jax.tree.map(lambda a: a[slot, t][None, None], log)  # noqa: E731
    curvature = np.array([float(bicycle_inverse_step(take(t), take(t + 1))[0, 1]) for t in future[:-1]])
    moving = np.minimum(speed[future[:-1]], speed[future[1:]]) > 0.5  # curvature is ill-defined near standstill
    assert np.abs(curvature[moving]).max() <= config.max_curvature + 1e-3
    fastest = np.maximum(speed[future[:-1]], speed[future[1:]])
    assert (fastest**2 * np.abs(curvature))[moving].max() <= config.max_lateral_accel * 1.01
    both = moving[1:] & moving[:-1]
    assert np.abs(np.diff(curvature))[both].max() <= config.max_curvature_rate + 1e-3  # no swinging turns


@pytest.mark.slow  # ~11 s on 2 cores: kept out of the 10-minute default suite
def test_a_car_in_the_next_lane_is_replanned_into_a_feasible_cut_in():
    state, new, info = planned(side_by_side())
    assert info["adversary_found"] == 1.0 and info["adversary_slot"] == 1.0
    assert info["adversary_contact_step"] >= CONFIG.min_contact_step  # the SDC gets 1.5 s to react
    log, old = new.log_trajectory, state.log_trajectory
    contact = FIRST + int(info["adversary_contact_step"])
    assert float(log.y[1, contact]) < 2.0  # it has left its lane (y = 3.5) towards the SDC's (y = 0)
    assert np.array_equal(np.asarray(log.x[1, :FIRST + 1]), np.asarray(old.x[1, :FIRST + 1]))  # history kept
    assert np.array_equal(np.asarray(log.x[0]), np.asarray(old.x[0]))  # the SDC's log is untouched
    assert_within_bounds(log, 1, CONFIG)


@pytest.mark.slow  # ~14 s on 2 cores: kept out of the 10-minute default suite
def test_a_follower_is_never_turned_into_a_rear_end_attack():
    # top speed 1.05 x its logged 10 m/s: it cannot come alongside within the episode, only hit the rear
    _, new, info = planned(follower(), dataclasses.replace(CONFIG, speed_factor=1.05, min_max_speed=1.0))
    assert info["adversary_rear_end"] == 1.0  # the plan did reach the SDC ... from behind: rejected
    assert info["adversary_found"] == 0.0 and info["adversary_slot"] == -1.0


@pytest.mark.slow  # 8-38 s on 2 cores: the default suite stays under 10 minutes
def test_the_evaluated_sdc_meets_the_adversary(tmp_path):
    scenariomax.write_shards([side_by_side("side"), follower("behind")], tmp_path, sizes=SMALL_SIZES)
    data = small_data_config(tmp_path)
    logged = evaluate("expert", data, mode=EvalMode("adversarial"), env_config=ENV)
    plain = evaluate("expert", data, env_config=ENV)
    assert logged.summary["mode"] == "adversarial" and logged.summary["mode_options"]["max_accel"] == 3.0
    by_id = dict(zip(logged.scenario_ids, logged.episodes["overlap"].tolist()))
    found = dict(zip(logged.scenario_ids, logged.episodes["adversary_found"].tolist()))
    assert found == {"side": 1.0, "behind": 0.0}
    assert by_id == {"side": 1.0, "behind": 0.0}  # the log-replaying SDC cannot avoid the cut-in
    assert plain.episodes["overlap"].tolist() == [0.0, 0.0]  # and nothing collides without the adversary


@pytest.mark.slow
def test_every_attack_on_synthetic_scenes_stays_within_the_bounds(synthetic_shards):  # noqa: F811
    config = DataConfig(path=str(synthetic_shards), batch_size=4, num_objects=16)
    env = Environment(EnvConfig(max_num_objects=16))
    states = scenarios_to_batch(scenariomax.read_shards(synthetic_shards), config)
    new, info = jax.jit(jax.vmap(lambda s: plan_adversary(env.reset(s), CONFIG, FIRST, EPISODE)))(states)
    found = np.flatnonzero(np.asarray(info["adversary_found"]) == 1.0)
    assert len(found) >= 3, info["adversary_found"]
    for i in found:
        log = jax.tree.map(lambda a, i=i: a[i], new.log_trajectory)
        assert_within_bounds(log, int(info["adversary_slot"][i]), CONFIG)


@pytest.mark.slow  # 10-14 s of the default suite's 10-minute budget; runs in CI's slow stage
def test_the_viewer_draws_the_adversary_where_it_drove(tmp_path):
    import base64
    import re

    from click.testing import CliRunner

    from scenariomax.view import unpack_scene
    from vmax_cli.vmax_cli import main

    scenariomax.write_shards([side_by_side("side")], tmp_path / "shards", sizes=SMALL_SIZES)
    out = tmp_path / "page.html"
    result = CliRunner().invoke(main, ["evaluate", "--policy", "expert", "--data", str(tmp_path / "shards"),
                                       "--num-objects", "8", "--mode", "adversarial", "--view", str(out), "--quiet"])
    assert result.exit_code == 0, result.output
    (blob,) = re.findall(r'<script type="application/octet-stream" id="scene-\d+">([^<]*)</script>', out.read_text())
    meta, arrays = unpack_scene(base64.b64decode(blob))
    row = meta["object_ids"].index(101)  # the car logged in the next lane (y = 3.5 m)
    y = (arrays["obj_y"].reshape(meta["num_objects"], -1)[row] * meta["scale"] + meta["origin"][1])
    assert abs(y[FIRST] - 3.5) < 0.05 and y[FIRST + 40] < 2.0  # logged start, then the cut-in, as simulated
    assert "re-planned adversary is drawn where it drove" in out.read_text()
