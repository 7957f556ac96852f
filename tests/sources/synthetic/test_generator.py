"""End-to-end behaviour of generated scenarios: determinism, validity, safety, lane graph, lights."""


import numpy as np
import pytest

from scenariomax.codec import decode_scenario, encode_scenario
from scenariomax.scenario import array_fields
from scenariomax.schema import (
    LANE_TYPES,
    OBJECT_TYPE_CYCLIST,
    OBJECT_TYPE_PEDESTRIAN,
    OBJECT_TYPE_VEHICLE,
    RG_CROSSWALK,
    RG_ROAD_EDGE_BOUNDARY,
    RG_STOP_SIGN,
    ROAD_EDGE_TYPES,
    TL_CAUTION,
    TL_GO,
    TL_STOP,
    Sizes,
)
from scenariomax.sources.synthetic import (
    TOPOLOGIES,
    build_network,
    generate_scenario,
    lane_graph_distance,
    overlapping_vehicle_pairs,
    red_light_crossings,
    road_edge_signed_distance,
)

SIZES = Sizes()


@pytest.fixture(scope="module")
def scenarios():
    """Two scenarios of every topology (the generator's topology override keeps this small)."""
    return {(topology, k): generate_scenario(7, 100 * k + i, SIZES, topology=topology)
            for i, topology in enumerate(TOPOLOGIES) for k in range(2)}


def test_same_seed_and_index_give_identical_arrays():
    a, b = generate_scenario(3, 5, SIZES), generate_scenario(3, 5, SIZES)
    assert a.scenario_id == b.scenario_id == "synthetic-3-000005"
    for name in array_fields():
        assert np.array_equal(getattr(a, name), getattr(b, name)), name


def test_different_seeds_or_indices_differ():
    a = generate_scenario(3, 5, SIZES)
    for other in (generate_scenario(4, 5, SIZES), generate_scenario(3, 6, SIZES)):
        assert other.scenario_id != a.scenario_id
        assert other.x.shape != a.x.shape or not np.array_equal(other.x, a.x)


def test_every_topology_is_drawn_over_a_range_of_indices():
    # The topology is the first draw of each scenario's rng, exactly as generate_scenario makes it.
    drawn = {build_network(np.random.default_rng([0, i])).topology for i in range(100)}
    assert drawn == set(TOPOLOGIES)


def test_scenarios_validate_and_fit_the_budget(scenarios):
    for key, s in scenarios.items():
        assert s.validate() == [], key
        assert s.source_dataset == "synthetic"
        assert s.num_timesteps == 91 and s.current_time_index == 10
        assert s.num_objects <= SIZES.num_objects and len(s.roadgraph_xyz) < 15000
        assert s.tl_state.shape[0] <= SIZES.num_lights and len(s.lane_id) <= SIZES.num_lanes
        assert 5 <= s.num_objects


def test_sdc_is_slot_zero_valid_and_moving(scenarios):
    for key, s in scenarios.items():
        assert s.is_sdc[0] and s.is_sdc.sum() == 1, key
        assert s.valid[0].all(), key
        assert s.object_type[0] == OBJECT_TYPE_VEHICLE
        assert s.speed[0].max() > 3.0


def test_logged_vehicles_never_overlap(scenarios):
    for key, s in scenarios.items():
        assert overlapping_vehicle_pairs(s) == [], key


def test_vehicles_never_overlap_pedestrians_or_cyclists(scenarios):
    types = (OBJECT_TYPE_VEHICLE, OBJECT_TYPE_PEDESTRIAN, OBJECT_TYPE_CYCLIST)
    for key, s in scenarios.items():
        pairs = overlapping_vehicle_pairs(s, types)
        both_walkers = [p for p in pairs if s.object_type[p[0]] == s.object_type[p[1]] == OBJECT_TYPE_PEDESTRIAN]
        assert pairs == both_walkers, key  # pedestrians may walk side by side, nothing else touches


