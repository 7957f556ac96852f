"""The map index: fixed shapes whatever the map size, and hand-worked map queries."""

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from scenariomax.errors import InputError
from scenariomax.schema import RG_LANE_SURFACE_STREET, RG_ROAD_EDGE_BOUNDARY
from tests.metrics.helpers import LEFT_EDGE_Y, RIGHT_EDGE_Y, road_index, route_paths, straight_road
from vmax_sim.map_index import (
    MapIndexConfig,
    build_map_index,
    lane_candidates,
    nearest_lane,
    observation_points,
    project_on_paths,
    query_segments,
    signed_edge_distance,
)


@pytest.fixture(scope="module")
def index():
    return road_index()


def test_corner_half_a_metre_off_the_right_edge(index):
    pts = jnp.array([[0.0, RIGHT_EDGE_Y - 0.5], [0.0, RIGHT_EDGE_Y + 0.5], [0.0, LEFT_EDGE_Y + 0.5],
                     [0.0, LEFT_EDGE_Y - 1.0], [10.3, 0.0]])
    got = signed_edge_distance(index, pts, jnp.array([0.0, 0.0]))
    np.testing.assert_allclose(got, [0.5, -0.5, 0.5, -1.0, RIGHT_EDGE_Y], atol=1e-4)


def test_shapes_do_not_depend_on_the_roadgraph_size():
    small, large = road_index(length=100.0), road_index(length=600.0)
    shapes = jax.tree_util.tree_map(lambda x: x.shape, small)
    assert shapes == jax.tree_util.tree_map(lambda x: x.shape, large)


def test_straight_runs_are_merged_into_cell_long_segments(index):
    config = MapIndexConfig()
    lengths = np.linalg.norm(np.asarray(index.seg_end - index.seg_start), axis=1)[np.asarray(index.seg_valid)]
    assert lengths.max() <= config.cell_size + 1e-3
    # 2 lanes + 2 edges (lines are not segments) of 200 m at 1 m spacing would be 800 segments;
    # merged into 7 m runs they are about 4 * 200 / 7
    assert 100 <= int(index.seg_valid.sum()) <= 130


def test_query_segments_returns_nearby_edges(index):
    idx, ok = query_segments(index, jnp.array([0.0, 0.0]), "edge")
    ids = set(np.asarray(index.seg_id[idx])[np.asarray(ok)].tolist())
    assert ids == {4, 5}
    _, far_ok = query_segments(index, jnp.array([5000.0, 0.0]), "edge")
    assert not bool(jnp.any(far_ok))


def test_far_from_any_edge_uses_the_host_distance_field():
    r = straight_road()
    index = build_map_index(r["xyz"], r["dir"], r["types"], r["ids"], r["valid"], center_xy=np.zeros(2))
    got = signed_edge_distance(index, jnp.array([[0.0, -60.0], [0.0, 60.0]]), jnp.array([0.0, -60.0]))
    assert float(got[0]) > 50.0  # far right of the right edge: off road
    assert float(got[1]) > 50.0  # far left of the left edge (which runs -x): off road too


def test_lane_candidates_pick_the_lane_under_the_agent(index):
    lanes = lane_candidates(index, jnp.array([3.0, 3.2]))
    k = nearest_lane(lanes, jnp.asarray(0.0))
    assert int(lanes.lane_id[k]) == 2
    assert float(lanes.distance[k]) == pytest.approx(0.5, abs=1e-4)
    assert float(lanes.lateral[k]) == pytest.approx(-0.5, abs=1e-4)  # right of lane 2's centreline
    assert float(lanes.speed_limit[k]) == pytest.approx(10.0)


def test_observation_points_are_thinned_and_fixed_size(index):
    config = MapIndexConfig()
    pts = observation_points(index, jnp.array([0.0, 0.0]), window=5)
    assert pts.xy.shape == (25 * config.obs_slots_per_cell, 2)
    xy = np.asarray(pts.xy)[np.asarray(pts.valid)]
    assert len(xy) > 0 and np.all(np.abs(xy[:, 0]) <= 2.5 * config.obs_cell_size + config.obs_cell_size)


def _polylines_reordered(road: dict, order: list[int]) -> dict:
    """The roadgraph arrays with their polylines (by id) listed in `order`."""
    rows = np.concatenate([np.flatnonzero(road["ids"] == polyline) for polyline in order])
    return {name: value[rows] for name, value in road.items()}


