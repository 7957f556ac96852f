"""One scenario's map: nuPlan features around the ego trajectory -> MapPolylines, LaneLinks and the
stop points of lane connectors (where their traffic lights are placed)."""

from __future__ import annotations

import dataclasses

import numpy as np
import shapely
from shapely.geometry.polygon import orient

from scenariomax import schema as sch
from scenariomax.enrich.roadgraph import LaneLinks, MapPolyline
from scenariomax.sources.nuplan.map_reader import CityMap, FeatureTable

# nuPlan fids are per layer; one offset per layer keeps every roadgraph id unique and readable.
ID_BLOCK = 100_000_000
LANE_ID_OFFSET = 0
CONNECTOR_ID_OFFSET = 1 * ID_BLOCK
BOUNDARY_ID_OFFSET = 2 * ID_BLOCK
CROSSWALK_ID_OFFSET = 3 * ID_BLOCK
STOP_ID_OFFSET = 4 * ID_BLOCK
ROAD_EDGE_ID_OFFSET = 5 * ID_BLOCK

BIKE_LANE_TYPE_FID = 1  # lanes_polygons.lane_type_fid (second-hand: 0 vehicle, 1 bike)
STOP_SIGN_TYPE_FID = 1  # stop_polygons.stop_polygon_type_fid StopLineType.STOP_SIGN
BOUNDARY_TYPES = {0: sch.RG_BROKEN_SINGLE_WHITE, 2: sch.RG_SOLID_SINGLE_WHITE}  # others -> 0 unknown
MAX_FEATURE_LENGTH_M = 5_000.0  # longer lines are corrupt (nuPlan lanes are tens of metres)
_EDGE_CONTEXT_M = 50.0  # drivable polygons this far outside the crop still shape its edges


@dataclasses.dataclass(frozen=True)
class ScenarioMap:
    polylines: tuple  # MapPolyline, ...
    lane_links: tuple  # LaneLinks, ...
    stop_points: dict  # lane connector fid -> (x, y) start of its centreline


def map_id(offset: int, fid: int) -> int:
    if not 0 <= fid < ID_BLOCK:
        raise ValueError(f"map fid {fid} outside [0, {ID_BLOCK})")
    return offset + int(fid)


def scenario_map(city: CityMap, crop: tuple[float, float, float, float]) -> ScenarioMap:
    """Features overlapping the crop box (minx, miny, maxx, maxy) in UTM metres."""
    lanes = city.lanes.within_box(crop)
    connectors = city.connectors.within_box(crop)
    polylines = (_lane_polylines(lanes, connectors) + _boundary_polylines(city.boundaries.within_box(crop))
                 + _road_edge_polylines(city.drivable, crop) + _crosswalk_polylines(city.crosswalks.within_box(crop))
                 + _stop_sign_polylines(city.stop_polygons.within_box(crop)))
    stop_points = {}
    for fid, line in zip(connectors.fid, connectors.geometry):
        parts = _line_coords(line)
        if parts:
            stop_points[int(fid)] = (float(parts[0][0, 0]), float(parts[0][0, 1]))
    return ScenarioMap(tuple(polylines), tuple(lane_links(lanes, connectors)), stop_points)


def _line_coords(geometry) -> list[np.ndarray]:
    """(n, 2) coordinate arrays of each line part (polygons: exterior rings)."""
    if geometry is None or shapely.is_empty(geometry):
        return []
    parts = []
    for part in shapely.get_parts(geometry):
        if isinstance(part, shapely.Polygon):
            part = part.exterior
        if not isinstance(part, (shapely.LineString, shapely.LinearRing)):
            continue
        coords = shapely.get_coordinates(part)
        if len(coords) >= 2 and np.isfinite(coords).all() and part.length <= MAX_FEATURE_LENGTH_M:
            parts.append(coords)
    return parts


def _xyz(coords: np.ndarray) -> np.ndarray:
    # nuPlan maps are 2-D; z = 0.
    return np.column_stack([coords, np.zeros(len(coords))])


def _lane_polylines(lanes: FeatureTable, connectors: FeatureTable) -> list[MapPolyline]:
    out = []
    for fid, line, limit, lane_type in zip(lanes.fid, lanes.geometry, lanes.attributes["speed_limit"],
                                           lanes.attributes["lane_type"]):
        kind = sch.RG_LANE_BIKE if lane_type == BIKE_LANE_TYPE_FID else sch.RG_LANE_SURFACE_STREET
        out += [MapPolyline(map_id(LANE_ID_OFFSET, fid), kind, _xyz(c), float(limit)) for c in _line_coords(line)]
    for fid, line, limit in zip(connectors.fid, connectors.geometry, connectors.attributes["speed_limit"]):
        out += [MapPolyline(map_id(CONNECTOR_ID_OFFSET, fid), sch.RG_LANE_SURFACE_STREET, _xyz(c), float(limit))
                for c in _line_coords(line)]
    return out


def _boundary_polylines(boundaries: FeatureTable) -> list[MapPolyline]:
    out = []
    for fid, line, kind in zip(boundaries.fid, boundaries.geometry, boundaries.attributes["boundary_type"]):
        rg_type = BOUNDARY_TYPES.get(int(kind), 0)
        out += [MapPolyline(map_id(BOUNDARY_ID_OFFSET, fid), rg_type, _xyz(c)) for c in _line_coords(line)]
    return out


