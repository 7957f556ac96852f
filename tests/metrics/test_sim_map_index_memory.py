"""The map index's compact layout (issue 12): under half a megabyte per scene at 30000 roadgraph points, and
queries on the quantised / shared-table layout agree with brute force over the float32 roadgraph."""

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from scenariomax.schema import LANE_TYPES, ROAD_EDGE_TYPES, ROAD_LINE_TYPES
from vmax_sim.bench import synthetic_scene
from vmax_sim.map_index import MapIndexConfig, build_map_index, lane_candidates, observation_points

WORLD = np.array([2950.0, -3290.0], np.float32)  # world-sized coordinates, as in real WOMD scenes
POSITION_TOLERANCE = 5e-4  # metres: int16 steps of 0.12 mm plus float32 rounding at ~4 km from the origin


@pytest.fixture(scope="module")
def scene():
    """A 30000-point synthetic roadgraph moved to world-sized coordinates, and its index."""
    raw = synthetic_scene(30000, num_objects=4, seed=3)
    raw["xyz"][:, :2] += WORLD
    index = build_map_index(raw["xyz"], raw["dir"], raw["types"], raw["ids"], raw["valid"], center_xy=WORLD,
                            speed_limit=raw["speed_limit"])
    return raw, index


def test_index_of_a_30000_point_scene_is_under_half_a_megabyte(scene):
    _, index = scene
    nbytes = sum(leaf.nbytes for leaf in jax.tree_util.tree_leaves(index))
    assert nbytes < 500_000, f"{nbytes} bytes per scene"
    assert int(index.num_dropped) == 0  # nothing was given up to get there


def test_quantised_observation_points_match_the_roadgraph(scene):
    raw, index = scene
    rng = np.random.default_rng(0)
    centres = WORLD + rng.uniform(-150, 150, (16, 2)).astype(np.float32)
    pts = jax.jit(jax.vmap(observation_points, in_axes=(None, 0)))(index, jnp.asarray(centres))
    valid = np.asarray(pts.valid)
    feats, types = np.asarray(pts.features)[valid], np.asarray(pts.types)[valid]
    assert len(feats) > 300
    # every observation point is a roadgraph point: its nearest one, found by brute force in float64
    xy = raw["xyz"][:, :2].astype(np.float64)
    nearest = np.argmin(((feats[:, None, :2] - xy[None]) ** 2).sum(-1), axis=1)
    np.testing.assert_allclose(feats[:, :2], xy[nearest], atol=POSITION_TOLERANCE, rtol=0)
    np.testing.assert_allclose(feats[:, 2:4], raw["dir"][nearest, :2], atol=1e-4)
    np.testing.assert_allclose(feats[:, 4], np.maximum(raw["speed_limit"][nearest], 0.0), atol=0.005)
    np.testing.assert_array_equal(types, raw["types"][nearest])
    np.testing.assert_array_equal(feats[:, 5:], np.stack([np.isin(types, ROAD_EDGE_TYPES), np.isin(types, LANE_TYPES),
                                                          np.isin(types, ROAD_LINE_TYPES)], -1))
    assert np.all(np.asarray(pts.features)[~valid] == 0)  # empty slots read as zeros


def test_lane_candidates_match_brute_force_over_the_lane_segments(scene):
    _, index = scene
    rng = np.random.default_rng(1)
    queries = WORLD + rng.uniform(-200, 200, (64, 2)).astype(np.float32)
    lanes = jax.jit(jax.vmap(lane_candidates, in_axes=(None, 0)))(index, jnp.asarray(queries))
    got = np.asarray(lanes.distance).min(1)
    lane = np.isin(np.asarray(index.seg_type), LANE_TYPES)
    a, b = np.asarray(index.seg_start, np.float64)[lane], np.asarray(index.seg_end, np.float64)[lane]
    p = queries.astype(np.float64)[:, None]
    t = np.clip(np.sum((p - a) * (b - a), -1) / np.sum((b - a) ** 2, -1), 0, 1)
    dist = np.linalg.norm(p - (a + t[..., None] * (b - a)), axis=-1)
    expected = dist.min(1)
    close = expected < MapIndexConfig().cell_size  # the 3x3 window covers at least one cell around the query
    np.testing.assert_allclose(got[close], expected[close], atol=1e-3)
    assert close.sum() > 10
    k = np.argmin(np.asarray(lanes.distance), 1)
    ids = np.asarray(lanes.lane_id)[np.arange(64), k]
    expected_ids = np.asarray(index.seg_id)[lane][dist.argmin(1)]
    assert np.mean(ids[close] == expected_ids[close]) > 0.9  # ties at shared vertices may pick either lane


def test_roadgraph_types_beyond_int8_are_refused():
    with pytest.raises(ValueError, match="types must be in 0..127"):
        MapIndexConfig(obs_types=(1, 300))


def test_bench_table_prints_the_map_index_bytes_per_scene():
    from vmax_sim.bench import format_table

    row = {"env": "real", "config": "env", "batch": 32, "roadgraph": 30000, "compile_s": 0.3,
           "scene_steps_per_s": 1000, "bytes_per_scene": 2_000_000, "map_index_bytes_per_scene": 454_668}
    results = {"device": "cpu:cpu", "num_objects": 64, "steps": 2, "configs": [row], "roadgraph_scaling": [row]}
    assert "map index bytes per scene: 454,668" in format_table(results)
