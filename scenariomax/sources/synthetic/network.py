"""The road network of one synthetic scenario: lanes with links, lines, edges, crosswalks, parking.

Topology builders (see `topologies`) draw into a mutable `NetworkBuilder` in a local frame;
`NetworkBuilder.build` moves everything into the world frame and derives what the traffic
simulation and the roadgraph need: road edges from the union of the drivable area (so they
enclose junctions too), and which junction lanes may not be occupied at the same time.
"""

from __future__ import annotations

import dataclasses
import itertools

import numpy as np
import shapely
from shapely.geometry import LineString, Polygon
from shapely.geometry.polygon import orient

from scenariomax.enrich.roadgraph import MapPolyline
from scenariomax.schema import RG_CROSSWALK, RG_ROAD_EDGE_BOUNDARY, RG_ROAD_EDGE_MEDIAN, RG_STOP_SIGN
from scenariomax.sources.synthetic import geometry as geo
from scenariomax.sources.synthetic.signals import SignalPlan

LANE_SPACING_M = 1.0  # centreline sampling, as the roadgraph
FIRST_LANE_ID = 100
FIRST_FEATURE_ID = 10_000  # lines, edges, crosswalks and signs: ids never clash with lanes
CONFLICT_DISTANCE_M = 2.8  # centrelines this close always conflict
CROSSING_DISTANCE_M = 5.2  # ... and this close when their headings differ (box corners reach out)
CROSSING_ANGLE_RAD = np.radians(20.0)


@dataclasses.dataclass(frozen=True)
class Lane:
    lane_id: int
    xy: np.ndarray  # (n, 2) float64, centreline ~1 m apart, in driving direction
    width: float
    speed_limit: float  # m/s
    lane_type: int  # enum roadgraph_type
    successors: tuple[int, ...]
    predecessors: tuple[int, ...]
    left_neighbors: tuple[int, ...]
    right_neighbors: tuple[int, ...]
    signal_group: int  # light at the END of this lane (-1: none)
    light_index: int  # row in the scenario's light arrays (-1: none)
    has_stop_sign: bool  # stop sign at the END of this lane
    is_gated: bool  # entering needs a reservation (junction connectors, merge zones)
    conflicts: tuple[int, ...]  # gated lanes that may not be occupied together with this one
    yields_to: tuple[int, ...]  # priority lanes whose approaching traffic this lane gives way to
    is_uturn: bool = False  # a junction lane turning back into the road it came from (knob junction_uturns)

    @property
    def length(self) -> float:
        return float(geo.arc_length(self.xy)[-1])


@dataclasses.dataclass(frozen=True)
class Crosswalk:
    feature_id: int
    polygon: np.ndarray  # (4, 2) float64, corners in order
    start: np.ndarray  # (2,) where pedestrians wait, on the kerb
    end: np.ndarray  # (2,) the opposite kerb
    is_signalised: bool  # pedestrians cross in the signal's pedestrian phase


@dataclasses.dataclass(frozen=True)
class RoadNetwork:
    topology: str
    lanes: tuple[Lane, ...]
    lines: tuple[MapPolyline, ...]  # painted road lines
    edges: tuple[MapPolyline, ...]  # road edges, drivable area on their left
    crosswalks: tuple[Crosswalk, ...]
    stop_signs: tuple[MapPolyline, ...]
    parking_spots: np.ndarray  # (k, 3) float64: x, y, yaw of free parking places
    signal_plan: SignalPlan | None
    drivable_area: object  # shapely geometry, for checks

    def lane(self, lane_id: int) -> Lane:
        return self.lanes[lane_id - FIRST_LANE_ID]

    @property
    def lights(self) -> tuple[Lane, ...]:
        """Lanes ending at a traffic light, in light-index order."""
        return tuple(sorted((lane for lane in self.lanes if lane.light_index >= 0), key=lambda lane: lane.light_index))

    def map_polylines(self) -> list[MapPolyline]:
        lanes = [MapPolyline(lane.lane_id, lane.lane_type, _xyz(lane.xy), lane.speed_limit) for lane in self.lanes]
        walks = [MapPolyline(c.feature_id, RG_CROSSWALK, _xyz(c.polygon), closed=True) for c in self.crosswalks]
        return lanes + list(self.lines) + list(self.edges) + walks + list(self.stop_signs)


def _xyz(xy: np.ndarray) -> np.ndarray:
    return np.concatenate([xy, np.zeros((len(xy), 1))], axis=1)


