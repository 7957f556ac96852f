"""The small pure functions of the GPUDrive source, against hand-worked values."""

from __future__ import annotations

import numpy as np
import pytest

from scenariomax.schema import Sizes
from scenariomax.sources.gpudrive import (
    LAYOUT_GPUDRIVE_METADATA,
    LAYOUT_NOCTURNE,
    ScenarioError,
    box_dimensions,
    choose_sdc,
    consistent_velocity,
    fix_yaw_flips,
    headings_in_degrees,
    light_state_code,
    log_window_starts,
    road_type,
)
from scenariomax.sources.gpudrive.layout import RawRoad
from scenariomax.sources.gpudrive.tracks import box_centre_heights, flipped_steps, usable_steps

VEHICLE, PEDESTRIAN, CYCLIST, OTHER = 1, 2, 3, 4


def test_flipped_steps_needs_long_runs_on_each_side():
    yaw = np.zeros(12)
    yaw[5:7] = np.pi  # a two-step flip inside two 5-step runs
    assert np.flatnonzero(flipped_steps(yaw, np.ones(12, bool))).tolist() == [5, 6]
    yaw = np.zeros(12)
    yaw[:2] = np.pi  # a flip at the start: one long run after it is enough
    assert np.flatnonzero(flipped_steps(yaw, np.ones(12, bool))).tolist() == [0, 1]
    yaw = np.zeros(6)
    yaw[3:] = np.pi  # 3 + 3 steps: no side is long enough to trust, nothing changes
    assert not flipped_steps(yaw, np.ones(6, bool)).any()
    yaw = np.linspace(0, np.pi, 30)  # a U-turn, 6 degrees per step: not a flip
    assert not flipped_steps(yaw, np.ones(30, bool)).any()


def test_fix_yaw_flips_leaves_pedestrians_alone():
    yaw = np.zeros((2, 12))
    yaw[:, 5] = np.pi
    fixed, count = fix_yaw_flips(yaw, np.ones((2, 12), bool), np.array([VEHICLE, PEDESTRIAN]))
    assert count == 1 and fixed[0, 5] == pytest.approx(0.0) and fixed[1, 5] == pytest.approx(np.pi)


def test_box_dimensions():
    boxes = box_dimensions(np.array([1.9, 0.6, 0.0, 4.0, 1.0]), np.array([4.6, 0.7, 0.0, 4.4, 2.0]),
                           np.array([1.5, np.nan, 1.7, -1.0, 1.0]), np.array([VEHICLE, PEDESTRIAN, VEHICLE, VEHICLE,
                                                                              OTHER]))
    np.testing.assert_allclose(boxes.length, [4.6, 0.6, 4.5, 4.0, 1.0])  # only the clearly swapped vehicle
    np.testing.assert_allclose(boxes.width, [1.9, 0.7, 2.0, 4.4, 2.0])  # 4.4 / 4.0 < 1.2: not clearly wider
    np.testing.assert_allclose(boxes.height, [1.5, 1.7, 1.7, 1.6, 1.0])
    assert boxes.swapped.tolist() == [True, False, False, False, False]
    assert boxes.defaulted.tolist() == [False, False, True, False, False]
    assert boxes.height_defaulted.tolist() == [False, True, False, True, False]


def test_consistent_velocity():
    xy = np.zeros((1, 5, 2))
    xy[0, :, 0] = [0.0, 1.0, 2.0, 3.0, 4.0]  # 10 m/s east
    velocity = np.array([[[10.0, 0], [10.5, 0], [0.0, 0], [np.nan, 0], [9.0, 0]]])
    usable = np.ones((1, 5), bool)
    out, derived = consistent_velocity(xy, velocity, usable)
    assert derived.tolist() == [[False, False, True, True, False]]
    np.testing.assert_allclose(out[0, :, 0], [10.0, 10.5, 10.0, 10.0, 9.0])
    usable[0, 2] = False  # an unusable step is neither checked nor used as a neighbour
    out, derived = consistent_velocity(xy, velocity, usable)
    assert derived.tolist() == [[False, False, False, True, False]] and out[0, 2, 0] == 0.0
    lone = consistent_velocity(xy[:, :1], np.full((1, 1, 2), np.nan), np.ones((1, 1), bool))[0]
    np.testing.assert_array_equal(lone, 0.0)  # no neighbour to derive from


