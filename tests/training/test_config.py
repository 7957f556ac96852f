"""Presets, key=value overrides and the run directory's config round trip."""

from __future__ import annotations

import pytest

from vmax_sim.agents import PPOConfig, SACConfig
from vmax_sim.training import apply_overrides, config_from_dict, config_to_dict, preset_config
from vmax_sim.training.config import policy_name


def test_preset_names_choose_algorithm_encoder_reward_and_paper_settings():
    config = preset_config("sac-lq-navigation")
    assert (config.algo, config.network.name, config.reward.preset) == ("sac", "lq", "navigation")
    paper = preset_config("paper-ppo-wayformer-behavior")
    assert isinstance(paper.algo_config, PPOConfig) and paper.algo_preset == "paper"
    assert paper.network.name == "wayformer" and paper.reward.preset == "behavior"
    with pytest.raises(ValueError, match="unknown preset word 'transformer'"):
        preset_config("sac-transformer")


def test_overrides_are_typed():
    config = apply_overrides(preset_config("sac"), [
        "algo.learning_rate=3e-4", "algo.buffer_size=1e5", "network.embed_dim=32", "algo.learn_alpha=false",
        "train.total_env_steps=50_000", "reward.weights=collision:-2,progress:0.5", "obs.noise.position_std=0.2",
        "algo.policy_hidden_sizes=128,64", "env.terminate_on=collision,offroad"])
    assert isinstance(config.algo_config, SACConfig)
    assert config.algo_config.learning_rate == 3e-4 and config.algo_config.buffer_size == 100_000
    assert config.algo_config.learn_alpha is False and config.algo_config.policy_hidden_sizes == (128, 64)
    assert config.network.embed_dim == 32 and config.train.total_env_steps == 50_000
    assert config.reward.weights == (("collision", -2.0), ("progress", 0.5))
    assert config.obs.noise.position_std == 0.2 and config.env.terminate_on == ("collision", "offroad")


@pytest.mark.parametrize(("override", "message"), [
    ("algo.learnin_rate=1", "has no field 'learnin_rate'"),
    ("trian.seed=1", "must start with one of"),
    ("train.seed", "not of the form"),
    ("train.total_env_steps=2.5", "expected an integer"),
    ("algo.learn_alpha=maybe", "expected true or false"),
    ("train.pool_refresh=1000", "pool_refresh"),
    ("train.traffic=replay", "train.traffic must be one of log, idm"),
    ("train.traffic_agents=0", "train.traffic_agents must be at least 1"),
])
def test_bad_overrides_fail_in_one_line(override, message):
    with pytest.raises(ValueError, match=message) as error:
        apply_overrides(preset_config("sac"), [override])
    assert "\n" not in str(error.value)


def test_a_check_spanning_two_fields_sees_both_overrides_in_either_order():
    # behaviour cloning on the mode's squared error alone: nll_weight=0 is refused only while mse_weight is 0 too
    for order in (["algo.nll_weight=0", "algo.mse_weight=1"], ["algo.mse_weight=1", "algo.nll_weight=0"]):
        config = apply_overrides(preset_config("bc-dagger"), order)
        assert (config.algo_config.nll_weight, config.algo_config.mse_weight) == (0.0, 1.0)
    with pytest.raises(ValueError, match="nll_weight and mse_weight must be >= 0 and not both 0"):
        apply_overrides(preset_config("bc-dagger"), ["algo.nll_weight=0"])
    with pytest.raises(ValueError, match="train.teacher_speed_factor must be in"):
        apply_overrides(preset_config("bc-dagger"), ["train.teacher_speed_factor=3", "train.teacher=idm"])


def test_idm_traffic_is_a_training_option_that_self_play_refuses():
    from vmax_sim.training.run import components, train_data_config

    config = apply_overrides(preset_config("bc-mlp"), ["train.traffic=idm", "train.traffic_agents=4"])
    env, _ = components(config)
    from vmax_sim.policies.traffic import idm_traffic

    assert (env.traffic, env.traffic_agents) == (idm_traffic, 4)
    passing, _ = components(apply_overrides(config, ["train.traffic=idm_pass"]))
    assert passing.traffic.func is idm_traffic and passing.traffic.keywords["standing_clearance"] > 0
    assert train_data_config(apply_overrides(config, ["train.traffic=idm_pass"]), "shards", 0).include_agent_paths
    both, _ = components(apply_overrides(config, ["train.traffic=idm_follow_pass"]))  # passing, and blind across
    assert both.traffic.keywords["standing_clearance"] > 0 and 0 < both.traffic_sees_sdc_cos < 1
    assert train_data_config(config, "shards", 0).include_agent_paths  # the agents' own routes are loaded
    assert not train_data_config(preset_config("bc-mlp"), "shards", 0).include_agent_paths
    with pytest.raises(ValueError, match="choose one"):
        apply_overrides(preset_config("ppo-selfplay"), ["train.traffic=idm"])


def test_switching_algorithm_resets_its_config():
    config = apply_overrides(preset_config("sac"), ["algo=ppo", "algo.num_epochs=2"])
    assert isinstance(config.algo_config, PPOConfig) and config.algo_config.num_epochs == 2


