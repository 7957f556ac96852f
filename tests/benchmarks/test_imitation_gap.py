"""benchmarks/imitation_gap.py: the student-vs-teacher statistics it prints."""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np
import pytest

sys.path.insert(0, str(Path(__file__).resolve().parents[2] / "benchmarks"))
from imitation_gap import gap_statistics  # noqa: E402


def test_a_student_that_stays_where_its_teacher_pulls_away_is_counted():
    # four standing steps where the teacher pulls away: the student holds still in three; two moving steps
    teacher = np.array([[0.25, 0.0]] * 4 + [[0.0, 0.1], [-0.2, 0.0]])
    student = np.array([[0.0, 0.0], [0.01, 0.0], [-0.1, 0.0], [0.2, 0.0], [0.0, 0.1], [-0.1, 0.0]])
    speed = np.array([0.0, 0.1, 0.2, 0.3, 8.0, 9.0])
    stats = gap_statistics(student, teacher, speed)
    assert stats["steps"] == 6
    assert stats["held_still_share"] == pytest.approx(0.75)
    assert stats["standing_share"] == pytest.approx(4 / 6)
    assert stats["mae_accel"] == pytest.approx((0.25 + 0.24 + 0.35 + 0.05 + 0.0 + 0.1) / 6)
    assert stats["bias_accel"] == pytest.approx((-0.25 - 0.24 - 0.35 - 0.05 + 0.0 + 0.1) / 6)
    assert stats["mae_steer"] == pytest.approx(0.0)
