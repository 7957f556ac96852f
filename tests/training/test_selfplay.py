"""Self-play: one policy drives the SDC and the controllable agents; per-agent rewards, terminations, goals, masks."""

from __future__ import annotations

import csv
import dataclasses
import json
import subprocess
import sys
from pathlib import Path

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from tests.evaluation import modes_scenes
from tests.evaluation.modes_scenes import PARKED_X
from tests.integration_sim.conftest import small_data_config
from tests.training.conftest import tiny_config
from vmax_sim.data import load_batch
from vmax_sim.env import EnvConfig
from vmax_sim.env.selfplay import SelfPlayConfig, SelfPlayEnv
from vmax_sim.evaluation.modes import EvalMode
from vmax_sim.evaluation.selfplay import SelfPlayResult, format_selfplay
from vmax_sim.observation import ObservationConfig
from vmax_sim.training import apply_overrides, preset_config, train
from vmax_sim.training.config import config_from_dict, config_to_dict

parked_shards = modes_scenes.parked_shards  # the fixture
K = 3  # agent slots: the SDC, the controllable agent, one empty slot


def _rollout(shards, crashed: str, steps: int = 85, at_goal: str = "leave"):
    """Zero actions (hold speed, straight) for `steps` steps: (outputs stacked over time, x of every object)."""
    pool = load_batch(small_data_config(shards, include_agent_paths=True))
    env = SelfPlayEnv(EnvConfig(max_num_objects=8),
                      selfplay=SelfPlayConfig(max_agents=K, crashed=crashed, at_goal=at_goal))
    state = jax.jit(env.reset, static_argnums=1)(pool, 2, jax.random.PRNGKey(0))
    step = jax.jit(env.step)
    outs, xs = [], []
    for _ in range(steps):
        state, out = step(state, jnp.zeros((2 * K, env.action_dim)), pool)
        outs.append(jax.device_get(out))
        xs.append(np.asarray(state.sim.current_sim_trajectory.x[..., 0]))
    stacked = jax.tree.map(lambda *a: np.stack(a), *outs)
    return state, stacked, np.stack(xs)


@pytest.fixture(scope="module")
def removed(parked_shards):
    return _rollout(parked_shards, "remove")


def test_agents_are_the_sdc_then_the_controllable_ones_and_empty_slots_are_masked(parked_shards):
    pool = load_batch(small_data_config(parked_shards, include_agent_paths=True))
    env = SelfPlayEnv(EnvConfig(max_num_objects=8), selfplay=SelfPlayConfig(max_agents=K))
    state = jax.jit(env.reset, static_argnums=1)(pool, 2, jax.random.PRNGKey(0))
    assert state.slots[:, :2].tolist() == [[0, 1], [0, 1]]  # the SDC, then the agent (the parked car is not one)
    assert state.active.tolist() == [[True, True, False]] * 2
    assert jax.tree.leaves(state.observation)[0].shape[0] == 2 * K  # one learner row per (scene, agent slot)
    np.testing.assert_allclose(state.goal_xy[0, 1], [90.0, 0.0])  # the agent's last logged position


def test_the_preset_packs_every_roadgraph_point_of_the_synthetic_maps_into_fewer_slots(synthetic_shards):
    """ppo-selfplay gives each agent's in-box roadgraph points 96 slots instead of the observation window's 200 (the
    encoder runs on every slot): on the synthetic maps every agent still sees every point, in the same order."""
    preset = preset_config("ppo-selfplay")
    assert preset.obs.num_roadgraph_points == 96
    pool = load_batch(small_data_config(synthetic_shards, batch_size=12, num_objects=16, num_roadgraph_points=30000,
                                        include_agent_paths=True))

    def first_observation(obs_config: ObservationConfig):
        env = SelfPlayEnv(EnvConfig(max_num_objects=16), obs_config=obs_config, selfplay=SelfPlayConfig(max_agents=8))
        state = jax.jit(env.reset, static_argnums=1)(pool, 12, jax.random.PRNGKey(0))
        return jax.device_get(state.observation), np.asarray(state.present).reshape(-1)

    window, present = first_observation(dataclasses.replace(preset.obs, num_roadgraph_points=None))
    packed, _ = first_observation(preset.obs)
    assert window.roadgraph.shape[1] == 200 and packed.roadgraph.shape[1] == 96
    assert present.sum() >= 24 and window.roadgraph_valid[present].sum(-1).max() > 48  # agents with maps in view
    for row in np.flatnonzero(present):
        np.testing.assert_array_equal(packed.roadgraph[row][packed.roadgraph_valid[row]],
                                      window.roadgraph[row][window.roadgraph_valid[row]])
    np.testing.assert_array_equal(packed.objects, window.objects)  # nothing else changes
    np.testing.assert_array_equal(packed.path_targets, window.path_targets)


