"""The benchmark's synthetic scenes and step run end to end; the full table is a slow test."""

import jax
import jax.numpy as jnp
import pytest

from vmax_sim.bench import (
    _batched_scenes,
    format_table,
    initial_state,
    make_step_fn,
    run_bench,
    synthetic_scene,
)


def test_synthetic_scene_has_the_requested_sizes():
    scene = synthetic_scene(3000, num_objects=16, seed=1)
    assert scene["xyz"].shape == (3000, 3) and scene["obj_xy"].shape == (16, 91, 2)
    assert scene["path_xy"].shape == (10, 300, 2)


def test_full_step_runs_batched_and_map_index_shapes_ignore_roadgraph_size():
    small = _batched_scenes(2, 16, 2000, num_distinct=2)
    large = _batched_scenes(2, 16, 6000, num_distinct=2)
    assert jax.tree_util.tree_map(lambda x: x.shape, small.map_index) == \
        jax.tree_util.tree_map(lambda x: x.shape, large.map_index)
    step = jax.jit(jax.vmap(make_step_fn(with_observation=True, with_metrics=True)))
    state = jax.vmap(initial_state)(small)
    action = jnp.zeros((2, 2))
    new_state, out = step(small, state, action)
    assert bool(jnp.all(jnp.isfinite(out))) and new_state.sdc_xy.shape == state.sdc_xy.shape
    step(large, state, action)  # same shapes: reuses the compiled step


@pytest.mark.slow
def test_run_bench_reports_every_configuration():
    results = run_bench(batch_sizes=(2,), num_objects=16, roadgraph_sizes=(2000, 4000), steps=3)
    assert {row["config"] for row in results["configs"]} == {"env", "env+obs", "env+metrics", "env+metrics+obs"}
    assert len(results["roadgraph_scaling"]) == 2
    assert all(row["scene_steps_per_s"] > 0 for row in results["configs"])
    assert "scene-steps/s" in format_table(results)
