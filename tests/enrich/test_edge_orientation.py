"""The one road-edge orientation rule (scenariomax.enrich.orientation), on hand-made maps.

Main case: a freeway and a street side by side, separated by a 0.6 m barrier whose two sides are two road
edges. For the freeway-side edge the nearest lane is the street's, beyond the barrier: a blind
nearest-lane vote reverses the (correct) edge; the rule only lets lanes it can see vote.
"""

from __future__ import annotations

import numpy as np
import pytest

from scenariomax import schema as sch
from scenariomax.enrich import edges_to_reverse, extract_lanes, with_edges_oriented, with_recomputed_directions
from scenariomax.enrich.orientation import edge_votes, lane_side_vote, orient_road_edges
from scenariomax.enrich.roadgraph import MapPolyline
from tests.enrich.scenes import line, make_scenario, straight_xy, track

EDGE, MEDIAN, LANE = sch.RG_ROAD_EDGE_BOUNDARY, sch.RG_ROAD_EDGE_MEDIAN, sch.RG_LANE_SURFACE_STREET
FREEWAY_SIDE, STREET_SIDE = 11, 12  # the two sides of the barrier


def barrier_map(freeway_side_reversed: bool = False, with_street_side: bool = True) -> list[MapPolyline]:
    """Freeway lane y = -1.5 between the edge y = -4 and the barrier's south face y = 1.3; barrier 1.3 .. 1.9;
    street with a bike lane y = 2.2 and a lane y = 4.5 between the barrier's north face y = 1.9 and the
    edge y = 6.5. Every edge is drawn with its road on the left unless `freeway_side_reversed`."""
    freeway_side = line((100, 1.3), (0, 1.3))  # westbound: the freeway (south) is on its left
    if freeway_side_reversed:
        freeway_side = freeway_side[::-1]
    polylines = [
        MapPolyline(1, sch.RG_LANE_FREEWAY, line((0, -1.5), (100, -1.5))),
        MapPolyline(2, sch.RG_LANE_BIKE, line((0, 2.2), (100, 2.2))),
        MapPolyline(3, LANE, line((100, 4.5), (0, 4.5))),
        MapPolyline(10, EDGE, line((0, -4), (100, -4))),
        MapPolyline(FREEWAY_SIDE, MEDIAN, freeway_side),
        MapPolyline(14, EDGE, line((100, 6.5), (0, 6.5))),
    ]
    if with_street_side:
        polylines.append(MapPolyline(STREET_SIDE, MEDIAN, line((0, 1.9), (100, 1.9))))  # eastbound: street on its left
    return polylines


def _first_x(polylines, feature_id) -> float:
    return float(next(p for p in polylines if p.feature_id == feature_id).xyz[0, 0])


def test_blind_vote_would_reverse_the_barrier_edge():
    """The scene really is the trap: without the other face of the barrier, the street's bike lane (0.9 m away)
    is the nearest lane of every point of the freeway-side edge, and it lies on its right."""
    alone = orient_road_edges(barrier_map(with_street_side=False))
    assert _first_x(alone, FREEWAY_SIDE) == 0.0  # reversed


def test_barrier_edge_keeps_its_correct_orientation():
    oriented = orient_road_edges(barrier_map())
    for feature_id, first_x in ((10, 0.0), (FREEWAY_SIDE, 100.0), (STREET_SIDE, 0.0), (14, 100.0)):
        assert _first_x(oriented, feature_id) == first_x, feature_id  # nothing reversed


def test_barrier_edge_drawn_backwards_is_still_fixed_by_the_lane_it_sees():
    """The visibility test blocks only lanes behind an edge: the freeway lane (2.8 m away, in sight) still
    corrects a freeway-side edge drawn the wrong way."""
    polylines = barrier_map(freeway_side_reversed=True)
    polylines = [p for p in polylines if p.feature_id != 2]  # no bike lane: the freeway lane is the nearest
    assert _first_x(orient_road_edges(polylines), FREEWAY_SIDE) == 100.0


def test_enrichment_uses_the_same_rule():
    scenario = make_scenario(barrier_map(), [track(straight_xy(10, 20, y=-1.5))])
    lanes = extract_lanes(scenario)
    assert len(edges_to_reverse(scenario, lanes)) == 0
    blind = make_scenario(barrier_map(with_street_side=False), [track(straight_xy(10, 20, y=-1.5))])
    runs = edges_to_reverse(blind, extract_lanes(blind))
    assert [int(blind.roadgraph_id[a]) for a, _ in runs] == [FREEWAY_SIDE]
    fixed = with_recomputed_directions(with_edges_oriented(scenario, lanes))
    west = fixed.roadgraph_dir[fixed.roadgraph_id == FREEWAY_SIDE]
    assert west[0, 0] < -0.99  # still westbound


def test_far_part_of_the_same_edge_blocks_too():
    """A U-shaped edge drawn as one polyline (east along y = 1, south, west along y = -3: the road is outside
    the U). The lane south of the lower arm is on the lower arm's left; the upper arm sees it only through
    the lower arm, so it does not vote (alone, the upper arm would call the lane on its right)."""
    upper, side, lower = line((0, 1), (50, 1)), line((50, 1), (50, -3))[1:], line((50, -3), (0, -3))[1:]
    lane_beyond = line((0, -4), (50, -4))[:, :2]
    assert edge_votes([upper], lane_beyond)[0] < -45
    assert edge_votes([lower], lane_beyond)[0] > 45
    assert edge_votes([np.vstack([upper, side, lower])], lane_beyond)[0] == pytest.approx(50.0, abs=2.5)


def test_sparse_vertices_vote_along_the_whole_edge():
    """Two vertices 100 m apart: votes are taken every 2 m along the edge, not only at its ends (where the
    nearest lanes here belong to a crossing street on the wrong side)."""
    edge = np.array([[0.0, -2.0], [100.0, -2.0]])
    lanes = np.vstack([line((0, 0), (100, 0))[:, :2], line((-1, -3), (-1, -30))[:, :2],
                       line((101, -3), (101, -30))[:, :2]])
    assert edge_votes([edge], lanes)[0] > 90  # ~100 m of the edge see the lane on their left


def test_lane_side_vote_units_and_abstention():
    lane = np.array([[x, 0.0] for x in range(11)], float)
    assert lane_side_vote(np.array([[0, -2], [10, -2]], float), lane) == pytest.approx(10.0)
    assert lane_side_vote(np.array([[10, -2], [0, -2]], float), lane) == pytest.approx(-10.0)
    assert lane_side_vote(np.array([[0, -200], [10, -200]], float), lane) == 0.0
    assert lane_side_vote(np.array([[0, -2], [10, -2]], float), np.zeros((0, 2))) == 0.0


def test_closed_edges_and_degenerate_input():
    square = np.array([[0, 0], [10, 0], [10, 10], [0, 10]], float)  # counter-clockwise, inside on the left
    inside = line((2, 5), (8, 5))[:, :2]
    assert edge_votes([square], inside, closed=[True])[0] > 0
    assert edge_votes([square[::-1]], inside, closed=[True])[0] < 0
    assert edge_votes([np.zeros((1, 2)), np.zeros((3, 2))], inside).tolist() == [0.0, 0.0]
    assert edge_votes([], inside).shape == (0,)