@pytest.mark.slow  # with the next test, its rollout (~35 s) on 2 cores: kept out of the 10-minute default suite
def test_an_agent_that_crashes_ends_its_episode_and_leaves_the_scene(removed):
    _, out, xs = removed
    agent = out.terminated[:, 1]
    crash = int(np.argmax(agent))
    assert agent.any() and out.episode_flags["overlap"][crash, 1]  # it drove into the parked car
    assert out.reward[crash, 1] < -0.5  # the collision penalty, its own
    assert not out.active[crash + 1:crash + 20, 1].any()  # then it no longer acts...
    assert not out.terminated[crash + 1:crash + 20, 1].any()  # ...nor ends another episode
    assert not out.active[:, 2].any() and not out.done[:, 2].any()  # the empty slot never carries experience
    front = xs[:crash + 1, 0, 1] + 2.25
    assert front.max() > PARKED_X - 2.25  # it really reached the parked car


@pytest.mark.slow  # shares the rollout above on 2 cores: kept out of the 10-minute default suite
def test_the_sdc_reaches_its_goal_and_the_scene_restarts(removed):
    _, out, _ = removed
    goal_step = int(np.argmax(out.episode_flags["goal_reached"][:, 0]))
    assert out.episode_flags["goal_reached"][goal_step, 0] and out.terminated[goal_step, 0]
    assert out.reward[goal_step, 0] > 1.0  # the goal bonus on top of progress
    assert not out.episode_flags["overlap"][:, 0].any()
    assert out.scene_done[goal_step].all()  # nobody left acting: both scenes restart
    assert out.active[goal_step + 1].tolist() == [True, True, False] * 2  # with their agents back


@pytest.mark.slow  # a second compilation of the step (~35 s)
def test_a_crashed_agent_can_stay_as_a_still_obstacle(parked_shards, removed):
    _, out, xs = _rollout(parked_shards, "obstacle", steps=60)
    crash = int(np.argmax(out.terminated[:, 1]))
    np.testing.assert_allclose(xs[crash:, 0, 1], xs[crash, 0, 1])  # stays where it crashed
    _, _, removed_xs = removed
    assert crash == int(np.argmax(removed[1].terminated[:, 1]))  # same crash either way


@pytest.mark.slow  # another compilation of the step (~35 s)
def test_a_goal_reacher_can_drive_on_to_the_time_limit(parked_shards, removed):
    """`selfplay.at_goal=drive_on`: the SDC gets its goal reward once, keeps driving (and learning) past its goal,
    and its episode ends at the scene's time limit with the goal counted."""
    _, left, _ = removed
    goal_step = int(np.argmax(left.episode_flags["goal_reached"][:, 0]))
    _, out, xs = _rollout(parked_shards, "remove", steps=goal_step + 10, at_goal="drive_on")
    assert not out.terminated[:, 0].any()  # the goal no longer ends its episode
    end = int(np.flatnonzero(out.truncated[:, 0])[0])  # the scene's time limit (then it restarts)
    assert end > goal_step + 1 and out.active[goal_step + 1:end + 1, 0].all()
    assert xs[end - 1, 0, 0] > xs[goal_step, 0, 0] + 0.5  # it drove on past its goal
    assert int(np.sum(out.reward[:end + 1, 0] > 1.0)) == 1  # one goal reward, no approach term after it
    assert out.episode_flags["goal_reached"][end, 0]  # counted when the scene's time is up


