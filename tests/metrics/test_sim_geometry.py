"""Hand-worked geometry: box corners, SAT overlap, swept contact time, circle covers, segments."""

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from shapely.geometry import Polygon

from vmax_sim.geometry import (
    box_corners,
    boxes_overlap,
    circle_cover,
    contact_time,
    point_segment_distance,
    side_of_segment,
    to_local_points,
    wrap_angle,
)


def test_corners_of_an_axis_aligned_and_a_rotated_box():
    corners = box_corners(jnp.array([1.0, 2.0, 4.0, 2.0, 0.0]))
    np.testing.assert_allclose(corners, [[3, 3], [-1, 3], [-1, 1], [3, 1]], atol=1e-6)
    rotated = box_corners(jnp.array([0.0, 0.0, 4.0, 2.0, np.pi / 2]))
    np.testing.assert_allclose(rotated, [[-1, 2], [-1, -2], [1, -2], [1, 2]], atol=1e-6)


@pytest.mark.parametrize("other, expected", [
    ([3.9, 0.0, 4.0, 2.0, 0.0], True),  # 0.1 m bumper overlap
    ([4.0, 0.0, 4.0, 2.0, 0.0], False),  # exactly touching
    ([4.5, 0.0, 4.0, 2.0, 0.0], False),  # 0.5 m apart
    ([0.0, 1.9, 4.0, 2.0, 0.0], True),  # side by side, 0.1 m overlap
    ([3.0, 3.0, 4.0, 2.0, np.pi / 4], False),  # rotated, corners miss: SAT on the rotated axes separates
    ([2.8, 0.0, 4.0, 2.0, np.pi / 2], True),  # perpendicular, its side reaches x = 1.8 < 2
])
def test_overlap_cases(other, expected):
    assert bool(boxes_overlap(jnp.array([0.0, 0.0, 4.0, 2.0, 0.0]), jnp.array(other))) is expected


def test_overlap_broadcasts_over_many_boxes():
    others = jnp.array([[3.9, 0, 4, 2, 0], [10, 0, 4, 2, 0], [0, 0, 1, 1, 1.0]])
    np.testing.assert_array_equal(boxes_overlap(jnp.array([0.0, 0, 4, 2, 0]), others), [True, False, True])


def test_contact_time_two_cars_closing_at_10_mps_5_m_apart():
    # bumpers 5 m apart (centres 9 m for 4 m cars), closing at 10 m/s -> contact after 0.5 s
    ego = jnp.array([0.0, 0.0, 4.0, 2.0, 0.0])
    other = jnp.array([9.0, 0.0, 4.0, 2.0, np.pi])
    t = contact_time(ego, jnp.array([10.0, 0.0]), other, jnp.array([0.0, 0.0]), horizon=1.0)
    assert float(t) == pytest.approx(0.5, abs=1e-5)
    both_moving = contact_time(ego, jnp.array([5.0, 0.0]), other, jnp.array([-5.0, 0.0]), horizon=1.0)
    assert float(both_moving) == pytest.approx(0.5, abs=1e-5)
    assert np.isinf(float(contact_time(ego, jnp.array([10.0, 0.0]), other, jnp.zeros(2), horizon=0.4)))
    # parallel lanes never meet; overlapping boxes touch at t=0; moving apart never
    assert np.isinf(float(contact_time(ego, jnp.array([10.0, 0]), other.at[1].set(3.0), jnp.zeros(2), 5.0)))
    assert float(contact_time(ego, jnp.zeros(2), ego, jnp.zeros(2), 1.0)) == 0.0
    assert np.isinf(float(contact_time(ego, jnp.array([-10.0, 0]), other, jnp.zeros(2), 5.0)))


def test_contact_time_crossing_paths():
    # ego heading +x at 10 m/s, a car 20 m ahead crossing from y=-10 heading +y at 10 m/s
    ego = jnp.array([0.0, 0.0, 4.0, 2.0, 0.0])
    other = jnp.array([20.0, -10.0, 4.0, 2.0, np.pi / 2])
    t = contact_time(ego, jnp.array([10.0, 0.0]), other, jnp.array([0.0, 10.0]), horizon=5.0)
    # x-gap closes when 20 - 10t <= 3 (t >= 1.7); y-gap when |-10 + 10t| <= 3 (0.7 <= t <= 1.3): never both
    assert np.isinf(float(t))
    slower = contact_time(ego, jnp.array([10.0, 0.0]), other.at[0].set(15.0), jnp.array([0.0, 10.0]), 5.0)
    assert float(slower) == pytest.approx(1.2, abs=1e-5)  # x from 1.2 s, y until 1.3 s


def test_circle_cover_contains_every_corner():
    box = jnp.array([1.0, -2.0, 4.5, 2.0, 0.7])
    centres, radius = circle_cover(box, 3)
    corners = box_corners(box)
    inside = jnp.min(jnp.linalg.norm(corners[:, None] - centres[None], axis=-1), axis=1) <= radius + 1e-5
    assert bool(jnp.all(inside))
    assert float(radius) == pytest.approx(np.hypot(1.0, 0.75))


def test_point_segment_distance_and_side():
    a, b = jnp.array([0.0, 0.0]), jnp.array([10.0, 0.0])
    pts = jnp.array([[5.0, 2.0], [5.0, -3.0], [-3.0, 4.0], [12.0, 0.0]])
    np.testing.assert_allclose(point_segment_distance(pts, a, b), [2.0, 3.0, 5.0, 2.0], atol=1e-6)
    assert np.sign(side_of_segment(pts, a, b)[:2]).tolist() == [1.0, -1.0]


def test_frame_transform_and_wrap():
    local = to_local_points(jnp.array([[1.0, 1.0]]), jnp.array([1.0, 0.0]), jnp.asarray(np.pi / 2))
    np.testing.assert_allclose(local, [[1.0, 0.0]], atol=1e-6)
    assert float(wrap_angle(jnp.asarray(3 * np.pi / 2))) == pytest.approx(-np.pi / 2)


BOX = st.tuples(st.floats(-6, 6), st.floats(-6, 6), st.floats(0.5, 6), st.floats(0.5, 3), st.floats(-4, 4))
_OVERLAP = jax.jit(boxes_overlap)
_CONTACT = jax.jit(contact_time, static_argnames="horizon")


@settings(max_examples=30, deadline=None)
@given(BOX, BOX)
def test_overlap_agrees_with_shapely_and_is_symmetric(a, b):
    box_a, box_b = jnp.asarray(a, jnp.float32), jnp.asarray(b, jnp.float32)
    poly_a, poly_b = (Polygon(np.asarray(box_corners(x))) for x in (box_a, box_b))
    area = poly_a.intersection(poly_b).area
    got = bool(_OVERLAP(box_a, box_b))
    assert got == bool(_OVERLAP(box_b, box_a))
    if area > 1e-3:
        assert got and float(_CONTACT(box_a, jnp.zeros(2), box_b, jnp.zeros(2), horizon=1.0)) == 0.0
    elif poly_a.distance(poly_b) > 1e-3:
        assert not got