def _nearest_edge_point_side(s, points):
    """The simulator-style test: sign from the nearest road-edge sample and its direction vector
    (positive = off road)."""
    mask = s.roadgraph_valid & np.isin(s.roadgraph_type, ROAD_EDGE_TYPES)
    xy, dirs = s.roadgraph_xyz[mask, :2].astype(np.float64), s.roadgraph_dir[mask, :2].astype(np.float64)
    rel = points[:, None, :] - xy[None]
    nearest = np.hypot(rel[..., 0], rel[..., 1]).argmin(axis=1)
    rel, d = rel[np.arange(len(points)), nearest], dirs[nearest]
    return -(d[:, 0] * rel[:, 1] - d[:, 1] * rel[:, 0])


def test_every_vehicle_position_is_on_the_road(scenarios):
    for key, s in scenarios.items():
        mask = s.valid & (s.object_type == OBJECT_TYPE_VEHICLE)[:, None]
        points = np.stack([s.x[mask], s.y[mask]], axis=-1).astype(np.float64)
        assert road_edge_signed_distance(s, points).max() < 0.0, key
        assert _nearest_edge_point_side(s, points[::3]).max() < 0.0, key


def test_sdc_never_crosses_a_stop_point_on_red(scenarios):
    for key, s in scenarios.items():
        assert red_light_crossings(s, 0) == [], key


def test_no_vehicle_runs_a_red_light_and_some_wait_at_one(scenarios):
    waiting = 0
    for key, s in scenarios.items():
        for obj in np.flatnonzero(s.object_type == OBJECT_TYPE_VEHICLE):
            assert red_light_crossings(s, obj) == [], (key, obj)
        for light in range(s.tl_state.shape[0]):
            stop = np.array([s.tl_x[light, 0], s.tl_y[light, 0]])
            near = (np.hypot(s.x - stop[0], s.y - stop[1]) < 8.0) & (s.object_type == OBJECT_TYPE_VEHICLE)[:, None]
            waiting += int((near & s.valid & (s.speed < 0.1) & (s.tl_state[light] == TL_STOP)).any())
    assert waiting >= 1  # the lights really hold traffic back


def test_sdc_stays_on_lanes_reachable_from_its_first_lane(scenarios):
    for key, s in scenarios.items():
        assert lane_graph_distance(s, 0).max() < 1.0, key


def test_lane_graph_links_reference_existing_lanes(scenarios):
    for key, s in scenarios.items():
        lane_ids = set(s.lane_id.tolist())
        centreline_ids = set(s.roadgraph_id[np.isin(s.roadgraph_type, LANE_TYPES)].tolist())
        assert lane_ids == centreline_ids, key
        for name in ("lane_successors", "lane_predecessors", "lane_left_neighbors", "lane_right_neighbors"):
            links = getattr(s, name)
            assert set(links[links >= 0].tolist()) <= lane_ids, (key, name)
        # successor and predecessor tables mirror each other
        succ = {(a, b) for a, row in zip(s.lane_id, s.lane_successors) for b in row if b >= 0}
        pred = {(b, a) for a, row in zip(s.lane_id, s.lane_predecessors) for b in row if b >= 0}
        assert succ == pred, key


def test_lights_are_bound_to_the_end_of_existing_lanes(scenarios):
    num_signalised = 0
    for key, s in scenarios.items():
        if s.tl_state.shape[0] == 0:
            continue
        num_signalised += 1
        assert s.tl_valid.all()
        assert set(np.unique(s.tl_state).tolist()) <= {TL_GO, TL_CAUTION, TL_STOP}
        for light in range(s.tl_state.shape[0]):
            lane = int(s.tl_lane_id[light, 0])
            assert (s.tl_lane_id[light] == lane).all()
            points = s.roadgraph_xyz[s.roadgraph_id == lane]
            assert len(points) > 1, key
            assert np.allclose(points[-1, :2], [s.tl_x[light, 0], s.tl_y[light, 0]], atol=1e-3)
    assert num_signalised >= 1