@pytest.mark.slow  # a third compilation of the step, with IDM on every agent's view (~40 s)
def test_a_teacher_labels_every_agent_and_drives_them_round_the_parked_car(parked_shards):
    """`SelfPlayEnv(teacher=...)` runs the rule driver on each agent's own view: its labels fill the rows of the
    agents (none for the empty slot), and driven by them (evaluation with no policy) the agent that zero actions
    drove into the parked car stops behind it, while the SDC still reaches its goal."""
    from vmax_sim.evaluation.selfplay import episode_outcomes
    from vmax_sim.policies.teacher import idm_teacher

    pool = load_batch(small_data_config(parked_shards, include_agent_paths=True))
    env = SelfPlayEnv(EnvConfig(max_num_objects=8), selfplay=SelfPlayConfig(max_agents=K), teacher=idm_teacher)
    state = jax.jit(env.reset, static_argnums=1)(pool, 2, jax.random.PRNGKey(0))
    labels = np.asarray(state.expert_action).reshape(2, K, -1)
    assert np.abs(labels[:, :2]).max() > 0.01 and np.all(labels[:, 2] == 0)  # agents labelled, the empty slot not
    outcomes = jax.device_get(jax.jit(lambda scenes, key: episode_outcomes(env, None, None, scenes, key))(
        pool, jax.random.PRNGKey(0)))
    assert not outcomes["overlap"][:, 1].any()  # it braked for the parked car
    assert outcomes["goal_reached"][:, 0].all() and not outcomes["overlap"][:, 0].any()
    with pytest.raises(ValueError, match="teacher"):  # no policy and no teacher: nothing would drive
        episode_outcomes(SelfPlayEnv(EnvConfig(max_num_objects=8)), None, None, pool, jax.random.PRNGKey(0))


@pytest.mark.slow  # one more compilation of the step, with IDM driving the ruled SDCs (~40 s)
def test_ruled_agents_are_driven_by_the_rule_and_teach_nothing(parked_shards, removed):
    """`selfplay.rule_sdc` / `rule_agents`: IDM drives that share of SDCs / other agents; their rows carry no
    experience and end no episode, while the agents beside them still learn."""
    from vmax_sim.policies.teacher import idm_teacher

    pool = load_batch(small_data_config(parked_shards, include_agent_paths=True))
    shares = SelfPlayConfig(max_agents=K, rule_sdc=0.5, rule_agents=0.25)
    half = SelfPlayEnv(EnvConfig(max_num_objects=8), selfplay=shares, rule_driver=idm_teacher)
    drawn = jax.jit(half.reset, static_argnums=1)(pool, 400, jax.random.PRNGKey(1)).ruled
    assert 0.4 < float(np.mean(drawn[:, 0])) < 0.6 and 0.2 < float(np.mean(drawn[:, 1:])) < 0.3  # drawn per agent
    env = SelfPlayEnv(EnvConfig(max_num_objects=8), selfplay=SelfPlayConfig(max_agents=K, rule_sdc=1.0),
                      rule_driver=idm_teacher)
    state = jax.jit(env.reset, static_argnums=1)(pool, 2, jax.random.PRNGKey(0))
    assert state.ruled[:, 0].all() and not state.ruled[:, 1:].any()
    step = jax.jit(env.step)
    outs, xs = [], []
    for _ in range(30):
        state, out = step(state, jnp.zeros((2 * K, env.action_dim)), pool)
        outs.append(jax.device_get(out))
        xs.append(np.asarray(state.sim.current_sim_trajectory.x[..., 0]))
    out = jax.tree.map(lambda *a: np.stack(a), *outs)
    assert not out.active[:, 0].any() and not out.done[:, 0].any()  # the ruled SDC teaches nothing
    assert out.active[0, 1]  # the agent beside it does
    zero_action_x = removed[2][:30, 0, 0]  # the same SDC under zero actions
    assert np.abs(np.stack(xs)[:, 0, 0] - zero_action_x).max() > 0.5  # it moved by the rule, not by the policy


