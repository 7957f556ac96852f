"""SDC paths: start lanes, successor search, lane changes that follow the log, ranking, padding."""

from __future__ import annotations

import numpy as np

from scenariomax import schema as sch
from scenariomax.enrich import EnrichSettings, enrich_scenario
from scenariomax.enrich.geometry import project_to_polyline
from scenariomax.enrich.roadgraph import MapPolyline
from scenariomax.sources.base import MANIFEST_NOTES
from tests.enrich.scenes import CURRENT, NUM_STEPS, line, make_scenario, straight_xy, track

LANE = sch.RG_LANE_SURFACE_STREET
FAST = EnrichSettings(label_controllable=False, infer_lights=False)


def _two_lanes(length=400.0):
    return [MapPolyline(1, LANE, line((0, 0), (length, 0), 400)),
            MapPolyline(2, LANE, line((0, 3.5), (length, 3.5), 400))]


def _lane_change_xy():
    """10 m/s east; moves from y=0 to y=3.5 between steps 30 and 60 (smooth)."""
    xy = straight_xy(10, 10.0)
    u = np.clip((np.arange(NUM_STEPS) - 30) / 30.0, 0, 1)
    xy[:, 1] = 3.5 * (u * u * (3 - 2 * u))
    return xy


def test_straight_lane_path_starts_at_projection_and_is_padded():
    xy = straight_xy(10, 10.0, y=0.4)
    polylines = [MapPolyline(1, LANE, line((0, 0), (200, 0), 200))]
    out = enrich_scenario(make_scenario(polylines, [track(xy)]), FAST)
    assert out.path_xyz.shape == (10, 300, 3)
    assert out.path_valid[0].sum() == 181  # 200 m lane, start at x=20: 180 m -> 181 points at 1 m
    np.testing.assert_allclose(out.path_xyz[0, 0, :2], [20.0, 0.0], atol=1e-4)
    np.testing.assert_allclose(np.diff(out.path_arc_length[0, :181]), 1.0, atol=1e-4)
    assert out.path_on_route[0] and not out.path_valid[0, 181:].any()
    assert set(out.path_lane_id[0, :181]) == {1}


def test_lane_change_path_follows_the_logged_change():
    xy = _lane_change_xy()
    out = enrich_scenario(make_scenario(_two_lanes(), [track(xy)]), FAST)
    best = out.path_xyz[0][out.path_valid[0]]
    assert out.path_on_route[0]
    dist = project_to_polyline(xy[CURRENT:], best)[0]
    assert dist.max() < 0.3  # the blend follows the log exactly where it changes lanes
    ids = out.path_lane_id[0][out.path_valid[0]]
    assert ids[0] == 1 and ids[-1] == 2
    # The stay-in-lane path exists too, ranked lower and off route.
    stays = [p for p in range(10) if out.path_valid[p].any() and set(out.path_lane_id[p][out.path_valid[p]]) == {1}]
    assert stays and not out.path_on_route[stays[0]] and stays[0] > 0


def test_successor_chain_and_dead_end_branch_ranked_by_the_log():
    polylines = [MapPolyline(1, LANE, line((0, 0), (50, 0))), MapPolyline(2, LANE, line((50, 0), (400, 0), 400)),
                 MapPolyline(3, LANE, line((50, 0), (80, 17.3)))]  # 30-deg branch, not taken
    out = enrich_scenario(make_scenario(polylines, [track(straight_xy(10, 10.0))]), FAST)
    first = out.path_lane_id[0][out.path_valid[0]]
    assert list(dict.fromkeys(first.tolist())) == [1, 2] and out.path_on_route[0]
    assert out.path_valid[0].sum() == 300  # budget reached
    branch = [p for p in range(10) if 3 in out.path_lane_id[p]]
    assert branch and not out.path_on_route[branch[0]]


