"""Sim-agent realism (vmax_sim.evaluation.realism*): estimators and features on hand-worked numbers, the log at
the top of the meta-metric on synthetic scenes, and `vmax-sim realism` end to end."""

from __future__ import annotations

import dataclasses
import json
import math

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from click.testing import CliRunner

from vmax_cli.vmax_cli import main
from vmax_sim.evaluation.realism import (
    CHALLENGE_2024,
    FeatureConfig,
    RealismConfig,
    SimTrajectories,
    aggregate_scenes,
    bernoulli_log_likelihood,
    histogram_log_likelihood,
    kinematic_features,
    time_to_collision,
    timeseries_log_likelihood,
)
from vmax_sim.evaluation.realism import rectangle_signed_distance as _rectangle_signed_distance
from vmax_sim.evaluation.realism import rounded_box_distance as _rounded_box_distance
from vmax_sim.evaluation.realism import scene_likelihoods as _scene_likelihoods

NUM_OBJECTS = 16


@pytest.fixture(scope="module")
def realism_shards(tmp_path_factory):
    """3 enriched synthetic scenes (16 object slots, 5000 roadgraph points) written by the real pipeline."""
    from scenariomax.enrich.transform import make_transform
    from scenariomax.pipeline import ConvertSettings, convert
    from scenariomax.schema import Sizes
    from scenariomax.sources.synthetic import SyntheticSource

    out = tmp_path_factory.mktemp("realism") / "shards"
    sizes = Sizes(num_objects=NUM_OBJECTS, num_roadgraph=5000)
    transform, transform_settings = make_transform()
    settings = ConvertSettings(out=out, workers=1, sizes=sizes, progress=False, transform=transform,
                               transform_settings=transform_settings)
    convert(SyntheticSource(num_scenarios=3, seed=11, sizes=sizes), settings)
    return out


# ----------------------------------------------------------------------------- estimators


def test_the_challenge_weights_sum_to_one():
    assert math.isclose(sum(f.weight for _, f in CHALLENGE_2024), 1.0, abs_tol=1e-9)


def test_histogram_likelihood_on_known_numbers():
    feature = FeatureConfig(1.0, min_val=0.0, max_val=10.0, num_bins=10, pseudocount=0.1)
    sim = jnp.array([[0.5, 1.5, 1.6, 9.9, 4.0]])
    weight = jnp.array([[1.0, 1.0, 1.0, 1.0, 0.0]])  # the last sample is invalid: not counted
    log = jnp.array([[1.2, 5.0, 50.0, -3.0, 10.0]])  # 50 and 10 fall in the last bin, -3 in the first
    total = 4 + 10 * 0.1
    expected = np.log([2.1 / total, 0.1 / total, 1.1 / total, 1.1 / total, 1.1 / total])
    np.testing.assert_allclose(histogram_log_likelihood(log, sim, weight, feature)[0], expected, rtol=1e-6)


def test_bernoulli_likelihood_and_smoothing():
    feature = FeatureConfig(1.0, kind="bernoulli", pseudocount=0.001)
    sim = jnp.array([[True, False, False, False]])
    ll = bernoulli_log_likelihood(jnp.array([[True, False]]), sim, jnp.ones((1, 4)), feature)[0]
    np.testing.assert_allclose(ll, np.log([1.001 / 4.002, 3.001 / 4.002]), rtol=1e-6)


def test_time_pooled_and_per_step_histograms():
    pooled = FeatureConfig(1.0, min_val=0.0, max_val=2.0, num_bins=2, pseudocount=0.0)
    per_step = dataclasses.replace(pooled, independent_timesteps=False)
    sim = jnp.array([[[0.5, 1.5]], [[0.5, 1.5]]])  # (R=2, E=1, T=2): step 0 in bin 0, step 1 in bin 1
    log = jnp.array([[0.5, 0.5]])
    weight = jnp.ones_like(sim)
    np.testing.assert_allclose(timeseries_log_likelihood(log, sim, weight, pooled), np.log([[0.5, 0.5]]), rtol=1e-6)
    per = timeseries_log_likelihood(log, sim, weight, per_step)
    assert per[0, 0] == pytest.approx(0.0) and per[0, 1] == -np.inf  # no pseudocount: an empty bin is log 0


