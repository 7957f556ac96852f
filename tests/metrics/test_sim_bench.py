"""The benchmark's synthetic scenes and timed step run end to end; the full table is a slow test."""

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from vmax_sim.bench import _scenes, format_table, make_episode_fns, run_bench, synthetic_scene
from vmax_sim.env import EnvConfig
from vmax_sim.env.learning import LearningEnv
from vmax_sim.metrics import MetricsConfig
from vmax_sim.observation import ObservationConfig


def test_synthetic_scene_has_the_requested_sizes():
    scene = synthetic_scene(3000, num_objects=16, seed=1)
    assert scene["xyz"].shape == (3000, 3) and scene["obj_xy"].shape == (16, 91, 2)
    assert scene["path_xy"].shape == (10, 300, 2)


def test_map_index_shapes_ignore_roadgraph_size():
    small = _scenes(2, 16, 2000, num_distinct=2)
    large = _scenes(2, 16, 6000, num_distinct=2)
    assert jax.tree_util.tree_map(lambda x: x.shape, small.map_index) == \
        jax.tree_util.tree_map(lambda x: x.shape, large.map_index)


@pytest.mark.slow  # 8-38 s on 2 cores: the default suite stays under 10 minutes
def test_full_step_runs_batched():
    init_fn, step_fn = make_episode_fns(with_observation=True, with_metrics=True, num_objects=16)
    state, arcs = jax.vmap(init_fn)(_scenes(2, 16, 2000, num_distinct=2))
    new_state, out = jax.jit(jax.vmap(step_fn))(arcs, state, jnp.zeros((2, 2)))
    assert bool(jnp.all(jnp.isfinite(out))) and np.all(np.asarray(new_state.timestep) == np.asarray(state.timestep) + 1)


@pytest.mark.slow  # compiles both the bench's and the training's full step (~30 s on 2 cores)
def test_the_timed_step_is_the_training_step():
    """The bench's full step (batched) steps the scene exactly as `LearningEnv` (training) does."""
    scenes = _scenes(2, 16, 2000, num_distinct=2)
    init_fn, step_fn = make_episode_fns(with_observation=True, with_metrics=True, num_objects=16)
    state, arcs = jax.jit(jax.vmap(init_fn))(scenes)
    bench_step = jax.jit(jax.vmap(step_fn))
    # no termination: a random scene may start in a collision, and training would restart that episode
    env = LearningEnv(EnvConfig(max_num_objects=16, init_steps=5, terminate_on=()), ObservationConfig(),
                      metrics_config=MetricsConfig(), expert_labels=False)
    training = jax.jit(env.reset, static_argnums=1)(scenes, 2, jax.random.PRNGKey(0))  # eager: ~10x slower
    raw = jnp.asarray([[0.5, 0.002], [-1.0, 0.0]], jnp.float32)  # accel m/s^2, curvature 1/m
    normalised = jax.vmap(env.core.dynamics.normalize)(raw)  # LearningEnv takes actions in [-1, 1]
    for _ in range(3):
        state, out = bench_step(arcs, state, raw)
        training, output = env.step(training, normalised, scenes)
        assert bool(jnp.all(jnp.isfinite(out))) and not bool(jnp.any(output.done))
        for name in ("x", "y", "yaw", "valid"):
            np.testing.assert_allclose(getattr(state.sim_trajectory, name), getattr(training.sim.sim_trajectory, name),
                                       atol=1e-4)
    assert not np.allclose(state.sim_trajectory.x, scenes.log_trajectory.x)  # the SDC left its log


@pytest.mark.slow
def test_run_bench_reports_every_configuration():
    results = run_bench(batch_sizes=(2,), num_objects=16, roadgraph_sizes=(2000, 4000), steps=3)
    assert {row["config"] for row in results["configs"]} == {"env", "env+obs", "env+metrics", "env+metrics+obs"}
    assert len(results["roadgraph_scaling"]) == 2
    assert all(row["scene_steps_per_s"] > 0 and row["env"] == "real" for row in results["configs"])
    assert "scene-steps/s" in format_table(results)


def test_env_both_or_minimal_times_the_real_environment_once(capsys, monkeypatch):
    timed = []
    monkeypatch.setattr("vmax_sim.bench._timed", lambda *args: timed.append(args) or {
        "env": "real", "config": args[3], "batch": args[0], "roadgraph": args[2], "compile_s": 0.1,
        "scene_steps_per_s": 1})
    results = run_bench(batch_sizes=(1,), roadgraph_sizes=(1000,), steps=2, configs=("env",),
                        env_kinds=("real", "minimal"))  # what `vmax-sim bench --env both` asks for
    assert len(timed) == 2 and len(results["configs"]) == 1 and len(results["roadgraph_scaling"]) == 1
    assert "minimal array step was removed" in capsys.readouterr().err
    with pytest.raises(ValueError, match="unknown env kind"):
        run_bench(env_kinds=("fast",))


@pytest.mark.parametrize("batch, device, said",
                         [(64, "cpu:cpu", True), (32, "cpu:cpu", False), (64, "gpu:H100", False)])
def test_the_table_says_when_a_batch_ran_in_chunks(batch, device, said):
    row = {"env": "real", "config": "env+metrics+obs", "batch": batch, "roadgraph": 30000, "compile_s": 1.0,
           "scene_steps_per_s": 1000}
    results = {"device": device, "num_objects": 64, "steps": 5, "configs": [row], "roadgraph_scaling": []}
    assert ("ran as a loop over chunks of 32 episodes" in format_table(results)) == said
