"""benchmarks/crossing_traffic.py: what counts as something crossing close in front of the moving SDC."""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[2] / "benchmarks"))
from crossing_traffic import close_parked_passes, crossing_steps, slow_leader_steps, standing_steps  # noqa: E402


def _scene():
    # the SDC (object 0) drives along +x at 5 m/s for 6 steps; object 1 a vehicle crossing (+y) 8 m ahead at 6 m/s
    # at steps 2-3 only; object 2 a pedestrian 4 m ahead at step 4; object 3 a vehicle ahead driving the same way
    steps = 6
    x, y, yaw, speed = (np.zeros((4, steps)) for _ in range(4))
    valid = np.zeros((4, steps), bool)
    x[0], speed[0], valid[0] = np.arange(steps) * 0.5, 5.0, True
    x[1, 2:4], yaw[1], speed[1], valid[1, 2:4] = x[0, 2:4] + 8.0, np.pi / 2, 6.0, True
    x[2, 4], yaw[2], speed[2], valid[2, 4] = x[0, 4] + 4.0, np.pi / 2, 1.2, True
    x[3], speed[3], valid[3] = x[0] + 12.0, 5.0, True
    return x, y, yaw, speed, valid, np.array([1, 1, 2, 1])


def test_a_vehicle_crossing_nearest_ahead_counts_and_one_driving_the_same_way_does_not():
    x, y, yaw, speed, valid, types = _scene()
    assert crossing_steps(x, y, yaw, speed, valid, types, sdc=0, start=0) == (6, 2, 1)


def test_only_moving_steps_from_the_current_step_on_count():
    x, y, yaw, speed, valid, types = _scene()
    assert crossing_steps(x, y, yaw, speed, valid, types, sdc=0, start=3) == (3, 1, 1)
    speed[0, 2] = 0.2  # standing at step 2: not counted, its crossing neither
    assert crossing_steps(x, y, yaw, speed, valid, types, sdc=0, start=0) == (5, 1, 1)


def test_a_slow_or_distant_crossing_vehicle_does_not_count():
    x, y, yaw, speed, valid, types = _scene()
    speed[1] = 1.0  # rolling across below 2 m/s
    assert crossing_steps(x, y, yaw, speed, valid, types, sdc=0, start=0)[1] == 0
    x, y, yaw, speed, valid, types = _scene()
    y[1] = 4.0  # 4 m to the side: outside the corridor
    assert crossing_steps(x, y, yaw, speed, valid, types, sdc=0, start=0)[1] == 0


def test_standing_counts_the_valid_steps_below_walking_pace_from_the_current_step_on():
    x, y, yaw, speed, valid, types = _scene()
    speed[0, [1, 4]] = 0.2
    valid[0, 5] = False
    assert standing_steps(speed, valid, sdc=0, start=0) == (5, 2)
    assert standing_steps(speed, valid, sdc=0, start=2) == (3, 1)


def test_a_slow_vehicle_going_the_sdcs_way_nearest_ahead_is_a_slow_leader():
    x, y, yaw, speed, valid, types = _scene()
    assert slow_leader_steps(x, y, yaw, speed, valid, types, sdc=0, start=0) == 0  # the leader keeps 5 m/s
    speed[3, 1:] = 2.0  # it crawls from step 1 on; at steps 2-4 the crossing car and the pedestrian are nearer
    assert slow_leader_steps(x, y, yaw, speed, valid, types, sdc=0, start=0) == 2
    speed[3, 1:] = 0.2  # standing: a queue, not a slow leader
    assert slow_leader_steps(x, y, yaw, speed, valid, types, sdc=0, start=0) == 0
    speed[3], yaw[3] = 2.0, np.pi  # oncoming
    assert slow_leader_steps(x, y, yaw, speed, valid, types, sdc=0, start=0) == 0


def test_a_parked_car_passed_with_less_than_a_metre_between_the_boxes_counts_once():
    x, y, yaw, speed, valid, types = _scene()
    length, width = np.full(x.shape, 4.5), np.full(x.shape, 2.0)
    x[3], y[3], speed[3] = 1.0, -2.6, 0.0  # parked beside the SDC's start: 0.6 m between the boxes
    assert close_parked_passes(x, y, yaw, speed, valid, types, length, width, sdc=0, start=0) == 1
    y[3] = -3.2  # 1.2 m: not close
    assert close_parked_passes(x, y, yaw, speed, valid, types, length, width, sdc=0, start=0) == 0
    y[3], speed[3, 5] = -2.6, 3.0  # it drives off at the end: not parked
    assert close_parked_passes(x, y, yaw, speed, valid, types, length, width, sdc=0, start=0) == 0
