"""Tiny ScenarioNet scenario descriptions built by the tests, pickled like ScenarioNet does."""

from __future__ import annotations

import enum
import pickle
import sys
from pathlib import Path

import numpy as np

# Stable int ids: keys sorted as strings.
OBJECT_IDS = {"cone": 0, "ego": 1, "ped-a": 2}
MAP_IDS = {"crosswalk-1": 0, "drivable-1": 1, "edge-1": 2, "lane-1": 3, "lane-2": 4}


def _state(num_steps, position, heading, velocity, size, valid, size_shape):
    return {"position": position, "heading": heading, "velocity": velocity, "valid": valid.astype(float),
            **{name: np.full(size_shape, value) for name, value in zip(("length", "width", "height"), size)}}


def build_description(num_steps: int = 41, step_seconds: float = 0.25, scenario_id: str = "toy-sn",
                      with_ts: bool = False) -> dict:
    """The SDC ('ego') drives east at 2 m/s along y = 0 (x = 2 t). 'ped-a' walks north at x = 5, valid
    except at source step 3. 'cone' stands still at (10, -3) with a 2-D position. Map: lane-1 (0..100 m,
    36 km/h) -> lane-2 (100..150 m, 30 mph), edge-1 at y = -2 drawn west-bound (must be flipped), a
    crosswalk and a drivable-area polygon (not in our enum: skipped). A light on lane-1: red for the
    first 5 s, then green; stop point (50, 0, 0)."""
    t = np.arange(num_steps) * step_seconds
    ones = np.ones(num_steps)
    ego = _state(num_steps, np.stack([2 * t, 0 * t, 0 * t + 0.5], 1), 0.0 * t, np.stack([2 + 0 * t, 0 * t], 1),
                 (4.5, 2.0, 1.5), ones > 0, (num_steps, 1))
    ped_valid = ones > 0
    ped_valid[3] = False
    ped = _state(num_steps, np.stack([5 + 0 * t, 3 + t, 0 * t], 1), np.full((num_steps, 1), np.pi / 2),
                 np.stack([0 * t, 1 + 0 * t], 1), (0.5, 0.5, 1.8), ped_valid, (num_steps,))
    cone = _state(num_steps, np.stack([10 + 0 * t, -3 + 0 * t], 1), 0 * t, np.zeros((num_steps, 2)),
                  (0.3, 0.3, 0.7), ones > 0, (num_steps,))
    tracks = {
        "ego": {"type": "VEHICLE", "state": ego, "metadata": {"object_id": "ego"}},
        "ped-a": {"type": "PEDESTRIAN", "state": ped, "metadata": {"object_id": "ped-a"}},
        "cone": {"type": "TRAFFIC_CONE", "state": cone, "metadata": {"object_id": "cone"}},
    }
    map_features = {
        "lane-1": {"type": "LANE_SURFACE_STREET", "polyline": [(float(x), 0.0, 0.0) for x in range(0, 101, 5)],
                   "speed_limit_kmh": 36.0, "exit_lanes": ["lane-2"], "entry_lanes": [], "left_neighbor": [],
                   "right_neighbor": []},
        "lane-2": {"type": "LANE_FREEWAY", "polyline": np.array([[100.0, 0.0], [150.0, 0.0]]),
                   "speed_limit_mph": 30.0, "entry_lanes": ["lane-1"]},
        "edge-1": {"type": "ROAD_EDGE_BOUNDARY", "polyline": np.array([[150.0, -2.0], [0.0, -2.0]])},
        "crosswalk-1": {"type": "CROSSWALK", "polygon": [[20.0, -1.0], [22.0, -1.0], [22.0, 1.0], [20.0, 1.0]]},
        "drivable-1": {"type": "DRIVABLE_AREA", "polygon": [[0.0, -5.0], [150.0, -5.0], [150.0, 5.0]]},
    }
    red_steps = round(5.0 / step_seconds)
    lights = {"tl-1": {"type": "TRAFFIC_LIGHT", "lane": "lane-1", "stop_point": np.array([50.0, 0.0, 0.0]),
                       "state": {"object_state": ["TRAFFIC_LIGHT_RED"] * red_steps
                                 + ["TRAFFIC_LIGHT_GREEN"] * (num_steps - red_steps)}}}
    metadata = {"scenario_id": scenario_id, "id": scenario_id, "dataset": "toy", "sdc_id": "ego",
                "timestep": step_seconds, "objects_of_interest": ["ped-a"],
                "tracks_to_predict": {"ped-a": {"track_id": "ped-a", "track_index": 1, "difficulty": 1}}}
    if with_ts:
        metadata["ts"] = t + 100.0
    return {"id": scenario_id, "version": "test", "length": num_steps, "tracks": tracks,
            "map_features": map_features, "dynamic_map_states": lights, "metadata": metadata}