def test_choose_sdc_rules():
    types = np.array([VEHICLE, VEHICLE, PEDESTRIAN])
    usable = np.ones((3, 4), bool)
    xy = np.zeros((3, 4, 2))
    xy[0, :, 0] = [0, 5, 10, 15]  # object 0 travels 15 m, object 1 stays
    assert choose_sdc(2, types, usable, xy) == (2, "named")
    assert choose_sdc(None, types, usable, xy) == (0, "furthest")  # the last object is a pedestrian
    types[2] = VEHICLE
    assert choose_sdc(None, types, usable, xy) == (2, "last-track")
    usable[:, 1] = False
    with pytest.raises(ScenarioError, match="no vehicle is valid at every step"):
        choose_sdc(None, types, usable, xy)
    with pytest.raises(ScenarioError, match="outside the 3 objects"):
        choose_sdc(7, types, usable, xy)


def test_box_centre_heights():
    usable = np.ones((2, 4), bool)
    height = np.array([1.6, 2.0])
    z, replaced, has_z = box_centre_heights(np.full((2, 4), np.nan), usable, height)
    assert not has_z and replaced == 0
    np.testing.assert_allclose(z, [[0.8] * 4, [1.0] * 4])
    raw = np.array([[5.0, 5.1, 30.0, 5.0], [np.nan, np.nan, np.nan, np.nan]])
    z, replaced, has_z = box_centre_heights(raw, usable, height)
    assert has_z and replaced == 5  # the spike, and the track without z (takes the scene's median)
    np.testing.assert_allclose(z, [[5.0, 5.1, 5.05, 5.0], [5.05] * 4])


def test_usable_steps_drop_sentinels_and_nan():
    position = np.array([[[1.0, 2.0, 0.0], [np.nan, 2.0, 0.0], [1e300, 0.0, 0.0], [1.0, 2.0, np.nan]]])
    heading = np.array([[0.0, 0.0, 0.0, np.inf]])
    assert usable_steps(position, heading, np.ones((1, 4), bool)).tolist() == [[True, False, False, False]]


def test_heading_unit_vote():
    velocity = np.zeros((1, 10, 2))
    velocity[..., 1] = 5.0  # moving north
    valid = np.ones((1, 10), bool)
    assert headings_in_degrees(np.full((1, 10), 90.0), velocity, valid, LAYOUT_GPUDRIVE_METADATA)
    assert not headings_in_degrees(np.full((1, 10), np.pi / 2), velocity, valid, LAYOUT_NOCTURNE)
    parked = np.zeros((1, 10, 2))  # nothing moves: small angles fall back on the layout
    assert headings_in_degrees(np.full((1, 10), 1.0), parked, valid, LAYOUT_NOCTURNE)
    assert not headings_in_degrees(np.full((1, 10), 1.0), parked, valid, LAYOUT_GPUDRIVE_METADATA)


@pytest.mark.parametrize("kind, element, expected", [
    ("lane", 0, 2), ("lane", 1, 1), ("lane", 3, 3), ("lane", None, 2), ("lane", 99, 2),
    ("road_line", 5, 0), ("road_line", 13, 13), ("road_line", None, 0),
    ("road_edge", 14, 15), ("road_edge", 16, 16), ("road_edge", None, 15),
    ("stop_sign", 17, 17), ("crosswalk", None, 18), ("speed_bump", 19, 19), ("driveway", -1, 20),
    ("unknown", 0, None), ("Lane", 1, 1),
])
def test_road_type(kind, element, expected):
    assert road_type(RawRoad(kind, element, None, np.zeros((0, 3)))) == expected


@pytest.mark.parametrize("state, expected", [
    ("unknown", 0), ("arrow_stop", 1), ("arrow_caution", 2), ("arrow_go", 3), ("stop", 4), ("caution", 5),
    ("go", 6), ("flashing_stop", 7), ("flashing_caution", 8), ("LANE_STATE_GO", 6), (6, 6), (42, None),
    ("purple", None),
])
def test_light_state_code(state, expected):
    assert light_state_code(state) == expected


def test_log_window_starts():
    sizes = Sizes()
    assert log_window_starts(91, sizes, 80) == [0]
    assert log_window_starts(199, sizes, 80) == [0, 80]
    assert log_window_starts(11, sizes, 80) == [0]
    assert log_window_starts(10, sizes, 80) == [-2]  # current step at log step 8, the history padded
    assert log_window_starts(2, sizes, 80) == [-10]
    assert log_window_starts(1, sizes, 80) == []