@dataclasses.dataclass
class _LaneDraft:
    xy: np.ndarray
    width: float
    speed_limit: float
    lane_type: int
    successors: list = dataclasses.field(default_factory=list)
    predecessors: list = dataclasses.field(default_factory=list)
    left: list = dataclasses.field(default_factory=list)
    right: list = dataclasses.field(default_factory=list)
    signal_group: int = -1
    has_stop_sign: bool = False
    is_gated: bool = False
    yields: bool = False  # gives way to the other gated lanes it conflicts with
    is_uturn: bool = False


class NetworkBuilder:
    """Collects lanes and map features in a local frame (mutable; internal to the generator)."""

    def __init__(self, topology: str):
        self.topology = topology
        self.lanes: list[_LaneDraft] = []
        self.lines: list[tuple[np.ndarray, int]] = []
        self.areas: list = []  # extra drivable polygons (junction boxes, parking strips)
        self.crosswalks: list[tuple[np.ndarray, np.ndarray, np.ndarray, bool]] = []
        self.parking: list[np.ndarray] = []
        self.signal_plan: SignalPlan | None = None

    def add_lane(self, xy: np.ndarray, width: float, speed_limit: float, lane_type: int, **flags) -> int:
        xy = geo.resample(np.asarray(xy, np.float64), LANE_SPACING_M)
        self.lanes.append(_LaneDraft(xy, width, speed_limit, lane_type, **flags))
        return FIRST_LANE_ID + len(self.lanes) - 1

    def draft(self, lane_id: int) -> _LaneDraft:
        return self.lanes[lane_id - FIRST_LANE_ID]

    def link(self, before: int, after: int) -> None:
        self.draft(before).successors.append(after)
        self.draft(after).predecessors.append(before)

    def neighbours(self, lane_ids_left_to_right: list[int]) -> None:
        """Marks lanes side by side in one direction, listed from left to right."""
        for left, right in itertools.pairwise(lane_ids_left_to_right):
            self.draft(left).right.append(right)
            self.draft(right).left.append(left)

    def connect(self, before: int, after: int, is_gated: bool = True, xy: np.ndarray | None = None, **flags) -> int:
        """A junction lane joining the end of `before` to the start of `after` smoothly (along `xy` when given)."""
        a, b = self.draft(before), self.draft(after)
        if xy is None:
            xy = geo.bezier(a.xy[-1], geo.tangents(a.xy)[-1], b.xy[0], geo.tangents(b.xy)[0])
        lane = self.add_lane(xy, min(a.width, b.width), min(a.speed_limit, b.speed_limit), a.lane_type,
                             is_gated=is_gated, **flags)
        self.link(before, lane)
        self.link(lane, after)
        return lane

    def add_line(self, xy: np.ndarray, line_type: int) -> None:
        self.lines.append((np.asarray(xy, np.float64), line_type))

    def add_area(self, polygon) -> None:
        self.areas.append(polygon)

    def add_crosswalk(self, center: np.ndarray, along: np.ndarray, length: float, width: float,
                      is_signalised: bool) -> None:
        """A zebra `length` long (kerb to kerb, along unit `along`) and `width` wide."""
        across = geo.left_normal(along)
        half_l, half_w = along * length / 2, across * width / 2
        polygon = np.stack([center - half_l - half_w, center + half_l - half_w,
                            center + half_l + half_w, center - half_l + half_w])
        # Pedestrians wait 1 m beyond the kerb (off the road) and walk the crosswalk's axis.
        start, end = center - along * (length / 2 + 1.0), center + along * (length / 2 + 1.0)
        self.crosswalks.append((polygon, start, end, is_signalised))

    def add_parking(self, xy: np.ndarray, yaw: float) -> None:
        self.parking.append(np.array([xy[0], xy[1], yaw]))

    def build(self, angle: float, shift: np.ndarray) -> RoadNetwork:
        """Rotates by `angle` and translates by `shift` into the world frame; derives edges and conflicts."""
        rot = geo.rotation(angle)

        def move(xy):
            return np.asarray(xy, np.float64) @ rot.T + shift

        drafts = [dataclasses.replace(d, xy=move(d.xy)) for d in self.lanes]
        area = _drivable_area(drafts, [shapely.affinity.affine_transform(
            p, [rot[0, 0], rot[0, 1], rot[1, 0], rot[1, 1], shift[0], shift[1]]) for p in self.areas])
        conflicts = _conflicts(drafts)
        light_index, lights = {}, 0
        for index, d in enumerate(drafts):
            if d.signal_group >= 0:
                light_index[index], lights = lights, lights + 1
        lanes = tuple(
            Lane(
                lane_id=FIRST_LANE_ID + i, xy=d.xy, width=d.width, speed_limit=d.speed_limit,
                lane_type=d.lane_type, successors=tuple(d.successors), predecessors=tuple(d.predecessors),
                left_neighbors=tuple(d.left), right_neighbors=tuple(d.right), signal_group=d.signal_group,
                light_index=light_index.get(i, -1), has_stop_sign=d.has_stop_sign, is_gated=d.is_gated,
                conflicts=conflicts[i],
                yields_to=tuple(c for c in conflicts[i] if d.yields and not drafts[c - FIRST_LANE_ID].yields),
                is_uturn=d.is_uturn,
            )
            for i, d in enumerate(drafts)
        )
        next_id = iter(range(FIRST_FEATURE_ID, FIRST_FEATURE_ID + 100_000))
        lines = tuple(MapPolyline(next(next_id), kind, _xyz(move(xy))) for xy, kind in self.lines)
        edges = tuple(MapPolyline(next(next_id), kind, _xyz(xy)) for xy, kind in _edge_rings(area))
        crosswalks = tuple(Crosswalk(next(next_id), move(poly), move(start), move(end), signalised)
                           for poly, start, end, signalised in self.crosswalks)
        stop_signs = tuple(MapPolyline(next(next_id), RG_STOP_SIGN, _xyz(lane.xy[-1:]))
                           for lane in lanes if lane.has_stop_sign)
        parking = np.array(self.parking).reshape(-1, 3)
        if len(parking):
            parking = np.concatenate([move(parking[:, :2]), geo.wrap_angle(parking[:, 2:] + angle)], axis=1)
        return RoadNetwork(self.topology, lanes, lines, edges, crosswalks, stop_signs, parking,
                           self.signal_plan, area)