def write_pickle(path: Path, obj) -> Path:
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_bytes(pickle.dumps(obj, protocol=4))
    return path


def early_metadrive_description(num_steps: int = 91, step_seconds: float = 0.1, with_ts: bool = True,
                                sdc_index=None) -> dict:
    """An early-MetaDrive style description (no `metadata`, digit-string keys, `ts` at the top, light
    lane and stop point stored per step with 0 / (0, 0, 0) where the light was not reported).

    Tracks: '7' drives east at 3 m/s on y = 0 (valid throughout: the SDC when nothing names it),
    '8' is parked at (20, 4) (valid throughout, travels 0), '9' drives east at 10 m/s but is only
    valid from step 5. Map: lane '11' (y = 0) and a CROSS_WALK '12'. Light on lane '11': not
    reported for steps 0-19 (fillers), reported UNKNOWN (0) at 20-29, STOP (4) at 30-59, GO (6) after."""
    t = np.arange(num_steps) * step_seconds
    zeros, ones = np.zeros(num_steps), np.ones(num_steps)

    def state(x, y, vx, valid):
        return {"position": np.stack([x, y, zeros], 1), "heading": zeros.copy(), "velocity": np.stack([vx, zeros], 1),
                "length": 4.5 * ones, "width": 2.0 * ones, "height": 1.5 * ones, "valid": valid.astype(float)}

    late = np.arange(num_steps) >= 5
    tracks = {"7": {"type": "VEHICLE", "state": state(3 * t, zeros, 3 * ones, ones > 0)},
              "8": {"type": "VEHICLE", "state": state(20 + zeros, 4 + zeros, zeros, ones > 0)},
              "9": {"type": "VEHICLE", "state": state(10 * t, 8 + zeros, 10 * ones, late)}}
    codes = np.zeros(num_steps, np.int64)
    codes[30:60], codes[60:] = 4, 6
    lane = np.where(np.arange(num_steps) >= 20, 11, 0).astype(np.int64)
    stop = np.where((lane > 0)[:, None], np.array([[40.0, 0.0, 0.0]]), 0.0)
    desc = {"id": "early", "tracks": tracks,
            "map_features": {"11": {"type": "LANE_SURFACE_STREET", "polyline": np.array([[0.0, 0.0], [300.0, 0.0]])},
                             "12": {"type": "CROSS_WALK",
                                    "polyline": np.array([[30.0, -2], [32, -2], [32, 2], [30, 2]])}},
            "dynamic_map_states": {"11": {"type": "TRAFFIC_LIGHT",
                                          "state": {"object_state": codes, "lane": lane, "stop_point": stop}}}}
    if with_ts:
        desc["ts"] = t + 5.0
    if sdc_index is not None:
        desc["sdc_index"] = sdc_index
    return desc


# --- MetaDrive 2021-2022 (`waymo_utils.py`): enum members pickled from the writer's `__main__` ----------
def writer_enums() -> dict[str, type[enum.Enum]]:
    """Local stand-ins for the converter's enum classes, built from the format: their names, their members'
    WOMD values (Track.ObjectType, RoadLine.RoadLineType, RoadEdge.RoadEdgeType), defined in `__main__`."""
    members = {"AgentType": ("UNSET", "VEHICLE", "PEDESTRIAN", "CYCLIST", "OTHER"),
               "RoadLineType": ("UNKNOWN", "BROKEN_SINGLE_WHITE", "SOLID_SINGLE_WHITE", "SOLID_DOUBLE_WHITE",
                                "BROKEN_SINGLE_YELLOW", "BROKEN_DOUBLE_YELLOW", "SOLID_SINGLE_YELLOW",
                                "SOLID_DOUBLE_YELLOW", "PASSING_DOUBLE_YELLOW"),
               "RoadEdgeType": ("UNKNOWN", "BOUNDARY", "MEDIAN")}
    classes = {}
    for name, names in members.items():
        cls = enum.Enum(name, {member: value for value, member in enumerate(names)}, module="__main__")
        cls.__qualname__ = name
        classes[name] = cls
    return classes