def test_missing_connector_is_bridged_along_the_log():
    # Lane 1 ends at x=50, lane 2 starts at x=70: the map lacks the 20 m connector.
    polylines = [MapPolyline(1, LANE, line((0, 0), (50, 0))), MapPolyline(2, LANE, line((70, 0), (300, 0), 300))]
    out = enrich_scenario(make_scenario(polylines, [track(straight_xy(10, 10.0))]), FAST)
    assert out.path_on_route[0]
    assert list(dict.fromkeys(out.path_lane_id[0][out.path_valid[0]].tolist())) == [1, 2]


def test_no_lane_near_the_sdc_leaves_no_path_and_a_note():
    """Not a failure (issue 24): the scenario simulates without an on-route path, and the manifest says why."""
    polylines = [MapPolyline(1, LANE, line((0, 50), (100, 50)))]
    out = enrich_scenario(make_scenario(polylines, [track(straight_xy(10, 10.0))]), FAST)
    assert not out.path_valid.any() and not out.path_on_route.any()
    assert "no lane within" in out.metadata[MANIFEST_NOTES]["no_sdc_path"]
    assert not out.validate()


def test_lane_heading_against_the_sdc_is_not_a_start_lane():
    polylines = [MapPolyline(1, LANE, line((200, 0), (0, 0), 200))]  # runs west, SDC drives east
    out = enrich_scenario(make_scenario(polylines, [track(straight_xy(10, 10.0))]), FAST)
    assert not out.path_valid.any() and "no_sdc_path" in out.metadata[MANIFEST_NOTES]


def test_an_oncoming_neighbour_is_no_lane_change_and_no_path_turns_back():
    """AV2 names the oncoming lane a left neighbour: a "lane change" into it made paths loop back past the log's
    end, outside the road edges. The same-direction neighbour still gets its lane change."""
    from scenariomax.enrich.roadgraph import LaneLinks, lane_graph_arrays

    east = MapPolyline(1, LANE, line((0, 0), (120, 0), 240))
    west = MapPolyline(2, LANE, line((120, 3.5), (0, 3.5), 240))  # oncoming, named 1's left neighbour
    beside = MapPolyline(3, LANE, line((0, -3.5), (120, -3.5), 240))  # same way, 1's right neighbour
    links = lane_graph_arrays([LaneLinks(1, left_neighbors=(2,), right_neighbors=(3,)), LaneLinks(2),
                               LaneLinks(3)])
    xy = straight_xy(10, 5.0)  # ends at x=55, before the lanes do
    out = enrich_scenario(make_scenario([east, west, beside], [track(xy)], **links), FAST)
    for p in np.flatnonzero(out.path_valid.any(axis=1)):
        points = out.path_xyz[p][out.path_valid[p]]
        assert (np.diff(points[:, 0]) > -1e-3).all(), f"path {p} turns back west: {points[-1]}"
        assert 2 not in set(out.path_lane_id[p][out.path_valid[p]])
    assert any(3 in set(out.path_lane_id[p][out.path_valid[p]]) for p in range(10))


def test_may_bridge_is_false_only_where_no_logged_position_is_near():
    from scenariomax.enrich.geometry import row_norm
    from scenariomax.enrich.paths import _may_bridge

    rng = np.random.default_rng(5)
    skipped = 0
    for _ in range(300):
        track = rng.normal(size=(int(rng.integers(2, 30)), 2)) * rng.uniform(0.1, 20) + rng.uniform(-1e4, 1e4, 2)
        box = (*track.min(axis=0).tolist(), *track.max(axis=0).tolist())
        for end in track[rng.integers(0, len(track), 4)] + rng.normal(size=(4, 2)) * rng.uniform(0.1, 30):
            gap = float(row_norm(track - end).min())  # as _bridge measures it
            if not _may_bridge(np.array([*end, 0.0]), box, 6.0):
                assert gap > 6.0
                skipped += 1
    assert skipped > 100
    assert not _may_bridge(np.zeros(3), None, 6.0)
