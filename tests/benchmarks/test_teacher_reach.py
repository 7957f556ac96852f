"""benchmarks/teacher_reach.py: which steps count as braking, and what its shares are over."""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[2] / "benchmarks"))

from teacher_reach import reach_shares  # noqa: E402


def test_shares_are_over_moving_steps_split_by_the_teachers_braking():
    label = np.array([-0.5, -0.5, -0.5, 0.1, 0.1, -0.5])
    speed = np.array([10.0, 10.0, 10.0, 10.0, 10.0, 1.0])  # the last step stands: not counted
    further = np.array([True, True, False, True, False, True])
    shares = reach_shares(label, speed, further)
    assert shares["moving_steps"] == 5
    assert shares["braking_share"] == 3 / 5
    assert shares["further_when_braking"] == 2 / 3 and shares["further_otherwise"] == 1 / 2


def test_no_braking_step_gives_no_share_instead_of_a_division_by_zero():
    shares = reach_shares(np.zeros(3), np.full(3, 10.0), np.ones(3, bool))
    assert shares["further_when_braking"] is None and shares["further_otherwise"] == 1.0