def pickle_from_main(obj, classes: dict[str, type], protocol: int) -> bytes:
    """`obj` pickled as the writer run as a script did: its enum classes named `__main__.<class>` (pickle
    checks the name resolves, so they sit in `__main__` while pickling only)."""
    main = sys.modules["__main__"]
    saved = {name: getattr(main, name) for name in classes if hasattr(main, name)}
    try:
        for name, cls in classes.items():
            setattr(main, name, cls)
        return pickle.dumps(obj, protocol=protocol)
    finally:
        for name in classes:
            if name in saved:
                setattr(main, name, saved[name])
            else:
                delattr(main, name)


def metadrive_2021_description(enums: dict[str, type[enum.Enum]], num_steps: int = 91) -> dict:
    """A description as MetaDrive's 2021-2022 converter wrote it: tracks keyed by int id with an AgentType
    member and one (T, 10) state array; the map under `map` (lanes `center_lane` with boundaries holding
    RoadLineType members, a road line and a road edge typed by members, a `cross_walk`, a `stop_sign`, a
    speed bump typed by itself); `sdc_index` the SDC's id; `dynamic_map_states` a list holding one dict (the
    converter appended only its last step) keyed by lane: {state: WOMD int, stop_point: [x, y, z]}.

    Track 7 (vehicle, SDC) drives east at 2 m/s on y = 0; 8 (pedestrian) stands at (5, 3); 9 (cyclist) rides
    east at 4 m/s on y = 4. Lane 1 on y = 0, lane 2 on y = 4; a solid double yellow line (7) at y = 2, a
    median edge (2) at y = -2 and a boundary edge (1) at y = 6."""
    agent, line, edge = enums["AgentType"], enums["RoadLineType"], enums["RoadEdgeType"]
    t = np.arange(num_steps) * 0.1

    def rows(x, y, size, speed):
        n = num_steps
        return np.stack([x, y, 0 * t, *(np.full(n, v) for v in size), 0 * t, np.full(n, speed), 0 * t,
                         np.ones(n)], axis=1)

    tracks = {7: {"type": agent.VEHICLE, "state": rows(2 * t, 0 * t, (4.5, 2.0, 1.5), 2.0)},
              8: {"type": agent.PEDESTRIAN, "state": rows(5 + 0 * t, 3 + 0 * t, (0.5, 0.5, 1.8), 0.0)},
              9: {"type": agent.CYCLIST, "state": rows(4 * t, 4 + 0 * t, (1.8, 0.6, 1.6), 4.0)}}

    def polyline(y):
        return np.array([[float(x), y, 0.0] for x in range(0, 201, 10)])

    boundary = {"index": [0, 20], "type": line.SOLID_DOUBLE_YELLOW, "id": 3}
    bump = {"polygon": np.array([[60.0, -1, 0], [61, -1, 0], [61, 1, 0], [60, 1, 0]])}
    bump["type"] = bump
    map_features = {
        1: {"type": "center_lane", "polyline": polyline(0.0), "interpolating": True, "entry": [], "exit": [],
            "left_boundaries": [boundary], "right_boundaries": [], "right_neighbor": [],
            "left_neighbor": [{"id": 2, "indexes": [0, 20, 0, 20], "boundaries": [boundary]}]},
        2: {"type": "center_lane", "polyline": polyline(4.0), "interpolating": True, "entry": [], "exit": [],
            "left_boundaries": [], "right_boundaries": [boundary], "left_neighbor": [], "right_neighbor": []},
        3: {"type": line.SOLID_DOUBLE_YELLOW, "polyline": polyline(2.0)},
        4: {"type": edge.MEDIAN, "polyline": polyline(-2.0)},
        5: {"type": edge.BOUNDARY, "polyline": polyline(6.0)},
        6: {"sign": "cross_walk", "polygon": np.array([[20.0, -1, 0], [22, -1, 0], [22, 1, 0], [20, 1, 0]])},
        10: {"type": "stop_sign", "lanes": [1], "pos": [50.0, 0.0, 0.0]},
        11: bump,
    }
    lights = [{1: {"state": 6, "stop_point": [50.0, 0.0, 0.0]}}]  # the last step: lane 1 go
    return {"id": "metadrive-2021", "ts": list(t + 3.0), "tracks": tracks, "dynamic_map_states": lights,
            "sdc_index": 7, "map": map_features}