def test_rule_shares_are_shares_and_need_a_driver():
    with pytest.raises(ValueError, match="rule_sdc"):
        SelfPlayConfig(rule_sdc=1.5)
    with pytest.raises(ValueError, match="rule_agents"):
        SelfPlayConfig(rule_agents=-0.1)
    with pytest.raises(ValueError, match="rule_driver"):
        SelfPlayEnv(EnvConfig(max_num_objects=8), selfplay=SelfPlayConfig(rule_sdc=0.5))


def test_ppo_imitates_a_teacher_only_when_asked_and_in_any_order():
    untaught = apply_overrides(preset_config("ppo-selfplay"), ["algo.imitation_coef=0", "train.teacher=log",
                                                               "train.teacher_speed_factor=1"])
    taught = apply_overrides(untaught, ["train.teacher=idm", "train.teacher_speed_factor=1.4",
                                        "algo.imitation_coef=1.0"])  # the teacher named before the coefficient
    assert taught.train.teacher == "idm" and taught.algo_config.imitation_coef == 1.0
    with pytest.raises(ValueError, match="imitation_coef"):
        apply_overrides(untaught, ["train.teacher=idm"])  # PPO would not read the labels
    with pytest.raises(ValueError, match="rule teacher"):
        apply_overrides(untaught, ["algo.imitation_coef=1.0"])  # self-play has no log labels
    with pytest.raises(ValueError, match="teacher_speed_factor sets the idm teacher's driving"):
        apply_overrides(taught, ["train.teacher_speed_factor=1.7", "train.teacher=pdm"])  # the pace is idm's
    swapped = apply_overrides(taught, ["train.teacher=pdm"]).train  # the preset's idm settings go with idm
    assert (swapped.teacher, swapped.teacher_speed_factor, swapped.teacher_max_accel) == ("pdm", 1.0, None)


def test_the_selfplay_preset_is_ppo_over_every_controllable_agent():
    config = preset_config("ppo-selfplay")
    assert config.algo == "ppo" and config.env.controlled == "controllable" and config.is_selfplay
    assert config.agents_per_env == config.selfplay.max_agents == 8
    assert config.reward.preset == "safety" and config.selfplay.approach_reward > 0  # the goal, not binary progress
    assert config.train.teacher == "idm" and config.algo_config.imitation_coef > 0  # taught by IDM on every agent
    assert config.algo_config.ema_decay > 0  # the moving average is what is evaluated (checkpoints swing)
    assert config.selfplay.at_goal == "drive_on"  # goal reachers keep driving, as traffic must
    assert preset_config("ppo-selfplay-navigation").reward.preset == "navigation"
    assert preset_config("ppo").reward.preset == "navigation" and not preset_config("ppo").is_selfplay
    changed = apply_overrides(config, ["selfplay.max_agents=4", "selfplay.crashed=obstacle"])
    assert config_from_dict(config_to_dict(changed)).selfplay == changed.selfplay
    with pytest.raises(ValueError, match="names ppo and sac"):
        preset_config("sac-ppo-selfplay")
    with pytest.raises(ValueError, match="self-play trains with ppo"):
        preset_config("bc-selfplay")  # behaviour cloning over agents is bc-dagger-selfplay
    with pytest.raises(ValueError, match="selfplay.crashed"):
        apply_overrides(config, ["selfplay.crashed=vanish"])
    with pytest.raises(ValueError, match="selfplay.at_goal"):
        apply_overrides(config, ["selfplay.at_goal=stop"])