def test_the_log_maximises_each_pooled_likelihood():
    """The time-pooled histogram of the logged values themselves is the maximum-likelihood histogram: any other
    simulated distribution scores lower."""
    config = RealismConfig()
    rng = np.random.default_rng(0)
    log = {name: jnp.asarray(rng.normal(5.0, 3.0, (3, 20)), jnp.float32) for name, _ in config.features}
    for name, feature in config.features:
        if feature.kind == "bernoulli":
            log[name] = jnp.asarray(rng.random((3, 20)) < 0.1)
    valid = {name: jnp.ones((3, 20), bool) for name in log}
    scene_likelihoods = jax.jit(_scene_likelihoods, static_argnums=(5, 6))
    same = scene_likelihoods(log, valid, jax.tree.map(lambda a: a[None], log),
                             jax.tree.map(lambda a: a[None], valid), jnp.ones(3, bool), config, copies=32)
    shifted = {name: (v if v.dtype == bool else v + 2.0)[None] for name, v in log.items()}
    shifted.update({name: ~log[name][None] for name, f in config.features if f.kind == "bernoulli"})
    other = scene_likelihoods(log, valid, shifted, jax.tree.map(lambda a: a[None], valid), jnp.ones(3, bool),
                              config, copies=32)
    for name, _ in config.features:
        assert float(same[name]) >= float(other[name]), name
    assert float(same["metametric"]) > float(other["metametric"])


# ----------------------------------------------------------------------------- features


def test_kinematics_by_central_differences():
    t = np.arange(12) * 0.1
    x = 10.0 * t + 0.5 * 2.0 * t**2  # 10 m/s, accelerating at 2 m/s^2
    yaw = np.pi - 0.05 + 0.5 * t  # turns at 0.5 rad/s through +-pi
    yaw = (yaw + np.pi) % (2 * np.pi) - np.pi
    out = kinematic_features(jnp.asarray(x), jnp.zeros(12), jnp.asarray(yaw), 0.1)
    np.testing.assert_allclose(out["linear_speed"][1:-1], 10.0 + 2.0 * t[1:-1], rtol=1e-5)
    np.testing.assert_allclose(out["linear_acceleration"][2:-2], 2.0, rtol=1e-3)
    np.testing.assert_allclose(out["angular_speed"][1:-1], 0.5, rtol=1e-4)
    np.testing.assert_allclose(out["angular_acceleration"][2:-2], 0.0, atol=1e-3)


def test_box_distances():
    a = jnp.array([0.0, 0.0, 4.0, 2.0, 0.0])
    rectangle_signed_distance = jax.jit(_rectangle_signed_distance)
    rounded_box_distance = jax.jit(_rounded_box_distance, static_argnums=2)
    assert float(rectangle_signed_distance(a, jnp.array([7.0, 0.0, 4.0, 2.0, 0.0]))) == pytest.approx(3.0)
    assert float(rectangle_signed_distance(a, jnp.array([3.5, 0.0, 4.0, 2.0, 0.0]))) == pytest.approx(-0.5)
    corner = rectangle_signed_distance(a, jnp.array([5.0, 3.0, 2.0, 2.0, 0.0]))  # corner (2, 1) to corner (4, 2)
    assert float(corner) == pytest.approx(math.hypot(2.0, 1.0), rel=1e-6)
    # rounded corners change nothing between flat sides, and lengthen a corner-to-corner gap
    assert float(rounded_box_distance(a, jnp.array([7.0, 0.0, 4.0, 2.0, 0.0]), 0.7)) == pytest.approx(3.0, rel=1e-6)
    assert float(rounded_box_distance(a, jnp.array([5.0, 3.0, 2.0, 2.0, 0.0]), 0.7)) > float(corner)


def test_time_to_collision_follows_the_object_ahead():
    boxes = jnp.array([[[0.0, 0.0, 4.0, 2.0, 0.0]], [[20.0, 0.5, 4.0, 2.0, 0.05]], [[10.0, 8.0, 4.0, 2.0, 0.0]]])
    speed = jnp.array([[10.0], [5.0], [0.0]])  # the stopped car is in another lane: not followed
    ttc = jax.jit(time_to_collision, static_argnums=4)(boxes, speed, jnp.ones((3, 1), bool), jnp.array([0, 1]),
                                                    RealismConfig())
    gap = 20.0 - 2.0 - (2.0 * math.cos(0.05) + 1.0 * math.sin(0.05))
    assert float(ttc[0, 0]) == pytest.approx(gap / 5.0, rel=1e-5)
    assert float(ttc[1, 0]) == 5.0  # nobody ahead of the leader


