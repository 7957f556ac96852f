"""Thresholds of every metric in one frozen config (published values where they exist)."""

from __future__ import annotations

import dataclasses

from scenariomax.schema import TL_ARROW_STOP, TL_FLASHING_STOP, TL_STOP


@dataclasses.dataclass(frozen=True)
class MetricsConfig:
    dt: float = 0.1  # seconds per step (10 Hz logs)
    # candidates shared by overlap / at-fault / TTC
    num_candidates: int = 8
    # Waymax set
    wrong_way_distance: float = 3.5  # m from every SDC path
    off_route_distance: float = 5.0  # m from the nearest on-route path
    off_route_relative_distance: float = 2.0  # m closer to an off-route path than to the route
    max_accel: float = 6.0  # m/s^2, kinematic feasibility bound (bicycle model action range)
    max_curvature: float = 0.3  # 1/m, kinematic feasibility bound
    # nuPlan set
    stopped_speed: float = 0.05  # m/s, ego/agent counted as stopped below it
    ttc_threshold: float = 0.95  # s, least acceptable time to collision
    ttc_ego_min_speed: float = 5e-3  # m/s, a slower ego never violates TTC
    max_overspeed: float = 2.23  # m/s, speed-limit violation that zeroes the score
    min_progress_ratio: float = 0.2  # making progress
    min_expert_progress: float = 1.0  # m; below it the expert did not move and progress scores 1
    direction_window_s: float = 1.0  # s, driving-direction window
    direction_fail_m: float = 6.0  # m against the lane in a window -> 0
    direction_warn_m: float = 2.0  # m against the lane in a window -> 0.5
    min_lon_accel: float = -4.05  # m/s^2
    max_lon_accel: float = 2.40  # m/s^2
    max_abs_lat_accel: float = 4.89  # m/s^2
    max_abs_lon_jerk: float = 4.13  # m/s^3
    max_abs_jerk: float = 8.37  # m/s^3, jerk magnitude
    max_abs_yaw_rate: float = 0.95  # rad/s
    max_abs_yaw_accel: float = 1.93  # rad/s^2
    comfort_window: int = 9  # samples of the Savitzky-Golay derivative (quadratic fit)
    # V-Max additions
    red_light_states: tuple[int, ...] = (TL_ARROW_STOP, TL_STOP, TL_FLASHING_STOP)
    red_light_lateral: float = 2.5  # m, stop point must be this close to the SDC's front
    lane_half_width: float = 1.85  # m, half a standard 3.7 m lane
    lane_max_angle_deg: float = 30.0  # lanes more skewed than this to the SDC do not count
    lane_match_distance: float = 3.0  # m, no lane (speed limit, lights) beyond it
    multiple_lanes_ok_s: float = 3.4  # s on several lanes -> score 1
    multiple_lanes_warn_s: float = 5.7  # s on several lanes -> score 0.5, above -> 0
    # scores
    nuplan_weights: tuple[tuple[str, float], ...] = (
        ("ttc_within_bound", 5.0), ("ego_progress", 5.0), ("speed_limit_compliance", 4.0), ("comfort", 2.0))
    vmax_extra_weights: tuple[tuple[str, float], ...] = (("multiple_lanes_score", 3.0),)


DEFAULT_METRICS_CONFIG = MetricsConfig()