@pytest.mark.parametrize("name", ["sac-lq", "paper-ppo-mtr", "bc-none-safety", "bc_sac-lqh-behavior"])
def test_config_round_trips_through_json(name):
    config = apply_overrides(preset_config(name), ["reward.weights=speed:0.1", "obs.noise.occlusion=true"])
    assert config_from_dict(config_to_dict(config)) == config


def test_chunk_and_pool_refresh_defaults_follow_the_algorithm():
    from vmax_sim.training.config import chunk_steps, pool_refresh

    sac, ppo = preset_config("sac"), preset_config("ppo")
    # 16 envs x 25 steps = 400 env steps, each action held 4 simulator steps: 1,600 simulator steps, ~20 episodes
    assert (chunk_steps(sac), pool_refresh(sac)) == (25, 20)
    # one ppo update is 2,560 env steps of 4 simulator steps (~128 episodes): the whole pool is fresh after every
    # update, so no scenario is driven dozens of times over (a fixed 4 per 25-update chunk overfitted the pool)
    assert (chunk_steps(ppo), pool_refresh(ppo)) == (1, 64)
    assert pool_refresh(apply_overrides(sac, ["train.action_repeat=1"])) == 5  # one step per action: ~5 episodes
    fixed = apply_overrides(ppo, ["train.chunk_steps=3", "train.pool_refresh=2"])
    assert (chunk_steps(fixed), pool_refresh(fixed)) == (3, 2)
    assert config_from_dict(config_to_dict(ppo)).train.pool_refresh is None  # "auto" survives config.json


def test_defaults_are_what_learns_best_here_and_paper_keeps_the_paper():
    from vmax_sim.training.config import action_repeat

    sac, ppo, bc = preset_config("sac"), preset_config("ppo"), preset_config("bc")
    assert (sac.network.name, action_repeat(sac), sac.algo_config.gamma) == ("mlp", 4, 0.96)
    assert (ppo.network.name, action_repeat(ppo), ppo.algo_config.gamma) == ("mlp", 4, 0.96)
    assert ppo.algo_config.transitions_per_update == 2_560  # 16 sequences x 4 minibatches x 40 steps
    assert (bc.network.name, action_repeat(bc)) == ("mlp", 1)
    paper = preset_config("paper-sac-lq")
    assert (paper.network.name, action_repeat(paper), paper.algo_config.gamma) == ("lq", 1, 0.99)
    assert action_repeat(apply_overrides(sac, ["train.action_repeat=2"])) == 2
    assert config_from_dict(config_to_dict(sac)).train.action_repeat is None  # "auto" survives config.json


def test_the_dagger_preset_is_the_documented_bc_recipe_and_overrides_still_apply():
    config = preset_config("bc-dagger")
    assert (config.algo, config.network.name) == ("bc", "mlp")
    assert (config.train.teacher, config.train.traffic) == ("pdm_state", "idm_follow_pass")  # sessions 47-48, 79
    # parked cars up to 1.5 m nearer the lanes, which that traffic passes: the student creeps less past them (s79)
    assert config.data.synthetic.parked_reach == (0.0, 1.5)
    assert (config.algo_config.student_drive, config.algo_config.student_mix) == (0.5, "episode")
    assert config.algo_config.updates_per_step == 4  # half of BC's: steadier on real scenes (docs/learning.md)
    assert config.algo_config.buffer_size == 500_000 and config.obs.object_selection == "route"  # = its steps
    assert config.data.synthetic.sdc_slow_start == 1.0 and config.data.synthetic.max_parked == 40
    # checkpoints carry the 2.9 GB buffer: far apart; past 500k env steps the real scenes fell (session 77)
    assert (config.train.checkpoint_every, config.train.total_env_steps) == (100_000, 500_000)
    # a brake that stops the car, and the last four checkpoints driving as one (docs/learning.md)
    assert (config.env.dynamics, config.train.ensemble, config.train.ensemble_every) == ("bicycle_no_reverse", 4, None)
    # a fresh quarter of the map's points hidden in each training observation: steadier on real scenes
    assert config.obs.noise.map_dropout == 0.25 and config.obs.noise.active
    # PDM-Closed's emergency brake over the student where it drives, and its name says so (docs/learning.md)
    assert config.train.brake_guard_ttc == 2.0 and policy_name(config) == "bc-mlp+guard"
    assert config.train.brake_guard_hold  # ... which also stops it speeding up into what is ahead (session 79)
    # objects read along and across the SDC's route (sessions 66-68: two guarded hours, seeds 0 and 2)
    assert config.obs.object_route_frame and not preset_config("bc").obs.object_route_frame
    assert preset_config("dagger") == config
    # a user's override wins over the preset's
    assert apply_overrides(config, ["algo.buffer_size=50000"]).algo_config.buffer_size == 50_000
    with pytest.raises(ValueError, match="dagger trains with bc: 'sac-dagger' names sac"):
        preset_config("sac-dagger")


def test_vmax_sim_train_without_a_preset_runs_the_dagger_recipe():
    from click.testing import CliRunner

    from vmax_cli.vmax_cli import main
    from vmax_sim.training.config import DEFAULT_PRESET

    assert DEFAULT_PRESET == "bc-dagger" and preset_config() == preset_config("bc-dagger")
    shown = CliRunner().invoke(main, ["train", "--help"], terminal_width=200).output
    assert "[default: bc-dagger]" in " ".join(shown.split()), shown
