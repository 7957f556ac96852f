"""The nuPlan ego vehicle: ego_pose rows (rear-axle pose, body-frame velocity) -> box-centre states.

Vehicle parameters are the devkit's Chrysler Pacifica (nuplan_vehicle_parameters.yaml).
"""

from __future__ import annotations

import numpy as np

from scenariomax.enrich.geometry import wrap_angle  # noqa: F401 (shared; re-exported)

EGO_LENGTH_M = 5.176
EGO_WIDTH_M = 2.297
EGO_HEIGHT_M = 1.777
REAR_AXLE_TO_CENTER_M = 1.461  # box centre lies this far ahead of the rear axle, along the heading


def quaternion_yaw(qw: np.ndarray, qx: np.ndarray, qy: np.ndarray, qz: np.ndarray) -> np.ndarray:
    """Heading (rotation about z) of scalar-first quaternions. (...) -> (...) radians in [-pi, pi]."""
    return np.arctan2(2.0 * (qw * qz + qx * qy), 1.0 - 2.0 * (qy * qy + qz * qz))


def rear_axle_to_center(x: np.ndarray, y: np.ndarray, yaw: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Box-centre position from the rear-axle position and heading. (...) -> (...), (...)"""
    return x + REAR_AXLE_TO_CENTER_M * np.cos(yaw), y + REAR_AXLE_TO_CENTER_M * np.sin(yaw)


def center_velocity_global(vx_body: np.ndarray, vy_body: np.ndarray, yaw_rate: np.ndarray, yaw: np.ndarray
                           ) -> tuple[np.ndarray, np.ndarray]:
    """Velocity of the box centre in the global frame.

    ego_pose velocities are the rear axle's, in the body frame; the centre moves with
    v + omega x r (r = REAR_AXLE_TO_CENTER_M along body x), then rotated by the heading.
    """
    vx_c = vx_body
    vy_c = vy_body + yaw_rate * REAR_AXLE_TO_CENTER_M
    cos, sin = np.cos(yaw), np.sin(yaw)
    return cos * vx_c - sin * vy_c, sin * vx_c + cos * vy_c