def test_the_dagger_selfplay_preset_is_bc_over_every_agent_taught_by_idm():
    config = preset_config("bc-dagger-selfplay")
    ppo = preset_config("ppo-selfplay")
    assert config.algo == "bc" and config.is_selfplay and config.agents_per_env == 8
    assert config.train.teacher == ppo.train.teacher and config.train.teacher_speed_factor == 1.4
    assert config.selfplay == ppo.selfplay and config.env == ppo.env and config.reward == ppo.reward
    assert config.algo_config.student_drive == 0.5 and config.algo_config.student_mix == "episode"
    assert config.algo_config.num_envs == ppo.algo_config.num_envs
    assert preset_config("dagger-selfplay") == config
    with pytest.raises(ValueError, match="dagger trains with bc"):
        preset_config("ppo-dagger-selfplay")
    with pytest.raises(ValueError, match="bc needs a rule teacher"):
        apply_overrides(config, ["train.teacher_speed_factor=1", "train.teacher=log"])


@pytest.mark.slow  # ~1 min each: an off-policy self-play run on 16-object synthetic scenes
@pytest.mark.parametrize("algo", ["sac", "bc_sac"])
def test_sac_over_agents_learns_from_every_agent_row_and_reports_goals(synthetic_shards, tmp_path, algo):
    """`sac-selfplay` / `bc_sac-selfplay`: SAC's updates read the agent rows of a replay of every slot (the losses
    masked to them: tests/agents/test_sac.py), and the run reports self-play's per-agent evaluation."""
    teacher = ("train.teacher=idm",) if algo == "bc_sac" else ()
    config = tiny_config(synthetic_shards, algo, "env.controlled=controllable", "selfplay.max_agents=4",
                         "algo.batch_size=8", "algo.learning_starts=8", "train.total_env_steps=40",
                         "train.chunk_steps=1", *teacher)
    result = train(config, tmp_path / "run", progress=False, print_fn=lambda line: None)
    assert result.summary["finished"]
    with open(tmp_path / "run" / "metrics.csv") as f:
        rows = list(csv.DictReader(f))
    assert float(rows[0]["agent_steps"]) > float(rows[0]["env_steps"])  # several agents act in a scene
    learned = [row for row in rows if float(row["updates"]) > 0]
    assert learned and all(np.isfinite(float(row["learner/critic_loss"])) for row in learned)
    selfplay = result.summary["selfplay_evaluation"]
    assert selfplay["num_scenes"] == 4 and selfplay["num_agents"] >= 4


def test_off_policy_selfplay_presets():
    sac, bc_sac = preset_config("sac-selfplay"), preset_config("bc_sac-selfplay")
    assert (sac.algo, bc_sac.algo) == ("sac", "bc_sac") and sac.is_selfplay and bc_sac.is_selfplay
    assert sac.train.teacher == "log" and bc_sac.train.teacher == "idm"  # BC+SAC imitates self-play's teacher
    assert sac.algo_config.num_envs == preset_config("ppo-selfplay").algo_config.num_envs
    assert sac.algo_config.buffer_size == 400_000  # 64 rows a scene step: SAC's 100k would hold ~1,600 of them


@pytest.mark.slow  # ~1 min: a bc-dagger self-play run on 16-object synthetic scenes
def test_dagger_selfplay_run_keeps_every_agent_row_and_reports_goals(synthetic_shards, tmp_path):
    config = tiny_config(synthetic_shards, "bc", "env.controlled=controllable", "selfplay.max_agents=4",
                         "train.teacher=idm", "algo.student_drive=0.5", "algo.student_mix=episode",
                         "algo.student_after=8", "algo.batch_size=8", "train.total_env_steps=40", "train.chunk_steps=1")
    lines = []
    result = train(config, tmp_path / "run", progress=False, print_fn=lines.append)
    assert result.summary["finished"]
    rows = config.algo_config.num_envs * 4
    assert any(f"replay buffer: {config.algo_config.buffer_size:,} transitions" in line for line in lines)
    with open(tmp_path / "run" / "metrics.csv") as f:
        first = next(csv.DictReader(f))
    assert float(first["agent_steps"]) > float(first["env_steps"])  # several agents act in a scene
    assert float(first["agent_steps"]) <= rows * float(first["env_steps"]) / config.algo_config.num_envs
    selfplay = result.summary["selfplay_evaluation"]
    assert selfplay["num_scenes"] == 4 and selfplay["num_agents"] >= 4