def test_map_has_edges_crosswalks_and_stop_signs(scenarios):
    types = np.concatenate([s.roadgraph_type for s in scenarios.values()])
    for needed in (RG_ROAD_EDGE_BOUNDARY, RG_CROSSWALK):
        assert needed in types
    for s in scenarios.values():
        assert RG_ROAD_EDGE_BOUNDARY in s.roadgraph_type
        lanes = np.isin(s.roadgraph_type, LANE_TYPES)
        assert (s.roadgraph_speed_limit[lanes] > 5.0).all()
    stop_signs = [s for (topology, _), s in scenarios.items() if RG_STOP_SIGN in s.roadgraph_type]
    assert all(np.sum(s.roadgraph_type == RG_STOP_SIGN) >= 3 for s in stop_signs)


def test_kinematics_are_consistent(scenarios):
    for key, s in scenarios.items():
        v = s.valid
        assert np.allclose(s.speed[v], np.hypot(s.velocity_x, s.velocity_y)[v], atol=1e-3)
        assert (np.abs(s.bbox_yaw[v]) <= np.pi + 1e-6).all()
        assert (s.timestamp_micros[v] == (np.arange(91) * 100_000)[None, :].repeat(s.num_objects, 0)[v]).all()
        # positions advance by about speed * dt along the heading (finite differences agree)
        both = v[:, 1:] & v[:, :-1]
        step = np.hypot(np.diff(s.x, axis=1), np.diff(s.y, axis=1))[both]
        assert np.abs(step - 0.1 * s.speed[:, 1:][both]).max() < 0.05, key


def test_parked_cars_stand_still_off_the_travel_lanes():
    s = generate_scenario(7, 0, SIZES, topology="straight")
    parked = np.flatnonzero((s.object_type == OBJECT_TYPE_VEHICLE) & (s.speed.max(axis=1) == 0) & s.valid.all(axis=1))
    if len(parked) == 0:
        pytest.skip("this draw has no parked cars")
    lanes = np.isin(s.roadgraph_type, LANE_TYPES)
    lane_xy = s.roadgraph_xyz[lanes, :2]
    for obj in parked:
        d = np.hypot(lane_xy[:, 0] - s.x[obj, 0], lane_xy[:, 1] - s.y[obj, 0]).min()
        assert d > 2.5  # the centre of the nearest lane is more than half a lane plus half a car away


def test_codec_round_trip_preserves_the_scenario(scenarios):
    s = scenarios[("intersection4", 0)]
    back = decode_scenario(encode_scenario(s, SIZES), SIZES)
    n, r, num_tl, k = s.num_objects, len(s.roadgraph_xyz), s.tl_state.shape[0], len(s.lane_id)
    assert back.scenario_id == s.scenario_id
    for name, count in (("x", n), ("y", n), ("bbox_yaw", n), ("velocity_x", n), ("valid", n), ("speed", n),
                        ("object_type", n), ("is_sdc", n), ("tracks_to_predict", n), ("roadgraph_xyz", r),
                        ("roadgraph_type", r), ("roadgraph_id", r), ("tl_state", num_tl),
                        ("tl_lane_id", num_tl), ("tl_x", num_tl), ("lane_id", k), ("lane_successors", k),
                        ("lane_left_neighbors", k)):
        original = getattr(s, name)
        assert np.array_equal(getattr(back, name)[:count], original.astype(getattr(back, name).dtype)), name
    assert not back.valid[n:].any() and not back.roadgraph_valid[r:].any()


@pytest.mark.slow
def test_two_hundred_scenarios_meet_every_bar():
    failures = []
    for index in range(200):
        s = generate_scenario(0, index, SIZES)
        mask = s.valid & (s.object_type == OBJECT_TYPE_VEHICLE)[:, None]
        points = np.stack([s.x[mask], s.y[mask]], axis=-1).astype(np.float64)
        if (s.validate() or overlapping_vehicle_pairs(s) or road_edge_signed_distance(s, points).max() >= 0
                or red_light_crossings(s, 0) or lane_graph_distance(s, 0).max() >= 1.0):
            failures.append(index)
    assert failures == []
