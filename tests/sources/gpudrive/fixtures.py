"""Tiny GPUDrive / Nocturne JSON scenarios in each real layout, written by hand for the tests.

The scene: a straight east-bound road (lane along y = 0, road edges at y = -2 running east and at
y = +5.5 running west, so the road is on their left), 91 steps at 10 Hz. Objects:
  0  pedestrian standing at (30, 4)
  1  vehicle driving north at 5 m/s, heading 90 degrees, valid at every step (travels 45 m)
  2  vehicle parked at (60, 3), width 4.6 and length 1.9 (written swapped)
  3  the SDC: vehicle driving east along y = 0 at 10 m/s from x = 0 (travels 90 m), always valid
Layouts differ as the real files do (see `scenariomax/sources/gpudrive/layout.py`).
"""

from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np

NUM_STEPS = 91
SDC_SPEED = 10.0


def _track(x0: float, y0: float, vx: float, vy: float, num_steps: int = NUM_STEPS) -> np.ndarray:
    t = np.arange(num_steps) * 0.1
    return np.stack([x0 + vx * t, y0 + vy * t], axis=1)  # (T, 2)


def make_object(xy: np.ndarray, heading_rad: np.ndarray, velocity: np.ndarray, valid: np.ndarray, *, kind: str,
                length: float, width: float, height: float | None = 1.6, layout: str = "nocturne",
                object_id: int | None = None) -> dict:
    """One `objects` entry in `layout`: degrees or radians, sentinels at invalid steps, z or not."""
    degrees = layout != "gpudrive-metadata"
    sentinel = 1e-4 if layout == "gpudrive-3d" else -10000.0
    position, vel, heading = [], [], []
    for (x, y), (vx, vy), yaw, ok in zip(xy, velocity, heading_rad, valid):
        point = {"x": float(x), "y": float(y)} if ok else {"x": sentinel, "y": sentinel}
        if layout != "nocturne":
            point["z"] = 0.8 if ok else sentinel
        position.append(point)
        vel.append({"x": float(vx), "y": float(vy)} if ok else {"x": sentinel, "y": sentinel})
        heading.append((math.degrees(yaw) if degrees else float(yaw)) if ok else sentinel)
    obj = {"position": position, "width": width, "length": length, "heading": heading, "velocity": vel,
           "valid": [bool(v) for v in valid], "goalPosition": {"x": float(xy[-1, 0]), "y": float(xy[-1, 1])},
           "type": kind}
    if layout != "nocturne" and height is not None:
        obj["height"] = height
    if layout == "gpudrive-metadata":
        obj["id"] = object_id
        obj["mark_as_expert"] = False
    return obj


def scene_objects(layout: str = "nocturne", num_steps: int = NUM_STEPS) -> list[dict]:
    always = np.ones(num_steps, bool)
    zeros = np.zeros((num_steps, 2))

    def heading(value: float) -> np.ndarray:
        return np.full(num_steps, value)

    sdc_xy = _track(0.0, 0.0, SDC_SPEED, 0.0, num_steps)
    north_xy = _track(40.0, -20.0, 0.0, 5.0, num_steps)
    return [
        make_object(_track(30.0, 4.0, 0, 0, num_steps), heading(0.3), zeros, always, kind="pedestrian",
                    length=0.6, width=0.7, height=1.7, layout=layout, object_id=11),
        make_object(north_xy, heading(math.pi / 2), np.tile([0.0, 5.0], (num_steps, 1)), always, kind="vehicle",
                    length=4.5, width=2.0, layout=layout, object_id=12),
        make_object(_track(60.0, 3.0, 0, 0, num_steps), heading(0.0), zeros, always, kind="vehicle",
                    length=1.9, width=4.6, layout=layout, object_id=13),
        make_object(sdc_xy, heading(0.0), np.tile([SDC_SPEED, 0.0], (num_steps, 1)), always, kind="vehicle",
                    length=4.8, width=2.1, layout=layout, object_id=14),
    ]


def _line(points: list[tuple[float, float]], layout: str, feature_id: int) -> list[dict]:
    out = []
    for x, y in points:
        point = {"x": x, "y": y}
        if layout != "nocturne":
            point["z"] = 0.0
        if layout == "gpudrive-3d":
            point["id"] = feature_id
        out.append(point)
    return out


def scene_roads(layout: str = "nocturne") -> list[dict]:
    """(kind, map_element_id, id, points) of the scene's map, in `layout`."""
    features = [
        ("lane", 1, 101, [(-50.0, 0.0), (400.0, 0.0)]),
        ("road_line", 7, 102, [(-50.0, 1.75), (400.0, 1.75)]),
        ("road_edge", 15, 103, [(-50.0, -2.0), (400.0, -2.0)]),
        ("road_edge", 16, 104, [(400.0, 5.5), (-50.0, 5.5)]),
        ("crosswalk", 18, 105, [(100.0, -2.0), (104.0, -2.0), (104.0, 5.5), (100.0, 5.5)]),
        ("stop_sign", 17, 106, [(98.0, -2.5)]),
        ("speed_bump", 19, 107, [(150.0, -2.0), (151.0, -2.0), (151.0, 5.5), (150.0, 5.5)]),
        ("driveway", 20, 108, [(200.0, 5.5), (206.0, 5.5), (206.0, 12.0), (200.0, 12.0)]),
    ]
    roads = []
    for kind, element, feature_id, points in features:
        road = {"geometry": _line(points, layout, feature_id), "type": kind}
        if layout != "nocturne":
            road["map_element_id"], road["id"] = element, feature_id
        roads.append(road)
    return roads


def scene_lights(num_steps: int = NUM_STEPS) -> dict:
    """Lane 101 reports go, then arrow_stop, then a state name we do not know; only steps 0..59."""
    steps = list(range(60))
    states = ["go"] * 20 + ["arrow_stop"] * 20 + ["purple"] * 20
    return {"101": {"state": states, "x": [98.0] * 60, "y": [0.0] * 60, "z": [0.0] * 60, "time_index": steps}}


def scene_document(layout: str = "nocturne", num_steps: int = NUM_STEPS, **overrides) -> dict:
    doc = {"name": "tfrecord-00000-of-01000_1.json", "objects": scene_objects(layout, num_steps),
           "roads": scene_roads(layout), "tl_states": {}}
    if layout != "nocturne":
        doc["scenario_id"] = f"toy-{layout}"
    if layout == "gpudrive-metadata":
        doc["metadata"] = {"sdc_track_index": 3, "objects_of_interest": [12],
                           "tracks_to_predict": [{"track_index": 1, "difficulty": 1}]}
    doc.update(overrides)
    return doc


def write_document(folder: Path, doc: object, name: str = "scene.json") -> Path:
    path = Path(folder) / name
    path.write_text(json.dumps(doc))
    return path
