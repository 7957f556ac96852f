"""benchmarks/slot_crowding.py: which steps count as losing a near object, and as showing a far one."""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[2] / "benchmarks"))

from slot_crowding import crowding_shares  # noqa: E402


def test_a_step_loses_a_near_object_only_when_the_default_shows_it_and_the_wider_choice_does_not():
    # 3 steps, 3 objects: object 0 near, a pedestrian; object 1 near, a car; object 2 far on the route
    base = np.array([[1, 1, 0], [1, 1, 0], [0, 1, 0]], bool)
    wide = np.array([[0, 1, 1], [1, 1, 0], [1, 0, 1]], bool)  # step 0 drops the pedestrian, step 2 the car
    near = np.tile([True, True, False], (3, 1))
    far = np.tile([False, False, True], (3, 1))
    types = np.tile([2, 1, 1], (3, 1))
    shares = crowding_shares(base, wide, near, far, types)
    assert shares["steps"] == 3 and shares["near_lost_share"] == 2 / 3
    assert shares["near_lost_by_type"] == {"pedestrian": 1, "vehicle": 1}
    assert shares["far_shown_share"] == 2 / 3


def test_dropping_an_object_beyond_the_near_radius_does_not_count():
    base, wide = np.array([[True]]), np.array([[False]])
    shares = crowding_shares(base, wide, np.array([[False]]), np.array([[False]]), np.array([[1]]))
    assert shares["near_lost_share"] == 0.0 and shares["near_lost_by_type"] == {}
