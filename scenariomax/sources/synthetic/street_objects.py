"""Static objects of type other along the road edges: rows of barriers and groups of traffic cones.

Real nuScenes and AV2 scenes log them (movable barriers lining works, cones beside a lane, bollards); the generator
had none, so a student trained on it never saw the object type. Each group stands along one road edge, on the road
or just off it; an object whose box (grown by CLEARANCE_M) would touch any logged box at any step, or another
street object, is left out, so the log stays collision-free.
"""

from __future__ import annotations

import dataclasses

import numpy as np

from scenariomax.sources.synthetic import agents as ag
from scenariomax.sources.synthetic import geometry as geo
from scenariomax.sources.synthetic.checks import box_corners, boxes_overlap
from scenariomax.sources.synthetic.network import RoadNetwork
from scenariomax.sources.synthetic.traffic import Traffic

CLEARANCE_M = 0.3  # room every street object leaves to every logged box
INWARD_M = (-1.0, 1.5)  # offset from the road edge towards the drivable area (negative: off the road)
CONE_SPACING_M = (1.5, 4.0)
BARRIER_GAP_M = (0.1, 0.4)  # between neighbouring barriers of a row
GROUP_SIZE = {"cones": (1, 5), "barriers": (2, 8)}
TRIES_PER_OBJECT = 4  # groups tried for each object wanted before giving up (crowded scenes)
EDGE_SPACING_M = 0.5

Box = tuple[float, float, float, ag.Body]  # a street object: x, y, yaw and its body


def with_street_objects(traffic: Traffic, network: RoadNetwork, rng: np.random.Generator,
                        count_range: tuple[float, float]) -> Traffic:
    """`traffic` with a number (drawn uniformly in `count_range`) of cones and barriers appended as parked objects
    of type other, standing for the whole log."""
    low, high = (int(round(v)) for v in count_range)
    wanted = int(rng.integers(low, high + 1)) if high > 0 else 0  # off: nothing drawn
    if wanted == 0:
        return traffic
    edges = [geo.resample(edge.xyz[:, :2].astype(np.float64), EDGE_SPACING_M) for edge in network.edges]
    edges = [xy for xy in edges if len(xy) >= 4]
    if not edges:
        return traffic
    lengths = np.array([geo.arc_length(xy)[-1] for xy in edges])
    blocking = _logged_boxes(traffic)
    placed: list[Box] = []
    for _ in range(TRIES_PER_OBJECT * wanted):
        if len(placed) >= wanted:
            break
        xy = edges[int(rng.choice(len(edges), p=lengths / lengths.sum()))]
        for box in _group_along(xy, rng):
            if len(placed) < wanted and _is_clear(box, blocking):
                placed.append(box)
                blocking = _with_box(blocking, box)
    return _appended(traffic, placed) if placed else traffic


def _group_along(edge_xy: np.ndarray, rng: np.random.Generator) -> list[Box]:
    """One group's boxes (x, y, yaw, body) along a road edge, the drivable area on its left."""
    kind = "cones" if rng.random() < 0.5 else "barriers"
    count = int(rng.integers(GROUP_SIZE[kind][0], GROUP_SIZE[kind][1] + 1))
    bodies = [ag.cone_body(rng) if kind == "cones" else ag.barrier_body(rng) for _ in range(count)]
    arc = geo.arc_length(edge_xy)
    start, inward = float(rng.uniform(0.0, arc[-1])), float(rng.uniform(*INWARD_M))
    tangent = geo.tangents(edge_xy)
    boxes, along = [], start
    for body in bodies:
        if along > arc[-1]:
            break
        point = np.array([np.interp(along, arc, edge_xy[:, 0]), np.interp(along, arc, edge_xy[:, 1])])
        k = min(int(np.searchsorted(arc, along)), len(arc) - 1)
        heading = float(np.arctan2(tangent[k, 1], tangent[k, 0]))
        centre = point + inward * geo.left_normal(tangent[k])
        # a barrier is logged across its span (its heading points across the edge), a cone along the edge
        yaw = heading + np.pi / 2 if kind == "barriers" else heading
        boxes.append((float(centre[0]), float(centre[1]), float(geo.wrap_angle(yaw)), body))
        step = (body.width + rng.uniform(*BARRIER_GAP_M)) if kind == "barriers" else rng.uniform(*CONE_SPACING_M)
        along += float(step)
    return boxes


def _logged_boxes(traffic: Traffic) -> dict[str, np.ndarray]:
    """Every valid (object, step) box of the log, flattened: x, y, yaw, length, width (k,)."""
    objects, steps = np.nonzero(traffic.valid)
    return {"x": traffic.x[objects, steps], "y": traffic.y[objects, steps], "yaw": traffic.yaw[objects, steps],
            "length": traffic.length[objects], "width": traffic.width[objects]}


def _with_box(boxes: dict[str, np.ndarray], box: Box) -> dict[str, np.ndarray]:
    """`boxes` with one more (a street object placed)."""
    x, y, yaw, body = box
    added = {"x": x, "y": y, "yaw": yaw, "length": body.length, "width": body.width}
    return {name: np.append(values, added[name]) for name, values in boxes.items()}


def _is_clear(box: Box, boxes: dict[str, np.ndarray]) -> bool:
    """Whether `box`, grown by CLEARANCE_M on every side, touches none of `boxes`."""
    x, y, yaw, body = box
    grown_length, grown_width = body.length + 2 * CLEARANCE_M, body.width + 2 * CLEARANCE_M
    reach = (np.hypot(grown_length, grown_width) + np.hypot(boxes["length"], boxes["width"])) / 2
    near = np.hypot(boxes["x"] - x, boxes["y"] - y) < reach
    count = int(near.sum())
    if count == 0:
        return True
    mine = box_corners(np.full(count, x), np.full(count, y), np.full(count, yaw), np.full(count, grown_length),
                       np.full(count, grown_width))
    theirs = box_corners(boxes["x"][near], boxes["y"][near], boxes["yaw"][near], boxes["length"][near],
                         boxes["width"][near])
    return not bool(boxes_overlap(mine, theirs).any())


def _appended(traffic: Traffic, placed: list[Box]) -> Traffic:
    """`traffic` with the placed boxes as parked objects standing at every step."""
    steps, count = traffic.x.shape[1], len(placed)
    x, y, yaw = (np.array([box[i] for box in placed]) for i in range(3))
    bodies = [box[3] for box in placed]

    def per_object(name):  # (count,)
        return np.array([getattr(body, name) for body in bodies])

    def standing(values):  # (count,) -> (count, T)
        return np.repeat(values[:, None], steps, axis=1)

    return dataclasses.replace(
        traffic,
        object_type=np.concatenate([traffic.object_type, per_object("object_type").astype(np.int64)]),
        length=np.concatenate([traffic.length, per_object("length")]),
        width=np.concatenate([traffic.width, per_object("width")]),
        height=np.concatenate([traffic.height, per_object("height")]),
        x=np.concatenate([traffic.x, standing(x)]), y=np.concatenate([traffic.y, standing(y)]),
        yaw=np.concatenate([traffic.yaw, standing(yaw)]),
        speed=np.concatenate([traffic.speed, np.zeros((count, steps))]),
        valid=np.concatenate([traffic.valid, np.ones((count, steps), bool)]),
        is_parked=np.concatenate([traffic.is_parked, np.ones(count, bool)]),
        is_stalled=np.concatenate([traffic.is_stalled, np.zeros(count, bool)]),
        routes=traffic.routes + ((),) * count,
        gates_entered=traffic.gates_entered + ((),) * count,
    )