def _crosswalk_polylines(crosswalks: FeatureTable) -> list[MapPolyline]:
    return [MapPolyline(map_id(CROSSWALK_ID_OFFSET, fid), sch.RG_CROSSWALK, _xyz(c), closed=True)
            for fid, polygon in zip(crosswalks.fid, crosswalks.geometry) for c in _line_coords(polygon)]


def _stop_sign_polylines(stops: FeatureTable) -> list[MapPolyline]:
    return [MapPolyline(map_id(STOP_ID_OFFSET, fid), sch.RG_STOP_SIGN, _xyz(c), closed=True)
            for fid, polygon, kind in zip(stops.fid, stops.geometry, stops.attributes["stop_type"])
            if kind == STOP_SIGN_TYPE_FID for c in _line_coords(polygon)]


def _road_edge_polylines(drivable: FeatureTable, crop) -> list[MapPolyline]:
    """Outline of the drivable area inside the crop, walked with the road on the LEFT."""
    minx, miny, maxx, maxy = crop
    context = drivable.within_box((minx - _EDGE_CONTEXT_M, miny - _EDGE_CONTEXT_M,
                                   maxx + _EDGE_CONTEXT_M, maxy + _EDGE_CONTEXT_M))
    polygons = [p for g in context.geometry for p in shapely.get_parts(shapely.make_valid(g))
                if isinstance(p, shapely.Polygon) and not p.is_empty]
    if not polygons:
        return []
    union = shapely.union_all(polygons)
    shapely.prepare(union)
    box = shapely.box(minx, miny, maxx, maxy)
    rings = []
    for polygon in shapely.get_parts(union):
        if isinstance(polygon, shapely.Polygon):
            oriented = orient(polygon, sign=1.0)  # exterior CCW, holes CW: the area is on the left
            rings += [shapely.LineString(oriented.exterior.coords)]
            rings += [shapely.LineString(ring.coords) for ring in oriented.interiors]
    out = []
    for ring in rings:
        for piece in shapely.get_parts(shapely.line_merge(ring.intersection(box))
                                       if not ring.within(box) else ring):
            coords = [c for c in _line_coords(piece)]
            for line in coords:
                out.append(MapPolyline(ROAD_EDGE_ID_OFFSET + len(out), sch.RG_ROAD_EDGE_BOUNDARY,
                                       _xyz(_road_on_left(line, union))))
    return out


def _road_on_left(coords: np.ndarray, area) -> np.ndarray:
    """Flips the line when the drivable area lies on its right (clipping may reverse pieces)."""
    seg = np.diff(coords, axis=0)
    k = int(np.argmax(np.hypot(seg[:, 0], seg[:, 1])))
    mid = (coords[k] + coords[k + 1]) / 2
    normal = np.array([-seg[k, 1], seg[k, 0]]) / max(np.hypot(*seg[k]), 1e-9)
    left_inside = area.contains(shapely.Point(*(mid + 0.05 * normal)))
    right_inside = area.contains(shapely.Point(*(mid - 0.05 * normal)))
    return coords[::-1] if (right_inside and not left_inside) else coords


def lane_links(lanes: FeatureTable, connectors: FeatureTable) -> list[LaneLinks]:
    """Successors/predecessors through lane connectors; left/right neighbours within a lane group
    (lane_index 0 is the leftmost lane). Links to features outside the crop are dropped."""
    lane_fids = set(lanes.fid.tolist())
    successors: dict[int, list[int]] = {}
    predecessors: dict[int, list[int]] = {}
    for fid, up, down in zip(connectors.fid, connectors.attributes["upstream_lane"],
                             connectors.attributes["downstream_lane"]):
        if up in lane_fids:
            successors.setdefault(int(up), []).append(map_id(CONNECTOR_ID_OFFSET, fid))
        if down in lane_fids:
            predecessors.setdefault(int(down), []).append(map_id(CONNECTOR_ID_OFFSET, fid))
    slot = {(int(g), int(i)): int(f) for f, g, i in zip(lanes.fid, lanes.attributes["lane_group"],
                                                         lanes.attributes["lane_index"]) if g >= 0 and i >= 0}
    links = []
    for fid, group, index in zip(lanes.fid, lanes.attributes["lane_group"], lanes.attributes["lane_index"]):
        left = slot.get((int(group), int(index) - 1)) if group >= 0 and index >= 0 else None
        right = slot.get((int(group), int(index) + 1)) if group >= 0 and index >= 0 else None
        links.append(LaneLinks(
            map_id(LANE_ID_OFFSET, fid), sorted(successors.get(int(fid), [])), sorted(predecessors.get(int(fid), [])),
            [map_id(LANE_ID_OFFSET, left)] if left is not None else [],
            [map_id(LANE_ID_OFFSET, right)] if right is not None else []))
    for fid, up, down in zip(connectors.fid, connectors.attributes["upstream_lane"],
                             connectors.attributes["downstream_lane"]):
        links.append(LaneLinks(
            map_id(CONNECTOR_ID_OFFSET, fid),
            [map_id(LANE_ID_OFFSET, down)] if down in lane_fids else [],
            [map_id(LANE_ID_OFFSET, up)] if up in lane_fids else []))
    return links