def test_selfplay_summary_counts_agents_and_scenes():
    agents = {"goal_reached": np.array([True, True, False, True]), "overlap": np.array([False, True, False, False]),
              "offroad": np.array([False, False, True, False]), "red_light": np.zeros(4, bool),
              "length": np.array([30, 12, 5, 40]), "scene": np.array([0, 0, 1, 2])}
    summary = SelfPlayResult(agents=agents, scene_ids=["a", "b", "c"]).summary()
    assert summary["num_agents"] == 4 and summary["agents_per_scene"] == pytest.approx(4 / 3)
    assert summary["goal_reached"] == 0.75 and summary["goal_reached_clean"] == 0.5  # the second crashed after
    assert summary["collision_or_offroad"] == 0.5
    assert summary["scenes_all_agents_clean_goal"] == pytest.approx(1 / 3)  # only scene 2
    assert "goal reached (higher is better)" in format_selfplay(summary)


def test_learned_traffic_needs_a_trained_policy():
    with pytest.raises(ValueError, match="training run directory"):
        EvalMode(name="reactive", agents="learned")


@pytest.mark.slow  # ~2 min: a self-play ppo run on 16-object synthetic scenes, then its policy as traffic
def test_selfplay_run_logs_agent_steps_and_goals_then_drives_every_agent(synthetic_shards, tmp_path):
    config = tiny_config(synthetic_shards, "ppo", "env.controlled=controllable", "selfplay.max_agents=4",
                         "algo.unroll_length=4", "algo.num_minibatches=2", "algo.batch_size=4",
                         "train.total_env_steps=40", "train.chunk_steps=1")
    run = tmp_path / "run"
    result = train(config, run, progress=False, print_fn=lambda line: None)
    assert result.summary["finished"] and result.final_evaluation["num_episodes"] == 4
    selfplay = result.summary["selfplay_evaluation"]
    assert selfplay["num_scenes"] == 4 and selfplay["num_agents"] >= 4
    with open(run / "metrics.csv") as f:
        rows = list(csv.DictReader(f))
    assert rows and {"agent_steps", "episode/goal_reached"} <= set(rows[0])
    first = rows[0]  # the first chunk: its env steps are the scene steps it ran
    assert float(first["agent_steps"]) > float(first["env_steps"])  # several agents act in a scene
    with open(run / "eval.csv") as f:
        evaluation = next(csv.DictReader(f))
    assert "selfplay/goal_reached" in evaluation
    best = json.loads((run / "best" / "best.json").read_text())  # ranked by the agents' goals, not the SDC's score
    assert best["selfplay/goal_reached_clean"] == pytest.approx(float(evaluation["selfplay/goal_reached_clean"]))

    cli = [str(Path(sys.executable).parent / "vmax-sim")]
    shown = subprocess.run([*cli, "evaluate", "--mode", "selfplay", "--policy", str(run), "--num-scenarios", "4",
                            "--json", "--quiet"], capture_output=True, text=True, timeout=600)
    assert shown.returncode == 0, shown.stderr
    assert json.loads(shown.stdout)["num_agents"] == selfplay["num_agents"]  # same scenes, same agents
    traffic = subprocess.run([*cli, "evaluate", "--policy", "idm", "--mode", "reactive", "--agents", str(run),
                              "--data", str(synthetic_shards), "--num-objects", "16", "--num-scenarios", "4",
                              "--json", "--quiet"], capture_output=True, text=True, timeout=600)
    assert traffic.returncode == 0, traffic.stderr
    assert json.loads(traffic.stdout)["mode_options"]["agents"] == str(run)
