"""train.ensemble: RUN/ensemble holds the policies of the last checkpoints; their mean action drives."""

from __future__ import annotations

import json

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from tests.training.conftest import tiny_config
from vmax_sim.agents.types import Learner
from vmax_sim.training import train
from vmax_sim.training.ensemble import ensemble_learner, is_ensemble, stack_params
from vmax_sim.training.run_policy import evaluate_run, load_trained_policy


def _linear_learner() -> Learner:
    """act = tanh(obs @ w): enough to see what the ensemble does with its members."""
    def act(params, observation, key, deterministic):
        return jnp.tanh(observation @ params["w"])

    return Learner(init=None, update=None, act=act, policy_params=lambda state: state,
                   act_with_info=lambda *args: (act(*args[:4]), {}))


def test_the_ensemble_acts_with_the_mean_of_its_members_actions():
    learner = _linear_learner()
    members = [{"w": jnp.full((3, 2), value)} for value in (0.1, -0.3, 0.5)]
    observation = jnp.array([[1.0, 2.0, 0.5], [0.0, -1.0, 1.0]])  # (B=2, 3)
    key = jax.random.PRNGKey(0)
    mean = np.mean([learner.act(member, observation, key, True) for member in members], axis=0)
    ensemble = ensemble_learner(learner)
    np.testing.assert_allclose(ensemble.act(stack_params(members), observation, key, True), mean, rtol=1e-6)
    # one member alone drives as itself
    single = stack_params(members[:1])
    np.testing.assert_allclose(ensemble.act(single, observation, key, True), learner.act(members[0], observation,
                                                                                          key, True), rtol=1e-6)
    assert ensemble.value is None


def test_the_cautious_ensemble_steers_with_the_mean_and_accelerates_with_the_smallest():
    """train.ensemble_rule=cautious: one member braking makes the ensemble brake, where the mean would still go."""
    learner = _linear_learner()
    # member 0 goes (+, +), member 1 brakes and steers the other way: columns (acceleration, curvature)
    members = [{"w": jnp.array([[1.0, 0.5]])}, {"w": jnp.array([[-0.5, -0.5]])}]
    observation = jnp.array([[1.0], [2.0]])  # (B=2, 1)
    key = jax.random.PRNGKey(0)
    actions = np.stack([learner.act(member, observation, key, True) for member in members])  # (M, B, A)
    cautious = ensemble_learner(learner, "cautious").act(stack_params(members), observation, key, True)
    np.testing.assert_allclose(cautious[:, 0], actions[1, :, 0], rtol=1e-6)  # member 1's brake
    np.testing.assert_allclose(cautious[:, 1], actions[:, :, 1].mean(axis=0), rtol=1e-6)
    assert float(np.mean(actions[:, :, 0], axis=0)[0]) > 0  # the mean would accelerate: not what drives
    assert np.all(cautious[:, 0] < 0)


def test_the_median_ensemble_is_not_moved_by_one_member_far_from_the_others():
    """train.ensemble_rule=median: two members agree, the third is far off; the median drives as the two do."""
    learner = _linear_learner()
    members = [{"w": jnp.array([[0.2, 0.1]])}, {"w": jnp.array([[0.3, 0.0]])}, {"w": jnp.array([[-3.0, 2.0]])}]
    observation = jnp.array([[1.0], [0.5]])  # (B=2, 1)
    key = jax.random.PRNGKey(0)
    actions = np.stack([learner.act(member, observation, key, True) for member in members])  # (M, B, A)
    median = ensemble_learner(learner, "median").act(stack_params(members), observation, key, True)
    np.testing.assert_allclose(median, np.median(actions, axis=0), rtol=1e-6)
    assert np.all(median[:, 0] > 0) and np.all(median[:, 1] < 0.2)  # the two agreeing members' range
    assert np.all(np.mean(actions, axis=0)[:, 0] < 0)  # where the mean follows the outlier into a brake


def test_the_cautious_rule_needs_acceleration_actions_and_a_known_name(tmp_path):
    assert tiny_config(tmp_path, "bc", "train.ensemble_rule=cautious").train.ensemble_rule == "cautious"
    with pytest.raises(ValueError, match="ensemble_rule must be one of"):
        tiny_config(tmp_path, "bc", "train.ensemble_rule=vote")
    with pytest.raises(ValueError, match="env.dynamics=delta_local"):
        tiny_config(tmp_path, "bc", "train.ensemble_rule=cautious", "env.dynamics=delta_local")
    with pytest.raises(ValueError, match="env.dynamics=delta_local"):
        tiny_config(tmp_path, "bc", "algo.member_rule=cautious", "env.dynamics=delta_local")