def test_aggregate_recomputes_the_metametric_and_buckets():
    per_scene = {name: np.array([0.5, np.nan]) for name, _ in CHALLENGE_2024}
    out = aggregate_scenes(per_scene)
    assert out["metametric"] == pytest.approx(0.5) and out["kinematic"] == pytest.approx(0.5)


# ----------------------------------------------------------------------------- rollouts and the command


def _realism(policy, shards, **kw):
    from vmax_sim.data import DataConfig
    from vmax_sim.evaluation.realism_run import realism_for_policy

    data = DataConfig(path=str(shards), num_objects=NUM_OBJECTS, num_roadgraph_points=5000)
    return realism_for_policy(policy, data, max_agents=8, **kw)


@pytest.mark.slow
def test_the_log_scores_above_idm_and_constant_velocity(realism_shards):
    log = _realism("log", realism_shards, num_rollouts=8).summary
    constant = _realism("constant", realism_shards, num_rollouts=8).summary
    idm = _realism("idm", realism_shards, num_rollouts=8, action_noise=0.5).summary
    assert log["metametric"] > idm["metametric"] > constant["metametric"], (log, idm, constant)
    assert log["collision_rate"] == 0.0 and log["ade"] == 0.0
    assert constant["collision_rate"] > 0.0  # constant velocity drives into others
    for name, value in log["likelihoods"].items():
        assert value >= constant["likelihoods"][name] - 1e-6, name


@pytest.mark.slow
def test_rollouts_differ_only_when_the_policy_is_stochastic_or_noisy(realism_shards):
    from scenariomax import read_shards
    from vmax_sim.data import DataConfig, scenario_to_numpy_state
    from vmax_sim.env.config import EnvConfig
    from vmax_sim.env.factory import make_environment
    from vmax_sim.evaluation.realism_rollouts import named_rollout_fn

    config = DataConfig(num_objects=NUM_OBJECTS, num_roadgraph_points=5000, include_agent_paths=True)
    state = jax.device_put(scenario_to_numpy_state(next(iter(read_shards(realism_shards))), config))
    env = make_environment(EnvConfig(max_num_objects=NUM_OBJECTS))
    plain = named_rollout_fn("constant", env, 4, 8)(state, jax.random.PRNGKey(0))
    assert isinstance(plain, SimTrajectories) and plain.x.shape[0] == 1 and plain.num_rollouts == 4
    noisy = named_rollout_fn("constant", env, 4, 8, action_noise=1.0)(state, jax.random.PRNGKey(0))
    assert noisy.x.shape == (4, NUM_OBJECTS, 91) and noisy.copies == 1
    assert float(jnp.max(jnp.abs(noisy.x[0, 0, 20:] - noisy.x[1, 0, 20:]))) > 0.01  # the SDC's rollouts differ
    np.testing.assert_array_equal(noisy.x[:, :, :11], jnp.broadcast_to(state.log_trajectory.x[:, :11], (4, 16, 11)))


@pytest.mark.slow
def test_cli_end_to_end(realism_shards, tmp_path):
    out = tmp_path / "realism.json"
    args = ["realism", "--policy", "log,constant", "--data", str(realism_shards), "--scenes", "1", "--rollouts", "2",
            "--num-objects", str(NUM_OBJECTS), "--max-agents", "4", "--quiet", "--out", str(out)]
    result = CliRunner().invoke(main, args)
    assert result.exit_code == 0, result.output
    assert "**meta-metric**" in result.output and "collision_indication" in result.output
    summaries = json.loads(out.read_text())
    assert [s["policy"] for s in summaries] == ["log", "constant"]
    assert summaries[0]["metametric"] > summaries[1]["metametric"]
    assert summaries[0]["num_scenes"] == 1 and summaries[0]["num_rollouts"] == 2


def test_cli_bad_input_gives_one_line_errors(tmp_path):
    for bad, fragment in ((["--policy", "nobody", "--data", "x"], "neither one of log, constant, idm"),
                          (["--policy", "log", "--data", str(tmp_path / "none")], "no such file"),
                          (["--policy", "idm"], "give --data")):
        result = CliRunner().invoke(main, ["realism", *bad])
        assert result.exit_code == 2 and result.output.startswith("error: "), result.output
        assert fragment in result.output and len(result.output.strip().splitlines()) == 1
