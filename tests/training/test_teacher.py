"""train.teacher: a planner's action labels BC's steps (and drives them), instead of the log-following action."""

from __future__ import annotations

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from tests.integration_sim.conftest import NUM_STEPS, road_scenario, small_data_config
from vmax_sim.data import scenarios_to_batch
from vmax_sim.env import EnvConfig
from vmax_sim.env.learning import LearningEnv
from vmax_sim.policies.pdm import PDMConfig, pdm_action
from vmax_sim.training import apply_overrides, preset_config
from vmax_sim.training.run import TEACHERS


def waiting_scenario():
    """The logged SDC waits at x = 0 for the whole log on a free 13.4 m/s lane (a car stands 200 m ahead)."""
    xs = np.stack([np.zeros(NUM_STEPS), np.full(NUM_STEPS, 200.0)])
    return road_scenario("wait", xs, np.zeros_like(xs))


def driven_episode(teacher: str, steps: int = 40):
    """An episode driven by its own labels (BC without noise) -> (labels (T, A), the SDC's x (T,))."""
    env = LearningEnv(EnvConfig(max_num_objects=8), teacher=TEACHERS[teacher])
    pool = scenarios_to_batch([waiting_scenario()], small_data_config(""))

    @jax.jit
    def episode(pool):
        state = env.reset(pool, 1, jax.random.PRNGKey(0))

        def body(state, _):
            label = env.expert_action(state)
            state, out = env.step(state, label, pool, label)
            return state, (out.expert_action[0], state.sim.sim_trajectory.x[0, 0, state.sim.timestep[0]], out.done[0])
        return jax.lax.scan(body, state, None, length=steps)[1]

    labels, xs, done = episode(pool)
    return env, pool, np.asarray(labels), np.asarray(xs), np.asarray(done)


@pytest.mark.slow  # ~60 s on 2 cores (PDM-Closed compiles slowly): the default suite stays under 10 minutes
def test_a_pdm_teacher_drives_off_where_the_logged_driver_waited():
    env, pool, labels, xs, done = driven_episode("pdm")
    assert not done.any()
    assert labels[0, 0] > 0.03 and labels[:, 0].max() > 0.2  # accelerates toward the limit (jerk-bounded)
    assert xs[-1] > 8.0  # 4 s later it has driven off
    # the label is PDM-Closed's own action, as evaluation runs it
    state = env.core.reset(jax.tree.map(lambda a: a[0], pool))
    expected = env.core.dynamics.normalize(pdm_action(state, PDMConfig(), env.core.config.first_policy_timestep))
    np.testing.assert_allclose(labels[0], np.clip(np.asarray(expected), -1, 1), atol=1e-5)


@pytest.mark.slow  # ~11 s on 2 cores: kept out of the 10-minute default suite
def test_the_log_teacher_keeps_the_logged_driver_waiting():
    _, _, labels, xs, _ = driven_episode("log", steps=20)
    assert abs(xs[-1]) < 0.5
    assert labels[0, 0] < 0.05


def test_teacher_choices_are_checked():
    with pytest.raises(ValueError, match="train.teacher must be one of log, idm, pdm"):
        apply_overrides(preset_config("bc-mlp"), ["train.teacher=expert"])
    with pytest.raises(ValueError, match="sac imitates nothing"):
        apply_overrides(preset_config("sac-mlp"), ["train.teacher=pdm"])
    assert apply_overrides(preset_config("bc_sac-mlp"), ["train.teacher=pdm"]).train.teacher == "pdm"
    with pytest.raises(ValueError, match=r"student_drive must be in \[0, 1\], got 1.5"):
        apply_overrides(preset_config("bc-mlp"), ["algo.student_drive=1.5"])


def test_a_preset_teacher_goes_with_the_algorithm_config_that_used_it():
    debug = apply_overrides(preset_config("ppo-selfplay"), ["algo_preset=debug"])  # a debug ppo imitates nothing
    assert (debug.train.teacher, debug.train.teacher_speed_factor, debug.imitates) == ("log", 1.0, False)
    assert apply_overrides(preset_config("bc-dagger"), ["algo_preset=debug"]).train.teacher == "pdm_state"  # bc does
    with pytest.raises(ValueError, match="ppo imitates nothing"):  # a teacher the user names is checked, not dropped
        apply_overrides(preset_config("ppo-selfplay"), ["algo_preset=debug", "train.teacher=idm"])


def test_slim_training_states_keep_the_stop_signs():
    from scenariomax.schema import RG_STOP_SIGN
    from vmax_sim.env.agent_view import MAX_STOP_SIGN_POINTS
    from vmax_sim.training.pool import slim_state

    state = jax.tree.map(lambda a: np.asarray(a[0]), scenarios_to_batch([waiting_scenario()], small_data_config("")))
    rg = state.roadgraph_points
    types = np.asarray(rg.types).copy()
    types[[5, 17]] = RG_STOP_SIGN
    slim = slim_state(state.replace(roadgraph_points=rg.replace(types=types, valid=np.ones_like(rg.valid))))
    kept = slim.roadgraph_points
    assert kept.x.shape == (MAX_STOP_SIGN_POINTS,)
    assert kept.valid.sum() == 2 and (kept.types[kept.valid] == RG_STOP_SIGN).all()
    np.testing.assert_array_equal(kept.x[:2], np.asarray(rg.x)[[5, 17]])
    assert jnp.asarray(kept.valid[2:]).sum() == 0


