"""Building blocks with hand-worked values: signal phases, geometry checks, road edges."""

import numpy as np
import pytest

from scenariomax.enrich.roadgraph import MapPolyline, polylines_to_roadgraph
from scenariomax.scenario import Scenario
from scenariomax.schema import LANE_TYPES, RG_ROAD_EDGE_BOUNDARY, TL_CAUTION, TL_GO, TL_STOP
from scenariomax.sources.synthetic import build_network, road_edge_signed_distance
from scenariomax.sources.synthetic.checks import box_corners, boxes_overlap
from scenariomax.sources.synthetic.signals import SignalPlan, pedestrian_phase, signal_states


def test_signal_phases_follow_the_cycle():
    # Two approaches: green 5 s, yellow 3 s, all-red 1 s each, then 4 s for pedestrians: 22 s cycle.
    plan = SignalPlan(num_groups=2, green_s=5.0, yellow_s=3.0, all_red_s=1.0, pedestrian_s=4.0, offset_s=0.0)
    times = np.array([0.0, 6.0, 8.5, 9.5, 15.0, 19.0, 22.0])
    states = signal_states(plan, times)
    assert states[0].tolist() == [TL_GO, TL_CAUTION, TL_STOP, TL_STOP, TL_STOP, TL_STOP, TL_GO]
    assert states[1].tolist() == [TL_STOP, TL_STOP, TL_STOP, TL_GO, TL_CAUTION, TL_STOP, TL_STOP]
    assert pedestrian_phase(plan, times).tolist() == [False, False, False, False, False, True, False]
    # Never two approaches on green together.
    dense = signal_states(plan, np.arange(0, 44, 0.1))
    assert ((dense == TL_GO).sum(axis=0) <= 1).all()


def test_box_overlap_hand_cases():
    a = box_corners(np.array([0.0]), np.array([0.0]), np.array([0.0]), np.array([4.0]), np.array([2.0]))
    touching_corner = box_corners(np.array([3.9]), np.array([1.9]), np.array([np.pi / 4]), np.array([4.0]),
                                  np.array([2.0]))
    beside = box_corners(np.array([0.0]), np.array([2.2]), np.array([0.0]), np.array([4.0]), np.array([2.0]))
    behind = box_corners(np.array([-4.5]), np.array([0.0]), np.array([0.3]), np.array([4.0]), np.array([2.0]))
    crossing = box_corners(np.array([1.0]), np.array([1.0]), np.array([np.pi / 2]), np.array([4.0]), np.array([2.0]))
    assert not boxes_overlap(a, beside)[0]
    assert not boxes_overlap(a, behind)[0]
    assert boxes_overlap(a, crossing)[0]
    # rotated 45 degrees at (3.9, 1.9): its nearest corner pokes into the first box.
    assert boxes_overlap(a, touching_corner)[0]


def _scenario_with_map(polylines):
    rg = polylines_to_roadgraph(polylines)
    one = np.zeros((1, 1))
    return Scenario(scenario_id="t", object_id=[1], object_type=[1], is_sdc=[True], x=one, y=one, z=one,
                    bbox_yaw=one, length=one + 4, width=one + 2, height=one + 1.5, velocity_x=one,
                    velocity_y=one, valid=np.ones((1, 1), bool), current_time_index=0, **rg)


def test_signed_distance_is_negative_inside_a_counter_clockwise_edge():
    square = np.array([[0, 0, 0], [10, 0, 0], [10, 10, 0], [0, 10, 0], [0, 0, 0]], np.float64)
    s = _scenario_with_map([MapPolyline(1, RG_ROAD_EDGE_BOUNDARY, square)])
    d = road_edge_signed_distance(s, np.array([[5.0, 5.0], [1.0, 5.0], [12.0, 5.0], [5.0, -3.0]]))
    assert np.allclose(d, [-5.0, -1.0, 2.0, 3.0], atol=1e-5)


def test_every_lane_centre_point_is_inside_the_generated_edges():
    for i, topology in enumerate(["intersection4", "merge", "curve"]):
        network = build_network(np.random.default_rng([11, i]), topology)
        s = _scenario_with_map(network.map_polylines())
        lanes = np.isin(s.roadgraph_type, LANE_TYPES)
        lane_xy = s.roadgraph_xyz[lanes, :2].astype(np.float64)
        lane_xy = lane_xy[::7]  # a sample keeps the test fast
        d = road_edge_signed_distance(s, lane_xy)
        assert d.max() < -1.0, topology  # half a lane inside, at least, even where lanes leave the map
        assert np.median(d) < -1.0


def test_junction_lanes_are_linked_both_ways():
    network = build_network(np.random.default_rng([3, 3]), "intersection4")
    by_id = {lane.lane_id: lane for lane in network.lanes}
    for lane in network.lanes:
        for nxt in lane.successors:
            assert lane.lane_id in by_id[nxt].predecessors
            assert np.allclose(lane.xy[-1], by_id[nxt].xy[0], atol=1e-6)  # connected end to start
        if lane.is_gated:
            assert lane.predecessors and lane.successors
    # every lane entering the junction carries a light or a stop sign
    entering = [lane for lane in network.lanes if not lane.is_gated and any(by_id[n].is_gated for n in lane.successors)]
    assert entering and all(lane.light_index >= 0 or lane.has_stop_sign for lane in entering)


def test_unknown_topology_is_a_clear_error():
    with pytest.raises(ValueError, match="unknown synthetic topology 'spaghetti'"):
        build_network(np.random.default_rng(0), "spaghetti")