def test_observation_slots_do_not_follow_the_sources_polyline_order():
    # Real converted maps often list edges first, the synthetic generator lists lanes first: a crowded cell must keep
    # the same points from both, in the same slots (the flat `none` encoder reads them by position).
    road = straight_road()
    built = [build_map_index(r["xyz"], r["dir"], r["types"], r["ids"], r["valid"], None, np.zeros(2),
                             speed_limit=r["speed_limit"])
             for r in (road, _polylines_reordered(road, [5, 4, 3, 2, 1]))]
    lanes_first, edges_first = (observation_points(index, jnp.array([0.0, 0.0]), window=5) for index in built)
    np.testing.assert_array_equal(np.asarray(lanes_first.types), np.asarray(edges_first.types))
    types, valid = np.asarray(lanes_first.types).reshape(25, -1), np.asarray(lanes_first.valid).reshape(25, -1)
    group = np.where(types == RG_LANE_SURFACE_STREET, 0, np.where(types == RG_ROAD_EDGE_BOUNDARY, 2, 1))
    assert valid.any()
    for cell_group, cell_valid in zip(group, valid):  # per cell: lanes, then lines, then edges
        assert np.all(np.diff(cell_group[cell_valid]) >= 0)


def test_project_on_paths_gives_distance_and_arc():
    xy, valid, arc, _ = route_paths()
    proj = project_on_paths(jnp.asarray(xy), jnp.asarray(valid), jnp.asarray(arc), jnp.array([12.3, 1.0]))
    np.testing.assert_allclose(proj.distance, [1.0, 2.7], atol=1e-4)
    np.testing.assert_allclose(proj.arc, [62.3, 62.3], atol=1e-3)


def test_build_rejects_mismatched_arrays():
    r = straight_road()
    with pytest.raises(InputError, match="roadgraph"):
        build_map_index(r["xyz"], r["dir"][:10], r["types"], r["ids"], r["valid"])


def test_build_on_an_empty_map():
    index = build_map_index(np.zeros((0, 3)), np.zeros((0, 3)), np.zeros(0), np.zeros(0), np.zeros(0, bool))
    assert int(index.seg_valid.sum()) == 0
    assert float(signed_edge_distance(index, jnp.zeros((1, 2)), jnp.zeros(2))[0]) < 0  # no edges: on road


def test_signed_distance_matches_brute_force_on_a_random_map():
    from vmax_sim.bench import synthetic_scene

    scene = synthetic_scene(8000, num_objects=4, seed=3)
    centre = np.array([10.0, -2.0])
    index = build_map_index(scene["xyz"], scene["dir"], scene["types"], scene["ids"], scene["valid"],
                            center_xy=centre)
    rng = np.random.default_rng(0)
    queries = centre + rng.uniform(-20, 20, (64, 2))
    corners = queries[:, None] + rng.uniform(-2.5, 2.5, (64, 4, 2))
    got = np.asarray(jax.jit(jax.vmap(signed_edge_distance, in_axes=(None, 0, 0)))(
        index, jnp.asarray(corners, jnp.float32), jnp.asarray(queries, jnp.float32)))
    # brute force over every edge segment of the index
    edge = np.isin(np.asarray(index.seg_type), (15, 16)) & np.asarray(index.seg_valid)
    a, b = np.asarray(index.seg_start)[edge], np.asarray(index.seg_end)[edge]
    p = corners.reshape(-1, 1, 2)
    t = np.clip(np.sum((p - a) * (b - a), -1) / np.sum((b - a) ** 2, -1), 0, 1)
    dist = np.linalg.norm(p - (a + t[..., None] * (b - a)), axis=-1)
    nearest = np.argmin(dist, axis=1)
    cross = ((b - a)[nearest, 0] * (p[:, 0, 1] - a[nearest, 1]) - (b - a)[nearest, 1] * (p[:, 0, 0] - a[nearest, 0]))
    expected = np.where(cross < 0, dist.min(1), -dist.min(1)).reshape(64, 4)
    close = np.abs(expected) < 5.0  # the window guarantees >= 5 m around every corner
    np.testing.assert_allclose(got[close], expected[close], atol=1e-3)
    assert close.sum() > 50