def test_bc_drives_with_the_noisy_expert_or_on_its_share_of_rows_the_student():
    from vmax_sim.training.loop import bc_behaviour_action

    expert, student = jnp.full((400, 2), 0.5), jnp.full((400, 2), -0.25)
    key = jax.random.PRNGKey(3)
    noisy = np.asarray(bc_behaviour_action(expert, None, key, 0.1, 0.0, jnp.array(True)))
    assert 0.08 < noisy.std() < 0.12 and abs(noisy.mean() - 0.5) < 0.02  # DART: the expert's action, noisy
    half = np.asarray(bc_behaviour_action(expert, student, key, 0.0, 0.5, jnp.array(True)))
    by_student = (half == -0.25).all(axis=1)
    assert ((half == 0.5).all(axis=1) | by_student).all()  # whole rows: the student's or the expert's
    assert 0.4 < by_student.mean() < 0.6
    np.testing.assert_array_equal(bc_behaviour_action(expert, student, key, 0.0, 1.0, jnp.array(True)), student)
    # before algo.student_after env steps the expert drives every row
    np.testing.assert_array_equal(bc_behaviour_action(expert, student, key, 0.0, 1.0, jnp.array(False)), expert)


def test_whole_episode_dagger_keeps_the_same_rows_for_the_student_at_every_step():
    from vmax_sim.training.loop import bc_behaviour_action

    expert, student = jnp.full((16, 2), 0.5), jnp.full((16, 2), -0.25)
    drivers = []
    for step in range(5):
        action = np.asarray(bc_behaviour_action(expert, student, jax.random.PRNGKey(step), 0.1, 0.5, jnp.array(True),
                                                "episode"))
        drivers.append((action == -0.25).all(axis=1))
    # the first half of the rows is the student's at every step (its errors compound over a whole episode), the
    # other half the noisy expert's
    for by_student in drivers:
        np.testing.assert_array_equal(by_student, np.arange(16) < 8)
    with pytest.raises(ValueError, match="student_mix must be one of episode, step, got 'trajectory'"):
        apply_overrides(preset_config("bc-mlp"), ["algo.student_mix=trajectory"])


@pytest.mark.slow  # PDM-Closed compiles for ~20 s per configuration on 2 cores
def test_the_pdm_state_teacher_labels_from_the_state_not_from_the_last_action():
    from vmax_sim.policies.teacher import pdm_state_teacher, pdm_teacher

    # a car cruising at 10 m/s on a free 13.4 m/s lane; a second copy had braked hard on its last step
    xs = np.stack([10.0 * 0.1 * np.arange(NUM_STEPS), np.full(NUM_STEPS, 300.0)])
    scenario = road_scenario("cruise", xs, np.zeros_like(xs))
    env = LearningEnv(EnvConfig(max_num_objects=8))
    state = env.core.reset(jax.tree.map(lambda a: a[0], scenarios_to_batch([scenario], small_data_config(""))))
    t = int(state.timestep)
    traj = state.sim_trajectory
    braked = state.replace(sim_trajectory=traj.replace(vel_x=traj.vel_x.at[0, t - 1].set(10.5)))  # -5 m/s^2 just now
    pdm, pdm_state = jax.jit(pdm_teacher(env.core)), jax.jit(pdm_state_teacher(env.core))
    # PDM-Closed's label follows the last action (jerk-limited); the state teacher's is the same either way
    assert float(pdm(braked)[0]) < float(pdm(state)[0]) - 0.05
    np.testing.assert_allclose(pdm_state(braked), pdm_state(state), atol=1e-6)
    # and, free of the jerk limit's 0.4 m/s^2 per step, it accelerates toward the limit at once
    assert float(pdm_state(state)[0]) > float(pdm(state)[0]) + 0.05


def test_the_idm_teachers_acceleration_is_a_knob_that_reaches_its_labels():
    """`train.teacher_max_accel` (self-play's preset: 2.5 m/s^2) changes what the idm teacher labels: from rest on
    a free lane IDM asks for its full acceleration, so the label grows with it (the textbook 1.5 otherwise)."""
    from vmax_sim.training.run import teacher_of

    textbook = apply_overrides(preset_config("bc-mlp"), ["train.teacher=idm"])
    brisk = apply_overrides(textbook, ["train.teacher_max_accel=2.5", "train.teacher_bend_lateral_accel=3"])
    pool = scenarios_to_batch([waiting_scenario()], small_data_config(""))
    first = []
    for config in (textbook, brisk):
        env = LearningEnv(EnvConfig(max_num_objects=8), teacher=teacher_of(config))
        label = jax.jit(lambda pool, env=env: env.expert_action(env.reset(pool, 1, jax.random.PRNGKey(0))))(pool)
        first.append(float(label[0, 0]))
    assert first[0] > 0 and first[1] == pytest.approx(first[0] * 2.5 / 1.5, rel=0.02)
    with pytest.raises(ValueError, match=r"teacher_max_accel must be in \[0.5, 6\]"):
        apply_overrides(textbook, ["train.teacher_max_accel=9"])
    with pytest.raises(ValueError, match="teacher_bend_lateral_accel sets the idm teacher's driving"):
        apply_overrides(preset_config("bc-mlp"), ["train.teacher=pdm", "train.teacher_bend_lateral_accel=3"])
