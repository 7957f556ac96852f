"""benchmarks/imitation_gap.py: the student-vs-teacher statistics it prints."""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np
import pytest

sys.path.insert(0, str(Path(__file__).resolve().parents[2] / "benchmarks"))
from imitation_gap import AHEAD_KINDS, gap_statistics, nearest_ahead_type, observation_variants  # noqa: E402


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


def test_full_brake_labels_pull_the_stretched_mean_far_below_the_plain_one():
    # nine gentle +0.2 labels and one full brake: the plain mean stays positive, the likelihood's mode brakes
    teacher = np.array([[0.2, 0.0]] * 9 + [[-1.0, 0.0]])
    stats = gap_statistics(teacher, teacher, np.full(10, 5.0))
    assert stats["saturated_label_share"] == pytest.approx(0.1)
    assert stats["mean_label_accel"] == pytest.approx(0.08)
    assert stats["stretched_mean_label_accel"] < -0.15  # tanh((9 * atanh(0.2) + atanh(-0.999)) / 10) = -0.19


def test_the_students_spread_is_read_where_it_holds_and_where_it_moves():
    # held at steps 0 and 1 (spreads 0.3, 0.5), moving at step 3 (0.1); step 2 stands but the teacher holds too
    teacher = np.array([[0.25, 0.0], [0.25, 0.0], [-0.1, 0.0], [0.0, 0.0]])
    student = np.array([[0.0, 0.0], [0.0, 0.0], [0.0, 0.0], [0.0, 0.0]])
    stats = gap_statistics(student, teacher, np.array([0.0, 0.1, 0.2, 9.0]), np.array([0.3, 0.5, 0.9, 0.1]))
    assert stats["held_sample_std"] == pytest.approx(0.4)
    assert stats["moving_sample_std"] == pytest.approx(0.1)
    assert gap_statistics(student[3:], teacher[3:], np.array([9.0]), np.array([0.1]))["held_sample_std"] is None


def test_the_held_steps_count_where_a_changed_observation_pulls_away():
    # held at steps 0-2; hiding the objects pulls away at two of them (and at the moving step 3, not counted)
    teacher = np.array([[0.25, 0.0]] * 3 + [[0.1, 0.0]])
    student = np.zeros((4, 2))
    speed = np.array([0.0, 0.1, 0.2, 9.0])
    variants = {"no_objects": np.array([0.3, 0.2, 0.0, 0.4]), "green_ahead": np.array([0.0, 0.05, -0.1, 0.4])}
    stats = gap_statistics(student, teacher, speed, np.zeros(4), variants)
    assert stats["pulls_away_with"]["no_objects"] == pytest.approx(2 / 3)
    assert stats["pulls_away_with"]["green_ahead"] == 0.0  # +0.05 is not above the pull-away threshold
    moving = gap_statistics(student[3:], teacher[3:], speed[3:], np.zeros(1), {k: v[3:] for k, v in variants.items()})
    assert moving["pulls_away_with"]["no_objects"] is None


def test_each_variant_changes_only_its_part_of_the_observation():
    import jax
    import jax.numpy as jnp

    from vmax_sim.observation.features import Observation

    k, n, m, lights, targets = 5, 3, 4, 2, 2
    ones = lambda *shape: np.ones(shape, bool)  # noqa: E731
    obs = Observation(sdc=np.zeros((k, 6), np.float32), sdc_valid=ones(k), objects=np.zeros((n, k, 12), np.float32),
                      objects_valid=ones(n, k), roadgraph=np.zeros((m, 8), np.float32), roadgraph_valid=ones(m),
                      lights=np.zeros((lights, 6), np.float32), lights_valid=np.zeros(lights, bool),
                      path_targets=np.zeros((targets, 2), np.float32), path_targets_valid=ones(targets))
    variants = observation_variants(jax.tree.map(jnp.asarray, obs), max_distance=50.0)
    assert not np.asarray(variants["no_objects"].objects_valid).any()
    assert np.asarray(variants["no_objects"].roadgraph_valid).all()
    assert np.asarray(variants["no_own_past"].sdc_valid).tolist() == [False] * (k - 1) + [True]
    assert not np.asarray(variants["no_map"].roadgraph_valid).any()
    assert not np.asarray(variants["no_route"].path_targets_valid).any()
    green = variants["green_ahead"]
    assert np.asarray(green.lights_valid).tolist() == [True, False]
    np.testing.assert_allclose(np.asarray(green.lights[0]), [6.0 / 50.0, 0.0, 0.0, 0.0, 1.0, 0.0])  # green one-hot
    assert np.asarray(green.objects_valid).all() and np.asarray(green.sdc_valid).all()


def test_a_student_that_drives_on_where_its_teacher_brakes_is_counted_by_what_is_ahead():
    # moving steps where the teacher brakes: two with a pedestrian ahead (the student drives on at one), one with a
    # vehicle ahead (it brakes); a step where the teacher brakes gently and a standing one do not count
    teacher = np.array([[-0.5, 0.0], [-0.5, 0.0], [-0.3, 0.0], [-0.1, 0.0], [-0.5, 0.0]])
    student = np.array([[0.02, 0.0], [-0.3, 0.0], [-0.2, 0.0], [0.1, 0.0], [0.1, 0.0]])
    speed = np.array([1.5, 1.5, 5.0, 5.0, 0.0])
    ahead = np.array([2, 2, 1, 0, 2])
    stats = gap_statistics(student, teacher, speed, ahead_type=ahead)["drove_on"]
    assert stats["share"] == pytest.approx(1 / 3)
    assert stats["by_ahead"]["pedestrian"] == [0.5, 2]
    assert stats["by_ahead"]["vehicle"] == [0.0, 1]
    assert stats["by_ahead"]["nothing"] == [None, 0]
    assert set(stats["by_ahead"]) == set(AHEAD_KINDS)
    assert "drove_on" not in gap_statistics(student, teacher, speed)


def test_the_object_named_ahead_is_the_nearest_in_the_corridor_along_the_heading():
    import jax.numpy as jnp

    # the SDC (slot 0) at the origin heading +y: a pedestrian 4 m ahead, a vehicle 8 m ahead, a cyclist 2 m to the
    # side (outside the corridor), a vehicle behind and an invalid one 1 m ahead
    x = jnp.array([0.0, 0.5, -0.5, 6.0, 0.0, 0.0])
    y = jnp.array([0.0, 4.0, 8.0, 2.0, -5.0, 1.0])
    yaw = jnp.full(6, jnp.pi / 2)
    valid = jnp.array([True, True, True, True, True, False])
    types = jnp.array([1, 2, 1, 3, 1, 1])
    assert int(nearest_ahead_type(x, y, yaw, valid, types, 0)) == 2
    assert int(nearest_ahead_type(x, y, yaw, valid.at[1].set(False), types, 0)) == 1
    assert int(nearest_ahead_type(x, y, yaw, valid.at[1:3].set(False), types, 0)) == 0
