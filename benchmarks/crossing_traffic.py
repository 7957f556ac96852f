"""How often something crosses close in front of the logged SDC while it moves: synthetic scenes against real ones.

For every shard glob given, over the logged SDC's steps from the current step on where it moves (>= 0.5 m/s): the
share with a vehicle crossing the corridor ahead (the nearest object within AHEAD_M along the SDC's heading and
CORRIDOR_M to either side is a vehicle heading 45-135 degrees off the SDC's, above CROSSING_MPS) and the share with a
pedestrian there, and how many scenes have a crossing at all; and the share of its steps where it stands (below
MOVING_MPS: at a light, a stop, in a queue). A student learns to brake for, and to wait at, what its training shows:
real recordings had 0.75% crossing steps, 300 synthetic scenes of the bc-dagger knobs 0.25% (docs/learning.md,
session 46); real logged SDCs stand at about a third of their steps, those of the bc-dagger knobs at a tenth (session
47, the `sdc_waits` knob); and the share of its moving steps behind a slow leader (the nearest object ahead a vehicle
going its way at MOVING_MPS to SLOW_LEADER_MPS: a crawler, a queue moving off; session 48, the `slow_vehicles` knob);
and how many parked vehicles (never above MOVING_MPS) it passes with less than CLOSE_PASS_M between the boxes, per
scene (real 0.16, the bc-dagger knobs 0, `parked_reach=0:1.5` 0.30; session 48).

Usage: python benchmarks/crossing_traffic.py SHARDS [SHARDS ...] [--json]
"""

from __future__ import annotations

import argparse
import json

import numpy as np

MOVING_MPS = 0.5  # the SDC counts as moving from this speed
AHEAD_M, CORRIDOR_M = 15.0, 3.0  # the box ahead of the SDC's centre in which the nearest object is named
CROSSING_COS = np.cos(np.radians(45.0))  # a heading this far off the SDC's (either way) crosses its path
CROSSING_MPS = 2.0  # a crossing vehicle moves at least this fast
CLOSE_PASS_M = 1.0  # a parked vehicle whose box comes this near the SDC's is passed close
NEAR_M = 8.0  # only steps with the centres this near are measured (a box gap needs the centres within ~6 m)
SLOW_LEADER_MPS = 4.0  # a leader going the SDC's way below this (and moving) is a slow one
VEHICLE, PEDESTRIAN = 1, 2  # object type enums


def nearest_ahead(x, y, yaw, valid, sdc, xp=np):
    """The object nearest ahead of object `sdc`: its centre within AHEAD_M along the SDC's heading and CORRIDOR_M to
    either side. x, y, yaw, valid (N, ...) -> its index (...) and whether there is one (...). `xp`: numpy, or
    jax.numpy inside a traced function (benchmarks/imitation_gap.py)."""
    cos, sin = xp.cos(yaw[sdc]), xp.sin(yaw[sdc])
    dx, dy = x - x[sdc], y - y[sdc]
    along, across = cos * dx + sin * dy, cos * dy - sin * dx
    others = (xp.arange(x.shape[0]) != sdc).reshape((-1,) + (1,) * (x.ndim - 1))
    inside = valid & others & (along > 0.0) & (along < AHEAD_M) & (xp.abs(across) < CORRIDOR_M)
    return xp.argmin(xp.where(inside, along, xp.inf), axis=0), inside.any(axis=0)


def _moving_steps(speed: np.ndarray, valid: np.ndarray, sdc: int, start: int) -> np.ndarray:
    """The steps from `start` on where object `sdc` is valid and moves (>= MOVING_MPS). speed, valid (N, T) -> (m,)"""
    steps = np.arange(start, speed.shape[1])
    return steps[valid[sdc, steps] & (speed[sdc, steps] >= MOVING_MPS)]


def crossing_steps(x: np.ndarray, y: np.ndarray, yaw: np.ndarray, speed: np.ndarray, valid: np.ndarray,
                   object_type: np.ndarray, sdc: int, start: int) -> tuple[int, int, int]:
    """(moving steps, of them with a crossing vehicle nearest ahead, with a pedestrian nearest ahead) of object `sdc`
    from step `start` on. x, y, yaw, speed, valid (N, T); object_type (N,)."""
    moving = _moving_steps(speed, valid, sdc, start)  # (m,)
    if moving.size == 0:
        return 0, 0, 0
    nearest, found = nearest_ahead(x[:, moving], y[:, moving], yaw[:, moving], valid[:, moving], sdc)  # (m,), (m,)
    kind = np.where(found, object_type[nearest], 0)
    off_heading = np.abs(np.cos(yaw[nearest, moving] - yaw[sdc, moving])) < CROSSING_COS
    crossing = (kind == VEHICLE) & off_heading & (speed[nearest, moving] > CROSSING_MPS)
    return int(moving.size), int(crossing.sum()), int((kind == PEDESTRIAN).sum())


