"""Hand-built scenes for the enrichment tests (lanes and trajectories in plain numbers)."""

from __future__ import annotations

import numpy as np

from scenariomax.enrich.roadgraph import MapPolyline, polylines_to_roadgraph
from scenariomax.scenario import Scenario

NUM_STEPS = 91
CURRENT = 10


def line(start, stop, num=50) -> np.ndarray:
    """(num, 3) points from start to stop (2-D ends, z = 0)."""
    t = np.linspace(0.0, 1.0, num)[:, None]
    xy = (1 - t) * np.asarray(start, float) + t * np.asarray(stop, float)
    return np.column_stack([xy, np.zeros(num)])


def track(xy: np.ndarray, valid=None, object_type: int = 1) -> dict:
    """One object: positions (T, 2); yaw and velocity from finite differences."""
    xy = np.asarray(xy, float)
    vel = np.gradient(xy, 0.1, axis=0)
    speed = np.hypot(vel[:, 0], vel[:, 1])
    yaw = np.arctan2(vel[:, 1], vel[:, 0])
    # Standing still: keep the last moving heading (or 0).
    for t in range(len(yaw)):
        if speed[t] < 1e-3:
            yaw[t] = yaw[t - 1] if t else 0.0
    return dict(xy=xy, yaw=yaw, vel=vel, valid=np.ones(len(xy), bool) if valid is None else np.asarray(valid, bool),
                type=object_type)


def make_scenario(polylines: list[MapPolyline], objects: list[dict], **extra) -> Scenario:
    """Object 0 is the SDC."""
    n = len(objects)

    def stack(key, k=None):
        return np.stack([o[key] if k is None else o[key][:, k] for o in objects])

    valid = stack("valid")
    return Scenario(
        scenario_id="hand", object_id=np.arange(n), object_type=np.array([o["type"] for o in objects]),
        is_sdc=np.arange(n) == 0, x=stack("xy", 0), y=stack("xy", 1), z=np.zeros((n, NUM_STEPS)),
        bbox_yaw=stack("yaw"), length=np.full((n, NUM_STEPS), 4.5), width=np.full((n, NUM_STEPS), 2.0),
        height=np.full((n, NUM_STEPS), 1.5), velocity_x=stack("vel", 0), velocity_y=stack("vel", 1), valid=valid,
        **polylines_to_roadgraph(polylines, spacing=0.5), **extra,
    )


def straight_xy(x0: float, speed: float, y: float = 0.0) -> np.ndarray:
    x = x0 + speed * 0.1 * np.arange(NUM_STEPS)
    return np.column_stack([x, np.full(NUM_STEPS, y)])