MAP_BORDER_RUNOUT_M = 6.0


def _drivable_area(drafts: list[_LaneDraft], areas: list):
    strips = [LineString(_with_runout(d)).buffer(d.width / 2 + 0.1, cap_style="flat", join_style="round")
              for d in drafts]
    area = shapely.union_all(strips + areas)
    # Closing (grow then shrink) removes slivers between strips that only touch and rounds inner
    # corners, so the nearest edge point always tells on which side of the kerb a vehicle is.
    return area.buffer(2.0, quad_segs=4).buffer(-2.0, quad_segs=4)


def _with_runout(draft: _LaneDraft) -> np.ndarray:
    """Lanes that start or end at the map border get a few metres of road beyond, so vehicles
    entering or leaving the scene are never right next to the closing kerb. -> (n, 2)"""
    xy = draft.xy
    heading = geo.tangents(xy)
    if not draft.predecessors:
        xy = np.concatenate([xy[:1] - MAP_BORDER_RUNOUT_M * heading[:1], xy])
    if not draft.successors:
        xy = np.concatenate([xy, xy[-1:] + MAP_BORDER_RUNOUT_M * heading[-1:]])
    return xy


def _edge_rings(area) -> list[tuple[np.ndarray, int]]:
    """Road edges walked with the drivable area on their left: outer rings counter-clockwise
    (boundary), holes clockwise (median), each closed by repeating the first point."""
    polygons = [area] if area.geom_type == "Polygon" else list(area.geoms)
    rings = []
    for polygon in polygons:
        polygon = orient(polygon.simplify(0.05), sign=1.0)
        rings.append((np.asarray(polygon.exterior.coords)[:, :2], RG_ROAD_EDGE_BOUNDARY))
        for hole in polygon.interiors:
            if Polygon(hole).area > 4.0:
                rings.append((np.asarray(hole.coords)[:, :2], RG_ROAD_EDGE_MEDIAN))
    return rings


def _conflicts(drafts: list[_LaneDraft]) -> list[tuple[int, ...]]:
    """For each gated lane, the other gated lanes a vehicle could collide on (crossing or merging).
    Lanes leaving the same lane (diverging) are left to car following."""
    gated = [i for i, d in enumerate(drafts) if d.is_gated]
    out: list[tuple[int, ...]] = [() for _ in drafts]
    if not gated:
        return out
    points = [drafts[i].xy for i in gated]
    headings = [np.arctan2(*geo.tangents(xy)[:, ::-1].T) for xy in points]
    for a_pos, a in enumerate(gated):
        found = []
        for b_pos, b in enumerate(gated):
            if a == b or set(drafts[a].predecessors) & set(drafts[b].predecessors):
                continue
            dist = np.linalg.norm(points[a_pos][:, None, :] - points[b_pos][None, :, :], axis=-1)
            turn = np.abs(geo.wrap_angle(headings[a_pos][:, None] - headings[b_pos][None, :]))
            if np.any(dist < CONFLICT_DISTANCE_M) or np.any((dist < CROSSING_DISTANCE_M) & (turn > CROSSING_ANGLE_RAD)):
                found.append(FIRST_LANE_ID + b)
        out[a] = tuple(found)
    return out