def slow_leader_steps(x: np.ndarray, y: np.ndarray, yaw: np.ndarray, speed: np.ndarray, valid: np.ndarray,
                      object_type: np.ndarray, sdc: int, start: int) -> int:
    """Of the moving steps of object `sdc` from step `start` on, those whose nearest object ahead is a vehicle
    heading within 45 degrees of the SDC's and moving slowly (MOVING_MPS to SLOW_LEADER_MPS). Arrays as
    crossing_steps."""
    moving = _moving_steps(speed, valid, sdc, start)  # (m,)
    if moving.size == 0:
        return 0
    nearest, found = nearest_ahead(x[:, moving], y[:, moving], yaw[:, moving], valid[:, moving], sdc)  # (m,), (m,)
    same_way = np.cos(yaw[nearest, moving] - yaw[sdc, moving]) > CROSSING_COS
    lead_speed = speed[nearest, moving]
    slow = found & (object_type[nearest] == VEHICLE) & same_way & (lead_speed >= MOVING_MPS) \
        & (lead_speed < SLOW_LEADER_MPS)
    return int(slow.sum())


def _box(x: float, y: float, yaw: float, length: float, width: float):
    """An object's box as a shapely polygon (for the gap between two boxes)."""
    from shapely.geometry import Polygon

    from scenariomax.sources.synthetic.checks import box_corners

    return Polygon(box_corners(*(np.float64(v) for v in (x, y, yaw, length, width))))


def close_parked_passes(x: np.ndarray, y: np.ndarray, yaw: np.ndarray, speed: np.ndarray, valid: np.ndarray,
                        object_type: np.ndarray, length: np.ndarray, width: np.ndarray, sdc: int, start: int) -> int:
    """How many parked vehicles (valid, never above MOVING_MPS) object `sdc` passes from step `start` on with less
    than CLOSE_PASS_M between the two boxes. Arrays (N, T) as crossing_steps; length, width (N, T)."""
    steps = np.flatnonzero(valid[sdc, start:]) + start
    parked = (object_type == VEHICLE) & valid.any(axis=1) & (np.where(valid, speed, 0.0).max(axis=1) <= MOVING_MPS)
    parked[sdc] = False
    count = 0
    for other in np.flatnonzero(parked):
        near = steps[valid[other, steps] & (np.hypot(x[other, steps] - x[sdc, steps],
                                                     y[other, steps] - y[sdc, steps]) < NEAR_M)]
        count += any(_box(x[sdc, t], y[sdc, t], yaw[sdc, t], length[sdc, t], width[sdc, t]).distance(
            _box(x[other, t], y[other, t], yaw[other, t], length[other, t], width[other, t])) < CLOSE_PASS_M
            for t in near)
    return count


def standing_steps(speed: np.ndarray, valid: np.ndarray, sdc: int, start: int) -> tuple[int, int]:
    """(valid steps, of them standing) of object `sdc` from step `start` on. speed, valid (N, T)."""
    steps = valid[sdc, start:]
    return int(steps.sum()), int((steps & (speed[sdc, start:] < MOVING_MPS)).sum())


def shard_statistics(path: str) -> dict:
    """The shares over every scenario of the shards at `path` (a file, folder or glob)."""
    from scenariomax.shards import read_shards

    scenes = moving = crossing = pedestrian = with_crossing = steps = standing = slow = close = 0
    for scenario in read_shards(path):
        speed = np.hypot(scenario.velocity_x, scenario.velocity_y)
        m, c, p = crossing_steps(scenario.x, scenario.y, scenario.bbox_yaw, speed, scenario.valid,
                                 scenario.object_type, scenario.sdc_index, scenario.current_time_index)
        scenes, moving, crossing, pedestrian = scenes + 1, moving + m, crossing + c, pedestrian + p
        n, n_standing = standing_steps(speed, scenario.valid, scenario.sdc_index, scenario.current_time_index)
        steps, standing = steps + n, standing + n_standing
        with_crossing += c > 0
        slow += slow_leader_steps(scenario.x, scenario.y, scenario.bbox_yaw, speed, scenario.valid,
                                  scenario.object_type, scenario.sdc_index, scenario.current_time_index)
        close += close_parked_passes(scenario.x, scenario.y, scenario.bbox_yaw, speed, scenario.valid,
                                     scenario.object_type, scenario.length, scenario.width, scenario.sdc_index,
                                     scenario.current_time_index)

    def share(count: int) -> float | None:
        return count / moving if moving else None

    return {"data": path, "scenes": scenes, "moving_steps": moving, "crossing_share": share(crossing),
            "pedestrian_share": share(pedestrian), "scenes_with_crossing": with_crossing,
            "standing_share": standing / steps if steps else None, "slow_leader_share": share(slow),
            "close_parked_passes_per_scene": close / scenes if scenes else None}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("shards", nargs="+")
    parser.add_argument("--json", action="store_true")
    args = parser.parse_args()
    rows = [shard_statistics(path) for path in args.shards]
    if args.json:
        print(json.dumps(rows, indent=1))
        return
    for r in rows:
        print(f"{r['data']}: {r['scenes']} scenes, {r['moving_steps']} moving SDC steps; a vehicle crossing ahead at "
              f"{_percent(r['crossing_share'])} of them, a pedestrian ahead at {_percent(r['pedestrian_share'])}; "
              f"{r['scenes_with_crossing']} scenes with a crossing; the SDC stands at "
              f"{_percent(r['standing_share'])} of its steps; behind a slow leader at "
              f"{_percent(r['slow_leader_share'])} of its moving steps; parked cars passed within {CLOSE_PASS_M:g} m: "
              f"{_per_scene(r['close_parked_passes_per_scene'])} per scene")


def _per_scene(value: float | None) -> str:
    return "-" if value is None else f"{value:.2f}"


def _percent(share: float | None) -> str:
    return "-" if share is None else f"{100 * share:.2f}%"


if __name__ == "__main__":
    main()