@pytest.mark.slow  # ~70 s on 2 cores (a tiny BC run, its held-out evaluations and the ensemble's)
def test_a_run_keeps_its_last_checkpoints_as_an_ensemble_that_evaluates_as_recorded(synthetic_shards, tmp_path):
    config = tiny_config(synthetic_shards, "bc", "train.total_env_steps=80", "train.chunk_steps=2",
                         "train.checkpoint_every=16", "train.ensemble=3", "train.keep_best=false")
    run = tmp_path / "run"
    result = train(config, run, progress=False, print_fn=lambda line: None)
    directory = run / "ensemble"
    assert is_ensemble(directory) and not is_ensemble(run)
    record = json.loads((directory / "ensemble.json").read_text())
    kept = sorted(int(p.name) for p in (directory / "checkpoints").iterdir() if p.name.isdigit())
    assert record["members"] == kept and len(kept) == 3 and kept[-1] == result.env_steps  # the last three
    assert not any((directory / "checkpoints" / str(step) / "replay").exists() for step in kept)
    loaded = load_trained_policy(directory)
    assert jax.tree.leaves(loaded.params)[0].shape[0] == 3  # the members' parameters, stacked
    # the run's summary holds the ensemble's held-out evaluation; evaluated again as a run, it scores the same
    summary = result.summary["ensemble_evaluation"]
    assert summary["members"] == kept
    again = evaluate_run(directory, num_scenarios=config.train.eval_scenarios,
                         batch_size=config.train.eval_batch_size)
    assert again.summary["vmax_score"] == pytest.approx(summary["vmax_score"], abs=1e-5)
    # and it drives differently from its newest member alone
    newest = load_trained_policy(run, step=kept[-1])
    assert not np.allclose(jax.tree.leaves(loaded.params)[0][-1], jax.tree.leaves(loaded.params)[0][0])
    assert newest.env_steps == loaded.env_steps


@pytest.mark.slow  # ~40 s on 2 cores (a tiny BC run and the ensemble's held-out evaluation)
def test_ensemble_members_can_come_oftener_than_checkpoints(synthetic_shards, tmp_path):
    config = tiny_config(synthetic_shards, "bc", "train.total_env_steps=80", "train.chunk_steps=2",
                         "train.checkpoint_every=1000", "train.ensemble=3", "train.ensemble_every=16",
                         "train.keep_best=false")
    run = tmp_path / "run"
    result = train(config, run, progress=False, print_fn=lambda line: None)
    checkpoints = sorted(int(p.name) for p in (run / "checkpoints").iterdir() if p.name.isdigit())
    members = json.loads((run / "ensemble" / "ensemble.json").read_text())["members"]
    assert checkpoints == [result.env_steps]  # one checkpoint, at the end
    # three members from the run's last stretch, the newest the final policy, each at least 16 env steps apart
    assert len(members) == 3 and members[-1] == result.env_steps
    assert all(later - earlier >= 16 for earlier, later in zip(members, members[1:]))
    assert result.summary["ensemble_evaluation"]["members"] == members


@pytest.mark.slow  # ~60 s on 2 cores (a tiny BC run of two students and its evaluation)
def test_a_run_of_several_bc_members_saves_them_and_evaluates_them_as_one(synthetic_shards, tmp_path):
    """`algo.members=2`: the run trains two students on one buffer; its checkpoint holds both, stacked, and the
    loaded policy drives with the mean of their actions."""
    config = tiny_config(synthetic_shards, "bc", "algo.members=2", "train.total_env_steps=48", "train.chunk_steps=2",
                         "train.checkpoint_every=1000", "train.keep_best=false")
    run = tmp_path / "run"
    result = train(config, run, progress=False, print_fn=lambda line: None)
    assert result.env_steps >= 48
    loaded = load_trained_policy(run)
    first = jax.tree.leaves(loaded.params)[0]
    assert first.shape[0] == 2 and not np.allclose(first[0], first[1])  # two students, each its own
    evaluated = evaluate_run(run, num_scenarios=4, batch_size=4)
    assert 0.0 <= evaluated.summary["accuracy"] <= 1.0 and evaluated.summary["num_episodes"] == 4
